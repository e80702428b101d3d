#!/usr/bin/env python3
"""Benchmark of ``jident trend`` (issue 14 target: 10,000 windows in <= 60 s on this machine, gap path).

    .venv/bin/python bench/bench_trend_cli.py [--windows 10000] [--recordings 10] [--dir DIR] [--json out.json]
                                              [--profile]

Generates ``--recordings`` wear-scenario recordings (``jident simulate --scenario wear``: one entry an hour,
30 dB, K2 2.5 -> 3.5 mm, a 2.5 % J1 step half-way; consecutive recordings continue the drive clock) in
``--dir`` (kept and reused when present), then times the whole ``jident trend REC... --out DIR --quiet``
command in-process (reading, detector, gap diagnosis, tracker, CSV, PNG; ``--jobs``: its worker processes,
default one per core): wall clock (the target) and the CPU time of this process and its workers (what the
wall time would be on one idle core; the machine is shared).  ``--profile`` prints the 25 most expensive
functions of this process (cProfile, cumulative; use it with ``--jobs 1``).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from jident_ros.cli.main import main as jident  # noqa: E402
from jident_ros.cli.scenario import write_scenario_recording  # noqa: E402
from jident_ros.config import load_system_config  # noqa: E402
from jident_ros.sim.scenarios import wear_scenario  # noqa: E402

TARGET_S = 60.0


def make_recordings(directory: Path, windows: int, recordings: int, interval_s: float = 3600.0) -> list:
    system = load_system_config()
    sc = wear_scenario(system, windows, interval_s, 0.0025, 0.0035, j1_step_at_window=windows // 2)
    per = -(-windows // recordings)
    paths = []
    for k in range(recordings):
        path = directory / f"day{k:03d}"
        part = slice(k * per, min((k + 1) * per, windows))
        if not (path / "metadata.yaml").exists():
            sub = type(sc)(sc.name, sc.cases[part], sc.entry_times_s[part], None, None, sc.wear_rate_m_per_s)
            t0 = time.perf_counter()
            write_scenario_recording(path, system, sub, snr_db=30.0, seed=k)
            print(f"wrote {path} ({len(sub)} windows) in {time.perf_counter() - t0:.1f} s", flush=True)
        paths.append(path)
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", type=int, default=10_000)
    ap.add_argument("--recordings", type=int, default=10)
    ap.add_argument("--dir", default="/tmp/jident_bench_trend")
    ap.add_argument("--json")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--jobs", type=int, default=0, help="jident trend --jobs (default 0: one per core)")
    a = ap.parse_args(argv)
    directory = Path(a.dir) / f"w{a.windows}_r{a.recordings}"
    paths = make_recordings(directory, a.windows, a.recordings)
    out = Path(a.dir) / "trend_out"
    argv_trend = ["trend", *map(str, reversed(paths)), "--out", str(out), "--quiet",   # any order: sorted inside
                  "--jobs", str(a.jobs)]
    buf = io.StringIO()
    def cpu_now():   # this process and its finished children (jident trend's worker processes)
        t = os.times()
        return t.user + t.system + t.children_user + t.children_system

    c0 = cpu_now()
    t0 = time.perf_counter()
    if a.profile:
        import cProfile
        import pstats
        prof = cProfile.Profile()
        with contextlib.redirect_stdout(buf):
            rc = prof.runcall(jident, argv_trend)
        wall = time.perf_counter() - t0
        pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
    else:
        with contextlib.redirect_stdout(buf):
            rc = jident(argv_trend)
        wall = time.perf_counter() - t0
    cpu = cpu_now() - c0
    print(buf.getvalue())
    res = {"windows": a.windows, "recordings": a.recordings, "jobs": a.jobs or os.cpu_count(),
           "wall_s": wall, "cpu_s": cpu, "per_window_ms": wall / a.windows * 1e3,
           "target_s": TARGET_S, "met": wall <= TARGET_S and rc == 0, "exit": rc,
           "machine": f"{platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"}
    print(f"jident trend over {a.windows} windows in {a.recordings} recordings, --jobs {res['jobs']}: {wall:.1f} s wall "
          f"({res['per_window_ms']:.2f} ms/window), CPU {cpu:.1f} s (target <= {TARGET_S:g} s: {'met' if res['met'] else 'NOT met'}); "
          f"{res['machine']}")
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0 if res["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
