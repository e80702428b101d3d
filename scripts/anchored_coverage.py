#!/usr/bin/env python3
"""Error and 95 % interval coverage of the gap estimator's 'anchored' fit on simulated noisy windows.

The check of the two fixes of issue 11's mutation work (docs/mutation.md): the anchored fit's standard error was
1/kappa ~ 11.6 times too wide, and b1 omega1 was not taken off its pre-entry anchor.  On the paper's grid (168
cases) with white measurement noise at ``--snr`` dB (``add_measurement_noise``, seeds ``--seeds``), for the fits
in ``--keys`` (:data:`jident_ros.research.evaluation.robustness.CHANNEL_SETS`, with omega1 added): the median and max |J1 error|, the median
reported standard error, the spread (sd) of the relative error, the ratio of the two, and the share of 95 %
intervals that cover the true J1 (a failed fit counts as not covering).

``--bearing-friction`` sets motor.bearing_friction_nms_per_rad (the simulator's and the estimator's b1; the
system config has 0, the paper's model).

Usage (from the repository root)::

    PYTHONPATH=. python scripts/anchored_coverage.py --snr 30 --seeds 1 2 3
    PYTHONPATH=. python scripts/anchored_coverage.py --snr 30 --seeds 1 --bearing-friction 0.05
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.identify.gap import NoGapError, estimate_inertia
from jident_ros.research.evaluation.robustness import CHANNEL_SETS
from jident_ros.sim import add_measurement_noise, paper_grid_cases, simulate_grid


def fit_windows(system, windows, key: str) -> dict:
    """One fit of CHANNEL_SETS[key] on every window, with omega1 added to its channels (so a known b1 omega1 can be
    taken off m_el): relative error, standard error and whether the 95 % interval covers the true J1."""
    chans, method, _ = CHANNEL_SETS[key]
    chans = tuple(dict.fromkeys(chans + ("omega1",)))
    r, n = system.load.wheel_radius_m, len(windows.cases)
    err, se, covered = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, bool)
    for i, c in enumerate(windows.cases):
        try:
            g = estimate_inertia({k: windows.signals[k][i] for k in chans}, windows.entry_index, c.backlash_width_m,
                                 r, windows.sample_period_s, method, system.motor.bearing_friction_nms_per_rad)
        except NoGapError:
            continue
        err[i], se[i] = g.inertia_kgm2 / c.inertia_kgm2 - 1.0, g.std_error_kgm2
        covered[i] = g.ci95_kgm2[0] <= c.inertia_kgm2 <= g.ci95_kgm2[1]
    return {"rel_error": err, "se": se, "covered": covered}


def summary(gap: dict, true_j1: np.ndarray) -> dict:
    """The statistics of one fit over the windows (relative to the true J1)."""
    err = gap["rel_error"]
    ok = np.isfinite(err)
    rel_se = gap["se"][ok] / true_j1[ok]
    sd = float(np.std(err[ok], ddof=1)) if ok.sum() > 1 else np.nan
    return {"n": int(err.size), "failed": int((~ok).sum()),
            "median_err": float(np.median(np.abs(err[ok]))), "max_err": float(np.max(np.abs(err[ok]))),
            "median_rel_se": float(np.median(rel_se)), "sd_err": sd, "se_over_sd": float(np.median(rel_se)) / sd,
            "coverage": float(np.mean(gap["covered"]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--snr", type=float, default=30.0, help="SNR of the measurement noise, dB (default 30)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="noise seeds (default 1 2 3)")
    ap.add_argument("--keys", nargs="+", default=["anchored", "angles"], choices=sorted(CHANNEL_SETS),
                    help="fits to compare (default: anchored and the default fit)")
    ap.add_argument("--bearing-friction", type=float, default=None,
                    help="motor.bearing_friction_nms_per_rad, N m s/rad (default: the system config's)")
    args = ap.parse_args(argv)
    system = load_system_config()
    if args.bearing_friction is not None:
        system = dataclasses.replace(system, motor=dataclasses.replace(
            system.motor, bearing_friction_nms_per_rad=float(args.bearing_friction)))
    t0 = time.monotonic()
    cases = paper_grid_cases(system)
    clean = simulate_grid(system, cases)
    true_j1 = np.array([c.inertia_kgm2 for c in cases])
    per_key = {k: [] for k in args.keys}
    for seed in args.seeds:
        noisy = add_measurement_noise(clean, args.snr, seed)
        for k in args.keys:
            per_key[k].append(fit_windows(system, noisy, k))
    print(f"{len(cases)} grid cases x {len(args.seeds)} noise seeds {args.seeds} at {args.snr:g} dB, "
          f"b1 = {system.motor.bearing_friction_nms_per_rad:g} N m s/rad ({time.monotonic() - t0:.0f} s)")
    print("| fit | windows | failed | median \\|error\\| | max \\|error\\| | median se/J1 | sd of error | "
          "se/sd | 95 % CI coverage |")
    print("|---|---|---|---|---|---|---|---|---|")
    for k, runs in per_key.items():
        merged = {f: np.concatenate([r[f] for r in runs]) for f in ("rel_error", "se", "covered")}
        s = summary(merged, np.tile(true_j1, len(runs)))
        print(f"| {k} | {s['n']} | {s['failed']} | {100 * s['median_err']:.3f} % | {100 * s['max_err']:.3f} % | "
              f"{100 * s['median_rel_se']:.3f} % | {100 * s['sd_err']:.3f} % | {s['se_over_sd']:.2f} | "
              f"{100 * s['coverage']:.1f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
