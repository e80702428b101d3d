"""Issue 14's targets measured on REAL diagnosed windows of the simulator (not on the synthetic series
of :func:`jident_ros.research.evaluation.trend_simulation.simulate_series`).

    python -m jident_ros.research.evaluation.trend_targets [--quick] [--seed 0]

1. **Pools of diagnosed windows.**  One case (J1, K2 = 3 mm, eta_k = 0.025) is simulated once
   (:func:`jident_ros.sim.simulate_grid`), repeated, and every copy gets its own white noise at 30 dB
   (:func:`jident_ros.sim.add_measurement_noise`, MATLAB's awgn 'measured'); each copy is diagnosed
   with the gap estimator (:func:`jident_ros.identify.gap.estimate_inertia`, auto = the acceleration
   fit) -> (J1, its standard error).  Pools: the nominal J1 1.16 (steady drive) and J1 x 1.025 and
   x 0.975 (after a 2.5 % step).  The calibration of the reported errors is printed (mean and sd of
   z = (J1 - true) / se, coverage of the 95 % interval).
2. **False changes on a steady drive.**  Series of 20 commissioning + 1,000 monitored windows, each
   window drawn with replacement from the steady pool (a bootstrap of the real (J1, se) pairs: the
   pool has a few thousand windows, the target needs 10,000+), one window an hour, fed to a fresh
   :class:`~jident_ros.identify.trend.TrendTracker`; the J1 changes are counted.  Also the pool in its
   own order without resampling.
3. **Detection delay of a 2.5 % step.**  20 commissioning + 30 steady windows from the steady pool,
   then windows from the stepped pool (up or down, alternating) until the first J1 change of the
   right sign; delay 1 = detected at the first stepped window.
4. **Wear rate after 20 windows.**  Per trial 20 entries with K2 growing linearly (start uniform in
   2.5-3.0 mm so that the sample grid falls differently each trial).  ``source="flank"`` (the path of the
   node, of ``jident trend`` and of a real drive, :func:`flank_windows`): raw recordings (2^16-count encoders,
   arbitrary offsets, 30 dB), the flank detector, each window diagnosed and turned into the tracker's inputs
   by :func:`jident_ros.identify.trend_status.trend_inputs` (the flank detector's K2 with its se, no made-up
   noise); ``source="gap"`` (the fallback, for comparison): paper-detector windows with the given K2 and
   :func:`jident_ros.identify.gap.estimate_backlash_width`.  The tracker's wear rate after the 20th window
   against the truth, and the calibration of the width estimates (error, se, 95 % coverage).
5. **Tracker update time** on the real windows (median of 10,000 updates; the reference benchmark is
   bench/bench_trend.py, the ``jident trend`` time bench/bench_trend_cli.py).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.stats import chi2

from jident_ros.config import load_system_config
from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig
from jident_ros.identify.gap import NoGapError, estimate_backlash_width, estimate_inertia
from jident_ros.identify.trend import TrendConfig, TrendTracker
from jident_ros.identify.trend_status import trend_inputs
from jident_ros.research.evaluation.raw_inputs import event_window, flank_detector, raw_recordings, run_detector
from jident_ros.research.evaluation.trend_simulation import step_trials
from jident_ros.sim import Case, WindowSet, add_measurement_noise, simulate_grid

SNR_DB = 30.0
WINDOW_PERIOD_S = 3600.0
J1_NOMINAL = 1.16
WIDTH_M = 0.003
ETA = 0.025


def _tile(ws: WindowSet, n: int) -> WindowSet:
    sig = {k: np.repeat(v[:1], n, axis=0) for k, v in ws.signals.items()}
    return WindowSet(ws.t, sig, [ws.cases[0]] * n, ws.entry_index, ws.sample_period_s,
                     np.repeat(ws.initial_slip[:1], n), dict(ws.metadata))


def diagnose_gap(ws: WindowSet, system, width: bool = False) -> dict:
    """J1, se (and the width, its se) of every window by the gap estimator, as the diagnosis runs it
    (K2 of each case given, as the detector would have it); NaN where there is no gap."""
    n = len(ws)
    out = {k: np.full(n, np.nan) for k in ("j1", "se", "width", "width_se")}
    r, ts = system.load.wheel_radius_m, ws.sample_period_s
    for i in range(n):
        c = ws.case(i)
        try:
            g = estimate_inertia(c, ws.entry_index, ws.cases[i].backlash_width_m, r, ts,
                                 bearing_friction_nms_per_rad=system.motor.bearing_friction_nms_per_rad)
        except NoGapError:
            continue
        out["j1"][i], out["se"][i] = g.inertia_kgm2, g.std_error_kgm2
        if width:
            try:
                w = estimate_backlash_width(c, g.gap_end, r, ts, g.inertia_kgm2)
                out["width"][i], out["width_se"][i] = w.width_m, w.std_m
            except NoGapError:
                pass
    return out


def pool(system, j1: float, n: int, seed: int, chunk: int = 500) -> dict:
    """``n`` noisy copies of one case (J1 ``j1``, K2 3 mm), diagnosed."""
    base = simulate_grid(system, [Case(j1, WIDTH_M, ETA)])
    parts = []
    for k, c0 in enumerate(range(0, n, chunk)):
        ws = add_measurement_noise(_tile(base, min(chunk, n - c0)), SNR_DB, seed * 1000 + k)
        parts.append(diagnose_gap(ws, system))
    d = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    ok = np.isfinite(d["j1"])
    z = (d["j1"][ok] - j1) / d["se"][ok]
    return {"j1": d["j1"][ok], "se": d["se"][ok], "true": j1, "n": n, "no_gap": int((~ok).sum()),
            "z_mean": float(z.mean()), "z_sd": float(z.std(ddof=1)),
            "coverage95": float(np.mean(np.abs(z) <= 1.959963984540054)),
            "se_pct_median": float(np.median(d["se"][ok] / j1 * 100))}


def false_changes(steady: dict, monitored: int, seed: int, config: TrendConfig, series_windows: int = 1000) -> dict:
    rng = np.random.default_rng(seed)
    comm = config.commissioning_windows
    n_series = max(1, math.ceil(monitored / series_windows))
    count = 0
    for _ in range(n_series):
        idx = rng.integers(0, steady["j1"].size, comm + series_windows)
        tr = TrendTracker(config)
        t = WINDOW_PERIOD_S * np.arange(idx.size)
        for u in tr.batch(t, steady["j1"][idx], steady["se"][idx]):
            count += sum(1 for c in u.changes if c.quantity == "inertia")
    mon = n_series * series_windows
    # in the pool's own order, no resampling
    tr = TrendTracker(config)
    own = sum(len(u.changes) for u in tr.batch(WINDOW_PERIOD_S * np.arange(steady["j1"].size), steady["j1"],
                                               steady["se"]))
    return {"monitored": mon, "series": n_series, "changes": count, "per_10k": 1e4 * count / mon,
            "per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (count + 1))) / 2 / mon,
            "own_order_windows": int(steady["j1"].size - comm), "own_order_changes": own}


def detection(steady: dict, up: dict, down: dict, trials: int, seed: int, config: TrendConfig,
              pre: int = 30, post: int = 20) -> dict:
    rng = np.random.default_rng(seed)
    comm = config.commissioning_windows

    def series(k):
        after, sign = (up, 1) if k % 2 == 0 else (down, -1)
        i0 = rng.integers(0, steady["j1"].size, comm + pre)
        i1 = rng.integers(0, after["j1"].size, post)
        j = np.concatenate([steady["j1"][i0], after["j1"][i1]])
        se = np.concatenate([steady["se"][i0], after["se"][i1]])
        return WINDOW_PERIOD_S * np.arange(j.size), j, se, sign
    return step_trials(trials, series, config, comm + pre)


def flank_windows(system, cases: list, seed: int, steady_s: float = 0.2) -> list:
    """The path of a real drive and of ``jident trend``: one raw recording per case
    (:func:`jident_ros.research.evaluation.raw_inputs.raw_recordings`: 2^16-count encoders with arbitrary offsets,
    the slip moving the load encoder's, 30 dB white noise on the other channels), the flank detector
    (no K2), each event's window diagnosed as the diagnostic node does (gap only) and turned into the
    tracker's inputs by :func:`jident_ros.identify.trend_status.trend_inputs` (J1 when published; the
    window's flank-to-flank K2).  Per case a :class:`~jident_ros.identify.trend_status.TrendInputs`, or
    None when the detector gave no window for the event (counted by the caller)."""
    j1, eta = cases[0].inertia_kgm2, cases[0].consistency_pa_sn
    if any(c.inertia_kgm2 != j1 or c.consistency_pa_sn != eta for c in cases):
        raise ValueError("cases: one J1 and one eta_k (the widths vary)")
    recs = raw_recordings(system, [j1], [c.backlash_width_m for c in cases], eta, snr_db=SNR_DB, steady_s=steady_s,
                          seed=seed)
    ts = system.sampling.sample_period_s
    diagnoser = Diagnoser(system, None, DiagnosisConfig(2.0, "auto", image_method=False))
    out = []
    for rec in recs:
        wins = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"]
        t_entry = float(rec.data[rec.entry_row, 0])
        win = event_window(wins, t_entry, t_entry + 1.5 * ts, ts)
        if win is None:
            out.append(None)
            continue
        d = diagnoser.diagnose(win)
        out.append(trend_inputs(d, 0.0, win))
    return out


def wear(system, growth_m_per_window: float, trials: int, seed: int, config: TrendConfig, windows: int = 20,
         source: str = "flank") -> dict:
    """Wear rate after ``windows`` windows against the truth.  ``source`` 'flank': the flank detector's
    windows and K2 estimates (:func:`flank_windows`, what the node, ``jident trend`` and a real drive use);
    'gap': the paper detector's windows with the given K2 and the gap estimator's width (the fallback)."""
    rng = np.random.default_rng(seed)
    starts = rng.uniform(0.0025, 0.0030, trials)
    cases = [Case(J1_NOMINAL, float(s + growth_m_per_window * i), ETA) for s in starts for i in range(windows)]
    n = len(cases)
    d = {k: np.full(n, np.nan) for k in ("j1", "se", "width", "width_se")}
    no_window = 0
    if source == "flank":
        for k in range(trials):
            for i, ti in enumerate(flank_windows(system, cases[k * windows:(k + 1) * windows], seed * 100_003 + k)):
                if ti is None:
                    no_window += 1
                    continue
                for key, v in zip(("j1", "se", "width", "width_se"), ti[:4]):
                    d[key][k * windows + i] = np.nan if v is None else v
    elif source == "gap":
        d = diagnose_gap(add_measurement_noise(simulate_grid(system, cases), SNR_DB, seed), system, width=True)
    else:
        raise ValueError(f"source: 'flank' or 'gap', got {source!r}")
    truth = growth_m_per_window / WINDOW_PERIOD_S
    errs = []
    tw = np.array([c.backlash_width_m for c in cases])
    for k in range(trials):
        sl = slice(k * windows, (k + 1) * windows)
        tr = TrendTracker(config)
        us = tr.batch(WINDOW_PERIOD_S * np.arange(windows), d["j1"][sl], d["se"][sl], d["width"][sl],
                      d["width_se"][sl], nan_is_missing=True)
        rate = us[-1].wear_rate_m_per_s
        errs.append(abs(rate - truth) / truth if rate is not None else math.inf)
    e = np.array(errs)
    ok = np.isfinite(d["width"])
    wz = (d["width"][ok] - tw[ok]) / d["width_se"][ok]
    werr = np.abs(d["width"][ok] / tw[ok] - 1.0)
    return {"source": source, "growth_mm_per_window": growth_m_per_window * 1e3,
            "truth_mm_per_day": truth * 86400 * 1e3, "trials": trials, "windows": windows,
            "median_rel_error": float(np.median(e)), "p90_rel_error": float(np.percentile(e, 90)),
            "max_rel_error": float(e.max()), "within_10pct": float(np.mean(e <= 0.10)),
            "width_estimates": int(ok.sum()), "no_window": no_window,
            "width_se_mm_median": float(np.nanmedian(d["width_se"]) * 1e3) if ok.any() else math.nan,
            "width_rel_error_median": float(np.median(werr)) if ok.any() else math.nan,
            "width_rel_error_max": float(werr.max()) if ok.any() else math.nan,
            "width_coverage95": float(np.mean(np.abs(wz) <= 1.959963984540054)) if wz.size else math.nan}


def update_time(steady: dict, n: int, config: TrendConfig) -> dict:
    tr = TrendTracker(config)
    idx = np.arange(n) % steady["j1"].size
    times = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter_ns()
        tr.update(WINDOW_PERIOD_S * i, float(steady["j1"][idx[i]]), float(steady["se"][idx[i]]),
                  WIDTH_M + 1e-7 * i, 1e-5)
        times[i] = time.perf_counter_ns() - t0
    return {"median_ms": float(np.median(times)) / 1e6, "p95_ms": float(np.percentile(times, 95)) / 1e6}


def pools(system, seed: int = 0, quick: bool = False, path=None) -> tuple:
    """(steady, up, down) pools of :func:`pool`; with ``path`` (an .npz) read from it when it was written for the
    same seed and size, else computed and written there (a tracker design can then be tried on the same
    windows without diagnosing them again: ~10 min under load)."""
    n_pool = 1000 if quick else 4000
    key = f"seed={seed} n={n_pool}"
    if path is not None:
        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["key"]) == key:
                    return tuple({k[len(name) + 1:]: (z[k] if z[k].ndim else z[k].item()) for k in z.files
                                  if k.startswith(name + ".")} for name in ("steady", "up", "down"))
        except FileNotFoundError:
            pass
    out = (pool(system, J1_NOMINAL, n_pool, seed), pool(system, J1_NOMINAL * 1.025, n_pool // 2, seed + 1),
           pool(system, J1_NOMINAL * 0.975, n_pool // 2, seed + 2))
    if path is not None:
        np.savez(path, key=key, **{f"{name}.{k}": v for name, d in zip(("steady", "up", "down"), out)
                                   for k, v in d.items()})
    return out


def measure(seed: int = 0, quick: bool = False, config: TrendConfig | None = None, system=None,
            pools_path=None) -> dict:
    system = load_system_config() if system is None else system
    cfg = config if config is not None else TrendConfig()
    t0 = time.perf_counter()
    steady, up, down = pools(system, seed, quick, pools_path)
    r = {"steady": steady, "up": up, "down": down,
         "false": false_changes(steady, 20_000 if quick else 100_000, seed + 3, cfg),
         "detection": detection(steady, up, down, 100 if quick else 400, seed + 4, cfg),
         "wear": [wear(system, g, 20 if quick else 100, seed + 5 + k, cfg, source=src)
                  for src in ("flank", "gap") for k, g in enumerate((1.0e-5, 5.0e-5))],
         "update": update_time(steady, 10_000, cfg), "seed": seed, "quick": quick}
    r["seconds"] = time.perf_counter() - t0
    return r


def format_table(r: dict) -> str:
    s, f, d, u = r["steady"], r["false"], r["detection"], r["update"]
    lines = ["| target | measured (30 dB, gap estimator, real simulated windows) | met |", "|---|---|---|"]
    cal = (f"pool: {s['n']} steady windows (J1 {s['true']:g}, K2 {WIDTH_M * 1e3:g} mm), se median "
           f"{s['se_pct_median']:.2f} % of J1, z = (J1 - true)/se: mean {s['z_mean']:+.2f}, sd {s['z_sd']:.2f}, "
           f"95 % CI coverage {100 * s['coverage95']:.1f} %; no gap in {s['no_gap']}")
    lines.append(f"| (calibration) | {cal} | |")
    lines.append(f"| 2.5 % J1 step detected within <= 5 windows | {d['detected']}/{d['trials']} detected "
                 f"(+/- alternating), delay median {d['median']:g}, p95 {d['p95']:g}, max {d['max']:g} windows "
                 f"(histogram {d['histogram']}); false changes before the step {d['false_before_step']} | "
                 f"{'yes' if d['missed'] == 0 and d['max'] <= 5 else 'no'} |")
    lines.append(f"| <= 1 false change per 10,000 steady windows | {f['changes']} in {f['monitored']:,} monitored "
                 f"windows (bootstrap of the pool, {f['series']} series of 20 + 1,000) = {f['per_10k']:.2g} per "
                 f"10,000 (95 % upper bound {f['per_10k_upper95']:.2g}); pool in its own order: "
                 f"{f['own_order_changes']} in {f['own_order_windows']} | {'yes' if f['per_10k'] <= 1 else 'no'} |")
    for w in r["wear"]:
        what = ("flank detector's K2 (raw 2^16-count encoders)" if w["source"] == "flank"
                else "fallback: gap estimator's width, paper detector")
        lines.append(f"| wear rate within 10 % after 20 windows ({w['growth_mm_per_window']:g} mm/window = "
                     f"{w['truth_mm_per_day']:.3g} mm/day), {what} | {100 * w['within_10pct']:.0f} % of "
                     f"{w['trials']} trials within 10 %; error median {100 * w['median_rel_error']:.1f} %, p90 "
                     f"{100 * w['p90_rel_error']:.1f} %, max {100 * w['max_rel_error']:.1f} %; {w['width_estimates']} "
                     f"width estimates ({w['no_window']} events without a window): |error| median "
                     f"{100 * w['width_rel_error_median']:.2f} %, max {100 * w['width_rel_error_max']:.2f} %, se median "
                     f"{w['width_se_mm_median']:.4f} mm, 95 % coverage {100 * w['width_coverage95']:.0f} % | "
                     f"{'yes' if w['within_10pct'] >= 0.95 else 'no'}{'' if w['source'] == 'flank' else ' (fallback)'} |")
    lines.append(f"| tracker update <= 0.1 ms | median {u['median_ms']:.4f} ms, p95 {u['p95_ms']:.4f} ms "
                 f"(10,000 updates, J1 + width) | {'yes' if u['median_ms'] <= 0.1 else 'no'} |")
    lines.append(f"\nseed {r['seed']}{', --quick' if r['quick'] else ''}; {r['seconds']:.0f} s")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="issue 14's trend targets on real diagnosed simulator windows")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="smaller pools and fewer trials (~30 s)")
    ap.add_argument("--pools", help="an .npz: the diagnosed pools read from it when written for the same seed and "
                                    "size, else computed and written there")
    a = ap.parse_args(argv)
    print(format_table(measure(a.seed, a.quick, pools_path=a.pools)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
