"""The gap stage's cost per window (issue 20: <= 2 ms): estimate_inertia on JointState-like windows (motor encoder,
torque, no a1; the free angle fit with its change-point search), with an Imu (a1 fit and angle fit, cross-checked)
and with the load encoder too (the load side's bound, identify/gap_load.py), on the stress bench's speed step and
light-load reversal (evaluation/gap_stress.py), and a DOL blind draw's long light-load reversal whose constant torque
is fitted over the whole gap (test/data/dol_draws_light_reversal_constant.npz; skipped where a checkout lacks it).

    nice -n 10 .venv/bin/python bench/bench_gap.py [--repeats 200]

Prints the commit measured (with "+ uncommitted changes" when jident_ros/ differs from it) and the checkout it is
imported from (a venv with an editable install imports its own checkout, not the current directory's: run another
worktree's with ``PYTHONPATH=.``), the machine's load average before and after, then the wall-clock median and 90th
percentile and the CPU-time median and 10th percentile per window, ms.  On a loaded machine the CPU time is the
closer measure of the idle cost (the wall clock includes waiting for a core); a load above the core count still slows
it (shared caches, frequency), and its 10th percentile (the least disturbed runs) moves less from run to run than its
median.
"""
import argparse
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from jident_ros.identify import gap_free
from jident_ros.identify.gap import estimate_inertia
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.gap_load import LOAD_ANGLE_KEY
from jident_ros.research.evaluation.gap_stress import StressDrive, simulate


def commit() -> str:
    """The commit of the jident_ros measured (the checkout it is imported from), short, and whether its jident_ros/ has
    uncommitted changes ('unknown' when that is not a git checkout, e.g. an exported tree on PYTHONPATH)."""
    import jident_ros
    repo = Path(jident_ros.__file__).resolve().parents[1]
    if not (repo / ".git").exists():
        return f"unknown (jident_ros from {repo}, not a git checkout)"
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "jident_ros"], cwd=repo, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    return head + (" + uncommitted changes in jident_ros/" if dirty else "") + f" (jident_ros from {repo})"


def load() -> str:
    try:
        return "load average %.2f %.2f %.2f" % os.getloadavg() + f" on {os.cpu_count()} cores"
    except OSError:
        return "load average unknown"


def _steady_entry_window():
    """Our simulator's slip as a JointState drive records it (raw 2^16 encoder, no a1, the flank detector's window):
    a drive steady before the entry, where the steady-entry fit runs (gap_kink)."""
    from jident_ros.config import load_system_config
    from jident_ros.identify.monitor import DetectorConfig, make_detector
    from jident_ros.research.evaluation.raw_inputs import raw_recordings, run_detector, without
    system = load_system_config()
    rec = without(raw_recordings(system, [1.131], [0.0075], steady_s=0.2, seed=12)[0], ("a1", "a2", "v2"))
    det = make_detector(system, DetectorConfig("flank", channels=rec.channels, encoder_counts_per_rev=65536))
    return [e.window for e in run_detector(det, rec) if e.kind == "window"][0]


def _timed(repeats: int, fn) -> tuple:
    times, cpu = [], []
    memo = getattr(gap_free, "_INTERVAL_MEMO", None)   # stop 40's kept scan (a checkout before 41's window_memo)
    for _ in range(repeats):
        if memo is not None:
            memo.clear()                                  # every run a new window's cost, not the kept scan's
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return times, cpu


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=200)
    a = p.parse_args(argv)
    print(f"commit {commit()}; before: {load()}")
    model = GapModel(torque_accuracy=0.01, coulomb_friction_max_nm=1.5)
    for event in ("speed_step", "load_reversal"):
        rec = simulate(StressDrive(), event, seed=1)
        for label, drop, with_load in (("JointState (angle fit)", ("a1",), False), ("with Imu (cross-checked)", (), False),
                                       ("JointState + load encoder", ("a1",), True)):
            w = {k: v for k, v in rec["window"].items() if k not in drop}
            if with_load:  # the load side's bound (identify/gap_load.py), as a JointState window with both joints
                w[LOAD_ANGLE_KEY] = rec["load_angle"]
            e0, r0 = rec["entry"] - 5, rec["recontact"] + 2
            times, cpu = _timed(a.repeats, lambda: estimate_inertia(w, e0, 0.005, 0.08, 5e-4, recontact_index=r0,
                                                                    model=model))
            print(f"{event:>14} {label:<26} gap {rec['recontact'] - rec['entry']:>3} samples: wall median "
                  f"{np.median(times):.3f} ms, p90 {np.percentile(times, 90):.3f} ms; CPU median {np.median(cpu):.3f} ms, "
                  f"p10 {np.percentile(cpu, 10):.3f} ms ({a.repeats} runs)")
    # a drive steady before the entry (the steady-entry fit), with the node's defaults for a drive that declares
    # nothing (a typical drive's 1 ms lag, the coupling's release searched up to 4 ms) and with neither
    w = _steady_entry_window()
    d = w.as_dict()
    for label, extra in (("defaults (lag 1 ms, release 4 ms)", {"torque_lag_s": 1e-3, "coupling_release_s": 4e-3}),
                         ("no lag, rigid contact", {})):
        m = GapModel(torque_accuracy=0.03, coulomb_friction_max_nm=1.5, **extra)
        times, cpu = _timed(a.repeats, lambda: estimate_inertia(d, w.entry_index, w.backlash_width_m, w.wheel_radius_m,
                                                                5e-4, recontact_index=w.recontact_index, model=m))
        print(f"{'steady entry':>14} {label:<26} wall median {np.median(times):.3f} ms, p90 "
              f"{np.percentile(times, 90):.3f} ms; CPU median {np.median(cpu):.3f} ms, p10 "
              f"{np.percentile(cpu, 10):.3f} ms ({a.repeats} runs)")
    # a long light-load reversal whose constant torque (friction + the estimate's offset) is fitted over the whole gap
    # (DOL blind draw d1-05's window, test/data; stop 40's FITTED_CONSTANT_SCAN grows the quiet cores again there)
    path = Path(__file__).resolve().parents[1] / "test" / "data" / "dol_draws_light_reversal_constant.npz"
    if path.exists():
        d = dict(np.load(path))
        m = GapModel(torque_accuracy=0.01, coulomb_friction_max_nm=2.65, torque_offset_nm=2.119, torque_lag_s=4.5e-4,
                     coupling_release_s=0.004, torque_filter_s=2e-4)
        times, cpu = _timed(a.repeats, lambda: estimate_inertia(d, 48, 0.00323, 0.1, 5e-4, bearing_friction_nms_per_rad=0.02048,
                                                                recontact_index=178, model=m))
        print(f"{'light reversal':>14} {'DOL d1-05 (130-row gap)':<26} wall median {np.median(times):.3f} ms, p90 "
              f"{np.percentile(times, 90):.3f} ms; CPU median {np.median(cpu):.3f} ms, p10 "
              f"{np.percentile(cpu, 10):.3f} ms ({a.repeats} runs)")
    print(f"after: {load()}")


if __name__ == "__main__":
    main()
