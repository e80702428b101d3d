"""The ROS 2 nodes: simulator -> windowing -> diagnostic over DDS, replay, bad parameters, bad input.

Nodes run as separate processes (``python -m jident_ros.nodes.<x> --ros-args ...``) in the test run's
own ROS_DOMAIN_ID (conftest ``ros_env``), each test in its own namespace; the test talks to them
through an in-process rclpy node on its own Context.  The pattern library is built once per
session (1-2 s).  Timeouts are generous (process start-up is 1-3 s on a loaded 2-core machine).
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from jident_ros.resources import node_command, stop_process

REPO = Path(__file__).resolve().parents[1]
NODES = ("simulator", "windowing", "diagnostic", "replay")
TIMEOUT = 60.0  # per wait; a healthy run needs a few seconds


# --------------------------------------------------------------------------- without ROS


def test_nodes_yaml_matches_the_node_defaults():
    """config/nodes.yaml lists every parameter of every node with the node's built-in default."""
    import importlib
    doc = yaml.safe_load((REPO / "config" / "nodes.yaml").read_text())
    for name in NODES:
        mod = importlib.import_module(f"jident_ros.nodes.{name}")
        section = doc[f"/**/{mod.NODE_NAME}"]["ros__parameters"]
        assert section == mod.DEFAULTS, name


def test_interfaces_doc_names_every_parameter():
    import importlib
    doc = (REPO / "docs" / "interfaces.md").read_text()
    for name in NODES:
        mod = importlib.import_module(f"jident_ros.nodes.{name}")
        for p in mod.DEFAULTS:
            assert f"`{p}`" in doc, f"{name}: {p}"


def test_launch_file_compiles():
    import py_compile
    py_compile.compile(str(REPO / "launch" / "jident.launch.py"), doraise=True)


def test_the_core_and_ros_io_need_no_rclpy():
    """The node modules import rclpy at the top (their classes derive from Node); the core, the CLI's
    offline diagnosis and ros_io (used by the CLI) never do."""
    code = ("import sys, jident_ros.nodes.ros_io, jident_ros.nodes.params, jident_ros.parameters, "
            "jident_ros.stream.detector, jident_ros.identify.diagnosis, jident_ros.cli.offline; "
            "assert 'rclpy' not in sys.modules, 'rclpy imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert r.returncode == 0, r.stderr


# --------------------------------------------------------------------------- helpers


class Proc:
    """A node process with its output in a file."""

    def __init__(self, env, tmp: Path, node: str, *ros_args: str, args: tuple = ()):
        self.name = node
        self.log = tmp / f"{node}-{os.getpid()}-{time.monotonic_ns()}.log"
        self.out = open(self.log, "w")
        # found as `ros2 run jident_ros <node>` finds it: ament index prefix + lib/jident_ros/<node>
        cmd = node_command(node, require_index=os.environ.get("JIDENT_REQUIRE_ROS") == "1")
        self.p = subprocess.Popen([*cmd, *args, "--ros-args", *ros_args],
                                  env=env, cwd=tmp, stdout=self.out, stderr=subprocess.STDOUT)

    def text(self) -> str:
        if not self.out.closed:
            self.out.flush()
        return self.log.read_text()

    def alive(self) -> bool:
        return self.p.poll() is None

    def stop(self, sig=signal.SIGTERM, timeout=20.0) -> int:
        rc = stop_process(self.p, sig, timeout)
        self.out.close()
        return rc

    def wait(self, timeout=TIMEOUT) -> int:
        self.p.wait(timeout)
        return self.p.returncode


def logs(*procs) -> str:
    return "\n".join(f"--- {p.name} (rc {p.p.poll()}) ---\n{p.text()[-3000:]}" for p in procs)


def one_line_failures(env, tmp: Path, runs) -> list[str]:
    """Start every (node, ros args) of ``runs`` at once; each must stop with exit status 2 and one line
    of output (a bad parameter, a bad params file): those lines, in the order of ``runs``."""
    running = [Proc(env, tmp, node, *args) for node, args in runs]
    lines = []
    for proc in running:
        # all start at once: on a loaded 2-core machine their imports alone took over 60 s (a clean clone's CI
        # beside another job); a node that hangs instead of exiting still fails here
        rc = proc.wait(3 * TIMEOUT)
        out = proc.text().strip().splitlines()
        assert rc == 2 and len(out) == 1, logs(proc)
        lines.append(out[0])
    return lines


class Inbox(list):
    """Messages received on one subscription (``.sub``: the subscription)."""

    sub = None

    def matched(self) -> bool:
        return self.sub.get_publisher_count() >= 1


class Ros:
    """In-process test node on its own Context."""

    def __init__(self, name="jident_test"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node(name, context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def collect(self, msg_type, topic, qos) -> "Inbox":
        box = Inbox()
        box.sub = self.node.create_subscription(msg_type, topic, box.append, qos)
        return box

    def spin_until(self, pred, timeout=TIMEOUT) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred():
                return True
            self.ex.spin_once(timeout_sec=0.05)
        return pred()

    def close(self):
        import rclpy
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def statuses(arrays, name, hardware_id):
    """The statuses of one drive (hardware_id) whose name without the namespace is ``name``
    ("jident_diagnostic: inertia"; the full name is "<ns>/jident_diagnostic: inertia")."""
    from jident_ros.nodes.diagnostics import status_task
    return [s for a in arrays for s in a.status if status_task(s.name) == name and s.hardware_id == hardware_id]


@pytest.fixture(scope="session")
def node_env(ros_env):
    env = dict(ros_env)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


@pytest.fixture(scope="session")
def library(default_library_file):
    """Pattern library of the default configuration (conftest: built once per run)."""
    return default_library_file


@pytest.fixture
def ros(ros_env):
    r = Ros()
    yield r
    r.close()


@pytest.fixture
def procs():
    started = []
    yield started
    for p in started:
        p.stop()


# --------------------------------------------------------------------------- the pipeline


#: drive/signals batches of the pipeline's two cases: 400 pre-roll and 2048 window samples each, 50 per batch
PIPELINE_BATCHES = 2 * math.ceil((400 + 2048) / 50)


@pytest.fixture(scope="module")
def pipeline(ros_env, node_env, library, tmp_path_factory):
    """simulator -> windowing -> diagnostic (recording) on two cases, in namespace /e2e.

    Returns a dict with the estimates, statuses, cases, timings and the recording."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Float64MultiArray

    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, qos_signals
    tmp = tmp_path_factory.mktemp("e2e")
    bag = tmp / "bag"
    ns = ["-r", "__ns:=/e2e"]
    ros = Ros("jident_test_e2e")
    est = ros.collect(Float64, "/e2e/inertia_estimate", qos_latched(10))
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    cases = ros.collect(Float64MultiArray, "/e2e/drive/case", qos_latched(10))
    signals = ros.collect(Float64MultiArray, "/e2e/drive/signals", qos_signals())
    started = []
    try:
        diag = Proc(node_env, tmp, "diagnostic", *ns, "-p", f"pattern_library:={library}",
                    "-p", f"record_dir:={bag}", "-p", "use_sim_time:=true", "-p", "stale_after_s:=0.0")
        win = Proc(node_env, tmp, "windowing", *ns, "-p", "backlash_width_m:=0.005", "-p", "use_sim_time:=true")
        started += [diag, win]
        # this test hears the diagnostic node from its first estimate on
        assert ros.spin_until(est.matched), logs(diag)
        t0 = time.monotonic()
        # 3 subscribers of drive/signals: the windowing node, the diagnostic node's recorder and this test
        sim = Proc(node_env, tmp, "simulator", *ns, "-p", "cases:=zip", "-p", "inertias_kgm2:=[1.16, 1.073]",
                   "-p", "backlash_widths_m:=[0.005]", "-p", "consistencies_pa_sn:=[0.0375]",
                   "-p", "real_time_factor:=0.0", "-p", "wait_for_subscribers:=3", "-p", "wait_timeout_s:=60.0")
        started.append(sim)
        ok = ros.spin_until(lambda: len(est) >= 2 or not (diag.alive() and win.alive()), 2 * TIMEOUT)
        elapsed = time.monotonic() - t0
        assert ok and len(est) >= 2, logs(sim, win, diag)
        assert sim.wait() == 0, logs(sim)
        ros.spin_until(lambda: len(statuses(diags, "jident_diagnostic: inertia", "/e2e/drive")) >= 2, 10)
        assert diag.alive() and win.alive(), logs(win, diag)
        rc_diag = diag.stop(signal.SIGTERM)
        rc_win = win.stop(signal.SIGINT)
        ros.spin_until(lambda: len(cases) >= 2, 10)
        # the simulator exits once its reliable readers acknowledged every batch (runtime.drain): what this test has
        # not yet taken waits in its reader's queue, and spinning takes it (counting before that read 34 of 98 on a
        # clean clone's run: batches still queued, not lost)
        ros.spin_until(lambda: len(signals) >= PIPELINE_BATCHES, 10)
        return dict(estimates=[m.data for m in est], diags=list(diags), cases=list(cases), elapsed=elapsed,
                    n_signals=len(signals),
                    bag=bag, rc=(rc_diag, rc_win), logs=logs(sim, win, diag))
    finally:
        for p in started:
            p.stop()
        ros.close()


@pytest.mark.ros
def test_pipeline_publishes_the_true_inertia(pipeline):
    """Two grid cases (eta_k = 0.0375, off the pattern runs) -> /inertia_estimate within 1 % of J1."""
    est = pipeline["estimates"]
    assert len(est) == 2, pipeline["logs"]
    for got, true in zip(est, (1.16, 1.073)):
        assert abs(got - true) / true < 0.01, (got, true)
    # time from starting the simulator process to the second estimate (2 cases, 2 x 1.2 s of drive time)
    assert pipeline["elapsed"] < 60.0
    print(f"two estimates {est} within {pipeline['elapsed']:.1f} s of starting the simulator")
    assert pipeline["rc"] == (0, 0), pipeline["logs"]


@pytest.mark.ros
def test_pipeline_back_pressure_from_the_windowing_node(pipeline):
    """At real_time_factor 0 the windowing node's drive/progress paces the simulator (it never had to give up)."""
    # (two cases are 2.45 drive seconds: past max_lead_s = 2 s the simulator needs the windowing node's progress)
    assert "back-pressure off" not in pipeline["logs"], pipeline["logs"]


@pytest.mark.ros
def test_pipeline_diagnostics(pipeline):
    from jident_ros.identify.levels import OK, WARN
    from jident_ros.nodes.ros_io import status_level, status_values
    sts = statuses(pipeline["diags"], "jident_diagnostic: inertia", "/e2e/drive")
    # the verdict (jident_ros.identify.verdict) on the paper-consistent default drive: the first window is the
    # nominal class by the gap and by the image method (eta_k = 0.0375, off the pattern runs): OK. The second
    # deviates (1.073): WARN.  (On the heavy-film profile the image method disagrees: test_offline.)
    assert [status_level(s) for s in sts] == [OK, WARN], [s.message for s in sts]
    assert "nominal class 1.16" in sts[0].message and "disagrees" not in sts[0].message, sts[0].message
    assert "deviates from the nominal" in sts[1].message, sts[1].message
    assert status_values(sts[0])["verdict_agree"] == "true"
    assert [status_values(s)["status"] for s in sts] == ["nominal", "deviating"]
    for s, true in zip(sts, (1.16, 1.073)):
        v = status_values(s)
        assert float(v["identified_class_kgm2"]) == true and v["estimate_source"] == "gap"
        lo, hi = map(float, v["gap_ci95_kgm2"].split())
        assert lo < float(v["gap_j1_kgm2"]) < hi
        for key in ("backlash_width_m", "p", "entry_time_s", "fused_class_kgm2", "fused_margin",
                    "j1.a1", "h.a1", "margin.v2", "h.m_el", "estimate_latency_ms", "image_class_kgm2", "image_margin"):
            assert key in v, key
        assert len(v["h.a1"].split()) == 7
        assert float(v["backlash_width_m"]) == 0.005 and float(v["p"]) == 2.0
        # the verdict: the gap's class, not between classes; the image vote agrees or not
        assert float(v["verdict_class_kgm2"]) == true and v["verdict_between_classes"] == "false"
        assert v["verdict_agree"] in ("true", "false")
        assert (v["verdict_agree"] == "true") == (float(v["image_class_kgm2"]) == true)
        # K2 from the relative angle at re-contact, within a sample's travel of the detector's 0.005 m
        width, width_std = float(v["backlash_width_estimate_m"]), float(v["backlash_width_estimate_std_m"])
        assert 0 < width_std < 0.0005 and abs(width - 0.005) < 0.0005, (width, width_std)
    # use_sim_time: the windows' statuses are stamped with the drive clock (simulation starts at t = 1 s);
    # the periodic task statuses (steady timer) may go out before the first /clock (stamp 0)
    arrays = [a for a in pipeline["diags"] if any(s.hardware_id == "/e2e/drive" and s.name == "e2e/jident_diagnostic: inertia"
                                                  for s in a.status)]
    stamps = [a.header.stamp.sec + 1e-9 * a.header.stamp.nanosec for a in arrays]
    assert all(1.0 < t < 10.0 for t in stamps), stamps
    # the windows' entry times are the simulator's
    entries = [float(status_values(s)["entry_time_s"]) for s in sts]
    published = [m.data[-1] for m in pipeline["cases"]]
    assert entries == pytest.approx(published, abs=1e-9)
    print("window -> inertia_estimate inside the diagnostic node [ms]:",
          [status_values(s)["estimate_latency_ms"] for s in sts])


@pytest.mark.ros
def test_pipeline_recording_holds_every_message(pipeline):
    recording = pytest.importorskip("jident_ros.bag.reader")
    counts = {}
    for m in recording.read_bag(pipeline["bag"]):
        counts[m.topic] = counts.get(m.topic, 0) + 1
    batches = PIPELINE_BATCHES
    # the recording first (the product's claim), then this test's own subscriber (DDS on the way to it): a failure
    # says which lost batches (stop 26: once, on an overloaded machine, this test's subscriber had 1 of 98)
    assert counts.get("/e2e/drive/signals") == batches, (counts, pipeline["n_signals"])
    assert pipeline["n_signals"] == batches, (counts, pipeline["n_signals"])  # nothing lost on the way to this test
    assert counts.get("/e2e/drive/window") == 2 and counts.get("/e2e/inertia_estimate") == 2, counts
    assert counts.get("/diagnostics", 0) >= 2 and counts.get("/e2e/drive/case") == 2, counts


@pytest.mark.ros
def test_replay_gives_the_same_estimates(pipeline, node_env, library, ros, procs, tmp_path):
    pytest.importorskip("jident_ros.bag.reader")
    from std_msgs.msg import Float64

    from jident_ros.nodes.ros_io import qos_latched
    est = ros.collect(Float64, "/rep/inertia_estimate", qos_latched(10))
    ns = ["-r", "__ns:=/rep"]
    procs.append(Proc(node_env, tmp_path, "diagnostic", *ns, "-p", f"pattern_library:={library}"))
    procs.append(Proc(node_env, tmp_path, "windowing", *ns))
    assert ros.spin_until(est.matched), logs(*procs)
    # 2 subscribers of drive/signals: the windowing node and the diagnostic node's recorder (on by default)
    rep = Proc(node_env, tmp_path, "replay", *ns, "-p", "rate:=0.0", "-p", "wait_for_subscribers:=2",
               args=(str(pipeline["bag"]),))
    procs.append(rep)
    assert ros.spin_until(lambda: len(est) >= 2), logs(*procs)
    assert rep.wait() == 0, logs(rep)
    assert [m.data for m in est] == pipeline["estimates"]  # same samples, same numbers
    assert "back-pressure off" not in rep.text(), logs(rep)  # paced by the windowing node's drive/progress


@pytest.mark.ros
def test_offline_diagnosis_gives_the_same_estimates(pipeline, library):
    """`jident diagnose` on the pipeline's recording: the windowing node's detector and the diagnostic
    node's diagnose_window, without ROS -> the live estimates exactly (live == replay == offline)."""
    pytest.importorskip("jident_ros.bag.reader")
    from jident_ros.cli.offline import diagnose_recording
    from jident_ros.nodes.ros_io import status_level
    result = diagnose_recording(pipeline["bag"], library_path=library)
    assert result.signals_topic == "/e2e/drive/signals" and not result.dropped
    assert result.estimates == pipeline["estimates"]  # same samples, same code, same numbers
    live = statuses(pipeline["diags"], "jident_diagnostic: inertia", "/e2e/drive")
    assert [w.diagnosis.message for w in result.windows] == [s.message for s in live]
    assert [w.diagnosis.level for w in result.windows] == [status_level(s) for s in live]
    assert [w.true_inertia_kgm2 for w in result.windows] == [1.16, 1.073]


# --------------------------------------------------------------------------- bad parameters


@pytest.mark.ros
def test_bad_parameters_stop_the_node_with_one_line(node_env, tmp_path):
    cases = [
        ("windowing", ["-p", "backlash_width_m:=-1.0"], "backlash_width_m", "-1.0"),
        ("windowing", ["-p", "load.wheel_radius_m:=0.0"], "load.wheel_radius_m", "0.0"),
        ("windowing", ["-p", "backlash_widht_m:=0.005"], "backlash_widht_m", "0.005"),
        ("windowing", ["-p", "channels:=[alpha1, torque]"], "channels", "torque"),
        ("simulator", ["-p", "real_time_factor:=-2.0"], "real_time_factor", "-2.0"),
        ("simulator", ["-p", "cases:=everything"], "cases", "everything"),
        ("simulator", ["-p", "batch_size:=fifty"], "batch_size", "fifty"),
        ("diagnostic", ["-p", "p:=4.0"], "p", "4.0"),
        ("diagnostic", ["-p", "method.wavelets.a1:=nowave"], "method.wavelets.a1", "nowave"),
        ("replay", ["-p", "rate:=1.0"], "bag", "''"),
    ]
    lines = one_line_failures(node_env, tmp_path, [(node, args) for node, args, _, _ in cases])
    for line, (_, _, name, value) in zip(lines, cases):
        assert f"parameter {name}:" in line and value in line, line


# --------------------------------------------------------------------------- bad input


def _good_stream(n_cases=1):
    from jident_ros.config import load_system_config
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    w = simulate_grid(load_system_config(), [Case(1.16, 0.005, 0.025)][:n_cases])
    return w, embed_windows(w, 600, start_time_s=1.0)


def _msg(arr, channels, dims=None, offset=0):
    from std_msgs.msg import MultiArrayDimension

    from jident_ros.nodes.ros_io import multiarray_from_array
    m = multiarray_from_array(arr, channels)
    if dims is not None:
        m.layout.dim = [MultiArrayDimension(label=a, size=b, stride=c) for a, b, c in dims]
        m.layout.data_offset = offset
    return m


@pytest.mark.ros
def test_bad_messages_are_reported_and_the_windowing_node_keeps_running(node_env, ros, procs, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    from jident_ros.identify.levels import WARN
    from jident_ros.nodes.ros_io import (
        qos_diagnostics,
        qos_latched,
        qos_signals,
        status_level,
        status_values,
        window_from_msg,
    )
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    sim, (stream, rows) = _good_stream()
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    windows = ros.collect(Float64MultiArray, "/bad/drive/window", qos_latched(10))
    pub = ros.node.create_publisher(Float64MultiArray, "/bad/drive/signals", qos_signals())
    win = Proc(node_env, tmp_path, "windowing", "-r", "__ns:=/bad", "-p", "diagnostics_period_s:=0.0")
    procs.append(win)
    # the node's subscription matched ours, and its /diagnostics publisher is known to us
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1 and
                          ros.node.count_publishers("/diagnostics") >= 1), logs(win)
    ros.spin_until(lambda: False, 0.5)
    ch = list(DEFAULT_CHANNELS)
    b = stream[:50].copy()
    t = lambda k: stream[k:k + 50].copy()  # noqa: E731
    nan = t(50); nan[7, ch.index("m_el")] = np.nan  # noqa: E702
    inf = t(100); inf[3, ch.index("alpha2")] = np.inf  # noqa: E702
    ooo = t(150); ooo[10, 0] = ooo[9, 0] - 1e-4  # noqa: E702
    rep = t(200); rep[10, 0] = rep[9, 0]  # noqa: E702
    k = ch.index("m_el")
    bad = [
        ("layout", _msg(b, ch, dims=[("sample", 50, 450)])),
        ("layout", _msg(b, ch, dims=[("sample", 50, 450), ("t,alpha1", 2, 2)])),
        ("nonfinite", _msg(nan, ch)),
        ("nonfinite", _msg(inf, ch)),
        ("empty", _msg(np.empty((0, 9)), ch)),
        ("out_of_order", _msg(ooo, ch)),
        ("repeated_stamp", _msg(rep, ch)),
        (None, _msg(t(250), ch)), ("gap", _msg(t(310), ch)),  # 10 samples missing between the two
        ("missing_channel", _msg(np.delete(t(400), k, axis=1), ch[:k] + ch[k + 1:])),
        ("unknown_channel", _msg(np.column_stack([t(450), np.zeros(50)]), ch + ["foo"])),
    ]
    for _, m in bad:
        pub.publish(m)
    want = [r for r, _ in bad if r]
    reported = lambda: [status_values(s).get("reason") for s in statuses(diags, "jident_windowing: windows", "/bad/drive")]  # noqa: E731
    assert ros.spin_until(lambda: len(reported()) >= len(want)), (reported(), logs(win))
    assert reported() == want
    sts = statuses(diags, "jident_windowing: windows", "/bad/drive")
    assert all(status_level(s) == WARN for s in sts)
    assert status_values(sts[-1])["dropped.layout"] == "2"
    assert win.alive(), logs(win)
    # the node goes on: a good stream gives its window
    for s in range(0, len(stream), 50):
        pub.publish(_msg(stream[s:s + 50], ch))
    assert ros.spin_until(lambda: len(windows) >= 1), logs(win)
    w = window_from_msg(windows[0])
    np.testing.assert_array_equal(w.column("m_el"), sim.signals["m_el"][0])
    assert w.entry_time_s == stream[rows[0], 0] and w.window_id == 1
    assert win.alive()
    assert win.stop(signal.SIGTERM, timeout=10.0) == 0, logs(win)  # clean exit on SIGTERM


def damaged_libraries(library, tmp_path) -> dict:
    """Damaged copies of a good library: {name: (path, what the error must say)}."""
    import zipfile

    from jident_ros.method.patterns import PatternLibrary
    raw = library.read_bytes()
    out = {}
    p = tmp_path / "truncated.npz"
    p.write_bytes(raw[: len(raw) // 2])
    out["truncated"] = (p, "unreadable")
    with zipfile.ZipFile(library) as z:
        info = z.getinfo("centres.npy")
    p = tmp_path / "badcrc.npz"
    data = bytearray(raw)
    k = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size // 2
    data[k] ^= 0xFF
    p.write_bytes(bytes(data))
    out["bad_crc"] = (p, "unreadable")
    p = tmp_path / "empty.npz"
    p.write_bytes(b"")
    out["empty"] = (p, "empty file")
    lib = PatternLibrary.load(library)
    h5 = lib.h5.copy()
    h5[0, 0, 0] = np.nan
    out["nan_h5"] = (PatternLibrary(lib.centres, h5, lib.ranges, lib.p_values, lib.widths_m, lib.classes_kgm2,
                                    lib.signals, lib.metadata).save(tmp_path / "nan.npz"), "non-finite")
    three = PatternLibrary(lib.centres[:, :, :, :3], lib.h5, lib.ranges[:, :, :3], lib.p_values, lib.widths_m,
                           lib.classes_kgm2, lib.signals, lib.metadata).save(tmp_path / "three.npz")
    out["3_of_7_rows"] = (three, "shape")
    three_classes = PatternLibrary(lib.centres[:, :, :, :3], lib.h5, lib.ranges[:, :, :3], lib.p_values,
                                   lib.widths_m, lib.classes_kgm2[:3], lib.signals,
                                   lib.metadata).save(tmp_path / "three_classes.npz")
    out["3_of_7_classes"] = (three_classes, "J1 classes")
    return out


def test_damaged_libraries_are_refused_with_the_file_and_the_problem(library, tmp_path):
    """load_pattern_library never raises: every damaged library is an error naming the file and the problem."""
    from jident_ros.config import load_method_config, load_system_config
    from jident_ros.identify.library import load_pattern_library
    system, method = load_system_config(), load_method_config()
    for name, (path, what) in damaged_libraries(library, tmp_path).items():
        lib, error = load_pattern_library(path, system, method, build_if_missing=False)
        assert lib is None and error, name
        assert str(path) in error and what in error, (name, error)
        assert "\n" not in error


def test_jident_diagnose_with_a_damaged_library_says_it_in_one_line(library, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for name, (path, what) in list(damaged_libraries(library, tmp_path).items())[:2]:
        r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "diagnose", str(tmp_path), "--library", str(path)],
                           capture_output=True, text=True, timeout=120, env=env)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, (name, r.stderr)
        assert str(path) in lines[0] and what in lines[0], (name, lines[0])


@pytest.mark.ros
def test_diagnostic_with_a_bad_or_missing_library_reports_error_and_keeps_running(node_env, library, ros, procs,
                                                                                   tmp_path):
    """Mismatched, missing and damaged libraries (truncated zip, bad CRC, empty file, NaN h5, 3 of 7 class
    rows): an ERROR "jident_diagnostic: library" status naming the file and the problem, once a second; the
    node keeps running and publishes the gap estimate of a window (its window status ERROR)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Float64MultiArray

    from jident_ros.identify.levels import ERROR, STALE
    from jident_ros.method.patterns import PatternLibrary
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_level, status_values, window_to_msg
    from jident_ros.stream.detector import BacklashDetector
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    lib = PatternLibrary.load(library)
    lib.metadata = dict(lib.metadata, system=dict(lib.metadata["system"], load=dict(
        lib.metadata["system"]["load"], wheel_radius_m=0.2)), system_hash="0" * 64)
    other = lib.save(tmp_path / "other.npz")
    cases = {"mis": (other, "wheel_radius_m"), "gone": (tmp_path / "no.npz", "missing")}
    cases.update({"lib_" + k: v for k, v in damaged_libraries(library, tmp_path).items()})
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    est = {ns: ros.collect(Float64, f"/{ns}/inertia_estimate", qos_latched(10)) for ns in cases}
    pubs = {ns: ros.node.create_publisher(Float64MultiArray, f"/{ns}/drive/window", qos_latched(10)) for ns in cases}
    running = {ns: Proc(node_env, tmp_path, "diagnostic", "-r", f"__ns:=/{ns}", "-p", f"pattern_library:={path}",
                        "-p", "build_if_missing:=false", "-p", "stale_after_s:=1.0") for ns, (path, _) in cases.items()}
    procs += list(running.values())
    task = "jident_diagnostic: library"
    levels = lambda ns, name: {status_level(s) for s in statuses(diags, name, f"/{ns}/drive")}  # noqa: E731
    # the library error is repeated once a second, so a status published before we matched is no loss
    assert ros.spin_until(lambda: all(ERROR in levels(ns, task) for ns in cases)), logs(*running.values())
    assert ros.spin_until(lambda: STALE in levels("gone", "jident_diagnostic: diagnosis"))
    for ns, (path, what) in cases.items():
        first = statuses(diags, task, f"/{ns}/drive")[0]
        assert status_level(first) == ERROR and what in first.message, (ns, first.message)
        assert path.name in first.message, (ns, first.message)
    assert sum("wheel_radius_m" in line for line in running["mis"].text().splitlines()) == 1  # one log line
    # a window still gets its gap estimate, flagged ERROR because the library is unusable
    sim, (stream, rows) = _good_stream()
    det = BacklashDetector(0.005, 0.1, 5e-4)
    (ev,) = det.push(stream, DEFAULT_CHANNELS)
    assert ros.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()))
    for p in pubs.values():
        p.publish(window_to_msg(ev.window))
    assert ros.spin_until(lambda: all(est.values())), logs(*running.values())
    for ns in cases:
        assert ros.spin_until(lambda: any("estimate_source" in status_values(s)
                                          for s in statuses(diags, "jident_diagnostic: inertia", f"/{ns}/drive")))
        (s,) = [s for s in statuses(diags, "jident_diagnostic: inertia", f"/{ns}/drive") if "estimate_source" in status_values(s)]
        assert status_level(s) == ERROR and abs(est[ns][0].data - 1.16) < 0.01, (ns, s.message)
        assert status_values(s)["estimate_source"] == "gap"
    for ns, p in running.items():
        assert p.alive() and "Traceback" not in p.text(), logs(p)


@pytest.mark.ros
def test_simulator_back_pressure_waits_for_drive_progress(node_env, ros, procs, tmp_path):
    """real_time_factor 0: the simulator runs at most max_lead_s drive seconds ahead of drive/progress, goes on
    when progress comes, and without any progress gives up waiting after progress_timeout_s (warning)."""
    from std_msgs.msg import Float64, Float64MultiArray

    from jident_ros.nodes.ros_io import array_from_multiarray, qos_signals
    signals = ros.collect(Float64MultiArray, "/bp/drive/signals", qos_signals())
    progress = ros.node.create_publisher(Float64, "/bp/drive/progress", qos_signals(10))
    last_t = lambda: max((array_from_multiarray(m)[0][-1, 0] for m in signals), default=-1.0)  # noqa: E731
    common = ["-p", "cases:=zip", "-p", "inertias_kgm2:=[1.16]", "-p", "real_time_factor:=0.0",
              "-p", "wait_for_subscribers:=1", "-p", 'wait_for_node:=""',   # the subscriber is this test
              "-p", "publish_clock:=false", "-p", "start_time_s:=1.0"]
    sim = Proc(node_env, tmp_path, "simulator", "-r", "__ns:=/bp", *common,
               "-p", "max_lead_s:=0.5", "-p", "progress_timeout_s:=30.0")
    procs.append(sim)
    assert ros.spin_until(lambda: len(signals) >= 5, TIMEOUT), logs(sim)
    ros.spin_until(lambda: False, 1.5)              # no progress: the stream must stop at 1.0 + 0.5 s
    held = last_t()
    assert 1.4 < held <= 1.5 + 0.025 + 1e-9, (held, logs(sim))
    assert sim.alive()
    n_expected = math.ceil((400 + 2048 + 0) / 50)   # gap_samples + one window, 50-sample batches
    # progress as a windowing node would report it: the stream goes on to the end
    end = time.monotonic() + TIMEOUT
    while time.monotonic() < end and sim.alive():
        progress.publish(Float64(data=float(last_t())))
        ros.ex.spin_once(timeout_sec=0.02)
    assert sim.wait() == 0, logs(sim)
    ros.spin_until(lambda: len(signals) >= n_expected, 10)
    assert len(signals) == n_expected, (len(signals), logs(sim))
    assert "back-pressure" in sim.text() and "waited" in sim.text(), logs(sim)

    # nobody reports progress: after progress_timeout_s the simulator streams on (and says so)
    signals.clear()
    sim2 = Proc(node_env, tmp_path, "simulator", "-r", "__ns:=/bp", *common,
                "-p", "max_lead_s:=0.2", "-p", "progress_timeout_s:=0.5")
    procs.append(sim2)
    assert ros.spin_until(lambda: not sim2.alive(), TIMEOUT), logs(sim2)
    assert sim2.wait() == 0, logs(sim2)
    ros.spin_until(lambda: len(signals) >= n_expected, 10)
    assert len(signals) == n_expected and "back-pressure off" in sim2.text(), logs(sim2)


@pytest.mark.ros
def test_a_late_subscriber_gets_every_case_k2_and_j1(node_env, ros, procs, tmp_path):
    """A recorder whose drive/backlash_width subscription is matched after case 2 began (a loaded machine: the
    demo's recording held case 2's K2 alone, and its replay diagnosed case 1 with it) still receives every case's
    K2 and true J1, in order: the simulator keeps them as it keeps drive/case (keep last n_cases)."""
    from std_msgs.msg import Float64, Float64MultiArray

    from jident_ros.nodes.ros_io import array_from_multiarray, qos_latched, qos_signals
    signals = ros.collect(Float64MultiArray, "/late/drive/signals", qos_signals())
    sim = Proc(node_env, tmp_path, "simulator", "-r", "__ns:=/late", "-p", "cases:=zip",
               "-p", "inertias_kgm2:=[1.16, 1.073, 1.189]", "-p", "backlash_widths_m:=[0.005, 0.0025, 0.0075]",
               "-p", "consistencies_pa_sn:=[0.0375, 0.0375, 0.0375]", "-p", "real_time_factor:=1.0",
               "-p", "wait_for_subscribers:=1", "-p", 'wait_for_node:=""', "-p", "publish_clock:=false")
    procs.append(sim)
    last_t = lambda: max((array_from_multiarray(m)[0][-1, 0] for m in signals), default=-1.0)  # noqa: E731
    assert ros.spin_until(lambda: last_t() > 2.5, TIMEOUT), logs(sim)         # case 3 has begun
    widths = ros.collect(Float64, "/late/drive/backlash_width", qos_latched(100))
    inertias = ros.collect(Float64, "/late/drive/true_inertia", qos_latched(100))
    ros.spin_until(lambda: len(widths) >= 3 and len(inertias) >= 3, 20)
    assert [m.data for m in widths] == [0.005, 0.0025, 0.0075], logs(sim)
    assert [m.data for m in inertias] == [1.16, 1.073, 1.189], logs(sim)
