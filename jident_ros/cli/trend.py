"""``jident trend REC... --out DIR``: the trend of J1 and the backlash width over many recordings
(issue 14, offline).  ``jident simulate --scenario wear`` (a long simulated run written as a recording) is in
:mod:`jident_ros.cli.scenario`.

Trend
-----
Every recording is diagnosed window by window exactly as ``jident diagnose`` does
(:func:`jident_ros.cli.offline.diagnose_recording`; by default the gap estimator only, no image method, and the
flank detector, ``--detector flank``, which needs no K2).
Each window becomes a :class:`TrendWindow` (time, J1 with its standard error and 95 % interval, width
with its standard error and its source, or the reason why it has no J1) by the diagnostic node's rule
(:func:`jident_ros.identify.trend_status.trend_inputs`: the published gap J1 only -- a refused or ambiguous gap
estimate is not used -- and the flank detector's flank-to-flank K2 of the window, else the gap estimator's width
at re-contact).  The windows of all recordings are sorted by
their **drive time**: ``entry_time_s``, the ``t`` column (drive clock, s) of the window's entry sample,
as the drive publishes it on ``drive/signals`` (recordings are assumed to share one drive clock; the bag's
receive time is not used).  They then go through one :class:`jident_ros.identify.trend.TrendTracker`
in that order.  Outputs: ``DIR/trend.csv`` (one row per window),
``DIR/trend.png`` (J1 and K2 against time with their bands, the baseline and the detected changes) and a
summary on stdout.  ``--state FILE`` resumes from a saved tracker (windows at or before its last time are
left out: already in the state) and saves it back (atomically).
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from jident_ros.cli.argtypes import count_arg as _count
from jident_ros.cli.argtypes import finite_float_arg as _finite_float
from jident_ros.cli.offline import OfflineError, diagnose_recording
from jident_ros.cli.scenario import (  # noqa: F401  (re-exported: cli/main.py and the tests import them from here)
    add_scenario_arguments,
    cmd_simulate_scenario,
    write_scenario_recording,
)
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.trend import SECONDS_PER_DAY, TrendConfig, TrendStateError, TrendTracker
from jident_ros.identify.trend_status import WIDTH_SOURCES, Z95, trend_inputs
from jident_ros.parameters import cli_help
from jident_ros.stream.flank import DETECTORS

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
    inertia_kgm2, inertia_se_kgm2 : the published gap J1 and its standard error, kg m^2 (None: no published
        gap J1 -- refused, ambiguous, image method only or no gap; ``skip_reason`` says why)
    inertia_ci_low_kgm2, inertia_ci_high_kgm2 : its 95 % interval, kg m^2
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


def trend_window(ow, recording: str, width_se_floor_m: float = 0.0) -> TrendWindow:
    """An :class:`jident_ros.cli.offline.OfflineWindow` -> :class:`TrendWindow`, with the diagnostic node's
    rule (:func:`jident_ros.identify.trend_status.trend_inputs`): J1 only when the published J1 is the gap
    estimate (a refused or ambiguous gap J1 and an image class alone are skipped, with the reason); the
    width from the flank detector when the window has its estimate, else from the gap estimator."""
    d = ow.diagnosis
    j, se, wm, wse, source = trend_inputs(d, width_se_floor_m, ow)
    lo = hi = reason = None
    if j is not None:
        lo, hi = (float(v) for v in d.gap.ci95_kgm2)
    elif d.inertia_kgm2 is not None:
        reason = f"J1 {d.inertia_kgm2:.5g} kg m^2 from the {d.source} method has no standard error"
    elif d.gap is not None:
        reason = f"gap J1 {d.gap.inertia_kgm2:.5g} kg m^2 not published ({d.status}: {d.refused_reason or d.message})"
    else:
        reason = "; ".join(d.problems) or d.message
    return TrendWindow(float(ow.entry_time_s), recording, int(ow.window_id), j, se, lo, hi, wm, wse, reason,
                       ow.true_inertia_kgm2, source)


# --------------------------------------------------------------------------- the run

@dataclass
class TrendRun:
    """Result of :func:`run_trend`."""

    windows: list                # TrendWindow, in time order (the ones fed to the tracker)
    updates: list                # TrendUpdate, one per window
    tracker: TrendTracker
    recordings: list             # (path, windows, samples, dropped dict, clock jumps)
    already_in_state: int = 0    # windows at or before the resumed state's last time, left out
    seconds: float = 0.0


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


def run_trend(recordings: Sequence, *, system=None, method=None, config: Optional[TrendConfig] = None,
              tracker: Optional[TrendTracker] = None, p: float = 2.0, gap_method: str = "auto",
              image_method: bool = False, library_path=None, backlash_width_m: Optional[float] = None,
              detector: str = "flank", gear_ratio: float = 1.0, log: Callable[[str], Any] = lambda text: None,
              on_window: Optional[Callable[[Any], Any]] = None,
              on_recording: Optional[Callable[[int, str], Any]] = None, jobs: int = 1) -> TrendRun:
    """Diagnose every recording (``diagnose_recording``, with ``detector``: 'flank' -- no K2 needed, every
    window carries the flank-to-flank K2 estimate the trend follows -- or 'paper', inequality (1) with the
    recording's K2, the width then from the gap estimator), sort all windows by drive time and run the
    tracker (``tracker``, e.g. restored from a state, else a new one with ``config``) over them.

    ``jobs`` > 1 (without the image method): the recordings are diagnosed by that many worker processes
    (recordings are independent; the order of the result does not change); ``on_window`` is then not
    called and ``on_recording`` is called as each recording is done."""
    t0 = time.perf_counter()
    system = load_system_config() if system is None else system
    method = load_method_config() if method is None else method
    library = None
    if image_method:
        lib_path = Path(library_path).expanduser() if library_path else default_library_path(system, method)
        library, err = load_pattern_library(lib_path, system, method, True, log=log, warn=log)
        if err:
            log(f"{err}; windows are diagnosed from the gap only")
    windows, summary = [], []
    tr = tracker if tracker is not None else TrendTracker(config)
    floor = tr.config.width_se_floor_m
    kwargs = dict(system=system, method=method, p=p, library_path=library_path, build_if_missing=False,
                  gap_method=gap_method, image_method=image_method and library is not None,
                  backlash_width_m=backlash_width_m, detector=detector, gear_ratio=gear_ratio)
    jobs = max(1, min(int(jobs), len(recordings)))
    if jobs > 1 and not image_method:
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
    for wins, row, lines, error in results:
        for line in lines:
            log(line)
        if error is not None:
            raise OfflineError(error)
        windows.extend(wins)
        summary.append(row)
    windows.sort(key=lambda w: w.time_s)          # stable: recording order breaks ties
    skipped_old = 0
    if tr.last_time_s is not None:
        n0 = len(windows)
        windows = [w for w in windows if w.time_s > tr.last_time_s]
        skipped_old = n0 - len(windows)
    updates = [tr.update(w.time_s, w.inertia_kgm2, w.inertia_se_kgm2, w.width_m, w.width_se_m) for w in windows]
    return TrendRun(windows, updates, tr, summary, skipped_old, time.perf_counter() - t0)


# --------------------------------------------------------------------------- outputs

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


def _days(t, t0):
    return (np.asarray(t, dtype=float) - t0) / SECONDS_PER_DAY


def plot_trend(run: TrendRun, path, config: TrendConfig) -> Path:
    """trend.png: J1 (top) and K2 (bottom) against drive time in days: the per-window estimates with
    their 95 % intervals, the smoothed value with its 95 % band, the baseline, the true J1 when known,
    the width limit when within reach, and the detected changes (vertical lines)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    ws, us = run.windows, run.updates
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7.5), sharex=True, constrained_layout=True)
    if not ws:
        ax1.set_title("no window")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return path
    t0 = ws[0].time_s
    x = _days([w.time_s for w in ws], t0)
    few = len(ws) <= 400

    def col(seq, name):
        return np.array([np.nan if getattr(s, name) is None else getattr(s, name) for s in seq], dtype=float)

    def band(ax, v, se, color, label):
        ax.plot(x, v, color=color, lw=1.5, label=label)
        ax.fill_between(x, v - Z95 * se, v + Z95 * se, color=color, alpha=0.2, lw=0)

    # J1
    j, lo, hi = col(ws, "inertia_kgm2"), col(ws, "inertia_ci_low_kgm2"), col(ws, "inertia_ci_high_kgm2")
    if few:
        ax1.errorbar(x, j, yerr=[j - lo, hi - j], fmt="o", ms=3, lw=0.6, color="0.45", label="J1 per window (95 % CI)")
    else:
        ax1.plot(x, j, ".", ms=2, color="0.45", label="J1 per window")
    band(ax1, col(us, "inertia_kgm2"), col(us, "inertia_se_kgm2"), "C0", "smoothed (95 % band)")
    ax1.step(x, col(us, "inertia_baseline_kgm2"), where="post", color="C2", lw=1.2, ls="--", label="baseline")
    truth = col(ws, "true_inertia_kgm2")
    if np.isfinite(truth).any():
        ax1.step(x, truth, where="post", color="C3", lw=0.8, ls=":", label="true J1")
    ax1.set_ylabel("J1 [kg m$^2$]")
    # width
    wm, wse = col(ws, "width_m"), col(ws, "width_se_m")
    if few:
        ax2.errorbar(x, wm * 1e3, yerr=Z95 * wse * 1e3, fmt="o", ms=3, lw=0.6, color="0.45",
                     label="K2 per window (95 %)")
    else:
        ax2.plot(x, wm * 1e3, ".", ms=2, color="0.45", label="K2 per window")
    wv, wvse = col(us, "width_m") * 1e3, col(us, "width_se_m") * 1e3
    band(ax2, wv, wvse, "C1", "regression line (95 % band)")
    ax2.step(x, col(us, "width_baseline_m") * 1e3, where="post", color="C2", lw=1.2, ls="--", label="baseline")
    top = np.nanmax(np.concatenate([wm * 1e3, wv])) if np.isfinite(wm).any() else None
    if top is not None and config.width_limit_m * 1e3 <= 1.3 * top:
        ax2.axhline(config.width_limit_m * 1e3, color="C3", lw=1.0, label="width limit")
    ax2.set_ylabel("backlash width K2 [mm]")
    ax2.set_xlabel(f"drive time since the first window [days] (t0 = {t0:.0f} s)")
    for u in us:
        for c in u.changes:
            ax = ax1 if c.quantity == "inertia" else ax2
            xc = _days(c.time_s, t0)
            ax.axvline(xc, color="C3", lw=1.0)
            txt = f"{c.size_pct:+.1f} %" if c.quantity == "inertia" else f"{c.size * 1e3:+.2f} mm"
            ax.annotate(f"change {txt}", xy=(xc, 0.97), xycoords=("data", "axes fraction"), fontsize=8,
                        color="C3", ha="left", va="top", rotation=90)
    last = us[-1]
    ax1.set_title(f"J1 trend: {last.level_name}", loc="left", fontsize=10)
    rate = "" if last.wear_rate_m_per_day is None else \
        f": wear {last.wear_rate_m_per_day * 1e3:.3g} ± {last.wear_rate_se_m_per_day * 1e3:.2g} mm/day"
    ax2.set_title(f"backlash width{rate}", loc="left", fontsize=10)
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _pm(v, se, scale=1.0, fmt=".4g", sefmt=".2g"):
    if v is None:
        return "-"
    return f"{v * scale:{fmt}}" + ("" if se is None else f" ± {se * scale:{sefmt}}")


def format_summary(run: TrendRun, config: TrendConfig) -> str:
    """The stdout summary: windows, time span, baseline, current values, drift, changes, wear, health."""
    ws, us = run.windows, run.updates
    lines = []
    n_rec = len(run.recordings)
    dropped: dict = {}
    for *_, d, _ in run.recordings:
        for r, n in d.items():
            dropped[r] = dropped.get(r, 0) + n
    jumps = sum(r[4] for r in run.recordings)
    used = sum(1 for u in us if not u.skipped)
    skipped = len(us) - used
    text = (f"windows: {len(ws)} from {n_rec} recording(s) in drive-time order; {used} used by the trend, "
            f"{skipped} skipped")
    if skipped:
        reasons: dict = {}
        for w, u in zip(ws, us):
            if u.skipped:
                r = (w.skip_reason or u.reason or "?").split(":")[0]
                reasons[r] = reasons.get(r, 0) + 1
        text += " (" + ", ".join(f"{r}: {n}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])) + ")"
    if run.already_in_state:
        text += f"; {run.already_in_state} already in the state (at or before its last time) left out"
    lines.append(text)
    sources = {src: sum(1 for w in ws if w.width_source == src) for src in WIDTH_SOURCES}
    lines.append(f"width: the flank detector's flank-to-flank estimate in {sources['flank']} window(s), the gap "
                 f"estimator's width (fallback: no flank estimate) in {sources['gap']}, none in "
                 f"{len(ws) - sum(sources.values())}")
    if dropped or jumps:
        lines.append("detector: " + ", ".join([f"{r} {n}" for r, n in dropped.items()] +
                                              ([f"{jumps} clock jump(s) between windows"] if jumps else [])))
    if not ws:
        return "\n".join(lines + ["no window: nothing to trend"])
    t0, t1 = ws[0].time_s, ws[-1].time_s
    lines.append(f"time: drive clock t of the entry samples, {t0:.0f} s to {t1:.0f} s "
                 f"({(t1 - t0) / SECONDS_PER_DAY:.3g} days)")
    last = us[-1]
    if last.inertia_baseline_kgm2 is not None:
        ref = "" if last.inertia_reference_kgm2 == last.inertia_baseline_kgm2 else \
            f" (commissioned {last.inertia_reference_kgm2:.5g} kg m^2)"
        lines.append(f"J1 baseline {_pm(last.inertia_baseline_kgm2, last.inertia_baseline_se_kgm2, fmt='.5g')} "
                     f"kg m^2{ref}; now {_pm(last.inertia_kgm2, last.inertia_se_kgm2, fmt='.5g')} kg m^2, drift "
                     f"{last.inertia_drift_pct:+.2f} ± {last.inertia_drift_se_pct:.2f} % "
                     f"({last.inertia_drift_from_reference_pct:+.2f} % of the commissioned)")
    elif last.inertia_kgm2 is not None:
        lines.append(f"J1 {_pm(last.inertia_kgm2, last.inertia_se_kgm2, fmt='.5g')} kg m^2 (baseline still "
                     f"being learnt: {config.commissioning_windows} windows needed)")
    if last.width_m is not None:
        text = f"backlash width now {_pm(last.width_m, last.width_se_m, 1e3)} mm"
        if last.width_baseline_m is not None:
            text += f" (baseline {_pm(last.width_baseline_m, last.width_baseline_se_m, 1e3)} mm"
            text += "" if last.width_drift_pct is None else f", {last.width_drift_pct:+.1f} %"
            text += ")"
        if last.wear_rate_m_per_day is not None:
            text += (f"; wear rate {last.wear_rate_m_per_day * 1e3:.4g} ± {last.wear_rate_se_m_per_day * 1e3:.2g} "
                     f"mm/day")
        if last.time_to_limit_s is not None:
            text += (f"; {config.width_limit_m * 1e3:.4g} mm limit in {last.time_to_limit_s / SECONDS_PER_DAY:.3g} "
                     f"days [{last.time_to_limit_low_s / SECONDS_PER_DAY:.3g}, "
                     f"{last.time_to_limit_high_s / SECONDS_PER_DAY:.3g}]")
        else:
            text += f"; no significant wear towards the {config.width_limit_m * 1e3:.4g} mm limit"
        lines.append(text)
    changes = [c for u in us for c in u.changes]
    if changes:
        lines.append(f"changes: {len(changes)}")
        for c in changes:
            size = (f"{c.size:+.4g} ± {c.size_se:.2g} kg m^2 ({c.size_pct:+.2f} %)" if c.quantity == "inertia"
                    else f"{c.size * 1e3:+.3g} ± {c.size_se * 1e3:.2g} mm ({c.size_pct:+.1f} %)")
            lines.append(f"  {c.quantity}: {size} detected at t = {c.time_s:.0f} s (window {c.window_index}), "
                         f"onset t = {c.onset_time_s:.0f} s (window {c.onset_window_index})")
    else:
        lines.append("changes: none detected")
    lines.append(f"health: {last.level_name}: {last.message}")
    return "\n".join(lines)


#: The flags of `jident trend` that mirror the diagnostic node's trend_* parameters (their --help from the schema).
MIRRORED_FLAGS = ("--commissioning-windows", "--drift-warn-pct", "--drift-alarm-pct", "--width-limit-m")


def add_trend_parser(sub) -> None:
    """Register ``jident trend`` on the main parser's subparsers."""
    g = sub.add_parser("trend", help="trend of J1 and the backlash width over many recordings (diagnose every "
                       "window, time order, change detection, wear rate): trend.csv, trend.png, a summary")
    g.add_argument("recordings", nargs="+", metavar="REC", help="bag directories or .mcap files (any order)")
    g.add_argument("--out", required=True, metavar="DIR", help="directory for trend.csv and trend.png")
    g.add_argument("--state", metavar="FILE", help="resume from this tracker state when it exists and save the "
                   "state to it at the end (atomic write)")
    for flag, parse in ((MIRRORED_FLAGS[0], _count("--commissioning-windows", 2)),
                        *((f, _finite_float(f)) for f in MIRRORED_FLAGS[1:])):    # the node's trend_*, mirrored
        g.add_argument(flag, type=parse, help=cli_help("trend_" + flag[2:].replace("-", "_")))
    g.add_argument("--p", type=_finite_float("--p"), default=2.0, help="KHM exponent of the image method (default 2)")
    g.add_argument("--gap-method", choices=("auto", "acceleration", "anchored", "angle", "speed"), default="auto",
                   help="gap estimator (default auto, as jident diagnose)")
    g.add_argument("--image-method", action=argparse.BooleanOptionalAction, default=False,
                   help="also run the paper's image method on every window (slow; the trend uses the gap "
                        "estimate either way; default: off)")
    g.add_argument("--library", help="pattern library .npz for --image-method")
    g.add_argument("--detector", choices=DETECTORS, default="flank",
                   help="entry detector: flank (default: no K2 needed; every window carries the flank-to-flank K2 "
                        "estimate the width trend follows) or paper (inequality (1) with the recording's K2; the "
                        "width then comes from the gap estimator, ~25x noisier)")
    g.add_argument("--gear-ratio", type=_finite_float("--gear-ratio"), default=1.0,
                   help="flank detector: N in delta = alpha1 - N alpha2 (default 1)")
    g.add_argument("--backlash-width-m", type=_finite_float("--backlash-width-m"),
                   help="--detector paper: K2 of inequality (1), m (default: the recording's drive/backlash_width, "
                        "else 0.005)")
    g.add_argument("--config", help="system config YAML (default: config/system.yaml)")
    g.add_argument("--method-config", help="method config YAML (default: config/method.yaml)")
    g.add_argument("--jobs", type=_count("--jobs", 0), default=0,
                   help="worker processes diagnosing the recordings in parallel (0, default: one per core; 1: in "
                        "this process, progress per window; the image method always runs in this process)")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(func=cmd_trend)


def _trend_config(args, saved: Optional[dict]) -> TrendConfig:
    d = dict(saved) if saved else {}
    for name in ("commissioning_windows", "drift_warn_pct", "drift_alarm_pct", "width_limit_m"):
        v = getattr(args, name)
        if v is not None:
            d[name] = v
    return TrendConfig.from_dict(d)


def cmd_trend(args) -> int:
    missing = [r for r in args.recordings if not Path(r).exists()]
    if missing:
        raise OfflineError(f"recording {missing[0]}: no such file or directory")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise OfflineError(f"--out {out}: exists and is not a directory")
    system = load_system_config(args.config)
    method = load_method_config(args.method_config)
    tracker = None
    if args.state and Path(args.state).exists():
        try:
            saved = TrendTracker.load(args.state)
            tracker = TrendTracker.load(args.state, _trend_config(args, saved.config.to_dict()))
        except TrendStateError as exc:
            raise OfflineError(f"--state: {exc}") from None
        config = tracker.config
    else:
        config = _trend_config(args, None)
    out.mkdir(parents=True, exist_ok=True)
    bar, log = None, (lambda text: None)
    if not args.quiet:
        from tqdm import tqdm
        bar = tqdm(desc="diagnosing", unit="window", file=sys.stderr, leave=False)

        def log(text):
            bar.write(f"jident trend: {text}", file=sys.stderr)
    n_rec = len(args.recordings)
    jobs = args.jobs or (os.cpu_count() or 1)
    if bar is not None and jobs > 1 and n_rec > 1 and not args.image_method:
        bar.unit, bar.total = "recording", n_rec
    try:
        run = run_trend(args.recordings, system=system, method=method, config=config, tracker=tracker, p=args.p,
                        jobs=jobs,
                        gap_method=args.gap_method, image_method=args.image_method, library_path=args.library,
                        backlash_width_m=args.backlash_width_m, detector=args.detector,
                        gear_ratio=args.gear_ratio, log=log,
                        on_window=None if bar is None else (lambda w: bar.update(1)),
                        on_recording=None if bar is None else
                        (lambda k, rec: bar.update(1) if bar.unit == "recording" else
                         bar.set_description(f"recording {k + 1}/{n_rec}")))
    finally:
        if bar is not None:
            bar.close()
    csv_path = write_trend_csv(run, out / "trend.csv")
    png_path = plot_trend(run, out / "trend.png", run.tracker.config)
    if args.state:
        run.tracker.save(args.state)
    print(format_summary(run, run.tracker.config))
    print(f"wrote {csv_path} and {png_path}" + (f"; state {args.state}" if args.state else "")
          + f" ({run.seconds:.1f} s)")
    return 0 if run.windows else 1


__all__ = ["CSV_COLUMNS", "TrendRun", "TrendWindow", "add_scenario_arguments", "add_trend_parser",
           "cmd_simulate_scenario", "cmd_trend", "format_summary", "plot_trend", "run_trend", "trend_window",
           "write_scenario_recording", "write_trend_csv"]
