"""Simulation harness of the trend tracker (research, not runtime): synthetic per-window estimate series
(:func:`simulate_series`, miscalibrated standard errors and occasional outliers) and the measurement of the
tracker's targets (:func:`measure_targets`: detection delay, false-alarm rate, wear-rate accuracy, the CUSUM
design check).  ``python -m jident_ros.research.evaluation.trend_simulation [--quick]`` prints them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.stats import chi2

from jident_ros.identify.trend import SECONDS_PER_DAY, TrendConfig, TrendTracker, TrendUpdate
from jident_ros.identify.trend_maths import coverage_to_se_scale, cusum_arl, cusum_threshold_for_arl, two_sided_arl


@dataclass(frozen=True)
class SimulatedSeries:
    """Synthetic per-window estimates (what the gap estimator would report) and the truth."""

    time_s: np.ndarray
    inertia_kgm2: np.ndarray
    inertia_se_kgm2: np.ndarray
    width_m: np.ndarray
    width_se_m: np.ndarray
    true_inertia_kgm2: np.ndarray
    true_width_m: np.ndarray
    step_at: int | None
    se_scale: float            # true sd / reported se
    coverage: float            # probability that the reported 95 % interval covers the truth (Gaussian part)


def simulate_series(n_windows: int, step_at: int | None = None, step_pct: float = 2.5, j1_se_pct: float = 0.5,
                    width_growth_m_per_window: float = 1.0e-5, seed: int | None = None, *,
                    inertia_kgm2: float = 1.16, width_m: float = 0.0025, width_se_pct: float = 0.05,
                    window_period_s: float = 3600.0, start_time_s: float = 0.0,
                    coverage: float | None = None, se_jitter: float = 0.2,
                    outlier_prob: float = 0.002, outlier_sd: float = 6.0,
                    width_step_at: int | None = None, width_step_m: float = 0.0) -> SimulatedSeries:
    """Synthetic J1/K2 estimate series, one window every ``window_period_s`` (default an hour).

    * True J1 = ``inertia_kgm2``, times (1 + step_pct/100) from window ``step_at`` (0-based) on.
    * True width = ``width_m`` + ``width_growth_m_per_window`` * i (+ ``width_step_m`` from ``width_step_at``).
    * Reported se: J1 ``j1_se_pct`` % and width ``width_se_pct`` % of the true value, each window times
      exp(N(0, se_jitter^2)) (the estimator's se varies with the window).
    * Errors: reported se * se_scale * N(0, 1), se_scale from ``coverage`` (the 95 % interval's coverage;
      None: drawn uniformly in [0.92, 0.99] per series, i.e. se_scale in [0.76, 1.12]); with probability
      ``outlier_prob`` per window and quantity an outlier N(0, outlier_sd^2) in units of the true sd.
    """
    rng = np.random.default_rng(seed)
    if coverage is None:
        coverage = float(rng.uniform(0.92, 0.99))
    s = coverage_to_se_scale(coverage)
    i = np.arange(n_windows)
    t = start_time_s + window_period_s * i
    tj = np.full(n_windows, float(inertia_kgm2))
    if step_at is not None:
        tj[step_at:] *= 1.0 + step_pct / 100.0
    tw = width_m + width_growth_m_per_window * i
    if width_step_at is not None:
        tw[width_step_at:] += width_step_m

    def noisy(truth, se_pct):
        se = truth * se_pct / 100.0 * np.exp(se_jitter * rng.standard_normal(n_windows))
        e = rng.standard_normal(n_windows)
        out = rng.random(n_windows) < outlier_prob
        e[out] = outlier_sd * rng.standard_normal(int(out.sum()))
        return truth + s * se * e, se

    yj, sej = noisy(tj, j1_se_pct)
    yw, sew = noisy(tw, width_se_pct)
    return SimulatedSeries(t, yj, sej, yw, sew, tj, tw, step_at, s, coverage)


def run_series(series: SimulatedSeries, config: TrendConfig | None = None, width: bool = True) -> list[TrendUpdate]:
    """A fresh tracker over a simulated series."""
    tr = TrendTracker(config)
    return tr.batch(series.time_s, series.inertia_kgm2, series.inertia_se_kgm2,
                    series.width_m if width else None, series.width_se_m if width else None)


def detection_delays(trials: int = 200, seed: int = 0, config: TrendConfig | None = None, step_pct: float = 2.5,
                     pre_windows: int = 30, post_windows: int = 20) -> dict:
    """J1 step of +-step_pct % after commissioning + ``pre_windows`` steady windows, per-window se
    uniform in 0.4-0.6 % of J1, coverage uniform in 92-99 %.  Delay = windows from the step window
    (delay 1: detected at the step window) to the first J1 change at or after it; ``missed`` when none
    within ``post_windows``."""
    cfg = config if config is not None else TrendConfig()
    rng = np.random.default_rng(seed)
    step_at = cfg.commissioning_windows + pre_windows

    def series(trial):
        sign = 1 if trial % 2 == 0 else -1
        s = simulate_series(step_at + post_windows, step_at=step_at, step_pct=sign * step_pct,
                            j1_se_pct=float(rng.uniform(0.4, 0.6)), seed=int(rng.integers(2 ** 63)))
        return s.time_s, s.inertia_kgm2, s.inertia_se_kgm2, sign
    return step_trials(trials, series, cfg, step_at)


def step_trials(trials: int, make_series, config: TrendConfig, step_at: int) -> dict:
    """:func:`delay_summary` over ``trials`` series, each from ``make_series(trial)`` -> (time_s, inertia_kgm2,
    inertia_se_kgm2, sign of the step at window ``step_at``), each through a fresh tracker."""
    delays, missed, false_before = [], 0, 0
    for trial in range(trials):
        t, j, se, sign = make_series(trial)
        found, false = step_delay(TrendTracker(config), t, j, se, step_at, sign)
        false_before += false
        if found is None:
            missed += 1
        else:
            delays.append(found)
    return delay_summary(trials, delays, missed, false_before)


def step_delay(tracker: "TrendTracker", time_s, inertia_kgm2, inertia_se_kgm2, step_at: int,
               sign: int) -> tuple[int | None, int]:
    """Feed J1 windows to ``tracker`` until the first J1 change of ``sign`` at or after window ``step_at``:
    (delay in windows, 1 = detected at the step window, or None; J1 changes detected before the step)."""
    false_before = 0
    for i in range(len(time_s)):
        u = tracker.update(time_s[i], inertia_kgm2[i], inertia_se_kgm2[i])
        for ev in u.changes:
            if ev.quantity != "inertia":
                continue
            if i < step_at:
                false_before += 1
            elif ev.sign == sign:
                return i - step_at + 1, false_before
    return None, false_before


def delay_summary(trials: int, delays: Sequence[int], missed: int, false_before: int) -> dict:
    """The detection-delay statistics of :func:`detection_delays` (and of the evaluation on real windows):
    trials, detected, missed, false changes before the step, median / p95 / max delay (inf when none was
    detected) and the histogram {delay: trials}."""
    d = np.array(delays, dtype=float)
    return {"trials": trials, "detected": len(delays), "missed": missed, "false_before_step": false_before,
            "median": float(np.median(d)) if d.size else math.inf,
            "p95": float(np.percentile(d, 95)) if d.size else math.inf,
            "max": float(d.max()) if d.size else math.inf,
            "histogram": {int(k): int(v) for k, v in zip(*np.unique(d, return_counts=True))}}


def false_alarms(monitored_windows: int = 100_000, seed: int = 0, config: TrendConfig | None = None,
                 series_windows: int = 1000, width_growth_m_per_window: float = 1.0e-5) -> dict:
    """Steady J1 (and a steady linear width growth) over ``monitored_windows`` windows after
    commissioning, in series of ``series_windows`` (each with its own commissioning, se level and
    miscalibration, outliers included).  Counts the detected changes per quantity."""
    cfg = config if config is not None else TrendConfig()
    rng = np.random.default_rng(seed)
    n_series = max(1, math.ceil(monitored_windows / series_windows))
    comm = cfg.commissioning_windows
    fa_j = fa_w = monitored = 0
    for _ in range(n_series):
        n = comm + series_windows
        s = simulate_series(n, j1_se_pct=float(rng.uniform(0.4, 0.6)), seed=int(rng.integers(2 ** 63)),
                            width_growth_m_per_window=width_growth_m_per_window,
                            width_se_pct=float(rng.uniform(0.01, 0.1)))
        for u in run_series(s, cfg):
            for ev in u.changes:
                if ev.quantity == "inertia":
                    fa_j += 1
                else:
                    fa_w += 1
        monitored += series_windows
    return {"monitored_windows": monitored, "series": n_series, "inertia_changes": fa_j, "width_changes": fa_w,
            "inertia_per_10k": 1e4 * fa_j / monitored, "width_per_10k": 1e4 * fa_w / monitored,
            # one-sided 95 % Poisson upper bound of the rate (Garwood)
            "inertia_per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (fa_j + 1))) / 2 / monitored,
            "width_per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (fa_w + 1))) / 2 / monitored,
            "design_arl_windows": cfg.target_arl_windows, "threshold_sd": cfg.threshold_sd}


def wear_rate_accuracy(trials: int = 100, seed: int = 0, config: TrendConfig | None = None, after_windows: int = 20,
                       growth_m_per_window: float = 1.0e-5, window_period_s: float = 3600.0) -> dict:
    """Width 0.0025 m growing by ``growth_m_per_window`` (default: 0.0025 -> 0.0035 m over 100 windows),
    width se uniform in 0.01-0.1 %, one window per ``window_period_s``: relative error of the wear rate
    (m/s) after ``after_windows`` windows."""
    rng = np.random.default_rng(seed)
    truth = growth_m_per_window / window_period_s
    errs = []
    for _ in range(trials):
        s = simulate_series(after_windows, width_growth_m_per_window=growth_m_per_window,
                            width_se_pct=float(rng.uniform(0.01, 0.1)), window_period_s=window_period_s,
                            seed=int(rng.integers(2 ** 63)))
        u = run_series(s, config)[-1]
        errs.append(abs(u.wear_rate_m_per_s - truth) / truth if u.wear_rate_m_per_s is not None else math.inf)
    e = np.array(errs)
    return {"trials": trials, "after_windows": after_windows, "truth_m_per_s": truth,
            "truth_m_per_day": truth * SECONDS_PER_DAY, "median_rel_error": float(np.median(e)),
            "max_rel_error": float(e.max()), "within_10pct": float(np.mean(e <= 0.10))}


def siegmund_check(arl_windows: float = 200.0, runs: int = 400, seed: int = 0, reference_sd: float = 2.0,
                   se_scale: float = 1.0) -> dict:
    """Verifies the threshold design: ``runs`` two-sided CUSUMs with h = cusum_threshold_for_arl(arl_windows)
    on N(0, se_scale^2) increments (se_scale > 1: under-reported standard errors), each run to its first
    alarm; returns the simulated mean run length and Siegmund's prediction (k/se_scale, h/se_scale)."""
    h = cusum_threshold_for_arl(arl_windows, reference_sd)
    rng = np.random.default_rng(seed)
    pos = np.zeros(runs)
    neg = np.zeros(runs)
    length = np.zeros(runs)
    alive = np.ones(runs, dtype=bool)
    n = 0
    while alive.any():
        n += 1
        z = se_scale * rng.standard_normal(runs)
        pos = np.maximum(0.0, pos + z - reference_sd)
        neg = np.maximum(0.0, neg - z - reference_sd)
        fired = alive & ((pos > h) | (neg > h))
        length[fired] = n
        alive &= ~fired
    return {"design_arl": arl_windows, "threshold_sd": h, "se_scale": se_scale,
            "predicted_arl": cusum_arl(h, reference_sd, sd=se_scale),
            "siegmund_arl": two_sided_arl(h / se_scale, reference_sd / se_scale),
            "simulated_arl": float(length.mean()), "simulated_arl_se": float(length.std(ddof=1) / math.sqrt(runs)),
            "runs": runs}


def measure_targets(seed: int = 0, detection_trials: int = 200, steady_windows: int = 100_000,
                    wear_trials: int = 100, config: TrendConfig | None = None) -> dict:
    """All targets of issue 14 (the tracker-update time is in bench/bench_trend.py)."""
    return {"detection": detection_delays(detection_trials, seed, config),
            "false_alarms": false_alarms(steady_windows, seed + 1, config),
            "wear": wear_rate_accuracy(wear_trials, seed + 2, config),
            "siegmund": siegmund_check(2000.0, 400, seed + 3,
                                       (config if config is not None else TrendConfig()).cusum_reference_sd)}


def format_targets(r: dict) -> str:
    d, f, w, s = r["detection"], r["false_alarms"], r["wear"], r["siegmund"]
    return "\n".join([
        f"J1 2.5 % step, {d['trials']} trials: detected {d['detected']}, missed {d['missed']}, delay median "
        f"{d['median']:g}, p95 {d['p95']:g}, max {d['max']:g} windows (histogram {d['histogram']}); "
        f"false changes before the step {d['false_before_step']}",
        f"steady drive, {f['monitored_windows']} monitored windows in {f['series']} series: J1 changes "
        f"{f['inertia_changes']} ({f['inertia_per_10k']:.3g} per 10,000, 95 % upper bound "
        f"{f['inertia_per_10k_upper95']:.2g}), width changes {f['width_changes']} ({f['width_per_10k']:.3g} per "
        f"10,000, upper bound {f['width_per_10k_upper95']:.2g}); h = {f['threshold_sd']:.3f} sd for a design ARL "
        f"{f['design_arl_windows']:.3g}",
        f"wear rate after {w['after_windows']} windows, {w['trials']} trials (truth {w['truth_m_per_day'] * 1e3:.3g} "
        f"mm/day): median error {100 * w['median_rel_error']:.2f} %, max {100 * w['max_rel_error']:.2f} %, "
        f"within 10 %: {100 * w['within_10pct']:.0f} %",
        f"Siegmund check (bare CUSUM, N(0,1)): design ARL {s['design_arl']:g} (h = {s['threshold_sd']:.3f}), "
        f"simulated {s['simulated_arl']:.0f} ± {s['simulated_arl_se']:.0f} over {s['runs']} runs"])


if __name__ == "__main__":  # pragma: no cover
    import argparse
    ap = argparse.ArgumentParser(description="measure the trend tracker's targets (issue 14)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="20,000 steady windows instead of 100,000")
    a = ap.parse_args()
    print(format_targets(measure_targets(a.seed, steady_windows=20_000 if a.quick else 100_000)))
