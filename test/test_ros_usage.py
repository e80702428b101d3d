"""ROS 2 as its users run it (issue 22): launch-written params files, replay = live, foreign bags, stamped
estimates, aggregator names, recorded QoS, best-effort input.  The tests without ``ros`` need no rclpy."""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
import yaml
from test_nodes import Proc, logs, node_env, ros  # noqa: F401

from jident_ros.nodes.params import ParameterError
from jident_ros.nodes.runtime import check_params_files, load_params_file

REPO = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------- params files written by launch
def launch_params_file(tmp_path: Path, node_name: str, params: dict) -> Path:
    """A params file written exactly as launch_ros (jazzy, launch_ros/actions/node.py
    ``Node._create_params_file_from_dict``) writes one: ``yaml.dump`` of ``{node: {'ros__parameters':
    params}}``, default_flow_style=False; launch_ros' parameter evaluation turns list values into tuples."""
    path = tmp_path / f"launch_params_{node_name.strip('/').replace('/', '_')}"
    with open(path, "w") as h:
        yaml.dump({node_name: {"ros__parameters": params}}, h, default_flow_style=False)
    return path


def test_launch_written_params_file_is_accepted(tmp_path):
    path = launch_params_file(tmp_path, "/press3/jident_simulator",
                              {"inertias_kgm2": (1.16, 1.073), "channels": ("alpha1", "t"), "repeat": 1})
    assert "!!python/tuple" in path.read_text()          # what safe_load refused
    with pytest.raises(yaml.YAMLError):
        yaml.safe_load(path.read_text())
    check_params_files(["x", "--ros-args", "--params-file", str(path)])      # no ParameterError
    doc = load_params_file(path.read_text())
    assert doc["/press3/jident_simulator"]["ros__parameters"] == {
        "inertias_kgm2": [1.16, 1.073], "channels": ["alpha1", "t"], "repeat": 1}


def test_params_file_tags_never_construct_objects(tmp_path):
    """Any other python/ tag is read by its node kind (as rcl does), never run."""
    text = ("/**:\n  ros__parameters:\n    a: !!python/object/apply:os.system ['echo hi']\n"
            "    b: !!python/name:os.system ''\n    c: !custom 3\n")
    doc = load_params_file(text)["/**"]["ros__parameters"]
    assert doc == {"a": ["echo hi"], "b": "", "c": "3"}


def test_bad_params_files_still_give_one_line(tmp_path):
    (tmp_path / "bad.yaml").write_text("a: [1, 2\n")
    (tmp_path / "plain.yaml").write_text("backlash_width_m: 0.005\n")
    for name, text in (("bad.yaml", "not YAML"), ("plain.yaml", "not a ROS 2 params file")):
        with pytest.raises(ParameterError, match=text):
            check_params_files(["--params-file", str(tmp_path / name)])


@pytest.mark.ros
def test_node_starts_with_a_launch_written_params_file(node_env, tmp_path):  # noqa: F811
    """rcl reads the tuple as an array: the simulator runs its one case and stops waiting for its
    windowing node (exit 1 with the reason), not exit 2 on the params file."""
    ns = f"/lp{os.getpid()}"
    path = launch_params_file(tmp_path, f"{ns}/jident_simulator",
                              {"inertias_kgm2": (1.16,), "wait_timeout_s": 2.0, "publish_clock": False})
    p = Proc(node_env, tmp_path, "simulator", "-r", f"__ns:={ns}", "--params-file", str(path))
    rc = p.wait()
    assert rc == 1 and "no subscription" in p.text() and "params-file" not in p.text(), logs(p)


@pytest.mark.ros
@pytest.mark.parametrize("delay_s", [0.3, 1.5])
def test_sigint_while_a_node_is_starting_ends_quietly(node_env, tmp_path, delay_s):  # noqa: F811
    """launch stops every node with SIGINT as soon as one exits, also a node still importing: status 0 and
    no KeyboardInterrupt traceback (jident_ros/nodes/entry.py), whenever the signal comes."""
    import signal
    import time

    p = Proc(node_env, tmp_path, "diagnostic", "-p", "record:=false")
    time.sleep(delay_s)
    p.p.send_signal(signal.SIGINT)
    rc = p.wait()
    assert rc == 0 and "Traceback" not in p.text() and "KeyboardInterrupt" not in p.text(), logs(p)


# --------------------------------------------------------------------------- replay = live
def write_two_k2_recording(bag_dir: Path, misordered: bool) -> Path:
    """Two cases with different K2 as the diagnostic node records them.  ``misordered``: case 2's
    drive/backlash_width (and case row) is *received* before the batches that hold case 1's entry -- the
    race of the demo recording -- but carries the publish time the drive sent it at (after case 1's batches)."""
    import numpy as np

    from jident_ros.bag.writer import BagWriter
    from jident_ros.cli.offline import multiarray_message
    from jident_ros.config import load_system_config
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import CASE_LABEL, DEFAULT_CHANNELS

    cases = [Case(1.16, 0.0075, 0.025), Case(1.073, 0.01, 0.025)]
    ws = simulate_grid(load_system_config(), cases)
    gap = 400
    stream, entry_rows = embed_windows(ws, gap, 1.0, DEFAULT_CHANNELS)
    per, batch = gap + len(ws.t), 50
    ns = lambda t: int(round(t * 1e9))  # noqa: E731
    items = []          # (log time, publish time, topic, message)
    for i, c in enumerate(cases):
        t_pub = ns(stream[i * per, 0] - 0.5 * ws.sample_period_s)
        row = np.array([[i, c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn, stream[entry_rows[i], 0]]])
        t_log = ns(stream[entry_rows[0] - 100, 0]) if (misordered and i == 1) else t_pub
        items += [(t_log, t_pub, "/m/drive/backlash_width", {"data": c.backlash_width_m}),
                  (t_log, t_pub, "/m/drive/case", multiarray_message(row, CASE_LABEL.split(",")))]
        for s in range(i * per, (i + 1) * per, batch):
            b = stream[s:min(s + batch, (i + 1) * per)]
            items.append((ns(b[-1, 0]) + 1000, ns(b[-1, 0]), "/m/drive/signals", multiarray_message(b, DEFAULT_CHANNELS)))
    with BagWriter(bag_dir) as bag:
        bag.add_topic("/m/drive/signals", "std_msgs/msg/Float64MultiArray")
        bag.add_topic("/m/drive/backlash_width", "std_msgs/msg/Float64", qos="transient_local")
        bag.add_topic("/m/drive/case", "std_msgs/msg/Float64MultiArray", qos="transient_local")
        for t_log, t_pub, topic, msg in sorted(items, key=lambda x: x[0]):
            bag.write(topic, msg, t_log, t_pub)
    return bag_dir


def _windows(path):
    from jident_ros.cli.offline import diagnose_recording
    r = diagnose_recording(path, image_method=False)
    return [(w.window_id, w.entry_time_s, w.backlash_width_m, w.inertia_kgm2) for w in r.windows]


@pytest.mark.parametrize("executor", ["events", "single"])
@pytest.mark.parametrize("raw", [False, True])
def test_message_info_callbacks_work_on_both_executors(ros_env, executor, raw):
    """issue 25: the diagnostic node spins rclpy's EventsExecutor, which (rclpy 9.1) calls a callback with message
    info as cb((msg, info)) where SingleThreadedExecutor calls cb(msg, info): WithMessageInfo takes both, so the
    recorder still gets each message's source timestamp (the recorded publish time, replay = live)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from std_msgs.msg import Float64

    from jident_ros.nodes.ros_io import WithMessageInfo, qos_latched
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node(f"jident_info_{executor}_{int(raw)}", context=ctx)
        got = []
        node.create_subscription(Float64, "info_test", WithMessageInfo(lambda m, i: got.append((m, i))),
                                 qos_latched(), raw=raw)
        pub = node.create_publisher(Float64, "info_test", qos_latched())
        ex = EventsExecutor(context=ctx) if executor == "events" else SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        end = time.monotonic() + 10.0
        while len(got) < 2 and time.monotonic() < end:
            pub.publish(Float64(data=2.5))
            ex.spin_once(timeout_sec=0.05)
        assert len(got) >= 2
        msg, info = got[0]
        assert (isinstance(msg, bytes) if raw else msg.data == 2.5)
        assert info["source_timestamp"] > 0 and info["received_timestamp"] >= info["source_timestamp"]
        ex.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_k2_message_received_early_is_applied_in_publish_order(tmp_path):
    from jident_ros.bag.reader import in_publish_order, read_bag
    bad = write_two_k2_recording(tmp_path / "bad", misordered=True)
    good = write_two_k2_recording(tmp_path / "good", misordered=False)
    # the bag really holds the race: case 2's K2 logged before the batches of case 1's entry
    topics = [m.topic for m in read_bag(bad, raw=True)]
    first_k2 = [i for i, t in enumerate(topics) if t.endswith("backlash_width")]
    assert first_k2[1] < len(topics) // 4
    assert [m.topic for m in in_publish_order(read_bag(bad, raw=True))] == \
        [m.topic for m in read_bag(good, raw=True)]
    live = _windows(good)
    assert [w[2] for w in live] == [0.0075, 0.01] and all(w[3] is not None for w in live)
    assert _windows(bad) == live                            # bit for bit: same entries, K2 and J1


def test_in_publish_order_holds_back_no_longer_than_its_horizon():
    from jident_ros.bag.reader import BagMessage, in_publish_order
    msgs = [BagMessage("a", "", 10, b"", 10), BagMessage("k2", "", 11, b"", 30), BagMessage("b", "", 20, b"", 20),
            BagMessage("c", "", 40, b"", 40), BagMessage("d", "", 100, b"", 100)]
    out = in_publish_order(iter(msgs), horizon_ns=15)
    assert [m.topic for m in out] == ["a", "b", "k2", "c", "d"]
    assert [m.topic for m in in_publish_order(msgs[:1])] == ["a"] and msgs[0].publish_time_ns == 10
    assert BagMessage("x", "", 5, b"").publish_time_ns == 5     # no publish time: the receive time


def live_windows(recording) -> list:
    """(window_id, entry t, K2, J1) as the live nodes gave them: the recorded drive/window headers and the
    recorded inertia_estimate values (one per diagnosed window, in order)."""
    from jident_ros.bag.reader import read_bag
    from jident_ros.stream.layout import Window

    wins, estimates = [], []
    for m in read_bag(recording):
        if m.topic.endswith("drive/window"):
            w = Window.unpack(m.message.data, m.message.layout.dim, m.message.layout.data_offset)
            wins.append((int(w.window_id), float(w.entry_time_s), float(w.backlash_width_m)))
        elif m.topic.endswith("/inertia_estimate"):
            estimates.append(float(m.message.data))
    assert len(estimates) == len(wins), (wins, estimates)
    return [w + (j,) for w, j in zip(wins, estimates)]


def assert_replay_equals_live(recording, n_windows: int) -> None:
    live = live_windows(recording)
    assert len(live) == n_windows, live
    assert _windows(recording) == live


@pytest.mark.ros
@pytest.mark.slow
def test_diagnose_on_the_demo_recording_equals_live(ros_env, tmp_path):
    """`jident demo` (five cases, four K2 changes) then `jident diagnose` on its recording: 5/5 windows with
    the entry time, K2 and J1 the live nodes gave."""
    import subprocess
    import sys
    env = dict(ros_env, JIDENT_CACHE_DIR=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "demo", "--out", str(tmp_path / "demo")], env=env,
                       cwd=tmp_path, capture_output=True, text=True, timeout=400)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert_replay_equals_live(tmp_path / "demo" / "recording", 5)


# --------------------------------------------------------------------------- foreign bags
#: A service-event schema as `ros2 bag record -a` writes one on Jazzy with service introspection on: the
#: .srv text (request --- response); rosbags cannot parse it ("Could not parse: ...").
SERVICE_EVENT_SCHEMA = """string[] names

---
ParameterValue[] values
================================================================================
MSG: rcl_interfaces/ParameterValue
uint8 type
float64 double_value
"""


def write_jointstate_bag(bag_dir: Path, with_service_events: bool) -> Path:
    """Two simulated backlash entries as sensor_msgs/JointState per sample on /arm/joint_states (+ a
    `_service_event` topic of a type nobody can parse, written before and between the samples)."""
    import numpy as np

    from jident_ros.bag.writer import BagWriter
    from jident_ros.config import load_system_config
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import DEFAULT_CHANNELS

    ws = simulate_grid(load_system_config(), [Case(1.16, 0.005, 0.025), Case(1.16, 0.005, 0.025)])
    stream, _ = embed_windows(ws, 400, 1.0, DEFAULT_CHANNELS)   # the second entry: data after the first window
    col = {c: i for i, c in enumerate(DEFAULT_CHANNELS)}
    with BagWriter(bag_dir) as bag:
        if with_service_events:
            bag.add_topic("/arm/sim/get_parameters/_service_event", "rcl_interfaces/srv/GetParameters_Event",
                          msgdef=SERVICE_EVENT_SCHEMA, type_hash="RIHS01_" + "0" * 64)
        bag.add_topic("/arm/joint_states", "sensor_msgs/msg/JointState")
        for k, row in enumerate(stream):
            t_ns = int(round(row[0] * 1e9))
            if with_service_events and k % 500 == 0:
                bag.write("/arm/sim/get_parameters/_service_event", b"\x00\x01\x00\x00" + bytes(12), t_ns)
            bag.write("/arm/joint_states", {
                "header": {"stamp": {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}, "frame_id": ""},
                "name": ["motor", "load"],
                "position": np.array([row[col["alpha1"]], row[col["alpha2"]]]),
                "velocity": np.array([row[col["omega1"]], row[col["omega2"]]]),
                "effort": np.array([row[col["m_el"]], np.nan])}, t_ns)
    return bag_dir


def test_a_bag_with_service_event_topics_is_diagnosed(tmp_path):
    from rosbags.highlevel import AnyReader

    from jident_ros.cli.offline import diagnose_samples
    foreign = write_jointstate_bag(tmp_path / "record_a", with_service_events=True)
    plain = write_jointstate_bag(tmp_path / "plain", with_service_events=False)
    with pytest.raises(Exception, match="Could not parse"):    # what failed before: rosbags' AnyReader
        AnyReader([foreign]).open()
    notes = []
    r = diagnose_samples(foreign, image_method=False, log=notes.append)
    skipped = [n for n in notes if "skipped" in n]
    assert len(skipped) == 1 and "/arm/sim/get_parameters/_service_event (rcl_interfaces/srv/GetParameters_Event)" \
        in skipped[0], notes
    ref = diagnose_samples(plain, image_method=False)
    got = [(w.entry_time_s, w.inertia_kgm2) for w in r.windows]
    assert len(got) >= 1 and got == [(w.entry_time_s, w.inertia_kgm2) for w in ref.windows]
    assert abs(got[0][1] - 1.16) < 0.05


def test_jident_diagnose_on_a_foreign_bag_says_one_line_and_exits_0(tmp_path):
    import subprocess
    import sys
    foreign = write_jointstate_bag(tmp_path / "record_a", with_service_events=True)
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "diagnose", str(foreign), "--no-image"],
                       capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "Traceback" not in out and "Could not parse" not in out
    assert sum("_service_event" in line for line in out.splitlines()) == 1, out


# --------------------------------------------------------------------------- status names, diagnostic_aggregator
class _GenericAnalyzer:
    """diagnostic_aggregator's GenericAnalyzer as far as naming goes (ros/diagnostics,
    generic_analyzer.cpp ``match``: regex_match / startswith / contains; generic_analyzer_base.hpp: items are
    kept in a map keyed by the status name)."""

    def __init__(self, path: str, cfg: dict):
        import re
        self.path = path
        self.regex = [re.compile(r) for r in cfg.get("regex", [])]
        self.startswith, self.contains = cfg.get("startswith", []), cfg.get("contains", [])
        self.items: dict = {}

    def match(self, name: str) -> bool:
        return (any(r.fullmatch(name) for r in self.regex) or any(name.startswith(s) for s in self.startswith)
                or any(c in name for c in self.contains))

    def analyze(self, status) -> None:
        self.items[status.name] = status


def aggregator(analyzers_yaml: Path) -> list:
    """The GenericAnalyzers of an analyzers file (AnalyzerGroups flattened, paths joined)."""
    doc = yaml.safe_load(analyzers_yaml.read_text())["analyzers"]["ros__parameters"]
    out = []

    def walk(section: dict, base: str):
        for key, cfg in section.items():
            if not isinstance(cfg, dict):
                continue
            path = f"{base}/{cfg['path']}"
            if cfg["type"] == "diagnostic_aggregator/AnalyzerGroup":
                walk(cfg["analyzers"], path)
            else:
                assert cfg["type"] == "diagnostic_aggregator/GenericAnalyzer", cfg["type"]
                out.append(_GenericAnalyzer(path, cfg))
    walk(doc, "/" + doc["path"])
    return out


def aggregate(analyzers: list, statuses) -> set:
    """The aggregator's output keys ("<analyzer path>/<status name>") of ``statuses``."""
    for s in statuses:
        for a in analyzers:
            if a.match(s.name):
                a.analyze(s)
    return {f"{a.path}/{name}" for a in analyzers for name in a.items}


class _FakeNode:
    def __init__(self, fqn):
        self.fqn = fqn

    def get_fully_qualified_name(self):
        return self.fqn


def test_status_names_carry_namespace_node_and_task():
    from jident_ros.nodes.diagnostics import status_name, status_task
    assert status_name(_FakeNode("/press3/jident_diagnostic"), "inertia") == "press3/jident_diagnostic: inertia"
    assert status_name(_FakeNode("/jident_windowing"), "rate") == "jident_windowing: rate"
    assert status_name(_FakeNode("/plant/a/jident_diagnostic"), "trend") == "plant/a/jident_diagnostic: trend"
    assert status_task("plant/a/jident_diagnostic: trend") == "jident_diagnostic: trend"
    assert status_task("jident_windowing: rate") == "jident_windowing: rate"


def test_analyzers_file_groups_every_status_of_every_drive():
    from types import SimpleNamespace as S

    from jident_ros.nodes.diagnostic import TASKS
    from jident_ros.nodes.diagnostics import status_name
    names = [status_name(_FakeNode(f"{ns}/jident_diagnostic"), t) for ns in ("/a", "/b", "") for t in ("inertia",) + TASKS]
    names += [status_name(_FakeNode(f"{ns}/jident_windowing"), t) for ns in ("/a", "/b", "") for t in ("rate", "windows")]
    keys = aggregate(aggregator(REPO / "config" / "analyzers.yaml"), [S(name=n) for n in names])
    assert len(keys) == len(names)                                  # each status: one item, none shared
    assert "/Aggregation/J1 identification/Inertia estimates/a/jident_diagnostic: inertia" in keys
    assert "/Aggregation/J1 identification/Windowing node/b/jident_windowing: rate" in keys
    assert not aggregate(aggregator(REPO / "config" / "analyzers.yaml"), [S(name="other_node: inertia")])


@pytest.mark.ros
def test_two_drives_in_two_namespaces_give_distinct_aggregator_keys(node_env, tmp_path, ros):  # noqa: F811
    """Two diagnostic nodes (namespaces /agg1, /agg2): their periodic statuses reach /diagnostics with names
    that differ by drive, and the shipped analyzers file keeps one aggregator item per drive and task."""
    from diagnostic_msgs.msg import DiagnosticArray

    from jident_ros.nodes.diagnostic import TASKS
    from jident_ros.nodes.ros_io import qos_diagnostics
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    procs = [Proc(node_env, tmp_path, "diagnostic", "-r", f"__ns:=/agg{k}", "-p", "record:=false",
                  "-p", "image_method:=false") for k in (1, 2)]
    try:
        def names():
            return {s.name for a in diags for s in a.status if s.hardware_id in ("/agg1/drive", "/agg2/drive")}
        want = {f"agg{k}/jident_diagnostic: {t}" for k in (1, 2) for t in TASKS}
        assert ros.spin_until(lambda: want <= names()), (names(), logs(*procs))
        statuses = [s for a in diags for s in a.status if s.name in want]
        keys = aggregate(aggregator(REPO / "config" / "analyzers.yaml"), statuses)
        for t in TASKS:
            drive_keys = {k for k in keys if k.endswith(f"jident_diagnostic: {t}")}
            assert drive_keys == {f"/Aggregation/J1 identification/Diagnostic node/agg{k}/jident_diagnostic: {t}"
                                  for k in (1, 2)}, keys
    finally:
        for p in procs:
            p.stop()


# --------------------------------------------------------------------------- stamped estimate
def test_drive_time_and_std_error_helpers():
    import math

    from jident_ros.nodes.estimate_out import drive_time, std_error_of
    assert drive_time(3.672) == (3, 672_000_000) and drive_time(-1.0) == (0, 0)
    assert drive_time(1.0000000004) == (1, 0) and drive_time(2.9999999996) == (3, 0)
    assert std_error_of([("gap_std_error_kgm2", 8e-5)]) == 8e-5
    assert math.isnan(std_error_of([("gap_std_error_kgm2", None)])) and math.isnan(std_error_of([]))


@pytest.mark.ros
def test_the_estimate_goes_out_stamped_with_its_window_and_uncertainty(node_env, tmp_path, ros):  # noqa: F811
    from geometry_msgs.msg import InertiaStamped
    from std_msgs.msg import Float64, Float64MultiArray
    from test_nodes import _good_stream

    from jident_ros.nodes.ros_io import array_from_multiarray, qos_latched, window_to_msg
    from jident_ros.stream.detector import BacklashDetector
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    plain = ros.collect(Float64, "/st/inertia_estimate", qos_latched(10))
    stamped = ros.collect(InertiaStamped, "/st/inertia_estimate/stamped", qos_latched(10))
    detail = ros.collect(Float64MultiArray, "/st/inertia_estimate/detail", qos_latched(10))
    pub = ros.node.create_publisher(Float64MultiArray, "/st/drive/window", qos_latched(10))
    p = Proc(node_env, tmp_path, "diagnostic", "-r", "__ns:=/st", "-p", "record:=false", "-p", "image_method:=false")
    try:
        _, (stream, _) = _good_stream()
        (ev,) = BacklashDetector(0.005, 0.1, 5e-4).push(stream, DEFAULT_CHANNELS)
        ev.window.window_id = 7
        assert ros.spin_until(lambda: pub.get_subscription_count() >= 1), logs(p)
        pub.publish(window_to_msg(ev.window))
        assert ros.spin_until(lambda: plain and stamped and detail), logs(p)
    finally:
        p.stop()
    s, (row,) = stamped[0], array_from_multiarray(detail[0])[0]
    t = ev.window.entry_time_s
    assert (s.header.stamp.sec, s.header.stamp.nanosec) == (int(t), round((t - int(t)) * 1e9))
    assert s.inertia.izz == plain[0].data and s.inertia.m == 0.0
    cols = array_from_multiarray(detail[0])[1]
    d = dict(zip(cols, row))
    assert d["window_id"] == 7 and d["entry_time_s"] == t and d["inertia_kgm2"] == plain[0].data
    assert 0 < d["inertia_std_error_kgm2"] < 0.01 * d["inertia_kgm2"]


# --------------------------------------------------------------------------- recorded QoS
@pytest.mark.ros
def test_recorded_qos_is_what_the_publishers_offer(node_env, tmp_path, ros):  # noqa: F811
    """drive/case from a latched publisher is recorded transient local with the depth the recorder kept
    (100: every case message), drive/signals from a publisher that offers transient local and a lifespan is
    recorded so -- before, both were recorded with the recorder's own assumptions (depth 1; volatile)."""
    import numpy as np
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    from test_nodes import _msg

    from jident_ros.bag.reader import read_metadata
    from jident_ros.nodes.ros_io import multiarray_from_array
    from jident_ros.stream.layout import CASE_LABEL
    case_qos = QoSProfile(depth=3, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    sig_qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         lifespan=Duration(seconds=5))
    pub_case = ros.node.create_publisher(Float64MultiArray, "/rq/drive/case", case_qos)
    pub_sig = ros.node.create_publisher(Float64MultiArray, "/rq/drive/signals", sig_qos)
    root = tmp_path / "bags"
    p = Proc(node_env, tmp_path, "diagnostic", "-r", "__ns:=/rq", "-p", f"record_root:={root}",
             "-p", "image_method:=false")
    try:
        assert ros.spin_until(lambda: pub_case.get_subscription_count() >= 1 and pub_sig.get_subscription_count() >= 1), \
            logs(p)
        for i in range(3):
            pub_case.publish(multiarray_from_array(np.array([[i, 1.16, 0.005, 0.025, 1.0 + i]]), CASE_LABEL.split(",")))
        t = 1.0 + np.arange(50) * 5e-4
        pub_sig.publish(_msg(np.column_stack([t] + [np.zeros(50)] * 8),
                             ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2")))
        ros.spin_until(lambda: False, 2.0)
    finally:
        assert p.stop() == 0, logs(p)
    (bag,) = [p for p in root.iterdir() if p.is_dir()]   # beside it: the manifest .jident_ros_bags
    topics = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
              for t in read_metadata(bag)["topics_with_message_count"]}
    (case,) = topics["/rq/drive/case"]
    assert case["durability"] == "transient_local" and case["depth"] == 100 and case["history"] == "keep_last", case
    (sig,) = topics["/rq/drive/signals"]
    assert sig["durability"] == "transient_local" and sig["lifespan"] == {"sec": 5, "nsec": 0}, sig
    (est,) = topics["/rq/inertia_estimate"]          # our own publisher: its own profile
    assert est["durability"] == "transient_local"


# --------------------------------------------------------------------------- best-effort input
@pytest.mark.ros
def test_best_effort_input_is_selectable_and_a_mismatch_is_an_error_status(node_env, tmp_path, ros):  # noqa: F811
    """A best-effort drive/signals publisher (SensorDataQoS): the default (reliable) windowing node says in one
    ERROR status what cannot match and which parameter to change; with input_reliability:=best_effort it reads
    the batches."""
    import numpy as np
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from std_msgs.msg import Float64MultiArray
    from test_nodes import _msg, statuses

    from jident_ros.nodes.ros_io import qos_diagnostics, status_level, status_values
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    pubs = {ns: ros.node.create_publisher(Float64MultiArray, f"/{ns}/drive/signals", qos_profile_sensor_data)
            for ns in ("ber", "bee")}
    procs = [Proc(node_env, tmp_path, "windowing", "-r", "__ns:=/ber", "-p", "diagnostics_period_s:=0.5"),
             Proc(node_env, tmp_path, "windowing", "-r", "__ns:=/bee", "-p", "diagnostics_period_s:=0.5",
                  "-p", "input_reliability:=best_effort")]
    try:
        err = lambda: statuses(diags, "jident_windowing: input", "/ber/drive")  # noqa: E731
        assert ros.spin_until(lambda: err()), logs(*procs)
        assert "RELIABILITY" in err()[0].message and "input_reliability:=best_effort" in err()[0].message
        assert status_level(err()[0]) == 2 and err()[0].name == "ber/jident_windowing: input"
        channels = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2")
        rate = lambda: [status_values(s) for s in statuses(diags, "jident_windowing: rate", "/bee/drive")]  # noqa: E731

        def seen():
            t0 = 1.0 + 50 * 5e-4 * seen.k
            seen.k += 1
            pubs["bee"].publish(_msg(np.column_stack([t0 + np.arange(50) * 5e-4] + [np.full(50, 1.0)] * 8), channels))
            return any(int(v["batches_seen"]) > 0 for v in rate())
        seen.k = 0
        assert ros.spin_until(seen), logs(*procs)
        assert not statuses(diags, "jident_windowing: input", "/bee/drive")
        # the input status is periodic (a listener that starts late still sees the ERROR), and turns OK once the
        # incompatible publisher is gone
        n_err = len(err())
        assert ros.spin_until(lambda: len([s for s in err() if status_level(s) == 2]) > n_err), logs(*procs)
        ros.node.destroy_publisher(pubs.pop("ber"))
        assert ros.spin_until(lambda: status_level(err()[-1]) == 0), logs(*procs)
        assert "no publisher with an incompatible QoS now" in err()[-1].message
    finally:
        for p in procs:
            p.stop()


# --------------------------------------------------------------------------- per-sample view
def test_per_sample_bag_plots_every_sample_at_its_drive_time(tmp_path):
    import json
    import subprocess
    import sys

    import numpy as np

    from jident_ros.bag.reader import read_bag
    from jident_ros.stream.layout import unpack
    rec = write_two_k2_recording(tmp_path / "rec", misordered=True)
    batches = [m.message for m in read_bag(rec) if m.topic.endswith("drive/signals")]
    t_all = np.concatenate([unpack(b.data, b.layout.dim, b.layout.data_offset)[0][:, 0] for b in batches])
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "samples", str(rec), str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert r.returncode == 0, r.stderr
    out = list(read_bag(tmp_path / "out"))
    samples = [m for m in out if m.topic == "/drive/sample"]
    assert len(samples) == len(t_all)
    rows = [unpack(m.message.data, m.message.layout.dim, m.message.layout.data_offset) for m in samples]
    assert all(a.shape[0] == 1 for a, _, _ in rows)
    t = np.array([a[0, ch.index("t")] for a, ch, _ in rows])
    assert np.array_equal(np.sort(t), np.sort(t_all))
    assert [m.log_time_ns for m in samples] == [int(round(x * 1e9)) for x in t]      # log time = drive time
    # case 2's K2 goes along at the drive time of the batch after it (publish order), not where it was logged
    (k2_second,) = [m for m in out if m.topic == "/drive/backlash_width" and m.message.data == 0.01]
    assert k2_second.log_time_ns > samples[len(samples) // 2 - 1].log_time_ns
    channels = rows[0][1]
    layout = json.loads((REPO / "config" / "foxglove_layout.json").read_text())
    paths = [p for c in layout["configById"].values() for p in c.get("paths", [])]
    assert paths
    for p in paths:   # every plotted path indexes the channel it is labelled with
        i = int(p["value"].split("data[")[1].rstrip("]"))
        assert p["value"].startswith("/drive/sample.data[") and channels[i] == p["label"], p


def test_samples_of_a_missing_recording_is_one_line(tmp_path):
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "samples", str(tmp_path / "nope"), str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "nope" in r.stderr, r.stderr
