"""JointState at 2 kHz, one message per sample: the CPU that the windowing node needs (issue 12 target:
<= 25 % of one core on this 2-core machine, in real time, windows identical to the batched path's).

Default (``node``): the real windowing node (``input: joint_states``, ``use_imu: true``, detector auto =
flank) runs as its own process (bench_ros.Proc: the ``ros2 run`` executable, else ``python -m``); this
process publishes ``sensor_msgs/JointState`` (motor: position alpha1, velocity omega1, effort m_el; load:
position alpha2, velocity omega2, effort NaN) and ``sensor_msgs/Imu`` (linear_acceleration.x = a1), one of
each per sample, header stamp = t, paced at 2 kHz against the wall clock, over DDS (reliable, keep last
10000).  The recording is a raw-encoder single-event recording of our simulator (evaluation/raw_inputs.py:
``--steady-s`` s steady + one entry, 2^16 counts, 30 dB), >= 20 s drive time; each round takes another grid
case (J1 1.16, 0.957, 1.218, ...) and a fresh node.  Per round:

* **CPU**: utime + stime of the node process (/proc/PID/stat) from just before the first message to the moment
  its ``drive/progress`` reports the last sample read, per drive second -> % of one core (the median over
  ``--rounds`` is the result; per wall second too, the same when the node keeps up);
* **real time**: the publisher's largest lag behind the 2 kHz schedule, and the node's lag: wall time of each
  ``drive/progress`` (t of the last sample read) minus the time that sample was due (median / max);
* **nothing lost**: JointState and Imu messages published against the node's counts (``jointstate.messages``,
  ``jointstate.imu_messages``, ``samples_seen`` of its rate status on /diagnostics) and its drop counters;
* **windows identical to the batched path's**: the windows on ``drive/window`` against the same samples (t
  as the node reads it: header sec + 1e-9 nanosec) fed in batches of 50 to the detector the offline
  ``jident diagnose`` builds (cli.offline: same channels, same detector), every column bitwise; and the same
  samples written to CSV and run through ``jident diagnose --no-image --json`` (entry times and K2 estimates
  equal).

``--in-process``: the adapter + detector alone, plain Python messages, no DDS and no rclpy (the old bench;
a profile of the per-message path).

    python bench/bench_jointstate.py [--rounds 3] [--steady-s 20] [--json out/bench/bench_jointstate.json]
    python bench/bench_jointstate.py --in-process [--recordings 4] [--repeats 3]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))

import bench_ros  # noqa: E402
import numpy as np  # noqa: E402
from bench_ros import Proc, machine, ros_environment  # noqa: E402

from jident_ros.cli.offline import _make_detector  # noqa: E402
from jident_ros.config import load_system_config  # noqa: E402
from jident_ros.identify.monitor import DetectorConfig  # noqa: E402
from jident_ros.research.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector  # noqa: E402
from jident_ros.stream.detector import stream_batches  # noqa: E402
from jident_ros.stream.inputs import JointStateAdapter  # noqa: E402

CH = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1")
CASES = (1.16, 0.957, 1.218, 1.073, 1.131)
TARGET_PERCENT = 25.0
NS = "/jsbench"
CLOCK_START_S = 1.0           # the recording's t starts here (a header stamp of 0 looks unset)


class Vec3:
    __slots__ = ("x", "y", "z")

    def __init__(self, x, y, z):
        self.x, self.y, self.z = x, y, z


# --------------------------------------------------------------------------- the recording


def recording(system, j1: float, steady_s: float):
    """A raw-encoder single-event recording (30 dB, 2^16 counts), t from CLOCK_START_S; its t as the node reads
    it from a header stamp (sec + 1e-9 nanosec) and the stamps."""
    rec = raw_recordings(system, (j1,), (0.005,), snr_db=30.0, steady_s=steady_s, seed=7, channels=CH)[0]
    data = rec.data.copy()
    t = data[:, 0] - data[0, 0] + CLOCK_START_S
    stamps = []
    for k, tk in enumerate(t):
        sec = int(math.floor(tk))
        nsec = int(round((tk - sec) * 1e9))
        if nsec >= 1_000_000_000:
            sec, nsec = sec + 1, nsec - 1_000_000_000
        stamps.append((sec, nsec))
        data[k, 0] = sec + 1e-9 * nsec        # exactly what nodes/windowing.py computes
    return rec, data, stamps


def batched_windows(system, data, channels=CH) -> list:
    """The batched path: the detector the offline `jident diagnose` builds, fed batches of 50."""
    det = _make_detector(system, DetectorConfig("flank", None, None, None), channels, "bench")
    wins = []
    for b in stream_batches(data, 50):
        wins += [e.window for e in det.push(b, channels) if e.kind == "window"]
    return wins


def diagnose_csv(data, env, tmp: Path, channels=CH) -> list:
    """`jident diagnose --no-image --json` on the same samples written as CSV: its windows (JSON)."""
    csv_path, out = tmp / "recording.csv", tmp / "diagnose.json"
    np.savetxt(csv_path, data, delimiter=",", header=",".join(channels), comments="", fmt="%.17g")
    subprocess.run([sys.executable, "-m", "jident_ros.cli", "diagnose", str(csv_path), "--no-image", "--json",
                    str(out), "--quiet"], env=env, check=True, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())["windows"]


def same_windows(got, ref) -> bool:
    return len(got) == len(ref) >= 1 and all(
        g.channels == r.channels and g.entry_index == r.entry_index and np.array_equal(g.data, r.data)
        and np.array_equal([g.backlash_width_estimate_m, g.backlash_width_se_m],
                           [r.backlash_width_estimate_m, r.backlash_width_se_m], equal_nan=True)
        for g, r in zip(got, ref))


def same_as_diagnose(got, js) -> bool:
    return len(got) == len(js) >= 1 and all(
        g.entry_time_s == j["entry_time_s"] and g.backlash_width_estimate_m == j["backlash_width_estimate_m"]
        for g, j in zip(got, js))


# --------------------------------------------------------------------------- one round over DDS


class Bench:
    """This process's rclpy node: the JointState/Imu publishers and the listeners of the node's outputs."""

    def __init__(self):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import Imu, JointState
        from std_msgs.msg import Float64, Float64MultiArray

        from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, qos_signals
        self.rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node("jident_jointstate_bench", context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.JointState, self.Imu = JointState, Imu
        self.pub_js = self.node.create_publisher(JointState, f"{NS}/joint_states", qos_signals(10000))
        self.pub_imu = self.node.create_publisher(Imu, f"{NS}/imu", qos_signals(10000))
        self.windows, self.progress, self.status = [], [], {}
        self.node.create_subscription(Float64MultiArray, f"{NS}/drive/window",
                                      lambda m: self.windows.append(m), qos_latched(50))
        self.node.create_subscription(Float64, f"{NS}/drive/progress",
                                      lambda m: self.progress.append((time.monotonic(), m.data)), qos_signals(100))
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, qos_diagnostics())

    def on_diag(self, msg):
        for s in msg.status:
            if s.name.endswith(": rate") and "windowing" in s.name and s.hardware_id.startswith(NS + "/"):
                self.status = {kv.key: kv.value for kv in s.values}

    def spin_until(self, cond, timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while not cond() and time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.05)
        return bool(cond())

    def reset(self):
        self.windows, self.progress, self.status = [], [], {}

    def messages(self, data, stamps):
        """The JointState and Imu messages of every sample, built beforehand (not in the paced loop)."""
        from builtin_interfaces.msg import Time
        c = {name: data[:, i].tolist() for i, name in enumerate(CH)}
        out = []
        for k, (sec, nsec) in enumerate(stamps):
            js = self.JointState(name=["motor", "load"], position=[c["alpha1"][k], c["alpha2"][k]],
                                 velocity=[c["omega1"][k], c["omega2"][k]], effort=[c["m_el"][k], math.nan])
            js.header.stamp = Time(sec=sec, nanosec=nsec)
            imu = self.Imu()
            imu.header.stamp = Time(sec=sec, nanosec=nsec)
            imu.linear_acceleration.x = c["a1"][k]
            imu.linear_acceleration.z = 9.81
            out.append((js, imu))
        return out

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.ctx)


def run_round(bench: Bench, env, logdir: Path, msgs, data, ts: float, imu: bool) -> dict:
    from jident_ros.nodes.ros_io import window_from_msg
    bench.reset()
    win = Proc(env, logdir, "windowing", "-r", f"__ns:={NS}", "-p", "input:=joint_states", "-p",
               f"use_imu:={'true' if imu else 'false'}", "-p", "signals_queue_depth:=10000")
    try:
        ok = bench.spin_until(lambda: bench.pub_js.get_subscription_count() >= 1
                              and (not imu or bench.pub_imu.get_subscription_count() >= 1), 60.0)
        if not ok or not win.alive():
            raise RuntimeError(f"the windowing node did not subscribe:\n{win.text()[-2000:]}")
        bench.spin_until(lambda: bool(bench.status), 5.0)     # its first rate status: the node is spinning
        n, t0_drive = len(msgs), float(data[0, 0])
        last_t = float(data[-1, 0])
        # drive/progress goes out every progress_every_batches (10) x batch_size (50) samples read
        last_progress_t = float(data[(n // 500) * 500 - 1, 0])
        cpu0, wall0 = win.cpu_s(), time.monotonic()
        k, lag_pub = 0, 0.0
        while k < n:
            now = time.monotonic()
            due = min(n, int((now - wall0) / ts) + 1)
            if due > k:
                lag_pub = max(lag_pub, now - (wall0 + (due - 1) * ts))   # how late the last due message goes out
                for js, imu_msg in msgs[k:due]:
                    bench.pub_js.publish(js)
                    if imu:
                        bench.pub_imu.publish(imu_msg)
                k = due
            bench.ex.spin_once(timeout_sec=0)
            time.sleep(0.0005)
        pub_end = time.monotonic()
        done = bench.spin_until(lambda: bench.progress and bench.progress[-1][1] >= last_progress_t, 30.0)
        wall1, cpu1 = (bench.progress[-1][0] if done else time.monotonic()), win.cpu_s()
        # the rate status after the end: the node's counts (it goes out every diagnostics_period_s = 1 s)
        bench.status = {}
        bench.spin_until(lambda: bench.status.get("jointstate.messages") == str(n), 5.0)
        bench.spin_until(lambda: len(bench.windows) >= 1, 5.0)
        st = dict(bench.status)
    finally:
        rc = win.stop()
    lags = [w - (wall0 + (t - t0_drive) * 1.0) for w, t in bench.progress]
    wall = wall1 - wall0
    cpu = cpu1 - cpu0
    got = [window_from_msg(m) for m in bench.windows]
    drops = {k: v for k, v in st.items() if (k.startswith("dropped.") or k in ("dropped_total", "callback_errors",
                                                                                "jointstate.missing_joint",
                                                                                "jointstate.imu_unmatched"))}
    return {"messages_published": n, "imu_published": n if imu else 0,
            "node_jointstate_messages": _int(st.get("jointstate.messages")),
            "node_imu_messages": _int(st.get("jointstate.imu_messages")),
            "node_samples_seen": _int(st.get("samples_seen")),
            "node_drops": {k: _int(v) for k, v in drops.items()},
            "jitter_period_matches": st.get("jitter.period_matches"),
            "wall_s": wall, "publish_wall_s": pub_end - wall0, "drive_s": (last_t - t0_drive) + ts,
            "node_cpu_s": cpu, "cpu_percent_of_wall": 100.0 * cpu / wall,
            "cpu_percent_of_one_core": 100.0 * cpu / ((last_t - t0_drive) + ts),
            "publisher_max_lag_ms": 1e3 * lag_pub,
            "node_lag_ms_median": 1e3 * statistics.median(lags) if lags else None,
            "node_lag_ms_max": 1e3 * max(lags) if lags else None, "node_finished": bool(done),
            "node_exit_status": rc, "windows": got, "load_average": os.getloadavg()}


def _int(v):
    try:
        return int(v)
    except (TypeError, ValueError):
        return None


def main_node(a) -> dict:
    env = ros_environment()
    system = load_system_config()
    ts = system.sampling.sample_period_s
    info = machine()
    info["uptime"] = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    bench = Bench()
    rounds = []
    try:
        for r in range(a.rounds):
            j1 = CASES[r % len(CASES)]
            rec, data, stamps = recording(system, j1, a.steady_s)
            # what the node sees: without the Imu no a1 column
            chans = tuple(c for c in CH if c != "a1" or not a.no_imu)
            seen = data[:, [CH.index(c) for c in chans]]
            ref = batched_windows(system, seen, chans)
            with tempfile.TemporaryDirectory(prefix="jident-jsbench-") as tmp:
                js = diagnose_csv(seen, env, Path(tmp), chans)
                msgs = bench.messages(data, stamps)
                res = run_round(bench, env, Path(tmp), msgs, data, ts, not a.no_imu)
            got = res.pop("windows")
            res.update(case_j1_kgm2=j1, windows_node=len(got), windows_batched=len(ref),
                       windows_identical_to_batched=same_windows(got, ref),
                       windows_equal_to_jident_diagnose=same_as_diagnose(got, js),
                       entry_error_samples=[round((g.entry_time_s - float(data[rec.entry_row, 0])) / ts) for g in got])
            res["lost"] = (None if res["node_jointstate_messages"] is None else
                           (res["messages_published"] - res["node_jointstate_messages"])
                           + (res["imu_published"] - (res["node_imu_messages"] or 0)))
            rounds.append(res)
            print(f"round {r + 1}: J1 {j1}: {res['drive_s']:.2f} drive s in {res['wall_s']:.2f} wall s; node CPU "
                  f"{res['node_cpu_s']:.2f} s = {res['cpu_percent_of_one_core']:.1f} % of one core per drive s "
                  f"({res['cpu_percent_of_wall']:.1f} % per wall s); lost "
                  f"{res['lost']} (JointState {res['node_jointstate_messages']}/{res['messages_published']}, "
                  f"Imu {res['node_imu_messages']}/{res['imu_published']}); drops {res['node_drops']}; node lag "
                  f"median {res['node_lag_ms_median']:.1f} ms, max {res['node_lag_ms_max']:.1f} ms; publisher lag "
                  f"max {res['publisher_max_lag_ms']:.1f} ms; windows {len(got)} (batched {len(ref)}), identical "
                  f"{res['windows_identical_to_batched']}, = jident diagnose {res['windows_equal_to_jident_diagnose']}; "
                  f"load {res['load_average'][0]:.2f}", flush=True)
    finally:
        bench.close()
    med = statistics.median(r["cpu_percent_of_one_core"] for r in rounds)
    met = (med <= TARGET_PERCENT and all(r["lost"] == 0 and r["windows_identical_to_batched"]
                                         and r["windows_equal_to_jident_diagnose"] and r["node_finished"]
                                         and not any(r["node_drops"].values()) for r in rounds))
    info["uptime_end"] = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"windowing node, JointState{'' if a.no_imu else ' + Imu'} at {1 / ts:.0f} Hz over DDS: {med:.1f} % of one core (median of "
          f"{len(rounds)} rounds: {', '.join('%.1f' % r['cpu_percent_of_one_core'] for r in rounds)}); target "
          f"<= {TARGET_PERCENT:.0f} %, lossless, windows identical: {'met' if met else 'NOT met'}")
    print(f"machine: {info['uptime']} (start), {info['uptime_end']} (end)")
    return {"mode": "node", "imu": not a.no_imu, "machine": info, "rounds": rounds, "cpu_percent_of_one_core_median": med,
            "target_percent": TARGET_PERCENT, "met": bool(met)}


# --------------------------------------------------------------------------- in process (no DDS)


def plain_messages(rec):
    """(stamp, names, position, velocity, effort, imu vector) per sample, as a JointState/Imu would carry."""
    c = {name: rec.column(name).tolist() for name in CH}
    nan = math.nan
    return [(c["t"][k], ["motor", "load"], [c["alpha1"][k], c["alpha2"][k]], [c["omega1"][k], c["omega2"][k]],
             [c["m_el"][k], nan], Vec3(c["a1"][k], 0.0, 9.81)) for k in range(len(rec.data))]


def run_plain(system, msgs):
    ad = JointStateAdapter(system.sampling.sample_period_s, use_imu=True)
    det = flank_detector(system, channels=CH)
    wins = []
    for stamp, names, pos, vel, eff, acc in msgs:
        for arr, ch in ad.push(stamp, names, pos, vel, eff) + ad.push_imu(stamp, acc):
            wins += [e.window for e in det.push(arr, ch) if e.kind == "window"]
    for arr, ch in ad.flush():
        wins += [e.window for e in det.push(arr, ch) if e.kind == "window"]
    return wins


def main_in_process(a) -> dict:
    system = load_system_config()
    recs = raw_recordings(system, CASES[:a.recordings], (0.005,), snr_db=30.0, steady_s=10.0, seed=7, channels=CH)
    all_msgs = [plain_messages(r) for r in recs]
    drive_s = sum(len(r.data) for r in recs) * system.sampling.sample_period_s
    identical = True
    for rec, msgs in zip(recs, all_msgs):
        ref = [e.window for e in run_detector(flank_detector(system, channels=CH), rec) if e.kind == "window"]
        identical &= same_windows(run_plain(system, msgs), ref)
    cpu = []
    for _ in range(a.repeats):
        c0 = time.process_time()
        for msgs in all_msgs:
            run_plain(system, msgs)
        cpu.append(time.process_time() - c0)
    med = statistics.median(cpu)
    pct = 100.0 * med / drive_s
    print(f"in process (no DDS): JointState + Imu through JointStateAdapter + FlankDetector: {med:.2f} s CPU for "
          f"{drive_s:.1f} drive s = {pct:.1f} % of one core (median of {a.repeats}); windows identical to the "
          f"batched path's: {identical}")
    return {"mode": "in_process", "drive_s": drive_s, "cpu_s_median": med, "cpu_percent_of_one_core": pct,
            "rounds_cpu_s": cpu, "windows_identical_to_batched": bool(identical), "target_percent": TARGET_PERCENT,
            "met": bool(pct <= TARGET_PERCENT and identical)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=3, help="node mode: rounds (fresh node, another case), >= 1")
    p.add_argument("--steady-s", type=float, default=20.0, help="node mode: steady drive before the entry, s")
    p.add_argument("--no-imu", action="store_true", help="node mode: JointState only (use_imu false, no a1)")
    p.add_argument("--in-process", action="store_true", help="adapter + detector in this process, no DDS")
    p.add_argument("--recordings", type=int, default=4, help="in-process: recordings of 10 s steady")
    p.add_argument("--repeats", type=int, default=3, help="in-process: timing rounds")
    p.add_argument("--json", default="")
    p.add_argument("--profile", default="", help="node mode: run the node under cProfile, stats to this file "
                   "(the CPU then includes the profiler's overhead: not a result)")
    a = p.parse_args(argv)
    if a.profile:
        out = str(Path(a.profile).resolve())
        bench_ros.node_command = lambda name: [sys.executable, "-m", "cProfile", "-o", out, "-m",
                                               f"jident_ros.nodes.{name}"]
    if a.rounds < 1 or a.steady_s <= 0:
        p.error("--rounds >= 1 and --steady-s > 0")
    res = main_in_process(a) if a.in_process else main_node(a)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(res, indent=1, default=str) + "\n")
    return 0 if res["met"] else 1


if __name__ == "__main__":
    sys.exit(main())
