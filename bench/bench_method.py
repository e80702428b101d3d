#!/usr/bin/env python3
"""Benchmark of the identification method (issue "method", speed targets).

    .venv/bin/python bench/bench_method.py [--repeats N] [--full-eval] [--json out.json]

(a) one window, all five signals, scalogram to J1 (``identify_window`` at p = 2,
    and the gap estimator), median of N runs after a warm-up;
(b) building the whole pattern library (42 runs x 5 signals x 4 p), median of 3;
(c) with --full-eval, the method part of `jident evaluate` (``run_evaluation``: every
    variant, p, noise level and level-10 reading, and the gap estimator; not the
    robustness sweep, not writing files), once.
Targets: (a) <= 20 ms, (b) <= 10 s, (c) <= 60 s on the 2-core machine (the whole
`jident evaluate`, robustness sweep included, <= 2 min).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from jident_ros.config import load_method_config, load_system_config  # noqa: E402
from jident_ros.identify.gap import estimate_inertia  # noqa: E402
from jident_ros.method.patterns import PatternLibrary, identify_window  # noqa: E402
from jident_ros.sim import Case, paper_grid_cases, simulate_grid  # noqa: E402


def timed(fn, repeats):
    fn()
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--full-eval", action="store_true")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    system, method = load_system_config(), load_method_config()
    print(f"machine: {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}, "
          f"load average {os.getloadavg()[0]:.2f}")
    grid = simulate_grid(system, paper_grid_cases(system))
    lib_times = timed(lambda: PatternLibrary.build(system, method, windows=grid), 3)
    lib = PatternLibrary.build(system, method, windows=grid)
    case = Case(1.073, 0.005, 0.0375)
    win = simulate_grid(system, [case])
    w = win.case(0)
    window_times = timed(lambda: identify_window(w, win.entry_index, case.backlash_width_m, lib, method, 2.0),
                         args.repeats)
    gap_times = timed(lambda: estimate_inertia(w, win.entry_index, case.backlash_width_m,
                                               system.load.wheel_radius_m, win.sample_period_s), args.repeats)
    no_a1 = {k: v for k, v in w.items() if k in ("alpha1", "alpha2", "m_el")}   # a drive without an accelerometer
    angle_times = timed(lambda: estimate_inertia(no_a1, win.entry_index, case.backlash_width_m,
                                                 system.load.wheel_radius_m, win.sample_period_s, "angle"),
                        args.repeats)
    from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig, WindowInput
    # what the diagnostic node adds per window besides the image method: gap fit + width + verdict + status values
    diagnoser = Diagnoser(system, method, DiagnosisConfig(2.0, image_method=False), library=lib)
    stage_times = timed(lambda: diagnoser.diagnose(WindowInput(w, win.entry_index, case.backlash_width_m,
                                                               system.load.wheel_radius_m, win.sample_period_s)),
                        args.repeats)
    res = {"window_all_signals_p2_s": statistics.median(window_times),
           "gap_estimate_s": statistics.median(gap_times),
           "gap_estimate_angle_s": statistics.median(angle_times),
           "gap_stage_s": statistics.median(stage_times),
           "library_build_s": statistics.median(lib_times)}
    if args.full_eval:
        from jident_ros.research.evaluation.evaluate import run_evaluation
        t = time.perf_counter()
        run_evaluation(system, method, log=lambda *a: None)
        res["full_evaluation_s"] = time.perf_counter() - t
    print("| measurement | median | target |\n|---|---|---|")
    print(f"| one window, five signals, scalogram → J1 (p = 2) | {res['window_all_signals_p2_s'] * 1e3:.1f} ms | ≤ 20 ms |")
    print(f"| gap estimate of one window (gap.estimate_inertia) | {res['gap_estimate_s'] * 1e3:.2f} ms | ≤ 2 ms |")
    print(f"| gap estimate without a1 (angle fit: alpha1, alpha2, m_el) | {res['gap_estimate_angle_s'] * 1e3:.2f} ms "
          f"| ≤ 2 ms |")
    print(f"| gap stage of the node (diagnose_window without the image method: fit, width, verdict) | "
          f"{res['gap_stage_s'] * 1e3:.2f} ms | ≤ 2 ms |")
    print(f"| whole pattern library (42 runs × 5 signals × {len(method.p_values)} p) | {res['library_build_s']:.2f} s | ≤ 10 s |")
    if "full_evaluation_s" in res:
        print(f"| method part of jident evaluate (run_evaluation: all p, noise sweep, readings; "
              f"no robustness sweep) | {res['full_evaluation_s']:.0f} s | ≤ 60 s |")
    print(f"load average at end: {os.getloadavg()[0]:.2f}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
