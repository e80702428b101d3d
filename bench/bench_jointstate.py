"""JointState at 2 kHz, one message per sample: the CPU that the windowing node's input path needs.

Feeds the per-message path of ``input: joint_states`` — :class:`jident_ros.stream.inputs.JointStateAdapter`
(+ an Imu message per sample for a1) then :class:`jident_ros.stream.flank.FlankDetector` — with raw-encoder
single-event recordings of our simulator (evaluation/raw_inputs.py: 10 s steady + one entry each, 2^16
counts, 30 dB), message by message as plain Python objects (no DDS: the rclpy deserialisation is not
included), and reports the process CPU time per drive second as a percentage of one core (median of
``--repeats`` rounds).  Target (issue 12): <= 25 % of one core at 2 kHz.  It also checks that the windows
are identical to the batched path's (the detector fed the recording's array in batches of 50).

    python bench/bench_jointstate.py [--recordings 4] [--repeats 3] [--json out/bench/bench_jointstate.json]
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector
from jident_ros.stream.inputs import JointStateAdapter

CH = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1")


class Vec3:
    __slots__ = ("x", "y", "z")

    def __init__(self, x, y, z):
        self.x, self.y, self.z = x, y, z


def messages(rec):
    """(stamp, names, position, velocity, effort, imu vector) per sample, as a JointState/Imu would carry."""
    c = {name: rec.column(name).tolist() for name in CH}
    nan = math.nan
    out = []
    for k in range(len(rec.data)):
        out.append((c["t"][k], ["motor", "load"], [c["alpha1"][k], c["alpha2"][k]],
                    [c["omega1"][k], c["omega2"][k]], [c["m_el"][k], nan], Vec3(c["a1"][k], 0.0, 9.81)))
    return out


def run_messages(system, msgs):
    ad = JointStateAdapter(system.sampling.sample_period_s, use_imu=True)
    det = flank_detector(system, channels=CH)
    wins = []
    for stamp, names, pos, vel, eff, acc in msgs:
        for arr, ch in ad.push(stamp, names, pos, vel, eff) + ad.push_imu(stamp, acc):
            wins += [e.window for e in det.push(arr, ch) if e.kind == "window"]
    for arr, ch in ad.flush():
        wins += [e.window for e in det.push(arr, ch) if e.kind == "window"]
    return wins


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--recordings", type=int, default=4)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", default="")
    a = p.parse_args(argv)
    system = load_system_config()
    recs = raw_recordings(system, (1.16, 0.957, 1.218, 1.073)[:a.recordings], (0.005,), snr_db=30.0, steady_s=10.0,
                          seed=7, channels=CH)
    all_msgs = [messages(r) for r in recs]
    drive_s = sum(len(r.data) for r in recs) * system.sampling.sample_period_s
    identical = True
    for rec, msgs in zip(recs, all_msgs):
        ref = [e.window for e in run_detector(flank_detector(system, channels=CH), rec) if e.kind == "window"]
        got = run_messages(system, msgs)
        identical &= len(ref) == len(got) == 1 and all(
            np.array_equal(g.column(c), r.column(c)) for g, r in zip(got, ref) for c in CH)
    cpu = []
    for _ in range(a.repeats):
        c0 = time.process_time()
        for msgs in all_msgs:
            run_messages(system, msgs)
        cpu.append(time.process_time() - c0)
    med = statistics.median(cpu)
    pct = 100.0 * med / drive_s
    res = {"drive_s": drive_s, "messages_per_s": 1.0 / system.sampling.sample_period_s, "cpu_s_median": med,
           "cpu_percent_of_one_core": pct, "rounds_cpu_s": cpu, "windows_identical_to_batched": bool(identical),
           "target_percent": 25.0, "met": bool(pct <= 25.0 and identical)}
    print(f"JointState + Imu at {res['messages_per_s']:.0f} Hz through JointStateAdapter + FlankDetector: "
          f"{med:.2f} s CPU for {drive_s:.1f} drive s = {pct:.1f} % of one core (median of {a.repeats}); windows "
          f"identical to the batched path's: {identical}")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(res, indent=1) + "\n")
    return 0 if res["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
