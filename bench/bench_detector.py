"""The flank detector's cost per window, and the share of its zone-edge rules (issue 20's pick-up: stop 44's fast
departure rule and stop 45's slow departure rule were not benchmarked): ``FlankDetector._finish_flank`` -- the entry
rules, the zone moves, the window cut -- on the saved captures of two vector blind draws (test/data: s1-04's speed
reversal, a fast departure, and s1-12's light load reversal, a slow one; JointState channels t alpha1 alpha2 m_el,
2228 rows), a fresh detector per run, with the zone-edge back rules on (the default) and off (ZONE_BACK_MAX_MOVE and
ZONE_BACK_SLOW_MAX_MOVE 0: the entry then stays where the other rules left it, 6 and 38 samples late).

    nice -n 10 .venv/bin/python bench/bench_detector.py [--repeats 100]

Prints the commit measured, the load average before and after, and per capture and setting the wall-clock median and
the CPU-time median and 10th percentile per window in ms, the entry's offset from the truth's first row in the zone,
and the CPU median's difference (on - off): the zone-edge back rules' own cost.  The far-contact fit's one-entry memo
(flank_zone._LAST_FAR_FIT) is cleared before every run, so every run pays a new window's fits.
"""
import argparse
import time
from pathlib import Path

import numpy as np
from bench_gap import commit, load

from jident_ros.stream import flank_zone
from jident_ros.stream.flank import FlankDetector
from jident_ros.stream.flank_capture import _FlankCapture

CAPTURES = ("vector_draws_speed_reversal_fast_departure.npz", "vector_draws_light_load_reversal_slow_departure.npz")


def _run(d) -> int:
    """One window from the capture ``d`` through a fresh detector: its entry less the truth's."""
    rows = d["rows"]
    det = FlankDetector(0.1, 5e-4, channels=("t", "alpha1", "alpha2", "m_el"), nominal_inertia_kgm2=1.16)
    cap = _FlankCapture(rows=[rows], count=rows.shape[0], departure_row=int(d["departure"]), flank_rad=float(d["flank"]),
                        flank_sigma_rad=float(d["sigma"]))
    if det._finish_flank(cap) is None:
        raise RuntimeError("the capture gave no window")
    return det._emitted_entry_rows[-1] - int(d["true_entry"])


def _timed(repeats: int, d) -> tuple:
    times, cpu, offset = [], [], None
    for _ in range(repeats):
        flank_zone._LAST_FAR_FIT = (None, None)
        t0, c0 = time.perf_counter(), time.process_time()
        offset = _run(d)
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return times, cpu, offset


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=100)
    a = p.parse_args(argv)
    print(f"commit {commit()}; before: {load()}")
    data = Path(__file__).resolve().parents[1] / "test" / "data"
    saved = (flank_zone.ZONE_BACK_MAX_MOVE, flank_zone.ZONE_BACK_SLOW_MAX_MOVE)
    for name in CAPTURES:
        d = dict(np.load(data / name))
        cpu_median = {}
        for label, moves in (("zone-edge back on", saved), ("zone-edge back off", (0, 0))):
            flank_zone.ZONE_BACK_MAX_MOVE, flank_zone.ZONE_BACK_SLOW_MAX_MOVE = moves
            try:
                times, cpu, offset = _timed(a.repeats, d)
            finally:
                flank_zone.ZONE_BACK_MAX_MOVE, flank_zone.ZONE_BACK_SLOW_MAX_MOVE = saved
            cpu_median[label] = float(np.median(cpu))
            print(f"{name:<52} {label:<19} entry {offset:+d}: wall median {np.median(times):.3f} ms; CPU median "
                  f"{np.median(cpu):.3f} ms, p10 {np.percentile(cpu, 10):.3f} ms ({a.repeats} runs)")
        print(f"{name:<52} the zone-edge back rules' CPU (median on - off): "
              f"{cpu_median['zone-edge back on'] - cpu_median['zone-edge back off']:+.3f} ms")
    print(f"after: {load()}")


if __name__ == "__main__":
    main()
