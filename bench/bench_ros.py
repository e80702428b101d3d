#!/usr/bin/env python3
"""Benchmark of the ROS 2 node set: simulator -> windowing -> diagnostic over DDS (issue "ROS nodes").

    .venv/bin/python bench/bench_ros.py [--cases N] [--rtf 10 20 50 0] [--repeat R] [--out out.json]
                                        [--bisect LO HI] [--profile DIR] [--quick] [--check]

For every real-time factor of ``--rtf`` a fresh set of the three nodes is started as separate
processes (the ``ros2 run`` executables of the ament index, else ``python -m jident_ros.nodes.<x>``),
in a namespace of their own (``/bench_<k>``); windowing and diagnostic run with ``use_sim_time``
(the simulator publishes ``/clock``).  The simulator runs ``--cases`` grid cases (``cases:=zip``: the
seven J1 classes in turn, K2 = 0.005 m, eta_k = 0.0375 Pa s^n -- off the pattern runs), ``--repeat``
passes over them, at ``real_time_factor`` = the level (0 = ``fast_sleep_s`` per batch with back-pressure from the
windowing node's ``drive/progress``).  The
pattern library is built once beforehand (or taken from the CLI's cache) and passed to the node.

The bench's own rclpy node (in this process, its own Context) receives ``drive/signals``,
``drive/window``, ``drive/case``, ``inertia_estimate`` and ``/diagnostics`` and measures:

* **loss**: every sample index (from the ``t`` column) is checked against what the simulator
  publishes (cases x (gap_samples + 2048) samples, consecutive): lost, duplicated, out-of-order;
  windows on ``drive/window`` against the expected entry times; the windowing node's drop events;
  one ``inertia_estimate`` per window, within 1 % of the case's true J1;
* **speed**: stream rate = drive seconds / wall seconds between the first and the last batch received;
  end-to-end rate = drive seconds of the run / wall seconds from the first batch to the last estimate.
  A level *sustains* its factor when nothing is lost, every estimate is there and right, the stream
  ran at >= 95 % of the requested factor and the pipeline kept up (end-to-end rate >= 90 % of the
  stream rate and 90 % of the estimates within 1 s of their window's last sample: no backlog);
* **latency** "last sample of a window -> inertia_estimate": the window's last sample is the entry
  sample + 1999; wall time (time.monotonic, this process) from receiving the drive/signals batch
  that holds it to receiving the matching estimate; split into batch -> drive/window and
  drive/window -> estimate; plus the diagnostic node's own ``estimate_latency_ms`` and
  ``processing_ms`` (its /diagnostics status);
* **memory**: VmHWM (peak) and VmRSS of each node from /proc/<pid>/status at the end of the run
  (the simulator stays up with ``exit_when_done:=false`` until it is read); MiB;
* **CPU**: user + system seconds of each node (and of this process) while the stream ran.

* **CPU per drive second** of each node: utime + stime from /proc/<pid>/stat between the first batch
  received and the end of the run, divided by the drive seconds streamed meanwhile.  Valid on a loaded
  machine (the wall-clock rates are not); its inverse bounds the rate factor the node can sustain.

``--bisect LO HI`` then finds the highest sustained factor between LO and HI (log bisection, a fresh node set
per probe; :func:`find_limit`).  ``--profile DIR`` runs every node under cProfile with a CPU clock
(bench/cpu_profile.py): DIR/rtf<level>/<node>.prof.

Targets (issue 25, medians of 3 runs on an idle machine): (1) >= 30x sustained without back-pressure and without
a lost sample, window or estimate; (2) >= 40x end to end with back-pressure (rtf 0), lossless; (3) median latency
<= 50 ms at 20x (judged at the lowest level >= 20x); (4) diagnostic node peak resident memory (VmHWM) <= 150 MiB
at the levels it sustained (an overloaded level's peak, windows queued in its subscription, is reported apart).
``--check``: exit status 1 when a target is missed.
"""
from __future__ import annotations

import argparse
import bisect
import json
import math
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from jident_ros.resources import node_command, stop_process  # noqa: E402

SIM_START_S = 1.0          # simulator start_time_s (its default)
GAP_SAMPLES = 400          # simulator gap_samples (its default)
BATCH = 50                 # simulator batch_size (its default)
WIDTH_M = 0.005
ETA = 0.0375
IDLE_S = 10.0              # a run ends this long after the last message once the simulator is done
BACKLOG_MS = 1000.0        # kept up: 90 % of the estimates within 1 s of their window's last sample
TOL = 0.01                 # an estimate is right within 1 % of the true J1
# issue 25: >= 30x without back-pressure and without a lost sample, window or estimate; >= 40x with it (rate 0);
# median latency <= 50 ms at 20x; diagnostic node peak RSS <= 150 MiB
TARGET_RTF, TARGET_BP_RTF, TARGET_LAT_MS, TARGET_LAT_RTF, TARGET_RSS_MB = 30.0, 40.0, 50.0, 20.0, 150.0
CLK_TCK = os.sysconf("SC_CLK_TCK")


# --------------------------------------------------------------------------- environment


def ros_environment() -> dict:
    """AMENT_PREFIX_PATH with this venv, a domain id of our own, localhost discovery (as conftest)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        prefixes.insert(0, sys.prefix)
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 50))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "LOCALHOST"
    os.environ["PYTHONUNBUFFERED"] = "1"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def machine() -> dict:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from importlib.metadata import version

    import rclpy  # noqa: F401
    vers = {}
    for dist in ("rclpy", "ros-rmw-fastrtps-cpp", "ros-fastdds", "numpy", "scipy"):
        try:
            vers[dist] = version(dist)
        except Exception:
            pass
    return {"nproc": os.cpu_count(), "cpu_model": model, "python": platform.python_version(),
            "rmw": os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)"), "versions": vers,
            "load_average_start": os.getloadavg(), **code_commit()}


def code_commit() -> dict:
    """The commit of the tree the nodes import (this bench's checkout: :func:`ros_environment` puts it first on
    PYTHONPATH), with ``-dirty`` when its tracked files differ from it: every number names the code it measured."""
    tree = REPO

    def git(*a):
        try:
            return subprocess.run(["git", "-C", str(tree), *a], capture_output=True, text=True,
                                  timeout=30).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""
    head = git("rev-parse", "--short=7", "HEAD") or "unknown (not a git tree)"
    dirty = bool(git("status", "--porcelain", "--untracked-files=no")) if head[0] != "u" else False
    return {"commit": head + ("-dirty" if dirty else ""), "code_tree": str(tree)}


def pattern_library(path: str | None) -> tuple[Path, float]:
    """The pattern library file: given, else the CLI's cache path, built and saved when missing."""
    from jident_ros.config import load_method_config, load_system_config
    from jident_ros.method.patterns import PatternLibrary
    system, method = load_system_config(), load_method_config()
    if path:
        p = Path(path)
    else:
        from jident_ros.identify.library import default_library_path
        p = Path(default_library_path(system, method))
    if p.is_file():
        return p, 0.0
    t = time.perf_counter()
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="jident-bench-")) / p.name
    PatternLibrary.build(system, method).save(tmp)
    os.replace(tmp, p)
    return p, time.perf_counter() - t


# --------------------------------------------------------------------------- processes


class Proc:
    """A node process with its output in a log file."""

    def __init__(self, env, logdir: Path, node: str, *ros_args: str, profile: Path | None = None):
        self.name = node
        cmd = node_command(node)
        if profile is not None:  # cProfile writes its file when the node returns (SIGINT: the node's shutdown path)
            cmd = [sys.executable, str(REPO / "bench" / "cpu_profile.py"), str(profile / f"{node}.prof"),
                   f"jident_ros.nodes.{node}"]
        self.cmd = [*cmd, "--ros-args", *ros_args]
        self.log = logdir / f"{node}.log"
        self.out = open(self.log, "w")
        self.p = subprocess.Popen(self.cmd, env=env, cwd=logdir, stdout=self.out, stderr=subprocess.STDOUT)
        self.pid = self.p.pid
        self.mem = {}

    def alive(self) -> bool:
        return self.p.poll() is None

    def text(self) -> str:
        if not self.out.closed:
            self.out.flush()
        return self.log.read_text(errors="replace")

    def proc_status(self) -> dict:
        """VmHWM, VmRSS (MiB) from /proc/<pid>/status; {} when the process is gone."""
        try:
            txt = Path(f"/proc/{self.pid}/status").read_text()
        except OSError:
            return {}
        out = {}
        for line in txt.splitlines():
            key = line.split(":", 1)[0]
            if key in ("VmHWM", "VmRSS"):
                out[key] = int(line.split()[1]) / 1024.0
        return out

    def cpu_s(self) -> float | None:
        """user + system CPU seconds (/proc/<pid>/stat)."""
        try:
            fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return None
        return (int(fields[11]) + int(fields[12])) / CLK_TCK

    def stop(self, sig=signal.SIGINT, timeout=20.0) -> int:
        rc = stop_process(self.p, sig, timeout)
        if not self.out.closed:
            self.out.close()
        return rc


# --------------------------------------------------------------------------- the bench's node


class Listener:
    """The bench's rclpy node on its own Context: receives everything, stamps it with time.monotonic()."""

    def __init__(self, ns: str, total_samples: int, ts: float, executor: str = "events"):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import Float64, Float64MultiArray

        from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, qos_signals
        self.ns, self.ts, self.total = ns, ts, total_samples
        self.hw = f"{ns}/drive"
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node("jident_bench", namespace=ns, context=self.ctx)
        if executor == "events":  # far less overhead per callback than SingleThreadedExecutor
            from rclpy.experimental import EventsExecutor
            self.ex = EventsExecutor(context=self.ctx)
        else:
            self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.coverage = np.zeros(total_samples, dtype=np.int32)
        self.outside = 0           # samples with an index outside the expected stream
        self.out_of_order = 0      # batches whose first sample is not the one after the previous batch
        self.next_index = 0
        self.last_recv = time.monotonic()
        self.batch_first, self.batch_last, self.batch_recv = [], [], []
        self.n_batches = 0
        self.windows = []          # (recv, entry_time_s, window_id, n_rows)
        self.estimates = []        # (recv, value)
        self.inertia = []          # (recv, values dict, level)
        self.windowing = []        # (recv, values dict, level, message)
        self.cases = []            # rows of drive/case
        n = self.node
        n.create_subscription(Float64MultiArray, "drive/signals", self.on_signals, qos_signals(1000))
        n.create_subscription(Float64MultiArray, "drive/window", self.on_window, qos_latched(50))
        n.create_subscription(Float64MultiArray, "drive/case", self.on_case, qos_latched(1000))
        n.create_subscription(Float64, "inertia_estimate", self.on_estimate, qos_latched(100))
        n.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, qos_diagnostics())

    # callbacks: as little work as possible
    def on_signals(self, msg):
        recv = time.monotonic()
        self.last_recv = recv
        c = msg.layout.dim[1].size
        t = np.frombuffer(msg.data, dtype=np.float64)[msg.layout.data_offset::c]
        idx = np.rint((t - SIM_START_S) / self.ts).astype(np.int64)
        if idx.size == 0:
            return
        self.n_batches += 1
        if idx[0] != self.next_index or np.any(np.diff(idx) != 1):
            self.out_of_order += 1
        self.next_index = int(idx[-1]) + 1
        inside = (idx >= 0) & (idx < self.total)
        self.outside += int(idx.size - inside.sum())
        np.add.at(self.coverage, idx[inside], 1)
        self.batch_first.append(int(idx[0]))
        self.batch_last.append(int(idx[-1]))
        self.batch_recv.append(recv)

    def on_window(self, msg):
        recv = time.monotonic()
        self.last_recv = recv
        h = msg.data[:msg.layout.data_offset]
        self.windows.append((recv, float(h[2]), int(h[6]), int(msg.layout.dim[0].size)))

    def on_estimate(self, msg):
        self.last_recv = recv = time.monotonic()
        self.estimates.append((recv, float(msg.data)))

    def on_case(self, msg):
        self.cases.append(list(msg.data))

    def on_diagnostics(self, msg):
        recv = time.monotonic()
        self.last_recv = recv
        from jident_ros.nodes.diagnostics import status_task
        from jident_ros.nodes.ros_io import status_level, status_values
        for s in msg.status:
            if s.hardware_id != self.hw:
                continue
            task = status_task(s.name)   # "<ns>/jident_diagnostic: inertia" -> "jident_diagnostic: inertia"
            if task == "jident_diagnostic: inertia":
                self.inertia.append((recv, status_values(s), status_level(s)))
            elif task in ("jident_windowing: windows", "jident_windowing: rate"):
                self.windowing.append((recv, status_values(s), status_level(s), s.message))

    def spin_until(self, pred, timeout: float, every=None, period_s: float = 0.02) -> bool:
        """Spin until ``pred()`` (checked, with ``every()``, once per ``period_s`` of spinning: each check reads
        the simulator's log and /proc of every node; once per message they cost this process more CPU than
        its callbacks, CPU the nodes then lack on 2 cores)."""
        from rclpy.task import Future
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred():
                return True
            # every callback that is ready within period_s (the future never completes)
            self.ex.spin_until_future_complete(Future(), timeout_sec=period_s)
            if every is not None:
                every()
        return pred()

    def subscribers(self, topic: str) -> int:
        return self.node.count_subscribers(topic)

    def batch_holding(self, sample: int):
        """Receipt time of the first batch that holds sample index ``sample`` (None if never received)."""
        k = bisect.bisect_right(self.batch_first, sample) - 1  # batches arrive in order in a healthy run
        while k >= 0:
            if self.batch_first[k] <= sample <= self.batch_last[k]:
                return self.batch_recv[k]
            k -= 1
            if k >= 0 and self.batch_last[k] < sample - 10 * BATCH:
                break
        for f, last, r in zip(self.batch_first, self.batch_last, self.batch_recv):
            if f <= sample <= last:
                return r
        return None

    def close(self):
        import rclpy
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


# --------------------------------------------------------------------------- one level


def pct(values, q):
    return float(np.percentile(values, q)) if len(values) else None


def med(values):
    return float(statistics.median(values)) if len(values) else None


def run_level(k: int, rtf: float, args, env, library: Path, logroot: Path) -> dict:
    from jident_ros.config import load_system_config
    system = load_system_config()
    ts = system.sampling.sample_period_s
    before, after = system.sampling.samples_before_entry, system.sampling.samples_from_entry
    win_len = before + after
    classes = list(system.grid.inertia_classes_kgm2)
    inertias = [classes[i % len(classes)] for i in range(args.cases)]
    n_cases = args.cases * args.repeat
    per_case = GAP_SAMPLES + win_len
    total = n_cases * per_case
    batches_per_case = math.ceil(per_case / BATCH)
    drive_s = total * ts
    # case j (over all passes): its entry sample and the window's last sample (entry + after - 1)
    true_j1 = [inertias[j % args.cases] for j in range(n_cases)]
    entry_idx = [j * per_case + GAP_SAMPLES + before for j in range(n_cases)]
    last_idx = [e + after - 1 for e in entry_idx]
    entry_t = [SIM_START_S + e * ts for e in entry_idx]

    ns = f"/bench_{os.getpid()}_{k}"
    logdir = logroot / f"rtf{rtf:g}"
    logdir.mkdir(parents=True, exist_ok=True)
    lst = Listener(ns, total, ts, args.executor)
    procs = {}
    res = {"rtf": rtf, "namespace": ns, "cases": n_cases, "samples_expected": total,
           "batches_expected": n_cases * batches_per_case, "windows_expected": n_cases, "drive_s": drive_s}
    t_start = time.monotonic()
    try:
        nsarg = ["-r", f"__ns:={ns}"]
        prof = None
        if args.profile:
            prof = Path(args.profile).resolve() / f"rtf{rtf:g}"   # the nodes run in another cwd
            prof.mkdir(parents=True, exist_ok=True)
        procs["diagnostic"] = Proc(env, logdir, "diagnostic", *nsarg, "-p", f"pattern_library:={library}",
                                   "-p", f"use_sim_time:={str(args.sim_time).lower()}", "-p", "stale_after_s:=0.0", profile=prof)
        procs["windowing"] = Proc(env, logdir, "windowing", *nsarg, "-p", f"backlash_width_m:={WIDTH_M}",
                                  "-p", f"use_sim_time:={str(args.sim_time).lower()}", profile=prof)
        # ready: windowing listens to drive/signals, diagnostic (library loaded) to drive/window
        ready = lst.spin_until(lambda: lst.subscribers(f"{ns}/drive/signals") >= 2
                               and lst.subscribers(f"{ns}/drive/window") >= 2
                               or not all(p.alive() for p in procs.values()), 120)
        if not ready or not all(p.alive() for p in procs.values()):
            raise RuntimeError("nodes did not come up:\n" + "\n".join(p.text()[-2000:] for p in procs.values()))
        res["startup_s"] = time.monotonic() - t_start
        procs["simulator"] = Proc(
            env, logdir, "simulator", *nsarg, "-p", "cases:=zip",
            "-p", "inertias_kgm2:=[" + ", ".join(repr(float(j)) for j in inertias) + "]",
            "-p", f"backlash_widths_m:=[{WIDTH_M}]", "-p", f"consistencies_pa_sn:=[{ETA}]",
            "-p", f"real_time_factor:={float(rtf)}", "-p", f"repeat:={args.repeat}",
            "-p", f"gap_samples:={GAP_SAMPLES}", "-p", f"batch_size:={BATCH}", "-p", f"start_time_s:={SIM_START_S}",
            # 3 subscribers of drive/signals: windowing, the diagnostic node's recorder, this bench (with 2 it
            # could start before this bench's subscription matched: the first batches missed, a false "lost")
            "-p", "wait_for_subscribers:=3", "-p", "wait_timeout_s:=120.0", "-p", "exit_when_done:=false",
            "-p", f"fast_sleep_s:={args.fast_sleep}", "-p", f"max_lead_s:={args.max_lead}", profile=prof)
        sim = procs["simulator"]
        cpu0 = {}

        def poll():
            if not cpu0 and lst.n_batches:
                cpu0.update({n: p.cpu_s() for n, p in procs.items()}, bench=time.process_time(),
                            wall=time.monotonic())
            for p in procs.values():
                m = p.proc_status()
                if m:
                    p.mem = m

        rate_guess = rtf if rtf > 0 else 5.0
        timeout = 90 + 3 * drive_s / rate_guess
        sim_done = lambda: "done:" in sim.text()  # noqa: E731
        done = lambda: (len(lst.estimates) >= n_cases and lst.n_batches >= res["batches_expected"]  # noqa: E731
                        and sim_done())
        # the simulator is done and nothing arrived for IDLE_S: what is missing will not come
        idle = lambda: time.monotonic() - lst.last_recv > IDLE_S and sim_done()  # noqa: E731
        dead = lambda: not all(p.alive() for p in procs.values())  # noqa: E731
        lst.spin_until(lambda: done() or dead() or idle(), timeout, every=poll)
        t_end = time.monotonic()
        cpu1 = {n: p.cpu_s() for n, p in procs.items()}
        cpu1.update(bench=time.process_time(), wall=t_end)
        # stragglers: the last statuses, windowing summaries
        lst.spin_until(lambda: False, 1.5, every=poll)
        poll()
        res["timed_out"] = not done() and not idle()
        res["ended_idle"] = not done() and idle()
        res["died"] = [n for n, p in procs.items() if not p.alive()]
        res["memory_mib"] = {n: p.mem for n, p in procs.items()}
        if cpu0:
            wall = cpu1["wall"] - cpu0["wall"]
            res["cpu"] = {"wall_s": wall, **{n: {"cpu_s": (cpu1[n] - cpu0[n]) if cpu1.get(n) is not None
                                                 and cpu0.get(n) is not None else None}
                                             for n in (*procs, "bench")}}
            # drive seconds streamed while the CPU was counted (first batch received -> end of the run)
            res["cpu"]["drive_s"] = drive_s * (1.0 - lst.batch_first[0] / total) if lst.batch_first else drive_s
            for n in (*procs, "bench"):
                c = res["cpu"][n]["cpu_s"]
                res["cpu"][n]["percent_of_one_core"] = None if c is None else 100.0 * c / wall
                # CPU seconds per drive second: valid under load (the wall clock is not), the 1/x of the node's
                # CPU-bound limit on rate factor
                res["cpu"][n]["cpu_s_per_drive_s"] = None if c is None else c / max(res["cpu"]["drive_s"], 1e-9)
    finally:
        for name in ("simulator", "windowing", "diagnostic"):
            if name in procs:
                procs[name].stop(signal.SIGINT)
        res["exit_codes"] = {n: p.p.returncode for n, p in procs.items()}
        if "diagnostic" in procs:  # what the node itself says it diagnosed (tells pipeline loss from bench loss)
            import re
            res["windows_diagnosed_per_node_log"] = len(set(re.findall(r"window (\d+) \(entry t = ", procs["diagnostic"].text())))
        res["logs"] = str(logdir)
        lst.close()

    # ---------------------------------------------------------------- loss
    cov = lst.coverage
    res["batches_received"] = lst.n_batches
    res["samples_received_unique"] = int((cov > 0).sum())
    res["samples_lost"] = int((cov == 0).sum())
    res["samples_duplicated"] = int(np.maximum(cov - 1, 0).sum())
    res["samples_outside_stream"] = lst.outside
    res["discontinuities"] = lst.out_of_order
    got_entries = [w[1] for w in lst.windows]
    win_of_case = {}
    for recv, et, wid, n in lst.windows:
        j = int(round((et - SIM_START_S) / ts - GAP_SAMPLES - before)) // per_case
        if 0 <= j < n_cases and abs(entry_t[j] - et) < ts / 2 and n == win_len and j not in win_of_case:
            win_of_case[j] = recv
    res["windows_received"] = len(got_entries)
    res["windows_lost"] = n_cases - len(win_of_case)
    drops = [v for _, v, lvl, msg in lst.windowing if "reason" in v]
    res["windowing_drop_events"] = len(drops)
    res["windowing_drop_reasons"] = sorted({v["reason"] for v in drops})
    summaries = [v for _, v, lvl, msg in lst.windowing if "reason" not in v]
    res["windowing_last_summary"] = {k2: summaries[-1][k2] for k2 in ("samples_seen", "batches_seen", "windows_captured",
                                                                     "dropped_total")} if summaries else None
    # ---------------------------------------------------------------- estimates
    # a window's status carries entry_time_s and the value published on inertia_estimate; the Float64
    # itself is matched to its status by value, nearest in receipt time
    status_of_case = {}
    for recv, v, lvl in lst.inertia:
        if "entry_time_s" not in v:
            continue
        et = float(v["entry_time_s"])
        j = int(round((et - SIM_START_S) / ts - GAP_SAMPLES - before)) // per_case
        if 0 <= j < n_cases and abs(entry_t[j] - et) < ts / 2 and j not in status_of_case:
            status_of_case[j] = (recv, v, lvl)
    used = set()
    est_of_case = {}
    for j in sorted(status_of_case, key=lambda j: status_of_case[j][0]):
        recv, v, _ = status_of_case[j]
        if "inertia_estimate_kgm2" not in v:
            continue
        val = float(v["inertia_estimate_kgm2"])
        cands = [(abs(r - recv), i) for i, (r, x) in enumerate(lst.estimates) if i not in used and x == val]
        if cands:
            i = min(cands)[1]
            used.add(i)
            est_of_case[j] = lst.estimates[i]
    res["estimates_received"] = len(lst.estimates)
    res["statuses_received"] = len(lst.inertia)
    res["estimates_missing"] = n_cases - len(est_of_case)
    wrong = [(j, true_j1[j], est_of_case[j][1]) for j in est_of_case
             if abs(est_of_case[j][1] - true_j1[j]) / true_j1[j] > TOL]
    res["estimates_wrong"] = len(wrong)
    res["estimates_wrong_examples"] = wrong[:5]
    errs = [abs(est_of_case[j][1] - true_j1[j]) / true_j1[j] * 100 for j in est_of_case]
    res["estimate_error_percent_max"] = max(errs) if errs else None
    res["estimate_sources"] = sorted({v.get("estimate_source", "?") for _, v, _ in status_of_case.values()})
    # cross-check against the simulator's drive/case messages
    sim_cases = [(round(r[0]), r[1], r[4]) for r in lst.cases]
    res["drive_case_messages"] = len(sim_cases)
    res["drive_case_consistent"] = all(any(abs(et - entry_t[j]) < ts / 2 and jj == true_j1[j]
                                           for j in range(idx0, n_cases, args.cases))
                                       for idx0, jj, et in sim_cases)
    # ---------------------------------------------------------------- latency
    lat, lat_bw, lat_we = [], [], []
    for j in sorted(est_of_case):
        rb = lst.batch_holding(last_idx[j])
        if rb is None:
            continue
        lat.append((est_of_case[j][0] - rb) * 1e3)
        if j in win_of_case:
            lat_bw.append((win_of_case[j] - rb) * 1e3)
            lat_we.append((est_of_case[j][0] - win_of_case[j]) * 1e3)
    node_lat = [float(v[1]["estimate_latency_ms"]) for v in status_of_case.values() if "estimate_latency_ms" in v[1]]
    node_proc = [float(v[1]["processing_ms"]) for v in status_of_case.values() if "processing_ms" in v[1]]
    res["latency_ms"] = {"median": med(lat), "p90": pct(lat, 90), "max": max(lat) if lat else None,
                         "last": lat[-1] if lat else None, "n": len(lat)}
    res["latency_batch_to_window_ms"] = {"median": med(lat_bw), "p90": pct(lat_bw, 90)}
    res["latency_window_to_estimate_ms"] = {"median": med(lat_we), "p90": pct(lat_we, 90)}
    res["node_estimate_latency_ms"] = {"median": med(node_lat), "p90": pct(node_lat, 90)}
    res["node_processing_ms"] = {"median": med(node_proc), "p90": pct(node_proc, 90)}
    # ---------------------------------------------------------------- speed
    if len(lst.batch_recv) >= 2:
        span_drive = (lst.batch_last[-1] - lst.batch_last[0]) * ts
        res["stream_rate"] = span_drive / (lst.batch_recv[-1] - lst.batch_recv[0])
        res["stream_wall_s"] = lst.batch_recv[-1] - lst.batch_recv[0]
        if rtf > 0:  # receipt at the bench against the simulator's schedule (drive clock / rtf), best batch = 0
            off = np.array(lst.batch_recv) - np.array(lst.batch_last) * ts / rtf
            off = (off - off.min()) * 1e3
            res["signals_receipt_lag_ms"] = {"median": float(np.median(off)), "p90": pct(off, 90), "max": float(off.max())}
    else:
        res["stream_rate"] = None
    if est_of_case and lst.batch_recv:
        t_last = max(e[0] for e in est_of_case.values())
        res["end_to_end_rate"] = drive_s / (t_last - lst.batch_recv[0] + BATCH * ts / (rtf or res["stream_rate"] or 1))
    else:
        res["end_to_end_rate"] = None
    lossless = (res["samples_lost"] == 0 and res["samples_duplicated"] == 0 and res["discontinuities"] == 0
                and res["windows_lost"] == 0 and res["windowing_drop_events"] == 0)
    correct = res["estimates_missing"] == 0 and res["estimates_wrong"] == 0
    paced = rtf == 0 or (res["stream_rate"] or 0) >= 0.95 * rtf
    kept_up = bool(res["end_to_end_rate"] and res["stream_rate"] and res["end_to_end_rate"] >= 0.9 * res["stream_rate"]
                   and res["latency_ms"]["p90"] is not None and res["latency_ms"]["p90"] <= BACKLOG_MS)
    res.update(lossless=lossless, correct=correct, paced=paced, kept_up=kept_up,
               sustained=lossless and correct and paced and kept_up and not res["timed_out"] and not res["died"])
    res["wall_s"] = time.monotonic() - t_start
    return res


# --------------------------------------------------------------------------- report


def f(x, fmt="{:.1f}", none="–"):
    return none if x is None else fmt.format(x)


def label(rtf) -> str:
    return "max (0)" if rtf == 0 else f"{rtf:g}×"


def table(levels) -> str:
    rows = ["| rtf asked | stream rate | end-to-end rate | batches rx / exp | samples lost | windows rx / exp "
            "| estimates ok / exp | latency median / p90 / max [ms] | batch→window / window→estimate median [ms] "
            "| node est. latency / processing median [ms] | CPU sim / win / diag / bench [% of a core] "
            "| CPU per drive s sim / win / diag [ms] | sustained |",
            "|" + "---|" * 13]
    for r in levels:
        cpu = r.get("cpu", {})
        c = " / ".join(f((cpu.get(n) or {}).get("percent_of_one_core"), "{:.0f}")
                       for n in ("simulator", "windowing", "diagnostic", "bench"))
        per_drive = [(cpu.get(n) or {}).get("cpu_s_per_drive_s") for n in ("simulator", "windowing", "diagnostic")]
        cd = " / ".join(f(None if x is None else 1e3 * x, "{:.0f}") for x in per_drive)
        ok = r["cases"] - r["estimates_missing"] - r["estimates_wrong"]
        L = r["latency_ms"]
        why = [] if r["sustained"] else [w for w, bad in (
            ("loss", not r["lossless"]), ("estimates", not r["correct"]), ("pace", not r["paced"]),
            ("backlog", not r["kept_up"]), ("timeout", r["timed_out"]), ("died", bool(r["died"]))) if bad]
        rows.append(
            f"| {label(r['rtf'])} | {f(r['stream_rate'])}× | {f(r['end_to_end_rate'])}× "
            f"| {r['batches_received']} / {r['batches_expected']} | {r['samples_lost']} "
            f"| {r['windows_received']} / {r['windows_expected']} | {ok} / {r['cases']} "
            f"| {f(L['median'])} / {f(L['p90'])} / {f(L['max'])} "
            f"| {f(r['latency_batch_to_window_ms']['median'])} / {f(r['latency_window_to_estimate_ms']['median'])} "
            f"| {f(r['node_estimate_latency_ms']['median'])} / {f(r['node_processing_ms']['median'])} "
            f"| {c} | {cd} | {'yes' if r['sustained'] else 'no (' + ', '.join(why) + ')'} |")
    return "\n".join(rows)


def memory_table(levels) -> str:
    rows = ["| rtf asked | simulator VmHWM / VmRSS | windowing VmHWM / VmRSS | diagnostic VmHWM / VmRSS |",
            "|---|---|---|---|"]
    for r in levels:
        m = r["memory_mib"]
        cell = lambda n: f"{f(m.get(n, {}).get('VmHWM'), '{:.0f}')} / {f(m.get(n, {}).get('VmRSS'), '{:.0f}')} MiB"  # noqa: E731
        rows.append(f"| {label(r['rtf'])} | {cell('simulator')} | {cell('windowing')} "
                    f"| {cell('diagnostic')} |")
    return "\n".join(rows)


def targets(levels, limit=None) -> dict:
    ok_levels = [r for r in levels if r["sustained"] and r["rtf"] > 0]
    best = max([r["rtf"] for r in ok_levels] + ([limit["lossless_rtf"]] if limit and limit["lossless_rtf"] else []),
               default=None)
    bp = [r for r in levels if r["rtf"] == 0]
    bp_rate = max((r["end_to_end_rate"] or 0 for r in bp if r["lossless"] and r["correct"]), default=None)
    at = sorted([r for r in levels if r["rtf"] >= TARGET_LAT_RTF], key=lambda r: r["rtf"])
    lat_level = at[0] if at else None
    lat = lat_level["latency_ms"]["median"] if lat_level else None
    # the node in operation: the levels it sustained (an overloaded probe queues up to window_queue_depth windows
    # in its drive/window subscription by design; its peak is reported apart, as overloaded_mib)
    hwm = lambda r: r["memory_mib"].get("diagnostic", {}).get("VmHWM") or 0  # noqa: E731
    rss = max((hwm(r) for r in levels if r["sustained"]), default=None)
    rss_over = max((hwm(r) for r in levels if not r["sustained"]), default=None)
    return {
        "sustained_rtf": {"value": best, "target": f">= {TARGET_RTF:g}", "met": best is not None and best >= TARGET_RTF},
        "backpressured_rate": {"value": bp_rate, "target": f">= {TARGET_BP_RTF:g}",
                               "met": bp_rate is not None and bp_rate >= TARGET_BP_RTF},
        "latency_median_ms": {"value": lat, "at_rtf": lat_level["rtf"] if lat_level else None,
                              "target": f"<= {TARGET_LAT_MS:g} at >= {TARGET_LAT_RTF:g}x",
                              "met": lat is not None and lat <= TARGET_LAT_MS},
        "diagnostic_peak_rss_mib": {"value": rss, "target": f"<= {TARGET_RSS_MB:g}", "overloaded_mib": rss_over,
                                    "met": rss is not None and 0 < rss <= TARGET_RSS_MB},
    }


def find_limit(run, bounds, tol: float, max_probes: int) -> dict:
    """The highest rate factor the node set sustains (``run(rtf)["sustained"]``) between ``bounds`` = (lo, hi),
    by bisection on a log scale: lo is probed first (when it fails, the limit is below lo: reported as such),
    then hi (when it passes, the limit is at least hi), then the geometric mean of the bracket until
    hi / lo - 1 < ``tol`` or ``max_probes`` probes ran.  Returns {"lossless_rtf": the highest sustained factor
    probed (None: none), "failed_rtf": the lowest failing one above it (None: none), "probes": [(rtf,
    sustained, why-not)]}."""
    lo, hi = sorted(float(b) for b in bounds)
    if lo <= 0:
        raise ValueError("--bisect LO HI: both > 0 (rate 0 is the back-pressured level of --rtf)")
    probes = []

    def probe(rtf):
        r = run(rtf)
        why = [w for w, bad in (("loss", not r["lossless"]), ("estimates", not r["correct"]),
                                ("pace", not r["paced"]), ("backlog", not r["kept_up"]),
                                ("timeout", r["timed_out"]), ("died", bool(r["died"]))) if bad]
        probes.append((rtf, bool(r["sustained"]), why))
        return bool(r["sustained"])

    good = bad = None
    if probe(lo):
        good = lo
        if probe(hi):
            good = hi
        else:
            bad = hi
            while len(probes) < max_probes and bad / good - 1 > tol:
                mid = round(math.sqrt(good * bad), 1)
                if probe(mid):
                    good = mid
                else:
                    bad = mid
    else:
        bad = lo
    return {"lossless_rtf": good, "failed_rtf": bad, "probes": probes, "tolerance": tol}


def limit_line(limit: dict) -> str:
    good, bad = limit["lossless_rtf"], limit["failed_rtf"]
    probes = ", ".join(f"{r:g}× {'ok' if ok else 'no (' + ', '.join(why) + ')'}" for r, ok, why in limit["probes"])
    if good is None:
        head = f"highest lossless rate factor: below {bad:g}× (the lowest probe failed)"
    elif bad is None:
        head = f"highest lossless rate factor: at least {good:g}× (the highest probe passed)"
    else:
        head = f"highest lossless rate factor: {good:g}× (fails at {bad:g}×)"
    return f"{head}; probes: {probes}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=140,
                    help="grid cases per pass (the 7 J1 classes in turn; default 140 = 171 s of drive time)")
    ap.add_argument("--rtf", type=float, nargs="+", default=[10.0, 15.0, 20.0, 50.0, 0.0],
                    help="real-time factors to run, one fresh node set each (0 = as fast as possible)")
    ap.add_argument("--repeat", type=int, default=1, help="passes over the case list (simulator `repeat`)")
    ap.add_argument("--library", help="pattern library .npz (default: the CLI's cache, built when missing)")
    ap.add_argument("--executor", choices=("events", "single"), default="events",
                    help="executor of the bench's own node: rclpy.experimental.EventsExecutor (default) or "
                         "SingleThreadedExecutor")
    ap.add_argument("--no-sim-time", dest="sim_time", action="store_false",
                    help="run windowing and diagnostic without use_sim_time (no /clock subscription; profiling)")
    ap.add_argument("--fast-sleep", type=float, default=0.001,
                    help="simulator fast_sleep_s at rtf 0 (default 0.001; 0: only back-pressure paces the stream)")
    ap.add_argument("--max-lead", type=float, default=2.0,
                    help="simulator max_lead_s at rtf 0, drive s ahead of drive/progress (default 2; 0 = off)")
    ap.add_argument("--profile", metavar="DIR",
                    help="run every node under cProfile with a CPU-time clock (bench/cpu_profile.py; valid under load); "
                         "DIR/rtf<level>/<node>.prof (pstats); slower: not a result")
    ap.add_argument("--bisect", type=float, nargs=2, metavar=("LO", "HI"),
                    help="after the --rtf levels, find the highest sustained (lossless, every estimate right, paced, "
                         "no backlog) rate factor between LO and HI by bisection, a fresh node set per probe")
    ap.add_argument("--bisect-tol", type=float, default=0.05,
                    help="stop when HI/LO - 1 is below this (default 0.05)")
    ap.add_argument("--bisect-max", type=int, default=8, help="at most this many probes (default 8)")
    ap.add_argument("--out", help="write the results as JSON here")
    ap.add_argument("--logs", help="folder for the node logs (default: a temporary folder)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 7 cases, rtf 10 and 0 (not a result)")
    ap.add_argument("--check", action="store_true", help="exit status 1 when a target is missed")
    args = ap.parse_args(argv)
    if args.quick:
        args.cases, args.rtf, args.repeat = 7, [10.0, 0.0], 1
        if args.bisect:
            args.bisect_max = min(args.bisect_max, 2)
    if args.cases < 1 or args.repeat < 1 or any(r < 0 for r in args.rtf):
        ap.error("--cases and --repeat must be >= 1, --rtf >= 0")
    env = ros_environment()
    t0 = time.monotonic()
    mach = machine()
    print(f"machine: {mach['nproc']} cores ({mach['cpu_model']}), Python {mach['python']}, "
          f"rclpy {mach['versions'].get('rclpy', '?')}, {mach['rmw']}, ROS_DOMAIN_ID {os.environ['ROS_DOMAIN_ID']}, "
          f"load average {mach['load_average_start'][0]:.2f}", flush=True)
    print(f"code: commit {mach['commit']} ({mach['code_tree']})", flush=True)
    library, build_s = pattern_library(args.library)
    print(f"pattern library: {library}" + (f" (built in {build_s:.1f} s)" if build_s else " (cached)"), flush=True)
    logroot = Path(args.logs) if args.logs else Path(tempfile.mkdtemp(prefix="jident-bench-ros-"))
    levels = []

    def level(rtf):
        k = len(levels)
        print(f"--- real_time_factor {rtf:g}: {args.cases} cases x {args.repeat} pass(es) ...", flush=True)
        r = run_level(k, rtf, args, env, library, logroot)
        levels.append(r)
        print(f"    stream {f(r['stream_rate'])}x, end-to-end {f(r['end_to_end_rate'])}x, lost samples "
              f"{r['samples_lost']}, windows {r['windows_received']}/{r['windows_expected']}, estimates missing "
              f"{r['estimates_missing']} wrong {r['estimates_wrong']}, latency median {f(r['latency_ms']['median'])} ms, "
              f"diagnostic VmHWM {f(r['memory_mib'].get('diagnostic', {}).get('VmHWM'), '{:.0f}')} MiB, "
              f"{r['wall_s']:.1f} s, load {os.getloadavg()[0]:.2f}, sustained {'yes' if r['sustained'] else 'no'}",
              flush=True)
        return r

    for rtf in args.rtf:
        level(rtf)
    limit = find_limit(level, args.bisect, args.bisect_tol, args.bisect_max) if args.bisect else None
    tg = targets(levels, limit)
    total_s = time.monotonic() - t0
    print()
    print(table(levels))
    print()
    print(memory_table(levels))
    print()
    print("| target | measured | met |\n|---|---|---|")
    s, b, l, m = (tg[k] for k in ("sustained_rtf", "backpressured_rate", "latency_median_ms", "diagnostic_peak_rss_mib"))
    met = lambda t: "met" if t["met"] else "missed"  # noqa: E731
    print(f"| sustained real-time factor without back-pressure: no sample, window or estimate lost, every estimate "
          f"within 1 % | {f(s['value'], '{:g}×')} | {met(s)} (≥ {TARGET_RTF:g}×) |")
    print(f"| back-pressured (rate 0) end-to-end rate, lossless | {f(b['value'])}× | {met(b)} (≥ {TARGET_BP_RTF:g}×) |")
    print(f"| last sample of a window → inertia_estimate, median (at {f(l['at_rtf'], '{:g}×')}) | "
          f"{f(l['value'])} ms | {met(l)} (≤ {TARGET_LAT_MS:g} ms at ≥ {TARGET_LAT_RTF:g}×) |")
    print(f"| diagnostic node peak resident memory (VmHWM) at the sustained levels | {f(m['value'], '{:.0f}')} MiB"
          f" (overloaded levels: {f(m['overloaded_mib'], '{:.0f}')} MiB) | {met(m)} (≤ {TARGET_RSS_MB:g} MiB) |")
    if limit is not None:
        print()
        print(limit_line(limit))
    print(f"measured on commit {mach['commit']}")
    print(f"bench run time {total_s:.0f} s, load average at end {os.getloadavg()[0]:.2f}; node logs in {logroot}")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"machine": mach, "args": vars(args), "library": str(library),
                                              "levels": levels, "targets": tg, "limit": limit,
                                              "run_time_s": total_s},
                                             indent=2, default=str))
    if args.check and not all(t["met"] for t in tg.values()):
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
