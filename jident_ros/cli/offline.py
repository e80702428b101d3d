"""``jident diagnose``: the diagnostic node's per-window diagnosis on a recording, without ROS.

Reads the ``drive/signals`` batches of an MCAP recording (:func:`jident_ros.bag.reader.read_bag`; topic
name ending in ``drive/signals``, any namespace; std_msgs/Float64MultiArray in the 2-D sample x channel
layout of docs/interfaces.md), feeds them in the order of their samples' drive time ``t`` (not the
recorder's receive time) through the windowing node's
detector (:class:`jident_ros.stream.detector.BacklashDetector`, paper inequality 1) and diagnoses each
captured window with :func:`jident_ros.identify.diagnosis.diagnose_window`, the function the diagnostic node
runs.  A recording of the node set therefore gives the same J1 estimates offline as live and as
replayed (tested).

K2 (the backlash width of inequality 1): the ``backlash_width_m`` argument when given; else the
recording's ``drive/backlash_width`` messages (in receive-time order, as the windowing node with
``backlash_width_from_topic``); else the windowing node's default.  The true J1 of a window, when the
recording has it: the ``drive/case`` row whose ``entry_time_s`` is the window's (within T_s/2), else
the last ``drive/true_inertia`` received before the window's entry sample.

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from jident_ros.bag.drive_replay import DriveReplay, in_sample_time_order, read_drive_messages
from jident_ros.bag.messages import deserialize
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.diagnosis import GAP_METHODS, WindowDiagnosis, detector_arguments, diagnose_window
from jident_ros.identify.levels import ERROR, LEVEL_NAMES
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.verdict import VerdictPolicy
from jident_ros.parameters import DIAGNOSTIC as DIAGNOSTIC_DEFAULTS
from jident_ros.parameters import WINDOWING as WINDOWING_DEFAULTS
from jident_ros.stream.detector import BacklashDetector, stream_batches
from jident_ros.stream.dynamics import DynamicsDetector
from jident_ros.stream.flank import DETECTORS, FlankDetector
from jident_ros.stream.inputs import InputError, JointStateAdapter, read_csv
from jident_ros.stream.layout import DRIVE_TOPICS, REQUIRED_CHANNELS, SIGNALS_TOPIC, WIDTH_TOPIC, pack
from jident_ros.stream.layout import topic_matches as _matches

try:  # reading a `ros2 bag record` of /joint_states (any storage, any distro) needs rosbags
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
except ImportError:  # pragma: no cover - the drive/signals path does not need it
    AnyReader = None


class OfflineError(ValueError):
    """A user error (missing recording, no drive/signals topic, bad option): one line, exit status 2."""


def multiarray_message(array, channels: Sequence[str], header: Sequence[float] = ()) -> dict:
    """(n, c) samples + channel names -> std_msgs/Float64MultiArray as a dict of fields in the
    drive/signals layout (``header`` values in front, data_offset = len(header)), e.g. for
    :meth:`jident_ros.bag.writer.BagWriter.write` without ROS."""
    data, dims, offset = pack(array, channels, header)
    return {"layout": {"dim": [{"label": label, "size": int(size), "stride": int(stride)}
                               for label, size, stride in dims], "data_offset": int(offset)},
            "data": data}


@dataclass
class OfflineWindow:
    """One captured window and its diagnosis.

    window_id : running number of the captured windows (from 1)
    entry_time_s : drive clock t of the backlash-zone entry sample, s
    backlash_width_m : K2 the detector used, m
    true_inertia_kgm2 : J1 of the simulated case (drive/case, drive/true_inertia), kg m^2, or None
    diagnosis : the :class:`~jident_ros.identify.diagnosis.WindowDiagnosis`
    """

    window_id: int
    entry_time_s: float
    backlash_width_m: float
    true_inertia_kgm2: Optional[float]
    diagnosis: WindowDiagnosis
    backlash_width_estimate_m: Optional[float] = None   # the flank detector's K2 of this traversal, m
    backlash_width_se_m: Optional[float] = None
    detector: str = "paper"
    flags: tuple = ()                                   # "second_entry", "cut_off"

    @property
    def inertia_kgm2(self) -> Optional[float]:
        """The J1 the diagnostic node would publish on inertia_estimate, kg m^2 (None: not diagnosed)."""
        return self.diagnosis.inertia_kgm2

    @property
    def error_percent(self) -> Optional[float]:
        """(estimate - true J1) / true J1 in %, when both are known."""
        if self.true_inertia_kgm2 is None or self.inertia_kgm2 is None:
            return None
        return (self.inertia_kgm2 - self.true_inertia_kgm2) / self.true_inertia_kgm2 * 100.0

    def to_json(self) -> dict:
        d = self.diagnosis
        return {"window_id": self.window_id, "entry_time_s": self.entry_time_s,
                "backlash_width_m": _json_value(self.backlash_width_m), "true_inertia_kgm2": self.true_inertia_kgm2,
                "inertia_estimate_kgm2": d.inertia_kgm2, "estimate_source": d.source,
                "identified_class_kgm2": d.class_kgm2, "error_percent": self.error_percent,
                "level": d.level_name, "status": d.status, "refused_reason": d.refused_reason,
                "message": d.message, "detector": self.detector,
                "backlash_width_estimate_m": _json_value(self.backlash_width_estimate_m),
                "backlash_width_se_m": _json_value(self.backlash_width_se_m), "flags": list(self.flags),
                "values": {k: _json_value(v) for k, v in d.values}}


@dataclass
class OfflineResult:
    """Everything ``jident diagnose`` found in one recording."""

    recording: str
    signals_topic: str
    backlash_width_source: str          # "option", the width topic's name, or "default"
    windows: list = field(default_factory=list)    # OfflineWindow, in stream order
    dropped: dict = field(default_factory=dict)    # windowing drop reason -> count (non-zero only)
    samples: int = 0
    batches: int = 0
    clock_jumps: int = 0                # forward jumps of t between batches outside a window (DriveReplay)
    library_path: Optional[str] = None
    library_error: Optional[str] = None
    cut_off: list = field(default_factory=list)    # windows cut off by the end of the data: {entry_time_s, samples}
    jitter: Optional[dict] = None                  # JointState stamp period statistics
    notes: list = field(default_factory=list)      # one line each: a file read by salvaging it, dropped batches
    no_entry_hint: str = ""            # no window: why not, and what to set (the detector's no_entry_reason)
    detector: str = ""                 # the entry detector that ran (flank, paper, dynamics)

    @property
    def estimates(self) -> list:
        """The J1 estimates (kg m^2) of the diagnosed windows, in order: what inertia_estimate carried."""
        return [w.inertia_kgm2 for w in self.windows if w.inertia_kgm2 is not None]

    def level_counts(self) -> dict:
        out = {name: 0 for name in ("OK", "WARN", "ERROR")}
        for w in self.windows:
            out[w.diagnosis.level_name] = out.get(w.diagnosis.level_name, 0) + 1
        return out

    def to_json(self) -> dict:
        return {"recording": self.recording, "signals_topic": self.signals_topic,
                "backlash_width_source": self.backlash_width_source, "samples": self.samples,
                "batches": self.batches, "clock_jumps": self.clock_jumps, "dropped": dict(self.dropped),
                "library": self.library_path,
                "library_error": self.library_error, "notes": list(self.notes), "levels": self.level_counts(),
                "cut_off": [{k: _json_value(v) for k, v in c.items()} for c in self.cut_off],
                "jitter": None if self.jitter is None else {k: _json_value(v) for k, v in self.jitter.items()},
                "windows": [w.to_json() for w in self.windows]}


def _json_value(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return [_json_value(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_json_value(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(float(v)) else None
    return v


def _float_data(msg, topic: str) -> float:
    v = float(msg.data)
    if not math.isfinite(v) or v <= 0:
        raise OfflineError(f"{topic}: data must be a finite number > 0, got {v!r}")
    return v


def diagnose_recording(path, *, system=None, method=None, p: float = 2.0, library=None, library_path=None,
                       build_if_missing: bool = True, gap_method: str = "auto", image_method: bool = True,
                       backlash_width_m: Optional[float] = None, signals_topic: Optional[str] = None,
                       channels: Optional[Sequence[str]] = None, gap_tolerance: Optional[float] = None,
                       log: Callable[[str], Any] = lambda text: None,
                       on_window: Optional[Callable[[OfflineWindow], Any]] = None,
                       policy: Optional[VerdictPolicy] = None,
                       detector: str = "auto", gear_ratio: float = 1.0) -> OfflineResult:
    """Diagnose every backlash entry of a recording as the windowing + diagnostic nodes do.

    Parameters
    ----------
    path : bag directory or .mcap file
    system, method : SystemConfig / MethodConfig (default: the package's config/system.yaml, method.yaml)
    p : KHM exponent of the image method, one of ``method.p_values``
    library : a loaded PatternLibrary (else loaded from ``library_path``, default the CLI's cache path,
        built and saved there when missing and ``build_if_missing``, as the diagnostic node does)
    gap_method : one of :data:`jident_ros.identify.diagnosis.GAP_METHODS`
    image_method : run the paper's image method
    backlash_width_m : K2, m; None: from drive/backlash_width messages, else the windowing node's default
    signals_topic : the drive/signals topic to read; None: the recording's only topic ending in drive/signals
    channels : window channels besides t (default: the windowing node's ``channels`` that the first
        batch carries; alpha1 and alpha2 are required)
    gap_tolerance : the detector's gap tolerance in sample periods (default: the windowing node's)
    log : gets progress lines (library loading/building, warnings)
    on_window : called with each :class:`OfflineWindow` as soon as it is diagnosed
    policy : the publishing policy (default: the diagnostic node's default parameters,
        :func:`default_policy`)

    Raises :class:`OfflineError` (one line naming the field and value) on bad input.
    """
    system = load_system_config() if system is None else system
    method = load_method_config() if method is None else method
    if gap_method not in GAP_METHODS:
        raise OfflineError(f"gap_method: expected one of {', '.join(GAP_METHODS)}, got {gap_method!r}")
    if not image_method and gap_method in ("none", "off"):
        raise OfflineError("image_method: must be on when gap_method is none (nothing would be identified)")
    if float(p) not in [float(q) for q in method.p_values]:
        raise OfflineError(f"p: must be one of method.p_values {[float(q) for q in method.p_values]}, got {p!r}")
    policy = default_policy() if policy is None else policy
    for name, what in policy.problems():
        raise OfflineError(f"{name}: must be {what}, got {getattr(policy, name)!r}")
    if backlash_width_m is not None and not (math.isfinite(backlash_width_m) and backlash_width_m > 0):
        raise OfflineError(f"backlash_width_m: must be a finite number > 0, got {backlash_width_m!r}")
    notes: list = []
    messages, all_topics = read_drive_messages(path, OfflineError, note=notes.append)
    found = sorted({t for t, _, _ in messages if _matches(t, SIGNALS_TOPIC)})
    if signals_topic is not None:
        if signals_topic not in found:
            raise OfflineError(f"signals topic {signals_topic!r}: not in recording {path} "
                               f"(drive/signals topics: {', '.join(found) or 'none'})")
        topic = signals_topic
    elif not found:
        raise OfflineError(f"recording {path}: no drive/signals topic (topics: {', '.join(all_topics) or 'none'})")
    elif len(found) > 1:
        raise OfflineError(f"recording {path}: several drive/signals topics ({', '.join(found)}); "
                           f"choose one with --topic")
    else:
        topic = found[0]
    prefix = topic[:-len(SIGNALS_TOPIC)]
    names = {rel: prefix + rel for rel in DRIVE_TOPICS}
    unpacked: dict = {}
    messages = in_sample_time_order([m for m in messages if m[0] in names.values()], topic, unpacked)

    def decode(topic_name, msg_type, raw):
        try:
            return deserialize(msg_type, raw)
        except ValueError as exc:
            raise OfflineError(f"{topic_name}: undecodable {msg_type} message ({exc})") from None

    # K2: the option, else the recording's drive/backlash_width, else the windowing node's default
    widths = [m for m in messages if m[0] == names[WIDTH_TOPIC]]
    if backlash_width_m is not None:
        width, width_source = float(backlash_width_m), "option"
    elif widths:
        width, width_source = _float_data(decode(*widths[0]), widths[0][0]), widths[0][0]
    else:
        width, width_source = float(WINDOWING_DEFAULTS["backlash_width_m"]), "default"
    follow_width = width_source not in ("option", "default")

    result = OfflineResult(str(path), topic, width_source, notes=notes)
    for text in notes:
        log(text)
    if image_method and library is None:
        lib_path = Path(library_path).expanduser() if library_path else default_library_path(system, method)
        result.library_path = str(lib_path)
        library, result.library_error = load_pattern_library(lib_path, system, method, build_if_missing,
                                                             log=log, warn=log)
        if result.library_error:
            log(f"{result.library_error}; windows are diagnosed from the gap only (level ERROR)")

    ts = float(system.sampling.sample_period_s)

    def make_detector(batch_channels, topic_name, k2):
        kind = detector
        if kind == "auto":
            # the paper detector only where K2 is known (given, or the drive publishes it: zone-centred angles, our
            # simulator); any other drive/signals recording is read as raw encoder angles (issue 20)
            kind = ("paper" if width_source != "default" else "flank" if "alpha2" in batch_channels
                    else "dynamics")
        result.detector = kind
        if kind != "paper":
            result.backlash_width_source = "estimated"
        return _make_detector(system, k2, channels, batch_channels, gap_tolerance, WINDOWING_DEFAULTS, topic_name,
                              kind, gear_ratio)

    replay = DriveReplay(names, width, follow_width, decode=decode, read_width=_float_data,
                         read_truth=lambda msg, topic_name: float(msg.data), make_detector=make_detector,
                         log=log, unpacked=unpacked)
    diag = _window_diagnoser(system, method, p, library, gap_method, image_method, result, policy)
    for win in replay.windows(messages):
        _add_window(result, win, diag(win), replay.true_inertia(win.entry_time_s, ts)[0], on_window)
    detector = replay.detector
    if detector is None:
        if replay.dropped_before_start:
            raise OfflineError(f"recording {path}: topic {topic} holds no readable batch "
                               f"({len(replay.dropped_before_start)} dropped: {replay.dropped_before_start[0]})")
        raise OfflineError(f"recording {path}: topic {topic} holds no message")
    if replay.dropped_before_start:
        notes.append(f"{topic}: {len(replay.dropped_before_start)} unreadable batch(es) before the first readable "
                     f"one dropped and counted (layout): {replay.dropped_before_start[0]}")
        log(notes[-1])
    _finish(result, detector, log)
    result.clock_jumps = replay.clock_jumps
    return result


def default_policy(**overrides) -> VerdictPolicy:
    """The diagnostic node's default publishing policy (jident_ros/parameters.py), with ``overrides``."""
    return VerdictPolicy.from_params(dict(DIAGNOSTIC_DEFAULTS, **overrides))


def _window_diagnoser(system, method, p, library, gap_method, image_method, result, policy=None):
    def diag(win):
        try:
            return diagnose_window(win.as_dict(), win.entry_index, win.backlash_width_m, win.wheel_radius_m,
                                   win.sample_period_s, library=library, system=system, method=method, p=float(p),
                                   gap_method=gap_method, image_method=image_method,
                                   library_error=result.library_error or "", window_id=win.window_id,
                                   entry_time_s=win.entry_time_s, policy=policy, **detector_arguments(win))
        except Exception as exc:  # as the node: report the window, go on
            return WindowDiagnosis(ERROR, f"window could not be diagnosed: internal error "
                                          f"{type(exc).__name__}: {exc}", [])
    return diag


def _add_window(result, win, d, true_j1, on_window):
    est = getattr(win, "backlash_width_estimate_m", math.nan)
    ow = OfflineWindow(win.window_id, win.entry_time_s, win.backlash_width_m, true_j1, d,
                       est if math.isfinite(est) else None,
                       win.backlash_width_se_m if math.isfinite(est) else None, win.detector,
                       tuple(win.flag_names))
    result.windows.append(ow)
    if on_window is not None:
        on_window(ow)


def _finish(result, detector, log):
    """The end of the data: a window in progress is reported (cut_off), the counts collected; without a window,
    why (the detector's no_entry_reason, in result.no_entry_hint)."""
    for ev in detector.finish():
        w = ev.window
        result.cut_off.append({"entry_time_s": w.entry_time_s, "samples_from_entry": len(w) - w.entry_index})
        log(f"window cut off by the end of the data: {ev.detail}")
    if not result.windows and not result.cut_off and hasattr(detector, "no_entry_reason"):
        result.no_entry_hint = f"the {result.detector} detector: {detector.no_entry_reason()}"
    result.samples, result.batches = detector.samples_seen, detector.batches_seen
    result.dropped = {r: n for r, n in detector.counts.items() if n}


def _make_detector(system, width, channels, batch_channels, gap_tolerance, defaults, topic_name,
                   detector: str = "paper", gear_ratio: float = 1.0):
    sampling = system.sampling
    if channels is None:
        channels = [c for c in defaults["channels"] if c in batch_channels]
    needed = REQUIRED_CHANNELS if detector != "dynamics" else ("t", "m_el")
    missing = [c for c in needed if c not in batch_channels]
    if missing:
        raise OfflineError(f"{topic_name}: channel {missing[0]!r} missing (the data carry "
                           f"{','.join(batch_channels)}; the {detector} detector needs {', '.join(needed)})")
    common = dict(channels=("t",) + tuple(c for c in channels if c != "t"),
                  samples_before_entry=sampling.samples_before_entry, samples_from_entry=sampling.samples_from_entry,
                  gap_tolerance=defaults["gap_tolerance"] if gap_tolerance is None else gap_tolerance)
    try:
        if detector == "dynamics":
            return DynamicsDetector(system.load.wheel_radius_m, sampling.sample_period_s, gear_ratio=gear_ratio,
                                    nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2, **common)
        if detector == "flank":
            return FlankDetector(system.load.wheel_radius_m, sampling.sample_period_s, gear_ratio=gear_ratio,
                                 nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2, **common)
        if detector != "paper":
            raise ValueError(f"detector: expected one of {', '.join(DETECTORS)}, got {detector!r}")
        return BacklashDetector(width, system.load.wheel_radius_m, sampling.sample_period_s, **common)
    except ValueError as exc:
        raise OfflineError(str(exc)) from None


# --------------------------------------------------------------------------- JointState bags, CSV files

def jointstate_batches(path, sample_period_s: float, motor_joint: str = "motor", load_joint: str = "load",
                       imu_axis: str = "x", topic: Optional[str] = None, batch_size: int = 50):
    """(adapter, batch iterator, joint_states topic) of a `ros2 bag record` bag holding sensor_msgs/JointState
    (topic ending in ``joint_states``, any namespace) and optionally sensor_msgs/Imu (ending in ``imu``),
    read with rosbags' AnyReader; the header stamps give t."""
    if AnyReader is None:
        raise OfflineError("reading JointState bags needs the rosbags package (pip install rosbags)")
    path = Path(path)
    reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except Exception as exc:
        raise OfflineError(f"recording {path}: cannot be read as a rosbag2 bag ({type(exc).__name__}: {exc})") from None
    js = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/JointState" and _matches(c.topic, "joint_states")]
    topics = sorted({c.topic for c in js})
    if topic is not None:
        js = [c for c in js if c.topic == topic]
        if not js:
            raise OfflineError(f"joint_states topic {topic!r}: not in recording {path} (found: {', '.join(topics) or 'none'})")
    elif len(topics) > 1:
        raise OfflineError(f"recording {path}: several joint_states topics ({', '.join(topics)}); choose one with --topic")
    if not js:
        raise OfflineError(f"recording {path}: no drive/signals topic and no sensor_msgs/JointState topic ending in "
                           f"joint_states "
                           f"(topics: {', '.join(sorted({c.topic for c in reader.connections})) or 'none'})")
    prefix = js[0].topic[:-len("joint_states")]
    imu = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/Imu" and c.topic == prefix + "imu"]
    adapter = JointStateAdapter(sample_period_s, motor_joint, load_joint, batch_size=batch_size,
                                use_imu=bool(imu), imu_axis=imu_axis)

    def batches():
        try:
            for conn, _, raw in reader.messages(connections=js + imu):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
                if conn.msgtype.endswith("Imu"):
                    yield from adapter.push_imu(stamp, msg.linear_acceleration)
                else:
                    yield from adapter.push(stamp, msg.name, msg.position, msg.velocity, msg.effort)
            yield from adapter.flush()
        finally:
            reader.close()
    return adapter, batches(), js[0].topic


def diagnose_samples(path, *, system=None, method=None, p: float = 2.0, library=None, library_path=None,
                     build_if_missing: bool = True, gap_method: str = "auto", image_method: bool = True,
                     detector: str = "flank", backlash_width_m: Optional[float] = None, gear_ratio: float = 1.0,
                     motor_joint: str = "motor", load_joint: str = "load", imu_axis: str = "x",
                     topic: Optional[str] = None, maps: Optional[dict] = None,
                     log: Callable[[str], Any] = lambda text: None,
                     on_window: Optional[Callable[[OfflineWindow], Any]] = None,
                     policy: Optional[VerdictPolicy] = None) -> OfflineResult:
    """Diagnose a JointState bag or a CSV file (``.csv``) as the windowing (``input: joint_states``) and
    diagnostic nodes do.  ``detector``: "flank" (no K2; the default for real drives) or "paper"
    (inequality 1 with ``backlash_width_m``, zone-centred angles).  Raises OfflineError on bad input."""
    system = load_system_config() if system is None else system
    method = load_method_config() if method is None else method
    policy = default_policy() if policy is None else policy
    if detector not in DETECTORS:
        raise OfflineError(f"detector: expected one of {', '.join(DETECTORS)}, got {detector!r}")
    if detector == "paper" and backlash_width_m is None:
        raise OfflineError("backlash_width_m: the paper detector (inequality 1) needs K2 (--backlash-width-m)")
    if detector in ("flank", "dynamics") and backlash_width_m is not None:
        raise OfflineError("backlash_width_m: only for --detector paper (the flank and dynamics detectors need no K2)")
    if not (math.isfinite(gear_ratio) and gear_ratio > 0):
        raise OfflineError(f"gear_ratio: must be a finite number > 0, got {gear_ratio!r}")
    if float(p) not in [float(q) for q in method.p_values]:
        raise OfflineError(f"p: must be one of method.p_values {[float(q) for q in method.p_values]}, got {p!r}")
    ts = float(system.sampling.sample_period_s)
    path = Path(path)
    adapter = None
    try:
        if path.suffix.lower() == ".csv":
            data, channels, ignored = read_csv(path, maps)
            if ignored:
                log(f"{path}: columns ignored (not channels): {', '.join(ignored)}")
            source, batches = str(path), ((b, channels) for b in stream_batches(data, 50))
        else:
            adapter, batches, source = jointstate_batches(path, ts, motor_joint, load_joint, imu_axis, topic)
    except InputError as exc:
        raise OfflineError(str(exc)) from None
    result = OfflineResult(str(path), source, "estimated" if detector != "paper" else "option", detector=detector)
    if image_method and library is None:
        lib_path = Path(library_path).expanduser() if library_path else default_library_path(system, method)
        result.library_path = str(lib_path)
        library, result.library_error = load_pattern_library(lib_path, system, method, build_if_missing,
                                                             log=log, warn=log)
    diag = _window_diagnoser(system, method, p, library, gap_method, image_method, result, policy)
    det = None
    for arr, channels in batches:
        if det is None:
            det = _make_detector(system, backlash_width_m, None, channels, None, WINDOWING_DEFAULTS, source,
                                 detector, gear_ratio)
        for ev in det.push(arr, channels):
            if ev.kind == "window":
                _add_window(result, ev.window, diag(ev.window), None, on_window)
    if det is None:
        raise OfflineError(f"recording {path}: no sample")
    _finish(result, det, log)
    if adapter is not None:
        result.jitter = adapter.jitter()
        result.dropped.update({f"jointstate.{k}": v for k, v in adapter.counts.items()
                               if v and k in ("missing_joint", "imu_unmatched")})
        if result.jitter.get("periods") and not result.jitter["period_matches"]:
            log(f"{source}: stamp period {result.jitter['median_period_s']:.6g} s (median) does not match "
                f"sampling.sample_period_s {ts:g} s")
    return result


# --------------------------------------------------------------------------- output

TABLE_HEADER = (f"{'window':>6}  {'entry_t_s':>10}  {'true_J1':>8}  {'J1_estimate':>11}  {'source':>6}  "
                f"{'class':>6}  {'error_%':>7}  {'level':<5}  message")


def format_window_line(w: OfflineWindow) -> str:
    """One line per window: entry time, true J1, estimate (kg m^2), its source, class, error, level."""
    d = w.diagnosis

    def num(v, fmt):
        return "-" if v is None else format(v, fmt)
    return (f"{w.window_id:>6}  {w.entry_time_s:>10.4f}  {num(w.true_inertia_kgm2, '>8.5g')}  "
            f"{num(d.inertia_kgm2, '>11.6g')}  {d.source or '-':>6}  {num(d.class_kgm2, '>6.5g')}  "
            f"{num(w.error_percent, '>+7.3f')}  {LEVEL_NAMES[d.level]:<5}  {d.message}")


def summary_line(result: OfflineResult) -> str:
    lv = result.level_counts()
    k2 = {"option": "from --backlash-width-m", "default": "the windowing node's default",
          "estimated": "estimated per window"}.get(result.backlash_width_source, f"from {result.backlash_width_source}")
    text = (f"{len(result.windows)} window(s) from {result.signals_topic} ({result.samples} samples in "
            f"{result.batches} batches, K2 {k2}): {lv['OK']} OK, {lv['WARN']} WARN, {lv['ERROR']} ERROR")
    if result.clock_jumps:
        text += f"; the drive clock jumped forward {result.clock_jumps} time(s) between windows (history restarted)"
    if result.dropped:
        text += "; dropped: " + ", ".join(f"{r} {n}" for r, n in result.dropped.items())
    if result.cut_off:
        text += "; cut off by the end of the data: " + ", ".join(
            f"entry at {c['entry_time_s']:.4f} s ({c['samples_from_entry']} samples)" for c in result.cut_off)
    flagged = [w.window_id for w in result.windows if "second_entry" in w.flags]
    if flagged:
        text += f"; second entry inside window(s) {', '.join(map(str, flagged))}"
    errs = [abs(w.error_percent) for w in result.windows if w.error_percent is not None]
    if errs:
        text += f"; largest |J1 error| against the true J1 {max(errs):.3f} %"
    return text


def write_json(result: OfflineResult, out) -> Path:
    out = Path(out)
    if out.parent and not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result.to_json(), indent=1, allow_nan=False) + "\n")
    return out


__all__ = ["OfflineError", "OfflineResult", "OfflineWindow", "default_policy", "diagnose_recording",
           "diagnose_samples", "format_window_line", "jointstate_batches",
           "multiarray_message", "summary_line", "write_json", "TABLE_HEADER"]
