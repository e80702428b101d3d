"""``jident trend --fleet`` on a synthetic fleet (issue 21): wall time and peak memory.

    python bench/bench_fleet.py --drives 100 --recordings 100 [--jobs 0] [--work DIR]

One drive's ``--recordings`` one-window recordings are simulated (the wear scenario at 30 dB: K2 2.5 -> 3.5 mm,
J1 +2.5 % half-way; :func:`jident_ros.cli.scenario.write_scenario_recording`, one bag each) and hard-linked into
``--drives`` drive folders (the load is what matters: every drive's recordings are diagnosed and tracked on
their own), then ``jident trend WORK/fleet --fleet --drive-id parent --out WORK/out --jobs N`` runs as a child
process; its wall time and its peak RSS (the largest of the parent and its pool's workers, from
``resource.getrusage(RUSAGE_CHILDREN)``) are printed as one JSON line.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from jident_ros.cli.scenario import write_scenario_recording
from jident_ros.config import load_system_config
from jident_ros.sim.scenarios import wear_scenario


def make_fleet(root: Path, drives: int, recordings: int) -> Path:
    system = load_system_config()
    sc = wear_scenario(system, recordings, 3600.0, 0.0025, 0.0035, None, None, recordings // 2, 2.5, None)
    src = root / "fleet" / "drive_000"
    for i in range(recordings):
        sub = dataclasses.replace(sc, cases=sc.cases[i:i + 1], entry_times_s=sc.entry_times_s[i:i + 1])
        write_scenario_recording(src / f"rec_{i:03d}", system, sub, snr_db=30.0, seed=i)
    for d in range(1, drives):
        dst = root / "fleet" / f"drive_{d:03d}"
        for dirpath, _, files in os.walk(src):
            r = Path(dirpath)
            t = dst / r.relative_to(src)
            t.mkdir(parents=True, exist_ok=True)
            for f in files:
                os.link(r / f, t / f)
    return root / "fleet"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--drives", type=int, default=100)
    ap.add_argument("--recordings", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=0, help="worker processes (0: one per core)")
    ap.add_argument("--work", help="work directory (default: a temporary one)")
    a = ap.parse_args(argv)
    root = Path(a.work or tempfile.mkdtemp(prefix="bench_fleet_"))
    t0 = time.perf_counter()
    fleet = make_fleet(root, a.drives, a.recordings)
    t_gen = time.perf_counter() - t0
    cmd = [sys.executable, "-m", "jident_ros.cli", "trend", str(fleet), "--fleet", "--drive-id", "parent",
           "--out", str(root / "out"), "--jobs", str(a.jobs), "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    print(proc.stdout.splitlines()[-1] if proc.stdout else proc.stderr[-2000:])
    print(json.dumps({"drives": a.drives, "recordings_per_drive": a.recordings, "windows": a.drives * a.recordings,
                      "jobs": a.jobs or os.cpu_count(), "rc": proc.returncode, "generate_s": round(t_gen, 1),
                      "wall_s": round(wall, 1), "windows_per_s": round(a.drives * a.recordings / wall, 1),
                      "peak_rss_mb_largest_process": round(peak_kb / 1024, 1), "load_1min": os.getloadavg()[0]}))
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
