#!/usr/bin/env python3
"""Start-up benchmark of the ``jident`` command line (issue 23).

    .venv/bin/python bench/bench_cli.py [--repeats 5] [--json out/bench/bench_cli.json]

Runs each command as a fresh process (the installed ``jident`` console script next to this interpreter, else
``python -m jident_ros.cli.main``), ``--repeats`` times (>= 5), interleaved round-robin so that load changes on
this shared machine hit every command alike, and reports the median wall time and the median CPU time
(user + sys of the child, from ``resource.getrusage``).  Wall time well above CPU time means the process
waited for a core (the machine was busy): the load average is printed before and after.

Targets (issue 23): ``jident --help`` <= 0.5 s wall, ``jident simulate --grid --out g.npz`` <= 2 s wall
(medians of 5).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGETS_S = {"help": 0.5, "simulate_grid": 2.0}


def jident_command() -> list[str]:
    exe = Path(sys.executable).with_name("jident")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("jident")
    return [found] if found else [sys.executable, "-m", "jident_ros.cli.main"]


def timed(cmd: list[str], cwd: str) -> tuple[float, float]:
    """(wall s, CPU s) of one run of ``cmd`` (its output discarded; a failure raises)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=cwd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="runs of each command (>= 5; default 5)")
    ap.add_argument("--json", help="also write the results to this JSON file")
    ap.add_argument("--jident", help="the command to time instead of the installed jident, e.g. "
                    "\"python -m jident_ros.cli.main\" with PYTHONPATH set to another checkout (before/after)")
    args = ap.parse_args(argv)
    if args.repeats < 5:
        ap.error(f"--repeats must be >= 5, got {args.repeats}")
    jident = args.jident.split() if args.jident else jident_command()
    work = tempfile.mkdtemp(prefix="bench_cli_")
    commands = {
        "help": jident + ["--help"],
        "simulate_grid": jident + ["simulate", "--grid", "--out", "g.npz", "--quiet"],
        "simulate_one": jident + ["simulate", "--out", "one.npz", "--quiet"],
        "info": jident + ["info"],
    }
    load0 = os.getloadavg()
    print(f"jident: {' '.join(jident)}; {args.repeats} rounds; load average {load0[0]:.2f} {load0[1]:.2f} "
          f"{load0[2]:.2f}; {os.cpu_count()} CPUs", flush=True)
    for cmd in commands.values():          # warm-up: the page cache, the byte-code cache
        timed(cmd, work)
    runs = {k: [] for k in commands}
    names = list(commands)
    for r in range(args.repeats):
        for k in names[r % len(names):] + names[:r % len(names)]:
            runs[k].append(timed(commands[k], work))
    load1 = os.getloadavg()
    shutil.rmtree(work, ignore_errors=True)
    out = {"load_before": load0, "load_after": load1, "repeats": args.repeats, "command": jident, "results": {}}
    print(f"{'command':<40} {'wall median':>12} {'CPU median':>11} {'target':>8}")
    for k, cmd in commands.items():
        wall = statistics.median(w for w, _ in runs[k])
        cpu = statistics.median(c for _, c in runs[k])
        target = TARGETS_S.get(k)
        met = None if target is None else wall <= target
        out["results"][k] = {"argv": cmd[len(jident):], "wall_s": [w for w, _ in runs[k]],
                             "cpu_s": [c for _, c in runs[k]], "wall_median_s": wall, "cpu_median_s": cpu,
                             "target_s": target, "met": met}
        shown = "jident " + " ".join(cmd[len(jident):])
        verdict = "" if target is None else f"<= {target:g} s {'met' if met else 'NOT met'}"
        print(f"{shown:<40} {wall:>10.3f} s {cpu:>9.3f} s  {verdict}")
    print(f"load average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
