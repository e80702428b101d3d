"""``jident diagnose``: the diagnostic node's per-window diagnosis on a recording, without ROS.

Reads the ``drive/signals`` batches of an MCAP recording (:func:`jident_ros.bag.recording.read_bag`; topic
name ending in ``drive/signals``, any namespace; std_msgs/Float64MultiArray in the 2-D sample x channel
layout of docs/interfaces.md), feeds them in receive-time order through the windowing node's
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

from jident_ros.bag.recorded import DriveReplay, read_drive_messages
from jident_ros.bag.recording import RecordingError, deserialize
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.diagnosis import GAP_METHODS, WindowDiagnosis, diagnose_window
from jident_ros.identify.levels import ERROR, LEVEL_NAMES
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.parameters import WINDOWING as WINDOWING_DEFAULTS
from jident_ros.stream.detector import BacklashDetector
from jident_ros.stream.layout import DRIVE_TOPICS, REQUIRED_CHANNELS, SIGNALS_TOPIC, WIDTH_TOPIC, pack
from jident_ros.stream.layout import topic_matches as _matches


class OfflineError(ValueError):
    """A user error (missing recording, no drive/signals topic, bad option): one line, exit status 2."""


def multiarray_message(array, channels: Sequence[str], header: Sequence[float] = ()) -> dict:
    """(n, c) samples + channel names -> std_msgs/Float64MultiArray as a dict of fields in the
    drive/signals layout (``header`` values in front, data_offset = len(header)), e.g. for
    :meth:`jident_ros.bag.recording.BagWriter.write` without ROS."""
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
                "backlash_width_m": self.backlash_width_m, "true_inertia_kgm2": self.true_inertia_kgm2,
                "inertia_estimate_kgm2": d.inertia_kgm2, "estimate_source": d.source,
                "identified_class_kgm2": d.class_kgm2, "error_percent": self.error_percent,
                "level": d.level_name, "message": d.message,
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
    library_path: Optional[str] = None
    library_error: Optional[str] = None

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
                "batches": self.batches, "dropped": dict(self.dropped), "library": self.library_path,
                "library_error": self.library_error, "levels": self.level_counts(),
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
                       on_window: Optional[Callable[[OfflineWindow], Any]] = None) -> OfflineResult:
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
    if backlash_width_m is not None and not (math.isfinite(backlash_width_m) and backlash_width_m > 0):
        raise OfflineError(f"backlash_width_m: must be a finite number > 0, got {backlash_width_m!r}")
    messages, all_topics = read_drive_messages(path, OfflineError)
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
    messages = [m for m in messages if m[0] in names.values()]


    def decode(topic_name, msg_type, raw):
        try:
            return deserialize(msg_type, raw)
        except (RecordingError, ValueError) as exc:
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

    result = OfflineResult(str(path), topic, width_source)
    if image_method and library is None:
        lib_path = Path(library_path).expanduser() if library_path else default_library_path(system, method)
        result.library_path = str(lib_path)
        library, result.library_error = load_pattern_library(lib_path, system, method, build_if_missing,
                                                             log=log, warn=log)
        if result.library_error:
            log(f"{result.library_error}; windows are diagnosed from the gap only (level ERROR)")

    ts = float(system.sampling.sample_period_s)

    def first_layout_error(topic_name, reason):
        raise OfflineError(f"{topic_name}: the first message is not in the drive/signals layout ({reason})")

    def make_detector(batch_channels, topic_name, k2):
        return _make_detector(system, k2, channels, batch_channels, gap_tolerance, WINDOWING_DEFAULTS, topic_name)

    replay = DriveReplay(names, width, follow_width, decode=decode, read_width=_float_data,
                         read_truth=lambda msg, topic_name: float(msg.data), make_detector=make_detector,
                         first_layout_error=first_layout_error, log=log)
    for win in replay.windows(messages):
        try:
            d = diagnose_window(win.as_dict(), win.entry_index, win.backlash_width_m, win.wheel_radius_m,
                                win.sample_period_s, library=library, system=system, method=method, p=float(p),
                                gap_method=gap_method, image_method=image_method,
                                library_error=result.library_error or "", window_id=win.window_id,
                                entry_time_s=win.entry_time_s)
        except Exception as exc:  # as the node: report the window, go on
            d = WindowDiagnosis(ERROR, f"window could not be diagnosed: internal error "
                                       f"{type(exc).__name__}: {exc}", [])
        ow = OfflineWindow(win.window_id, win.entry_time_s, win.backlash_width_m,
                           replay.true_inertia(win.entry_time_s, ts)[0], d)
        result.windows.append(ow)
        if on_window is not None:
            on_window(ow)
    detector = replay.detector
    if detector is None:
        raise OfflineError(f"recording {path}: topic {topic} holds no message")
    result.samples, result.batches = detector.samples_seen, detector.batches_seen
    result.dropped = {r: n for r, n in detector.counts.items() if n}
    return result


def _make_detector(system, width, channels, batch_channels, gap_tolerance, defaults, topic_name):
    sampling = system.sampling
    if channels is None:
        channels = [c for c in defaults["channels"] if c in batch_channels]
    missing = [c for c in REQUIRED_CHANNELS if c not in batch_channels]
    if missing:
        raise OfflineError(f"{topic_name}: channel {missing[0]!r} missing (the batches carry "
                           f"{','.join(batch_channels)}; inequality 1 needs t, alpha1, alpha2)")
    try:
        return BacklashDetector(width, system.load.wheel_radius_m, sampling.sample_period_s,
                                channels=("t",) + tuple(c for c in channels if c != "t"),
                                samples_before_entry=sampling.samples_before_entry,
                                samples_from_entry=sampling.samples_from_entry,
                                gap_tolerance=defaults["gap_tolerance"] if gap_tolerance is None else gap_tolerance)
    except ValueError as exc:
        raise OfflineError(str(exc)) from None


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
    k2 = {"option": "from --backlash-width-m", "default": "the windowing node's default"}.get(
        result.backlash_width_source, f"from {result.backlash_width_source}")
    text = (f"{len(result.windows)} window(s) from {result.signals_topic} ({result.samples} samples in "
            f"{result.batches} batches, K2 {k2}): {lv['OK']} OK, {lv['WARN']} WARN, {lv['ERROR']} ERROR")
    if result.dropped:
        text += "; dropped: " + ", ".join(f"{r} {n}" for r, n in result.dropped.items())
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


__all__ = ["OfflineError", "OfflineResult", "OfflineWindow", "diagnose_recording", "format_window_line",
           "multiarray_message", "summary_line", "write_json", "TABLE_HEADER"]
