"""The engine of ``jident trend`` (issue 14), shared by one drive's trend (:mod:`jident_ros.cli.trend`) and a
fleet's (:mod:`jident_ros.cli.fleet`): every recording diagnosed as ``jident diagnose`` does, each window
turned into a :class:`TrendWindow` by the diagnostic node's rule, all windows in recording order
(:func:`order_recordings`) through one :class:`~jident_ros.identify.trend.TrendTracker` (:func:`run_trend`),
and the per-window ``trend.csv``.
"""
from __future__ import annotations

import csv
import dataclasses
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from mcap.reader import make_reader

from jident_ros.bag.metadata_yaml import read_metadata
from jident_ros.bag.reader import bag_files
from jident_ros.cli.offline import OfflineError, diagnose_recording
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.trend import Z95, TrendConfig, TrendTracker
from jident_ros.identify.trend_status import SAME_TRAVERSAL, trend_inputs

CSV_COLUMNS = ("time_s", "recording", "window_id", "inertia_kgm2", "inertia_se_kgm2", "inertia_ci_low_kgm2",
               "inertia_ci_high_kgm2", "backlash_width_m", "backlash_width_se_m", "true_inertia_kgm2",
               "inertia_smoothed_kgm2", "inertia_smoothed_se_kgm2", "inertia_baseline_kgm2", "inertia_drift_pct",
               "backlash_width_smoothed_m", "backlash_width_smoothed_se_m", "wear_rate_m_per_day",
               "wear_rate_se_m_per_day", "time_to_limit_s", "change", "change_quantity", "level", "skip_reason",
               "width_source")


# --------------------------------------------------------------------------- per-window input

@dataclass(frozen=True)
class TrendWindow:
    """What the trend needs of one diagnosed window.

    time_s : drive clock t of the entry sample, s
    inertia_kgm2, inertia_se_kgm2 : the gap J1 and its standard error, kg m^2, published or not (None: refused
        for a physical reason, image method only or no gap; ``skip_reason`` and ``refused_kind`` say why)
    inertia_ci_low_kgm2, inertia_ci_high_kgm2 : its 95 % interval, kg m^2 (the published one; where the trend reads
        another fit, GapEstimate.trend_fit, that fit's J1 ± Z95 of its standard error)
    width_m, width_se_m : backlash width K2 of the window and its standard uncertainty, m
    width_source : 'flank' (the flank detector's flank-to-flank estimate), 'gap' (the gap estimator's width
        at re-contact: the fallback when the window has no flank estimate) or None
    skip_reason : why there is no J1 (None when there is one)
    true_inertia_kgm2 : from drive/case or drive/true_inertia when the recording has it
    """

    time_s: float
    recording: str
    window_id: int
    inertia_kgm2: Optional[float]
    inertia_se_kgm2: Optional[float]
    inertia_ci_low_kgm2: Optional[float]
    inertia_ci_high_kgm2: Optional[float]
    width_m: Optional[float]
    width_se_m: Optional[float]
    skip_reason: Optional[str]
    true_inertia_kgm2: Optional[float] = None
    width_source: Optional[str] = None
    refused_kind: Optional[str] = None       # why there is no J1 (trend_status.REFUSAL_KINDS), None when there is one


def trend_window(ow, recording: str, width_se_floor_m: float = 0.0) -> TrendWindow:
    """An :class:`jident_ros.cli.offline.OfflineWindow` -> :class:`TrendWindow`, with the diagnostic node's
    rule (:func:`jident_ros.identify.trend_status.trend_inputs`): the gap J1 whenever physics allows it,
    published or not (an ambiguous class verdict does not keep it from the trend); none, with the reason, when
    it was refused as implausible or inconsistent, or the window has no gap estimate; the width from the flank
    detector when the window has its estimate, else from the gap estimator (none when the gap was refused)."""
    d = ow.diagnosis
    same = getattr(ow, "same_traversal_as", None)
    if same is not None:
        # the node's chain (identify.monitor.DriveMonitor): a second window of one traversal goes to the trend once
        return TrendWindow(float(ow.entry_time_s), recording, int(ow.window_id), None, None, None, None, None, None,
                           f"the gap fit read the traversal of window {same} again", ow.true_inertia_kgm2, None,
                           SAME_TRAVERSAL)
    ti = trend_inputs(d, width_se_floor_m, ow)
    lo = hi = reason = None
    if ti.inertia_kgm2 is not None:
        lo, hi = (float(v) for v in d.gap.ci95_kgm2)
        if getattr(d.gap, "trend_fit", ()):
            # the trend reads another fit than the published one (GapEstimate.trend_fit): its own interval beside it
            j_t, se_t = (float(v) for v in d.gap.trend_fit[:2])
            lo, hi = j_t - Z95 * se_t, j_t + Z95 * se_t
    elif d.inertia_kgm2 is not None:
        reason = f"J1 {d.inertia_kgm2:.5g} kg m^2 from the {d.source} method has no standard error"
    elif d.gap is not None:
        reason = f"gap J1 {d.gap.inertia_kgm2:.5g} kg m^2 refused ({d.status}: {d.refused_reason or d.message})"
    else:
        reason = "; ".join(d.problems) or d.message
    return TrendWindow(float(ow.entry_time_s), recording, int(ow.window_id), ti.inertia_kgm2, ti.inertia_se_kgm2,
                       lo, hi, ti.width_m, ti.width_se_m, reason, ow.true_inertia_kgm2, ti.width_source,
                       ti.inertia_refused)


# --------------------------------------------------------------------------- the run

@dataclass
class TrendRun:
    """Result of :func:`run_trend`."""

    windows: list                # TrendWindow, in recording order (the ones fed to the tracker)
    updates: list                # TrendUpdate, one per window
    tracker: TrendTracker
    recordings: list             # (path, windows, samples, dropped dict, clock jumps)
    already_in_state: int = 0    # windows the resumed state already covers (recording_cursor), left out
    seconds: float = 0.0
    order: str = ""              # how the recordings were ordered (order_recordings), for the summary


#: How ``jident trend`` orders the recordings (``--order``): 'recorded' (when they were recorded: each bag's start,
#: else each recording's first entry on the drive clock) or 'given' (as listed).
ORDERS = ("recorded", "given")


def recording_start_ns(rec) -> Optional[int]:
    """When recording ``rec`` began, ns since the epoch: its first message's log time (the MCAP summary's
    message_start_time, the earliest over a bag's files), else metadata.yaml's starting_time; None for a CSV
    file or a bag that has neither (a file cut off without its summary and no metadata.yaml)."""
    path = Path(rec)
    if path.suffix.lower() == ".csv":
        return None
    starts = []
    try:
        for f in bag_files(path):
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
            if summary is not None and summary.statistics is not None and summary.statistics.message_count:
                starts.append(int(summary.statistics.message_start_time))
    except Exception:    # a cut or foreign file: diagnose_recording says what is wrong with it
        starts = []
    if starts:
        return min(starts)
    if path.is_dir() and (path / "metadata.yaml").is_file():
        try:
            ns = read_metadata(path).get("starting_time", {}).get("nanoseconds_since_epoch")
            return int(ns) if ns else None
        except Exception:
            return None
    return None


def order_recordings(blocks: list, order: str = "recorded") -> tuple:
    """(blocks sorted, how) -- ``blocks``: [(start_ns or None, TrendWindows in stream order)] in the order
    given.  A recording's windows stay together and in their stream order: a drive whose clock restarted
    between recordings (t back to 0) is never interleaved.  'recorded': by each recording's start
    (:func:`recording_start_ns`) when every recording has one, else by each one's first entry on the drive
    clock (recordings sharing one clock); ties and recordings without a window keep the order given.  'given':
    as given."""
    idx = list(range(len(blocks)))
    if order == "given":
        return list(blocks), "in the order given"
    if order != "recorded":
        raise ValueError(f"order: expected one of {', '.join(ORDERS)}, got {order!r}")
    if blocks and all(b[0] is not None for b in blocks):
        idx.sort(key=lambda i: blocks[i][0])
        return [blocks[i] for i in idx], "in recording order (each recording's start)"
    first = [b[1][0].time_s if b[1] else math.inf for b in blocks]
    idx.sort(key=lambda i: first[i])
    return [blocks[i] for i in idx], "in recording order (each recording's first entry on the drive clock)"


def _not_in_state(blocks: list, tr: TrendTracker) -> tuple:
    """(windows not yet in the resumed tracker ``tr``, how many were left out): with its recording_cursor
    (start ns, time) a recording that started before the cursor's is in whole, the cursor's own recording up to
    its time; a recording without a start (CSV) or a cursor without one: windows at or before the tracker's
    last time are in (one shared drive clock)."""
    cur = tr.recording_cursor
    out, left = [], 0
    for start, wins in blocks:
        if cur is not None and cur[0] is not None and start is not None:
            keep = [] if start < cur[0] else ([w for w in wins if w.time_s > cur[1]] if start == cur[0] else wins)
        elif tr.last_time_s is not None:
            keep = [w for w in wins if w.time_s > tr.last_time_s]
        else:
            keep = wins
        left += len(wins) - len(keep)
        out.append((start, keep))
    return out, left


def _diagnose_for_trend(rec, floor: float, kwargs: dict) -> tuple:
    """One recording for :func:`run_trend` (also in a worker process): (TrendWindows, summary row, log
    lines, the OfflineError's text or None)."""
    lines: list = []
    try:
        res = diagnose_recording(rec, log=lines.append, **kwargs)
    except OfflineError as exc:
        return [], None, lines, str(exc)
    return ([trend_window(w, str(rec), floor) for w in res.windows],
            (str(rec), len(res.windows), res.samples, dict(res.dropped), res.clock_jumps), lines, None)


@dataclass(frozen=True)
class TrendOptions:
    """How :func:`run_trend` diagnoses the recordings (``jident diagnose``'s options) and how many worker
    processes it uses: ``detector`` 'flank' (no K2 needed, every window carries the flank-to-flank K2 estimate
    the trend follows) or 'paper' (inequality (1) with the recording's K2, the width then from the gap
    estimator); ``signals_topic`` the drive/signals topic to read (a recording of several drives; None: the
    recording's only one); ``jobs`` > 1 (without the image method): recordings diagnosed in parallel; ``policy``
    the drive's declaration (torque accuracy, friction bands: a drive file's /**/jident_diagnostic section)."""

    system: Any = None
    method: Any = None
    p: float = 2.0
    gap_method: str = "auto"
    image_method: bool = False
    library_path: Any = None
    backlash_width_m: Optional[float] = None
    detector: str = "flank"
    gear_ratio: float = 1.0
    signals_topic: Optional[str] = None
    jobs: int = 1
    order: str = "recorded"
    policy: Any = None          # the publishing policy (VerdictPolicy; None: the diagnostic node's defaults)


def run_trend(recordings: Sequence, options: Optional[TrendOptions] = None, *, config: Optional[TrendConfig] = None,
              tracker: Optional[TrendTracker] = None, log: Callable[[str], Any] = lambda text: None,
              on_window: Optional[Callable[[Any], Any]] = None,
              on_recording: Optional[Callable[[int, str], Any]] = None, **fields) -> TrendRun:
    """Diagnose every recording (``diagnose_recording`` with :class:`TrendOptions` ``options``, or its fields
    given by name), put the recordings in order (:func:`order_recordings`, ``order``; each one's windows in
    stream order), leave out what a resumed state already holds and run the tracker (``tracker``, e.g.
    restored from a state, else a new one with ``config``) over the rest.

    ``jobs`` > 1 (without the image method): the recordings are diagnosed by that many worker processes
    (recordings are independent; the order of the result does not change); ``on_window`` is then not
    called and ``on_recording`` is called as each recording is done."""
    t0 = time.perf_counter()
    o = dataclasses.replace(options or TrendOptions(), **fields)
    system = load_system_config() if o.system is None else o.system
    method = load_method_config() if o.method is None else o.method
    library = None
    if o.image_method:
        lib_path = Path(o.library_path).expanduser() if o.library_path else default_library_path(system, method)
        library, err = load_pattern_library(lib_path, system, method, True, log=log, warn=log)
        if err:
            log(f"{err}; windows are diagnosed from the gap only")
    windows, summary = [], []
    tr = tracker if tracker is not None else TrendTracker(config)
    floor = tr.config.width_se_floor_m
    kwargs = dict(system=system, method=method, p=o.p, library_path=o.library_path, build_if_missing=False,
                  gap_method=o.gap_method, image_method=o.image_method and library is not None,
                  backlash_width_m=o.backlash_width_m, detector=o.detector, gear_ratio=o.gear_ratio,
                  signals_topic=o.signals_topic)
    if o.policy is not None:
        kwargs["policy"] = o.policy
    jobs = max(1, min(int(o.jobs), len(recordings)))
    if jobs > 1 and not o.image_method:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_diagnose_for_trend, rec, floor, kwargs) for rec in recordings]
            results = []
            for k, (rec, fut) in enumerate(zip(recordings, futures)):
                results.append(fut.result())
                if on_recording is not None:
                    on_recording(k, str(rec))
    else:
        results = []
        for k, rec in enumerate(recordings):
            if on_recording is not None:
                on_recording(k, str(rec))
            try:
                res = diagnose_recording(rec, library=library, log=log, on_window=on_window, **kwargs)
            except OfflineError as exc:
                results.append(([], None, [], str(exc)))
                break
            results.append(([trend_window(w, str(rec), floor) for w in res.windows],
                             (str(rec), len(res.windows), res.samples, dict(res.dropped), res.clock_jumps), [], None))
    blocks = []
    for rec, (wins, row, lines, error) in zip(recordings, results):
        for line in lines:
            log(line)
        if error is not None:
            raise OfflineError(error)
        blocks.append((recording_start_ns(rec), wins))
        summary.append(row)
    blocks, how = order_recordings(blocks, o.order)
    blocks, skipped_old = _not_in_state(blocks, tr)
    updates = []
    for start, wins in blocks:
        for w in wins:
            windows.append(w)
            updates.append(tr.update(w.time_s, w.inertia_kgm2, w.inertia_se_kgm2, w.width_m, w.width_se_m,
                                     inertia_refused=w.refused_kind))
            tr.recording_cursor = (start, w.time_s)
    return TrendRun(windows, updates, tr, summary, skipped_old, time.perf_counter() - t0, how)


def _num(v) -> str:
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else repr(float(v))


def write_trend_csv(run: TrendRun, path) -> Path:
    """One row per window (columns :data:`CSV_COLUMNS`); ``change`` is 1 on the window at which a
    change was detected (``change_quantity``: inertia, width or both)."""
    path = Path(path)
    with open(path, "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(CSV_COLUMNS)
        for w, u in zip(run.windows, run.updates):
            reason = w.skip_reason if w.inertia_kgm2 is None else (u.reason if u.skipped else None)
            wr.writerow([_num(w.time_s), w.recording, w.window_id, _num(w.inertia_kgm2), _num(w.inertia_se_kgm2),
                         _num(w.inertia_ci_low_kgm2), _num(w.inertia_ci_high_kgm2), _num(w.width_m),
                         _num(w.width_se_m), _num(w.true_inertia_kgm2), _num(u.inertia_kgm2),
                         _num(u.inertia_se_kgm2), _num(u.inertia_baseline_kgm2), _num(u.inertia_drift_pct),
                         _num(u.width_m), _num(u.width_se_m), _num(u.wear_rate_m_per_day),
                         _num(u.wear_rate_se_m_per_day), _num(u.time_to_limit_s), int(u.change),
                         "+".join(c.quantity for c in u.changes), u.level_name, reason or "", w.width_source or ""])
    return path
