#!/usr/bin/env python3
"""cProfile of `jident evaluate`'s two parts, each in this one process (issue 23: where its time goes).

    .venv/bin/python bench/profile_evaluate.py robustness|method [--out out/prof_PART.prof] [--top 45]

``robustness``: ``run_robustness(system, method)`` as ``jident evaluate`` submits it (its own process there);
``method``: ``run_evaluation(...)`` with ``jident evaluate``'s default arguments but ``jobs=1`` (the feature tasks in
this process, so the profiler sees them).  Prints the CPU seconds and the top functions by cumulative and by own time,
and writes the raw profile (``python -m pstats FILE``).  Set ``JIDENT_CACHE_DIR`` to reuse a pattern-library cache.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

from jident_ros.config import load_method_config, load_system_config
from jident_ros.research.evaluation.evaluate import VALIDITY_FILM_SHARES, run_evaluation
from jident_ros.research.evaluation.robustness import run_robustness


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("part", choices=("robustness", "method"))
    ap.add_argument("--out", help="raw profile file (default out/prof_PART.prof)")
    ap.add_argument("--top", type=int, default=45, help="functions listed (default 45)")
    args = ap.parse_args(argv)
    system, method = load_system_config(), load_method_config()
    heavy = load_system_config("heavy_film")
    prof = cProfile.Profile()
    t0 = time.process_time()
    prof.enable()
    if args.part == "method":     # cmd_evaluate's defaults (no --full, --quick or --validity-map)
        run_evaluation(system, method, snr_db=(30.0,), seeds=(2,), readings=(), log=lambda *a: None,
                       variants=("paper", "sensor_matched"), matched_noise_free=False, library_cache=True,
                       film_shares=VALIDITY_FILM_SHARES, stress_system=None if heavy == system else heavy,
                       full_map=False, jobs=1)
    else:
        run_robustness(system, method, log=None, quick=False)
    prof.disable()
    print(f"{args.part}: {time.process_time() - t0:.1f} CPU-s (under the profiler)")
    out = Path(args.out or f"out/prof_{args.part}.prof")
    out.parent.mkdir(parents=True, exist_ok=True)
    prof.dump_stats(out)
    stats = pstats.Stats(prof)
    stats.sort_stats("cumtime").print_stats(args.top)
    stats.sort_stats("tottime").print_stats(30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
