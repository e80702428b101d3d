#!/usr/bin/env python3
"""Benchmark of the trend tracker (issue 14): time of one ``TrendTracker.update`` (J1 and width).

    .venv/bin/python bench/bench_trend.py [--windows N] [--json out.json]

A simulated drive (one window an hour, J1 se ~0.5 %, width growing 0.0025 -> 0.0035 m per 100
windows), commissioning done first, then N (default 10,000) monitored updates, each timed with
perf_counter_ns.  Prints the median, 95th percentile and maximum.  Target: median <= 0.1 ms.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from jident_ros.identify.trend import TrendConfig, TrendTracker  # noqa: E402
from jident_ros.research.evaluation.trend_simulation import simulate_series  # noqa: E402

TARGET_MS = 0.1


def measure(windows: int = 10_000, seed: int = 0) -> dict:
    cfg = TrendConfig()
    n = cfg.commissioning_windows + windows
    s = simulate_series(n, seed=seed, width_growth_m_per_window=1.0e-5 * 100 / max(n, 100))
    args = [(float(s.time_s[i]), float(s.inertia_kgm2[i]), float(s.inertia_se_kgm2[i]), float(s.width_m[i]),
             float(s.width_se_m[i])) for i in range(n)]
    tr = TrendTracker(cfg)
    for a in args[:cfg.commissioning_windows]:
        tr.update(*a)
    times = []
    clock = time.perf_counter_ns
    for a in args[cfg.commissioning_windows:]:
        t0 = clock()
        tr.update(*a)
        times.append(clock() - t0)
    ms = np.array(times) * 1e-6
    return {"windows": windows, "median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
            "max_ms": float(ms.max()), "mean_ms": float(ms.mean()), "target_ms": TARGET_MS}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=10_000)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}, "
          f"load average {os.getloadavg()[0]:.2f}")
    r = measure(args.windows)
    ok = r["median_ms"] <= TARGET_MS
    print(f"TrendTracker.update over {r['windows']} windows: median {r['median_ms']:.4f} ms, "
          f"p95 {r['p95_ms']:.4f} ms, max {r['max_ms']:.3f} ms, mean {r['mean_ms']:.4f} ms "
          f"(target median <= {TARGET_MS} ms: {'met' if ok else 'NOT met'})")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(r, indent=2))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
