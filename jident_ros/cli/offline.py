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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from jident_ros.bag.drive_replay import DriveReplay, in_sample_time_order, read_drive_messages
from jident_ros.bag.messages import deserialize
from jident_ros.cli.jointstate_bag import jointstate_batches
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig, WindowDiagnosis
from jident_ros.identify.levels import ERROR, LEVEL_NAMES
from jident_ros.identify.library import IMAGE_METHOD_OFF, default_library_path, load_pattern_library
from jident_ros.identify.monitor import DetectorConfig, DriveMonitor, make_detector, required_channels
from jident_ros.identify.verdict import VerdictPolicy
from jident_ros.parameters import DIAGNOSTIC as DIAGNOSTIC_DEFAULTS
from jident_ros.parameters import WINDOWING as WINDOWING_DEFAULTS
from jident_ros.parameters import gap_method_problem
from jident_ros.stream.flank import DETECTORS
from jident_ros.stream.imu_skew import ImuSkewGuard
from jident_ros.stream.inputs import CsvStream, InputError
from jident_ros.stream.layout import DRIVE_TOPICS, SIGNALS_TOPIC, WIDTH_TOPIC, pack
from jident_ros.stream.layout import topic_matches as _matches
from jident_ros.stream.text import plain_numbers


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
    recontact_time_s: Optional[float] = None            # drive clock t of the detector's first contact row, s
    same_traversal_as: Optional[int] = None             # the window whose gap fit read the same traversal (trend: once)

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
                "recontact_time_s": self.recontact_time_s,
                "values": {k: _json_value(v) for k, v in d.values}}


@dataclass
class OfflineResult:
    """Everything ``jident diagnose`` found in one recording."""

    recording: str
    signals_topic: str
    backlash_width_source: str          # "option", the width topic's name, or "default"
    windows: list = field(default_factory=list)    # OfflineWindow, in stream order
    dropped: dict = field(default_factory=dict)    # windowing drop reason -> count (non-zero only)
    windows_lost: dict = field(default_factory=dict)   # drop reason -> windows in progress it lost (entry found)
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
                "windows_lost": dict(self.windows_lost), "library": self.library_path,
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


@dataclass(frozen=True)
class OfflineOptions:
    """How ``jident diagnose`` reads and diagnoses a recording (the keyword arguments of :func:`diagnose_recording`
    and :func:`diagnose_samples`).

    system, method : SystemConfig / MethodConfig (default: the package's config/system.yaml, method.yaml)
    p : KHM exponent of the image method, one of ``method.p_values``
    library : a loaded PatternLibrary (else loaded from ``library_path``, default the CLI's cache path,
        built and saved there when missing and ``build_if_missing``, as the diagnostic node does)
    gap_method : one of :data:`jident_ros.parameters.GAP_METHODS`
    image_method : run the paper's image method
    policy : the publishing policy (default: the diagnostic node's default parameters, :func:`default_policy`)
    backlash_width_m : K2, m.  A drive/signals recording: None = from drive/backlash_width messages, else the
        windowing node's default.  JointState/CSV: only (and needed) with the paper detector
    detector : 'paper', 'flank', 'dynamics' or 'auto' (None: 'auto' for drive/signals: paper where K2 is known --
        backlash_width_m or the recording's drive/backlash_width --, else flank, dynamics without alpha2; 'flank'
        for JointState/CSV)
    gear_ratio : N of the flank and dynamics detectors
    signals_topic : drive/signals: the topic to read (None: the recording's only topic ending in drive/signals)
    channels : drive/signals: window channels besides t (default: the windowing node's ``channels`` that the
        first batch carries; alpha1 and alpha2 are required)
    gap_tolerance : drive/signals: the detector's gap tolerance in sample periods (default: the windowing node's)
    motor_joint, load_joint, imu_axis, topic : JointState: the joints, the Imu axis that is a1, the topic
    maps : CSV: column maps (:class:`jident_ros.stream.inputs.CsvStream`)
    """

    system: Any = None
    method: Any = None
    p: float = 2.0
    library: Any = None
    library_path: Any = None
    build_if_missing: bool = True
    gap_method: str = "auto"
    image_method: bool = True
    policy: Optional[VerdictPolicy] = None
    backlash_width_m: Optional[float] = None
    detector: Optional[str] = None
    gear_ratio: float = 1.0
    signals_topic: Optional[str] = None
    channels: Optional[Sequence[str]] = None
    gap_tolerance: Optional[float] = None
    motor_joint: str = "motor"
    load_joint: str = "load"
    imu_axis: str = "x"
    topic: Optional[str] = None
    maps: Optional[dict] = None


@dataclass
class _Setup:
    """The resolved options: configurations loaded, the diagnosis configured and checked."""

    options: OfflineOptions
    system: Any
    method: Any
    config: DiagnosisConfig
    policy: VerdictPolicy

    @classmethod
    def of(cls, options: Optional[OfflineOptions], fields: dict, detector: str) -> "_Setup":
        o = replace(options or OfflineOptions(), **fields)
        if o.detector is None:
            o = replace(o, detector=detector)
        system = load_system_config() if o.system is None else o.system
        method = load_method_config() if o.method is None else o.method
        config, policy = _diagnosis_config(method, o.p, o.gap_method, o.image_method, o.policy)
        return cls(o, system, method, config, policy)

    def monitor(self, result: "OfflineResult", log: Callable[[str], Any], say_gap_only: bool) -> DriveMonitor:
        """The chain without its detector (made at the first batch): the library loaded (or built) when the
        image method is on and none was given; ``result`` gets its path and error."""
        o, library = self.options, self.options.library
        if o.image_method and library is None:
            lib_path = (Path(o.library_path).expanduser() if o.library_path
                        else default_library_path(self.system, self.method))
            result.library_path = str(lib_path)
            library, result.library_error = load_pattern_library(lib_path, self.system, self.method,
                                                                 o.build_if_missing, log=log, warn=log)
            if result.library_error and result.library_error.startswith(IMAGE_METHOD_OFF):
                result.notes.append(result.library_error)     # a drive without a library: said once, here
                log(result.library_error)
            elif result.library_error and say_gap_only:
                log(f"{result.library_error}; windows are diagnosed from the gap only (level ERROR)")
        diagnoser = Diagnoser(self.system, self.method, self.config, self.policy, library,
                              result.library_error or "")
        return DriveMonitor(None, diagnoser, on_error=_internal_error)


def diagnose_recording(path, options: Optional[OfflineOptions] = None, *,
                       log: Callable[[str], Any] = lambda text: None,
                       on_window: Optional[Callable[[OfflineWindow], Any]] = None, **fields) -> OfflineResult:
    """Diagnose every backlash entry of a drive/signals recording (bag directory or .mcap file) as the
    windowing + diagnostic nodes do.  ``options`` (:class:`OfflineOptions`), or its fields as keyword
    arguments; ``log`` gets progress lines (library loading/building, warnings), ``on_window`` each
    :class:`OfflineWindow` as soon as it is diagnosed.

    Raises :class:`OfflineError` (one line naming the field and value) on bad input.
    """
    log = _plain_log(log)
    setup = _Setup.of(options, fields, "auto")
    o = setup.options
    if o.backlash_width_m is not None and not (math.isfinite(o.backlash_width_m) and o.backlash_width_m > 0):
        raise OfflineError(f"backlash_width_m: must be a finite number > 0, got {o.backlash_width_m!r}")
    notes: list = []
    messages, all_topics = read_drive_messages(path, OfflineError, note=notes.append)
    topic = _signals_topic(path, messages, all_topics, o.signals_topic)
    names = {rel: topic[:-len(SIGNALS_TOPIC)] + rel for rel in DRIVE_TOPICS}
    unpacked: dict = {}
    messages = in_sample_time_order([m for m in messages if m[0] in names.values()], topic, unpacked)
    width, width_source = _backlash_width(messages, names[WIDTH_TOPIC], o.backlash_width_m)
    result = OfflineResult(str(path), topic, width_source, notes=notes)
    for text in notes:
        log(text)
    monitor = setup.monitor(result, log, say_gap_only=True)

    def make_detector(batch_channels, topic_name, k2):
        kind = o.detector
        if kind == "auto":
            # the paper detector only where K2 is known (given, or the drive publishes it: zone-centred angles, our
            # simulator); any other drive/signals recording is read as raw encoder angles (issue 20)
            kind = ("paper" if width_source != "default" else "flank" if "alpha2" in batch_channels
                    else "dynamics")
        result.detector = kind
        if kind != "paper":
            result.backlash_width_source = "estimated"
            _say_undeclared(result, setup, log)
        config = DetectorConfig(kind, k2, o.channels, o.gap_tolerance, o.gear_ratio)
        return _make_detector(setup.system, config, batch_channels, topic_name)

    replay = DriveReplay(names, width, width_source not in ("option", "default"), decode=_decode,
                         read_width=_float_data, read_truth=lambda msg, topic_name: float(msg.data),
                         make_detector=make_detector, log=log, unpacked=unpacked)
    ts = float(setup.system.sampling.sample_period_s)
    for win in replay.windows(messages):
        _add_window(result, monitor.window(win), replay.true_inertia(win.entry_time_s, ts)[0], on_window)
    dropped = replay.dropped_before_start
    if replay.detector is None:
        if dropped:
            raise OfflineError(f"recording {path}: topic {topic} holds no readable batch "
                               f"({len(dropped)} dropped: {dropped[0]})")
        raise OfflineError(f"recording {path}: topic {topic} holds no message")
    if dropped:
        notes.append(f"{topic}: {len(dropped)} unreadable batch(es) before the first readable "
                     f"one dropped and counted (layout): {dropped[0]}")
        log(notes[-1])
    _finish(result, replay.detector, log)
    result.clock_jumps = replay.clock_jumps
    return result


def _signals_topic(path, messages, all_topics, wanted: Optional[str]) -> str:
    """The drive/signals topic to read: ``wanted``, else the recording's only one (OfflineError otherwise)."""
    found = sorted({t for t, _, _ in messages if _matches(t, SIGNALS_TOPIC)})
    if wanted is not None:
        if wanted not in found:
            raise OfflineError(f"signals topic {wanted!r}: not in recording {path} "
                               f"(drive/signals topics: {', '.join(found) or 'none'})")
        return wanted
    if not found:
        raise OfflineError(f"recording {path}: no drive/signals topic (topics: {', '.join(all_topics) or 'none'})")
    if len(found) > 1:
        raise OfflineError(f"recording {path}: several drive/signals topics ({', '.join(found)}); "
                           f"choose one with --topic")
    return found[0]


def _decode(topic_name, msg_type, raw):
    try:
        return deserialize(msg_type, raw)
    except ValueError as exc:
        raise OfflineError(f"{topic_name}: undecodable {msg_type} message ({exc})") from None


def _backlash_width(messages, width_topic: str, option: Optional[float]) -> tuple:
    """(K2 m, its source): the option, else the recording's first drive/backlash_width (then followed), else
    the windowing node's default."""
    if option is not None:
        return float(option), "option"
    first = next((m for m in messages if m[0] == width_topic), None)
    if first is not None:
        return _float_data(_decode(*first), first[0]), first[0]
    return float(WINDOWING_DEFAULTS["backlash_width_m"]), "default"


def _plain_log(log: Callable[[str], Any]) -> Callable[[str], Any]:
    """``log`` with plain numbers (no numpy reprs) in every line."""
    return lambda text: log(plain_numbers(str(text)))


def _say_undeclared(result: "OfflineResult", setup: _Setup, log) -> None:
    """Once per run, for windows of raw encoder angles (a real drive's recording): what a drive that declares nothing
    is taken for (:meth:`VerdictPolicy.undeclared_note`)."""
    note = setup.policy.undeclared_note(setup.system.motor.bearing_friction_nms_per_rad)
    if note and note not in result.notes:
        result.notes.append(note)
        log(note)


def default_policy(**overrides) -> VerdictPolicy:
    """The diagnostic node's default publishing policy (jident_ros/parameters.py), with ``overrides``."""
    return VerdictPolicy.from_params(dict(DIAGNOSTIC_DEFAULTS, **overrides))


def _diagnosis_config(method, p, gap_method, image_method, policy) -> tuple:
    """(DiagnosisConfig, VerdictPolicy) of the options; OfflineError naming the field on a bad one."""
    problem = gap_method_problem(gap_method, image_method)
    if problem is not None:
        raise OfflineError(f"{problem[0]}: {problem[1]}")
    if float(p) not in [float(q) for q in method.p_values]:
        raise OfflineError(f"p: must be one of method.p_values {[float(q) for q in method.p_values]}, got {p!r}")
    policy = default_policy() if policy is None else policy
    for name, what in policy.problems():
        raise OfflineError(f"{name}: must be {what}, got {getattr(policy, name)!r}")
    return DiagnosisConfig(float(p), gap_method, image_method), policy


def _internal_error(win, exc) -> WindowDiagnosis:
    """As the node: a window whose diagnosis raised is reported, the run goes on."""
    return WindowDiagnosis(ERROR, f"window could not be diagnosed: internal error {type(exc).__name__}: {exc}", [])


def _add_window(result, r, true_j1, on_window):
    """One diagnosed window (a :class:`~jident_ros.identify.monitor.MonitorResult`) into ``result``."""
    win, est, rc = r.window, getattr(r.window, "backlash_width_estimate_m", math.nan), getattr(r.window, "recontact_index", -1)
    ow = OfflineWindow(win.window_id, win.entry_time_s, win.backlash_width_m, true_j1, r.diagnosis,
                       est if math.isfinite(est) else None, win.backlash_width_se_m if math.isfinite(est) else None,
                       win.detector, tuple(win.flag_names),
                       win.entry_time_s + (rc - win.entry_index) * win.sample_period_s if rc >= 0 else None,
                       r.same_traversal_as)
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
    result.samples, result.batches = detector.samples_seen, detector.batches_seen
    result.dropped = {r: n for r, n in detector.counts.items() if n}
    result.windows_lost = dict(getattr(detector, "windows_lost", {}))
    if result.windows_lost:
        log(f"{_lost_text(result.windows_lost)}: an entry was found, its window's samples were interrupted")
    if not result.windows and not result.cut_off:
        why = detector.no_entry_reason() if hasattr(detector, "no_entry_reason") else ""
        if result.windows_lost:
            why = (f"{_lost_text(result.windows_lost)} (the stamps must step by sampling.sample_period_s, "
                   f"within [T_s/2, gap_tolerance x T_s])")
        elif not why and (n := getattr(detector, "windows_captured", 0)):   # entries, no window: never an empty reason
            why = f"{n} entr{'y' if n == 1 else 'ies'} found, no window diagnosed (drops: {_counts(result.dropped) or 'none counted'})"
        if why:
            result.no_entry_hint = f"the {result.detector} detector: {why}"


def _counts(counts: dict) -> str:
    return ", ".join(f"{r} {n}" for r, n in counts.items())


def _lost_text(lost: dict) -> str:
    return f"{sum(lost.values())} window(s) in progress lost to a drop of their samples ({_counts(lost)})"


def _make_detector(system, config: DetectorConfig, batch_channels, topic_name):
    """:func:`~jident_ros.identify.monitor.make_detector` with ``config.channels`` None: the windowing node's
    default channels that the data carry; OfflineError naming the topic and channel when a needed one is missing."""
    if config.channels is None:
        config = replace(config, channels=[c for c in WINDOWING_DEFAULTS["channels"] if c in batch_channels])
    needed = required_channels(config.kind)
    missing = [c for c in needed if c not in batch_channels]
    if missing:
        raise OfflineError(f"{topic_name}: channel {missing[0]!r} missing (the data carry "
                           f"{','.join(batch_channels)}; the {config.kind} detector needs {', '.join(needed)})")
    config = replace(config, channels=("t",) + tuple(c for c in config.channels if c != "t"),
                     gap_tolerance=WINDOWING_DEFAULTS["gap_tolerance"] if config.gap_tolerance is None
                     else config.gap_tolerance)
    try:
        return make_detector(system, config)
    except ValueError as exc:
        raise OfflineError(str(exc)) from None


# --------------------------------------------------------------------------- JointState bags, CSV files

def diagnose_samples(path, options: Optional[OfflineOptions] = None, *,
                     log: Callable[[str], Any] = lambda text: None,
                     on_window: Optional[Callable[[OfflineWindow], Any]] = None, **fields) -> OfflineResult:
    """Diagnose a JointState bag or a CSV file (``.csv``) as the windowing (``input: joint_states``) and
    diagnostic nodes do.  ``options`` (:class:`OfflineOptions`) or its fields as keyword arguments;
    ``detector``: "flank" (no K2; the default for real drives), "dynamics" (no load encoder) or "paper"
    (inequality 1 with ``backlash_width_m``, zone-centred angles).  Raises OfflineError on bad input."""
    log = _plain_log(log)
    setup = _Setup.of(options, fields, "flank")
    o = setup.options
    _check_sample_options(o)
    ts = float(setup.system.sampling.sample_period_s)
    path = Path(path)
    adapter = csv_stream = None
    try:
        if path.suffix.lower() == ".csv":
            csv_stream = CsvStream(path, o.maps)     # block by block: bounded memory for any file size
            if csv_stream.ignored:
                log(f"{path}: columns ignored (not channels): {', '.join(csv_stream.ignored)}")
            channels, source = csv_stream.channels, str(path)
            batches = ((b, channels) for b in csv_stream.batches(ts))
        else:
            adapter, batches, source = jointstate_batches(path, ts, o.motor_joint, o.load_joint, o.imu_axis, o.topic,
                                                           log=log)
    except InputError as exc:
        raise OfflineError(str(exc)) from None
    result = OfflineResult(str(path), source, "estimated" if o.detector != "paper" else "option",
                           detector=o.detector)
    if o.detector != "paper":
        _say_undeclared(result, setup, log)
    monitor = setup.monitor(result, log, say_gap_only=False)
    config = DetectorConfig(o.detector, o.backlash_width_m, None, None, o.gear_ratio)
    # every batch through the Imu skew check (the node's chain): a window whose a1 is out of step is detected
    # again without a1
    skew = ImuSkewGuard(adapter, lambda chans: _make_detector(setup.system, config, chans, source), log)
    try:
        for arr, channels in batches:
            monitor.detector, events = skew.push(monitor.detector, arr, channels)
            for ev in events:
                if ev.kind != "window":
                    monitor.events.append(ev)
                else:
                    _add_window(result, monitor.window(ev.window), None, on_window)
    except InputError as exc:   # a CSV read block by block: its errors come while streaming
        raise OfflineError(str(exc)) from None
    if monitor.detector is None:
        raise OfflineError(f"recording {path}: no sample")
    _finish(result, monitor.detector, log)
    if skew.skews:
        result.notes.append(f"Imu a1 out of step with the encoder in {skew.skews} window(s): a1 left out from then "
                            f"on, {skew.skews - skew.dropped} window(s) detected again from the encoder, "
                            f"{skew.dropped} lost")
    if skew.dropped:
        result.dropped["imu_skew"] = skew.dropped
    _input_counts(result, adapter or csv_stream, source, ts, log)
    return result


def _check_sample_options(o: OfflineOptions) -> None:
    if o.detector not in DETECTORS:
        raise OfflineError(f"detector: expected one of {', '.join(DETECTORS)}, got {o.detector!r}")
    if o.detector == "paper" and o.backlash_width_m is None:
        raise OfflineError("backlash_width_m: the paper detector (inequality 1) needs K2 (--backlash-width-m)")
    if o.detector in ("flank", "dynamics") and o.backlash_width_m is not None:
        raise OfflineError("backlash_width_m: only for --detector paper (the flank and dynamics detectors need no K2)")
    if not (math.isfinite(o.gear_ratio) and o.gear_ratio != 0):
        raise OfflineError(f"gear_ratio: must be a finite non-zero number (< 0: the load turns the other way), got {o.gear_ratio!r}")


def _input_counts(result, adapter, source, ts, log) -> None:
    """The input's time base (said when resampled), a JointState adapter's stamp period, drops and problems."""
    if adapter.grid is not None and adapter.grid.said():
        log(f"{source}: {adapter.grid.said()}")
    result.jitter = adapter.jitter()
    if isinstance(adapter, CsvStream):
        return
    result.dropped.update({f"jointstate.{k}": v for k, v in adapter.counts.items()      # counts, not drops, left out
                           if v and k not in ("messages", "samples", "imu_messages", "imu_unused")})
    for text, n in adapter.problems()[:3]:
        log(f"{source}: {n} message(s) dropped: {text}")
    if adapter.counts.get("imu_unused"):    # no drive sample lost (an Imu faster than the joint states)
        log(f"{source}: {adapter.counts['imu_unused']} Imu message(s) matched no JointState sample")
    if result.jitter.get("periods") and not result.jitter["period_matches"]:
        log(f"{source}: stamp period {result.jitter['median_period_s']:.6g} s (median) does not match sampling.sample_period_s {ts:g} s")


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
            f"{num(w.error_percent, '>+7.3f')}  {LEVEL_NAMES[d.level]:<5}  {plain_numbers(d.message)}")


def summary_line(result: OfflineResult) -> str:
    lv = result.level_counts()
    k2 = {"option": "from --backlash-width-m", "default": "the windowing node's default",
          "estimated": "estimated per window"}.get(result.backlash_width_source, f"from {result.backlash_width_source}")
    text = (f"{len(result.windows)} window(s) from {result.signals_topic} ({result.samples} samples in "
            f"{result.batches} batches, K2 {k2}): {lv['OK']} OK, {lv['WARN']} WARN, {lv['ERROR']} ERROR")
    if result.clock_jumps:
        text += f"; the drive clock jumped forward {result.clock_jumps} time(s) between windows (history restarted)"
    if result.dropped:
        text += "; dropped: " + _counts(result.dropped)
    if result.windows_lost:
        text += "; " + _lost_text(result.windows_lost)
    if result.cut_off:
        text += "; cut off by the end of the data: " + ", ".join(
            f"entry at {c['entry_time_s']:.4f} s ({c['samples_from_entry']} samples)" for c in result.cut_off)
    flagged = [w.window_id for w in result.windows if "second_entry" in w.flags]
    if flagged:
        text += f"; second entry inside window(s) {', '.join(map(str, flagged))}"
    errs = [abs(w.error_percent) for w in result.windows if w.error_percent is not None]
    if errs:
        text += f"; largest |J1 error| against the true J1 {max(errs):.3f} %"
    return plain_numbers(text)


def write_json(result: OfflineResult, out) -> Path:
    out = Path(out)
    if out.parent and not out.parent.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result.to_json(), indent=1, allow_nan=False) + "\n")
    return out


__all__ = ["OfflineError", "OfflineOptions", "OfflineResult", "OfflineWindow", "default_policy", "diagnose_recording",
           "diagnose_samples", "format_window_line", "jointstate_batches",
           "multiarray_message", "summary_line", "write_json", "TABLE_HEADER"]
