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
(:func:`jident_ros.identify.trend_status.trend_inputs`: the gap J1 whenever physics allows it -- published or
ambiguous, not refused as implausible or inconsistent -- and the flank detector's flank-to-flank K2 of the window,
else the gap estimator's width at re-contact).  The windows go through one
:class:`jident_ros.identify.trend.TrendTracker` **recording by recording** (``--order recorded``, the default:
by each bag's start, its first message's log time; CSV files, which have none, by their first entry on the drive
clock; ``--order given``: as listed), each recording's windows in their stream order (``entry_time_s``, the
``t`` of the entry sample on the drive clock).  A drive whose clock restarted between two recordings (t back
to 0) is therefore never interleaved: the tracker sees the clock go back once and starts a time segment.
Outputs: ``DIR/trend.csv`` (one row per window), ``DIR/trend.png`` (J1 and K2 against time with their bands,
the baseline and the detected changes) and a summary on stdout.  ``--state FILE`` resumes from a saved tracker
(what it already holds is left out: recordings that started before the last one it took, and that one's
windows up to its last; for CSV files, windows at or before its last drive time) and saves it back
(atomically).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Optional

import numpy as np

from jident_ros.cli.argtypes import count_arg as _count
from jident_ros.cli.argtypes import finite_float_arg as _finite_float
from jident_ros.cli.drive_file import read_drive_file, resolve
from jident_ros.cli.fleet import cmd_fleet
from jident_ros.cli.offline import OfflineError, default_policy
from jident_ros.cli.trend_run import (  # noqa: F401  (re-exported: the demo and the tests import them from here)
    CSV_COLUMNS,
    ORDERS,
    TrendOptions,
    TrendRun,
    TrendWindow,
    run_trend,
    trend_window,
    write_trend_csv,
)
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.trend import SECONDS_PER_DAY, TrendConfig, TrendStateError, TrendTracker
from jident_ros.identify.trend_status import WIDTH_SOURCES, Z95
from jident_ros.parameters import cli_help
from jident_ros.stream.flank import DETECTORS

# --------------------------------------------------------------------------- outputs

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
    fed = sum(1 for w, u in zip(ws, us) if w.inertia_kgm2 is not None and not u.skipped)
    text = (f"windows: {len(ws)} from {n_rec} recording(s) {run.order or 'in order'}; {used} used by the trend "
            f"(J1 fed from {fed}), {skipped} skipped")
    reasons: dict = {}
    for w, u in zip(ws, us):
        if w.inertia_kgm2 is None or u.skipped:
            r = w.refused_kind or (u.reason or w.skip_reason or "?").split(":")[0]
            reasons[r] = reasons.get(r, 0) + 1
    if reasons:
        text += "; without J1: " + ", ".join(f"{r} {n}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1]))
    if run.already_in_state:
        text += f"; {run.already_in_state} already in the state left out"
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
                   "state to it at the end (atomic write); with --fleet a directory: one state per drive, "
                   "FILE/<drive>.json")
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
    g.add_argument("--gear-ratio", type=_finite_float("--gear-ratio"), default=None,
                   help="flank detector: N in delta = alpha1 - N alpha2 (default: the drive file's, else 1)")
    g.add_argument("--backlash-width-m", type=_finite_float("--backlash-width-m"),
                   help="--detector paper: K2 of inequality (1), m (default: the recording's drive/backlash_width, "
                        "else 0.005)")
    g.add_argument("--order", choices=ORDERS, default="recorded",
                   help="order of the recordings: recorded (default: by each bag's start, its first message's log "
                        "time; CSV files by their first entry on the drive clock) or given (as listed); a "
                        "recording's windows always stay together, in stream order, so a drive clock that restarted "
                        "between recordings is never interleaved")
    g.add_argument("--config", help="system config YAML or drive file (default: config/system.yaml); a drive "
                   "file's /**/jident_diagnostic section declares the drive (torque accuracy, friction bands) and its "
                   "/**/jident_windowing section the gear ratio and joint names (docs/your_drive.md)")
    g.add_argument("--method-config", help="method config YAML (default: config/method.yaml)")
    g.add_argument("--jobs", type=_count("--jobs", 0), default=0,
                   help="worker processes diagnosing the recordings in parallel (0, default: one per core; 1: in "
                        "this process, progress per window; the image method always runs in this process)")
    g.add_argument("--fleet", action="store_true",
                   help="REC... are folders of many drives' recordings (searched recursively): one trend per drive, "
                        "OUT/fleet.csv (drive, J1 drift, width, wear rate, time to limit, level), OUT/fleet.png (small "
                        "multiples), OUT/drives/<drive>/trend.csv; drives in a process pool (--jobs)")
    g.add_argument("--drive-id", metavar="FILE|parent",
                   help="--fleet: which drive a recording belongs to: a CSV of 'recording,drive' lines, or 'parent' "
                        "(the recording's folder name); default: the namespace of its drive/signals topic")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.set_defaults(func=cmd_trend)


def trend_options(args, system, method, jobs: int) -> TrendOptions:
    """The :class:`TrendOptions` of ``jident trend``'s flags and the drive file (``--config``, cli/drive_file.py)."""
    declared = read_drive_file(getattr(args, "config", None))
    return TrendOptions(system=system, method=method, p=args.p, gap_method=args.gap_method,
                        image_method=args.image_method, library_path=args.library,
                        backlash_width_m=args.backlash_width_m, detector=args.detector,
                        gear_ratio=resolve(args.gear_ratio, declared, "gear_ratio"),
                        jobs=jobs, order=args.order, policy=default_policy(**declared.policy()))


def _overrides(args) -> dict:
    """The trend flags given (they replace a resumed state's saved values)."""
    names = ("commissioning_windows", "drift_warn_pct", "drift_alarm_pct", "width_limit_m")
    return {n: getattr(args, n) for n in names if getattr(args, n) is not None}


def _trend_config(args, saved: Optional[dict]) -> TrendConfig:
    return TrendConfig.from_dict({**(dict(saved) if saved else {}), **_overrides(args)})


def cmd_trend(args) -> int:
    missing = [r for r in args.recordings if not Path(r).exists()]
    if missing:
        raise OfflineError(f"recording {missing[0]}: no such file or directory")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise OfflineError(f"--out {out}: exists and is not a directory")
    system = load_system_config(args.config)
    method = load_method_config(args.method_config)
    if args.drive_id and not args.fleet:
        raise OfflineError("--drive-id: only with --fleet")
    if args.fleet:
        return cmd_fleet(args, trend_options(args, system, method, args.jobs), _trend_config(args, None),
                         _overrides(args))
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
        run = run_trend(args.recordings, trend_options(args, system, method, jobs), config=config, tracker=tracker,
                        log=log,
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


__all__ = ["CSV_COLUMNS", "TrendOptions", "TrendRun", "TrendWindow", "add_trend_parser", "cmd_trend", "format_summary", "plot_trend",
           "run_trend", "trend_window", "write_trend_csv"]
