"""Pattern library from calibration recordings with known J1 (``jident build-patterns --from-recordings``).

A user with a real drive records calibration runs with known J1 (e.g. with added masses) instead of
relying on our simulator.  From each recording (MCAP bag directory or .mcap file, see
docs/recording.md) the ``drive/signals`` batches are fed, in receive-time order, through the windowing
node's detector (:class:`jident_ros.stream.detector.BacklashDetector`, paper inequality 1, 48 + 2000
samples): the windows are exactly those the windowing node would publish.

Labels of a window:

* J1 (kg m^2): the command-line label of its recording (``PATH=J1``) when given; else the
  ``drive/case`` row whose ``entry_time_s`` is the window's entry time (within T_s / 2); else the last
  ``drive/true_inertia`` message received before the window's entry sample (what our simulator
  publishes).  A window without any of these is an error.
* K2 (backlash width, m): ``backlash_width_m`` (``--backlash-width-m``) when given; else the
  recording's ``drive/backlash_width`` messages (the first one sets the detector's K2 from the start,
  later ones change it, as the windowing node with ``backlash_width_from_topic``).  A recording
  without either is an error.

The library's classes are the distinct J1 labels (sorted ascending; at least 2), its widths the
distinct K2 (sorted ascending); every (class, width) pair needs at least one window.  Several windows
of one class and width are averaged: the pattern's KHM centres (an N2 row, per p and signal) are the
mean of the windows' sorted centres, its (h3, k3) the mean of theirs, and h5 (eq. 34) is computed
from these means exactly as for a simulator-built library.  With one window per pattern the result
equals :meth:`PatternLibrary.from_windows` on the same windows.

The metadata keeps the configuration hashes of :func:`library_metadata` (so
:meth:`PatternLibrary.load` still refuses a library built for another configuration) and adds
``source = "recordings"``, the recordings (file, windows, J1 labels and their source) and
``pattern_window_counts`` (windows averaged into each pattern, indexed [width][class]).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

from jident_ros.bag.drive_replay import DriveReplay, in_sample_time_order, read_drive_messages
from jident_ros.bag.messages import deserialize
from jident_ros.identify.monitor import DetectorConfig, make_detector
from jident_ros.method.patterns import PatternLibrary, h5_table, library_metadata
from jident_ros.method.pipeline import SIGNALS, MethodConfig, batch_features, pre_entry_reference
from jident_ros.parameters import WINDOWING as WINDOWING_DEFAULTS
from jident_ros.stream.layout import DRIVE_TOPICS, SIGNALS_TOPIC, TRUE_INERTIA_TOPIC, WIDTH_TOPIC
from jident_ros.stream.layout import topic_matches as _matches

#: Significant digits to which J1 labels and widths are compared when grouping windows.
LABEL_DIGITS = 12


class CalibrationError(ValueError):
    """Bad calibration input (file, label, width, too few classes): one line naming the field and value."""


@dataclass
class LabelledWindow:
    """One calibration window and its labels.

    Attributes
    ----------
    data : dict of str -> ndarray (n_samples,)
        Channels of the window (``t`` in s, ``alpha1``/``alpha2`` rad, ``a1``/``a2`` m/s^2, ``m_el`` N m,
        ``omega1`` rad/s, ``v2`` m/s, ...), 48 + 2000 samples.
    entry_index : int
        Row of the backlash-zone entry sample (48).
    inertia_kgm2 : float
        Known J1 of the run, kg m^2.
    backlash_width_m : float
        K2 the detector used for this window, m.
    recording : str
        The recording it was cut from.
    entry_time_s : float
        Drive clock t of the entry sample, s.
    label_source : str
        Where J1 came from: ``"label"`` (command line) or the topic name.
    """

    data: dict
    entry_index: int
    inertia_kgm2: float
    backlash_width_m: float
    recording: str = ""
    entry_time_s: float = float("nan")
    label_source: str = ""


def _key(x: float) -> float:
    """A label rounded to LABEL_DIGITS significant digits (so 1.073 typed and 1.073 recorded group together)."""
    return float(f"{float(x):.{LABEL_DIGITS}g}")


def _positive_number(v) -> bool:
    try:
        return not isinstance(v, bool) and math.isfinite(float(v)) and float(v) > 0
    except (TypeError, ValueError):
        return False


# --------------------------------------------------------------------------- labels


def parse_labels(texts: Sequence[str], recordings: Sequence[str]) -> dict:
    """``PATH=J1`` texts -> {recording as given: J1 in kg m^2}.

    PATH names one of ``recordings``: as given, as the same file/directory, or by its name (the bag
    directory's or the .mcap file's, with or without ``.mcap``) when that name is unique.
    """
    recs = [str(r) for r in recordings]
    out: dict = {}
    for text in texts or ():
        path, sep, value = str(text).rpartition("=")
        if not sep or not path:
            raise CalibrationError(f"--label {text!r}: expected PATH=J1, e.g. run_a=1.16 (J1 in kg m^2)")
        try:
            j1 = float(value)
        except ValueError:
            j1 = float("nan")
        if not _positive_number(j1):
            raise CalibrationError(f"--label {text!r}: J1 must be a finite number > 0 in kg m^2, got {value!r}")
        rec = _find_recording(path, recs)
        if rec is None:
            raise CalibrationError(f"--label {text!r}: {path!r} is not one of the recordings "
                                   f"({', '.join(recs) or 'none'})")
        if rec in out and out[rec] != j1:
            raise CalibrationError(f"--label {text!r}: recording {rec!r} already labelled J1 = {out[rec]:g} kg m^2")
        out[rec] = j1
    return out


def _find_recording(path: str, recs: Sequence[str]) -> Optional[str]:
    if path in recs:
        return path
    try:
        resolved = Path(path).expanduser().resolve()
        for r in recs:
            if Path(r).expanduser().resolve() == resolved:
                return r
    except OSError:
        pass
    by_name = [r for r in recs if path in (Path(r).name, Path(r).stem if Path(r).suffix == ".mcap" else Path(r).name)]
    return by_name[0] if len(by_name) == 1 else None


# --------------------------------------------------------------------------- reading


def read_calibration_windows(path, system, *, inertia_kgm2: Optional[float] = None,
                             backlash_width_m: Optional[float] = None,
                             log: Callable[[str], Any] = lambda text: None) -> list:
    """The labelled windows of one calibration recording.

    Parameters
    ----------
    path : bag directory or .mcap file holding ``drive/signals`` (std_msgs/Float64MultiArray batches,
        2-D sample x channel layout, docs/interfaces.md; the topic name ending in ``drive/signals``)
    system : SystemConfig (sample period, window lengths, wheel radius r of inequality 1)
    inertia_kgm2 : J1 of every window of this recording, kg m^2 (the ``PATH=J1`` label); None: from the
        recording's ``drive/case`` / ``drive/true_inertia`` messages
    backlash_width_m : K2, m; None: from the recording's ``drive/backlash_width`` messages
    log : gets one-line notes (drops of the detector)

    Returns a list of :class:`LabelledWindow` in stream order.  Raises :class:`CalibrationError` naming
    the file and the value: missing or unreadable recording, no ``drive/signals``, channels missing, no
    K2, no backlash entry, a window without a J1 label.
    """
    name = str(path)
    if inertia_kgm2 is not None and not _positive_number(inertia_kgm2):
        raise CalibrationError(f"recording {name}: J1 label must be a finite number > 0 in kg m^2, "
                               f"got {inertia_kgm2!r}")
    if backlash_width_m is not None and not _positive_number(backlash_width_m):
        raise CalibrationError(f"backlash_width_m: must be a finite number > 0, got {backlash_width_m!r}")
    if not Path(path).exists():
        raise CalibrationError(f"recording {name}: no such file or directory")
    rec = _CalibrationRecording(name)
    topic, names, messages = rec.drive_messages(path, log)
    follow_width = backlash_width_m is None
    if follow_width:
        first = next((m for m in messages if m[0] == names[WIDTH_TOPIC]), None)
        if first is None:
            raise CalibrationError(f"recording {name}: no backlash width (no {WIDTH_TOPIC} message); "
                                   f"give --backlash-width-m")
        width = rec.positive_data(rec.decode(*first), first[0])
    else:
        width = float(backlash_width_m)
    replay = DriveReplay(names, width, follow_width, decode=rec.decode, read_width=rec.positive_data,
                         read_truth=rec.positive_data, make_detector=lambda c, t, k2: rec.detector(system, c, t, k2),
                         log=lambda text: log(f"{name}: {text}"))
    windows: list = []
    unlabelled = None
    ts = float(system.sampling.sample_period_s)
    for win in replay.windows(messages):
        if inertia_kgm2 is not None:
            j1, source = float(inertia_kgm2), "label"
        else:
            j1, source = replay.true_inertia(win.entry_time_s, ts)
        if j1 is None:
            unlabelled = unlabelled or win
            continue
        windows.append(LabelledWindow(win.as_dict(), win.entry_index, j1, win.backlash_width_m, name,
                                      win.entry_time_s, source))
    rec.check_windows(replay, topic, windows, unlabelled, log)
    return windows


class _CalibrationRecording:
    """One calibration recording's reading: its errors name the file (CalibrationError)."""

    def __init__(self, name: str):
        self.name = name

    def drive_messages(self, path, log) -> tuple:
        """(the drive/signals topic, {relative drive topic: its name}, the drive messages in sample-time order)."""
        name = self.name
        messages, topics = read_drive_messages(path, CalibrationError, note=log)
        found = sorted({t for t, _, _ in messages if _matches(t, SIGNALS_TOPIC)})
        if not found:
            raise CalibrationError(f"recording {name}: no drive/signals topic "
                                   f"(topics: {', '.join(topics) or 'none'})")
        if len(found) > 1:
            raise CalibrationError(f"recording {name}: several drive/signals topics ({', '.join(found)}); "
                                   f"record one drive per calibration recording")
        prefix = found[0][:-len(SIGNALS_TOPIC)]
        names = {rel: prefix + rel for rel in DRIVE_TOPICS}
        return found[0], names, in_sample_time_order([m for m in messages if m[0] in names.values()], found[0])

    def decode(self, topic, msg_type, raw):
        try:
            return deserialize(msg_type, raw)
        except ValueError as exc:
            raise CalibrationError(f"recording {self.name}: undecodable {msg_type} message on {topic} "
                                   f"({exc})") from None

    def positive_data(self, msg, topic):
        v = float(msg.data)
        if not _positive_number(v):
            raise CalibrationError(f"recording {self.name}: {topic} must carry a finite number > 0, got {v!r}")
        return v

    def detector(self, system, channels, topic, k2):
        """The windowing node's paper detector (inequality 1) for the channels the recording carries."""
        missing = [c for c in ("t", "alpha1", "alpha2") + SIGNALS if c not in channels]
        if missing:
            raise CalibrationError(f"recording {self.name}: {topic} lacks channel {missing[0]!r} (it carries "
                                   f"{','.join(channels)}; inequality 1 needs t, alpha1, alpha2 and the "
                                   f"patterns need {','.join(SIGNALS)})")
        wanted = [c for c in WINDOWING_DEFAULTS["channels"] if c in channels]
        return make_detector(system, DetectorConfig("paper", k2, ("t",) + tuple(wanted),
                                                    WINDOWING_DEFAULTS["gap_tolerance"]))

    def check_windows(self, replay, topic, windows, unlabelled, log) -> None:
        """The drops said; CalibrationError when no batch was readable, a window has no J1 or none was found."""
        name, detector = self.name, replay.detector
        if detector is None:
            raise CalibrationError(f"recording {name}: topic {topic} holds no readable message"
                                   + (f" ({replay.dropped_before_start[0]})" if replay.dropped_before_start else ""))
        drops = ", ".join([f"{r} {n}" for r, n in detector.counts.items() if n] +
                          ([f"clock jumps {replay.clock_jumps}"] if replay.clock_jumps else []))
        if drops:
            log(f"{name}: windowing drops: {drops}")
        if unlabelled is not None:
            raise CalibrationError(f"recording {name}: no J1 label for window {unlabelled.window_id} (entry at "
                                   f"t = {unlabelled.entry_time_s:.4f} s): give --label {name}=J1 (kg m^2) or "
                                   f"record {TRUE_INERTIA_TOPIC}")
        if not windows:
            raise CalibrationError(f"recording {name}: no backlash entry found in {topic} ({detector.samples_seen} "
                                   f"samples, K2 = {', '.join(f'{w:g}' for w in replay.widths_used)} m"
                                   + (f"; windowing drops: {drops})" if drops else ")"))


# --------------------------------------------------------------------------- building


def pattern_grid(windows: Sequence[LabelledWindow]) -> tuple:
    """Classes and widths of a library from these windows, checked before any feature is computed.

    Returns (classes in kg m^2 sorted ascending, widths in m sorted ascending, {(e, f): window indices},
    window counts (n_widths, n_classes)).  Raises :class:`CalibrationError` with no window, fewer than 2
    distinct J1 labels, or a (class, width) pair without a window.
    """
    if not windows:
        raise CalibrationError("windows: no calibration window")
    classes = sorted({_key(w.inertia_kgm2) for w in windows})
    widths = sorted({_key(w.backlash_width_m) for w in windows})
    if len(classes) < 2:
        files = sorted({w.recording for w in windows})
        raise CalibrationError(f"J1 labels: need at least 2 distinct J1 classes, got only {classes[0]:g} kg m^2 "
                               f"(recordings: {', '.join(files)})")
    f_of = {c: i for i, c in enumerate(classes)}
    e_of = {c: i for i, c in enumerate(widths)}
    groups: dict = {}
    for b, w in enumerate(windows):
        groups.setdefault((e_of[_key(w.backlash_width_m)], f_of[_key(w.inertia_kgm2)]), []).append(b)
    counts = np.zeros((len(widths), len(classes)), dtype=int)
    for (e, f), members in groups.items():
        counts[e, f] = len(members)
    if (counts == 0).any():
        e, f = (int(i) for i in np.argwhere(counts == 0)[0])
        raise CalibrationError(f"J1 classes x widths: no window for J1 = {classes[f]:g} kg m^2 at K2 = "
                               f"{widths[e]:g} m (every class needs a window at every width; "
                               f"{int((counts == 0).sum())} pair(s) missing)")
    return classes, widths, groups, counts


def library_from_labelled_windows(windows: Sequence[LabelledWindow], system, method: MethodConfig,
                                  progress: Optional[Callable[[int, int], Any]] = None,
                                  recordings: Optional[list] = None) -> PatternLibrary:
    """Pattern library whose classes are the distinct J1 labels and widths the distinct K2 of ``windows``.

    Each pattern (class f, width e) is the mean of its windows' features: KHM centres (per p and
    signal) and (h3, k3); h5 (eq. 34) is computed from these means.  ``progress(k, n)`` is called after
    each of the n signals.  ``recordings``: the metadata's list of recordings (default: from the windows).
    Raises :class:`CalibrationError` with fewer than 2 classes or a (class, width) pair without a window.
    """
    classes, widths, groups, counts = pattern_grid(windows)
    entries = {w.entry_index for w in windows}
    if len(entries) != 1:
        raise CalibrationError(f"entry_index: all windows need the same entry row, got {sorted(entries)}")
    entry = entries.pop()
    ps = tuple(float(p) for p in method.p_values)
    nw, nc, ns = len(widths), len(classes), len(SIGNALS)
    centres = np.zeros((len(ps), nw, ns, nc, method.n_clusters))
    ranges = np.zeros((nw, ns, nc, 2))
    refs = (np.array([pre_entry_reference(w.data, entry) for w in windows])
            if method.variant != "paper" else None)
    for s, sig in enumerate(SIGNALS):
        batch = np.stack([np.asarray(w.data[sig], dtype=float) for w in windows])
        cen, rps, _ = batch_features(batch, sig, method, ps, refs, entry)
        h3k3 = np.array([(r.h3, r.k3) for r in rps])
        for (e, f), members in groups.items():
            centres[:, e, s, f] = cen[:, members].mean(axis=1)
            ranges[e, s, f] = h3k3[members].mean(axis=0)
        if progress:
            progress(s + 1, ns)
    h5 = h5_table(centres, ranges)
    if recordings is None:
        recordings = _recording_summary(windows)
    meta = library_metadata(system, method)
    meta.update(source="recordings", recordings=recordings,
                pattern_window_counts=counts.tolist(),
                averaging="mean of the windows' sorted KHM centres and of their (h3, k3); h5 from the means")
    return PatternLibrary(centres, h5, ranges, ps, tuple(widths), tuple(classes), SIGNALS, meta)


def _recording_summary(windows) -> list:
    out = {}
    for w in windows:
        r = out.setdefault(w.recording, {"file": w.recording, "windows": 0, "inertias_kgm2": set(),
                                         "label_sources": set()})
        r["windows"] += 1
        r["inertias_kgm2"].add(_key(w.inertia_kgm2))
        r["label_sources"].add(w.label_source)
    return [dict(r, inertias_kgm2=sorted(r["inertias_kgm2"]), label_sources=sorted(r["label_sources"]))
            for r in out.values()]


def pattern_window_counts(library: PatternLibrary) -> np.ndarray:
    """Windows averaged into each pattern, shape (n_widths, n_classes) (all 1 for a simulator-built library)."""
    counts = library.metadata.get("pattern_window_counts")
    if counts is None:
        return np.ones((len(library.widths_m), len(library.classes_kgm2)), dtype=int)
    return np.asarray(counts, dtype=int)


def read_recordings(paths: Sequence, system, *, labels: Optional[Mapping[str, float]] = None,
                    backlash_width_m: Optional[float] = None,
                    log: Callable[[str], Any] = lambda text: None) -> tuple:
    """The labelled windows of several calibration recordings and their summary for the metadata.

    Every recording must exist (checked first, before any is read).  ``labels``: {recording as in
    ``paths``: J1 in kg m^2}; ``backlash_width_m``: K2 of every recording, m; ``log`` gets one line per
    recording (its windows, J1 labels and their source, K2).  Returns (list of LabelledWindow, list of
    dict per recording).
    """
    labels = dict(labels or {})
    names = [str(p) for p in paths]
    if not names:
        raise CalibrationError("--from-recordings: need at least one recording")
    unknown = [k for k in labels if k not in names]
    if unknown:
        raise CalibrationError(f"labels: {unknown[0]!r} is not one of the recordings")
    missing = [n for n in names if not Path(n).exists()]
    if missing:
        raise CalibrationError(f"recording {missing[0]}: no such file or directory")
    windows, summary = [], []
    for p in paths:
        ws = read_calibration_windows(p, system, inertia_kgm2=labels.get(str(p)),
                                      backlash_width_m=backlash_width_m, log=log)
        windows += ws
        per_class: dict = {}
        for w in ws:
            per_class[_key(w.inertia_kgm2)] = per_class.get(_key(w.inertia_kgm2), 0) + 1
        summary += _recording_summary(ws)
        log(f"{p}: {len(ws)} window(s): " + ", ".join(f"J1 {j:g} x {n}" for j, n in sorted(per_class.items()))
            + f" (J1 from {', '.join(sorted({w.label_source for w in ws}))}; K2 "
            + ", ".join(f"{k:g}" for k in sorted({_key(w.backlash_width_m) for w in ws})) + " m)")
    return windows, summary


def build_library_from_recordings(paths: Sequence, system, method: MethodConfig, *,
                                  labels: Optional[Mapping[str, float]] = None,
                                  backlash_width_m: Optional[float] = None,
                                  log: Callable[[str], Any] = lambda text: None,
                                  progress: Optional[Callable[[int, int], Any]] = None) -> PatternLibrary:
    """Pattern library from calibration recordings (see the module docstring for the labelling rules).

    Parameters
    ----------
    paths : recordings (bag directories or .mcap files)
    system, method : SystemConfig and MethodConfig the library is built for (their hashes are kept)
    labels : {recording as in ``paths``: J1 in kg m^2} (e.g. from :func:`parse_labels`)
    backlash_width_m : K2 of every recording, m (default: their drive/backlash_width messages)
    log : gets one line per recording (its windows and labels)
    progress : ``progress(k, n)`` after each of the n signals of the feature computation
    """
    windows, summary = read_recordings(paths, system, labels=labels, backlash_width_m=backlash_width_m, log=log)
    return library_from_labelled_windows(windows, system, method, progress=progress, recordings=summary)


__all__ = ["CalibrationError", "LabelledWindow", "build_library_from_recordings", "library_from_labelled_windows",
           "parse_labels", "pattern_grid", "pattern_window_counts", "read_calibration_windows",
           "read_recordings"]
