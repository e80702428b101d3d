"""MCAP recording (jident_ros.bag.writer, .reader, .salvage): rosbag2 compatibility, crash behaviour, salvage.

Independent checks: the ``rosbags`` library (its own MCAP reader, .msg parser, CDR
codec and RIHS01 hash; AnyReader refuses a bag whose type hashes do not match the
definitions), ``mcap-ros2-support`` (Foxglove's Python ROS 2 decoder), the
type-description JSON files installed with the ROS 2 interface packages, and rclpy.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from jident_ros.bag.close_on_signal import install_signal_handlers
from jident_ros.bag.errors import RecordingError
from jident_ros.bag.messages import _QOS_KEYS as QOS_KEYS
from jident_ros.bag.messages import deserialize, message_definition, message_to_dict, qos_profiles, serialize, type_hash
from jident_ros.bag.metadata_yaml import dump_yaml
from jident_ros.bag.reader import read_bag, read_metadata
from jident_ros.bag.salvage import salvage
from jident_ros.bag.writer import BagWriter
from jident_ros.cli.salvage import salvage_main

REPO = Path(__file__).resolve().parents[1]
CHANNELS = "t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2"
SIGNALS = "std_msgs/msg/Float64MultiArray"


def batch(i: int, n: int = 40) -> dict:
    """A /drive/signals batch: n samples x 9 channels, value encodes (i, sample, channel)."""
    data = i * 1000.0 + np.arange(n * 9, dtype=float).reshape(n, 9) / 7.0
    return {"layout": {"dim": [{"label": "sample", "size": n, "stride": n * 9},
                               {"label": CHANNELS, "size": 9, "stride": 9}],
                       "data_offset": 0},
            "data": data}


def diag(i: int) -> dict:
    return {"header": {"stamp": {"sec": i, "nanosec": 250_000_000}, "frame_id": "f" * (i % 5)},
            "status": [{"level": i % 4, "name": "jident/inertia" + "x" * (i % 3),
                        "message": f"window {i}", "hardware_id": "press3",
                        "values": [{"key": "J1", "value": f"{1.073 + i / 1000:.4f}"},
                                   {"key": "class", "value": str(i % 7)}]},
                       {"level": 0, "name": "", "message": "", "hardware_id": "", "values": []}]}


def share_dir() -> Path | None:
    """share/ of an installed ROS 2 (ros-* wheels or a distribution), if any."""
    prefixes = [sys.prefix] + os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
    for prefix in prefixes:
        if prefix and (Path(prefix) / "share/std_msgs/msg/Float64MultiArray.msg").is_file():
            return Path(prefix) / "share"
    return None


def anyreader_messages(bag: Path) -> tuple[dict, list]:
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:  # checks every topic's type hash against its definition
        conns = {c.topic: c for c in reader.connections}
        msgs = [(c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    return conns, msgs


def run_child(tmp_path: Path, body: str, ignored: int | None = None) -> subprocess.Popen:
    """Run ``body`` in a child (``ignored``: a signal the child inherits as SIG_IGN)."""
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(f"""\
        import sys, time
        sys.path.insert(0, {str(REPO)!r})
        import numpy as np
        from jident_ros.bag.writer import BagWriter
        from jident_ros.bag.close_on_signal import install_signal_handlers
        def data(i):
            return {{"layout": {{"dim": [{{"label": "sample", "size": 2, "stride": 18}},
                                       {{"label": {CHANNELS!r}, "size": 9, "stride": 9}}]}},
                    "data": np.full(18, float(i))}}
        """) + textwrap.dedent(body))
    return subprocess.Popen([sys.executable, str(script), str(tmp_path / "bag")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            preexec_fn=None if ignored is None else lambda: signal.signal(ignored, signal.SIG_IGN))


def wait_for(proc: subprocess.Popen, word: str, timeout: float = 20.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith(word):
            return line
        if not line and proc.poll() is not None:
            break
    proc.kill()
    raise AssertionError(f"child did not print {word!r}: {proc.stderr.read()}")


# ---------------------------------------------------------------- definitions, hash, CDR
RECORDED_TYPES = ("std_msgs/msg/Float64", "std_msgs/msg/Float64MultiArray", "rosgraph_msgs/msg/Clock",
                  "diagnostic_msgs/msg/DiagnosticArray", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")


def test_module_does_not_import_rclpy():
    code = ("import sys, jident_ros.bag.writer, jident_ros.bag.reader, jident_ros.bag.salvage, "
            "jident_ros.bag.rotating_recorder, jident_ros.bag.messages as r; "
            "r.serialize('std_msgs/msg/Float64', {'data': 1.0}); "
            "print('rclpy' in sys.modules, 'mcap_ros2' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                         check=True).stdout
    assert out.split() == ["False", "False"]


def test_no_hand_written_codec_left_in_the_bag_package():
    """Issue 11: CDR, .msg parsing, type hashes and MCAP records come from rosbags and mcap."""
    for path in (REPO / "jident_ros" / "bag").glob("*.py"):
        text = path.read_text()
        for marker in ("struct.pack", "struct.unpack", "hashlib.sha256", "_PRIMITIVES", "zlib.crc32",
                       "MSG_FILES", "def _parse_msg"):
            assert marker not in text, f"{path.name}: {marker}"


def test_type_hashes_are_the_installed_ones():
    share = share_dir()
    if share is None:
        pytest.skip("no ROS 2 interface packages installed to compare with")
    for name in RECORDED_TYPES:
        info = json.loads((share / f"{name}.json").read_text())
        want = {h["type_name"]: h["hash_string"] for h in info["type_hashes"]}[name]
        assert type_hash(name) == want, name
    assert type_hash("std_msgs/Float64") == type_hash("std_msgs/msg/Float64")


def test_written_definitions_give_the_same_hash_to_an_independent_parser():
    """What a reader sees: the schema text parsed on its own (rosbags' parser into an empty store, as
    AnyReader does on open) hashes to the hash recorded with the topic."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    for name in RECORDED_TYPES:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(message_definition(name), name))
        assert store.hash_rihs01(name) == type_hash(name), name
    text = message_definition("diagnostic_msgs/msg/DiagnosticArray")
    assert "MSG: diagnostic_msgs/KeyValue" in text and "MSG: builtin_interfaces/Time" in text


def _samples():
    return [
        (SIGNALS, batch(3)),
        (SIGNALS, {"layout": {"dim": [], "data_offset": 0}, "data": []}),
        ("std_msgs/msg/Float64", {"data": 1.073e-3}),
        ("rosgraph_msgs/msg/Clock", {"clock": {"sec": 12, "nanosec": 999_999_999}}),
    ] + [("diagnostic_msgs/msg/DiagnosticArray", diag(i)) for i in range(6)]


def test_cdr_bytes_equal_mcap_ros2_and_round_trip():
    """rosbags' bytes (ours) equal those of Foxglove's independent encoder, which the previous
    hand-written codec matched too: recordings stay byte-compatible."""
    from mcap_ros2._dynamic import serialize_dynamic
    for name, msg in _samples():
        ours = serialize(name, msg)
        plain = message_to_dict(deserialize(name, ours))
        assert serialize_dynamic(name, message_definition(name))[name](plain) == ours, name
        assert serialize(name, deserialize(name, ours)) == ours
        assert serialize(name, plain) == ours


@pytest.mark.ros
def test_cdr_interoperates_with_rclpy():
    # rclpy leaves CDR padding bytes uninitialised, so compare decoded values, both ways
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message, serialize_message
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64, Float64MultiArray
    classes = {SIGNALS: Float64MultiArray, "std_msgs/msg/Float64": Float64,
               "rosgraph_msgs/msg/Clock": Clock, "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray}
    for name, msg in _samples():
        ros_msg = deserialize_message(serialize(name, msg), classes[name])
        ours_from_rclpy = deserialize(name, serialize_message(ros_msg))   # also an empty float64[]
        assert message_to_dict(ours_from_rclpy) == message_to_dict(deserialize(
            name, serialize(name, msg))), name
        # an rclpy message object is accepted by the writer's encoder as well
        assert serialize(name, ros_msg) == serialize(name, ours_from_rclpy), name
        if name == "diagnostic_msgs/msg/DiagnosticArray" and msg["status"][0]["level"]:
            assert ros_msg.status[0].level == bytes([msg["status"][0]["level"]])


@pytest.mark.ros
def test_qos_from_an_rclpy_profile():
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from jident_ros.bag.messages import qos_dicts
    q = QoSProfile(depth=3, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                   reliability=ReliabilityPolicy.BEST_EFFORT, deadline=Duration(seconds=1.5))
    (p,) = qos_dicts(qos_profiles(q))
    assert (p["history"], p["depth"], p["reliability"], p["durability"], p["deadline"],
            p["liveliness"]) == ("keep_last", 3, "best_effort", "transient_local",
                                 {"sec": 1, "nsec": 500_000_000}, "system_default")


def test_encoder_rejects_bad_messages():
    with pytest.raises(ValueError, match="unknown field"):
        serialize("std_msgs/msg/Float64", {"dat": 1.0})
    with pytest.raises(ValueError, match=r"status\[0\]\.values\[0\].*unknown field"):
        serialize("diagnostic_msgs/msg/DiagnosticArray",
                    {"status": [{"values": [{"key": "a", "val": "b"}]}]})
    with pytest.raises(ValueError, match="Float64.data: expected a number"):
        serialize("std_msgs/msg/Float64", {"data": "1.0"})
    with pytest.raises(ValueError, match=r"clock\.sec: 2147483648 is outside"):
        serialize("rosgraph_msgs/msg/Clock", {"clock": {"sec": 2**31}})
    with pytest.raises(ValueError, match=r"dim\[0\]\.label: expected str"):
        serialize(SIGNALS, {"layout": {"dim": [{"label": 3}]}})
    with pytest.raises(ValueError, match="float values for uint8"):
        serialize("std_msgs/msg/UInt8MultiArray", {"data": [1.5]})
    clock = deserialize("rosgraph_msgs/msg/Clock", serialize("rosgraph_msgs/msg/Clock", {}))
    with pytest.raises(TypeError, match="Clock message where std_msgs/msg/Float64 is expected"):
        serialize("std_msgs/msg/Float64", clock)
    with pytest.raises(ValueError, match="no definition of my_msgs/msg/Thing"):
        serialize("my_msgs/msg/Thing", {})
    with pytest.raises(ValueError, match="undecodable"):
        deserialize(SIGNALS, serialize(SIGNALS, batch(1))[:-3])


# ---------------------------------------------------------------- write / read
def write_reference_bag(path: Path, *, compression="zstd", flush_every=7, n=30) -> dict:
    """All four types; returns what was written per topic as (log_time, message)."""
    written = {"/drive/signals": [], "/clock": [], "/inertia_estimate": [], "/diagnostics": []}
    with BagWriter(path, chunk_size=64 * 1024, flush_age_s=None,
                     compression=compression) as bag:
        bag.add_topic("/drive/signals", SIGNALS)
        bag.add_topic("/clock", "rosgraph_msgs/msg/Clock", qos="best_effort")
        bag.add_topic("/inertia_estimate", "std_msgs/msg/Float64", qos="transient_local")
        bag.add_topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray",
                      qos={"depth": 5})
        t0 = 1_700_000_000_000_000_000
        for i in range(n):
            t = t0 + i * 10_000_000
            for topic, msg in (("/clock", {"clock": {"sec": i, "nanosec": 5}}),
                               ("/drive/signals", batch(i))):
                bag.write(topic, msg, t)
                written[topic].append((t, msg))
            if i % 3 == 2:
                msg = {"data": 1.0 + i / 100}
                bag.write("/inertia_estimate", msg, t + 1, publish_time_ns=t)
                written["/inertia_estimate"].append((t + 1, msg))
                bag.write("/diagnostics", diag(i), t + 2)
                written["/diagnostics"].append((t + 2, diag(i)))
            if i % flush_every == flush_every - 1:
                bag.flush()
    return written


def assert_same(topic: str, got, want) -> None:
    if topic == "/drive/signals":
        assert [d.label for d in got.layout.dim] == ["sample", CHANNELS]
        assert [d.size for d in got.layout.dim] == [40, 9]
        assert [d.stride for d in got.layout.dim] == [360, 9]
        np.testing.assert_array_equal(np.asarray(got.data).reshape(40, 9), want["data"])
    elif topic == "/clock":
        assert (got.clock.sec, got.clock.nanosec) == (want["clock"]["sec"], 5)
    elif topic == "/inertia_estimate":
        assert got.data == want["data"]
    else:
        assert (got.header.stamp.sec, got.header.stamp.nanosec, got.header.frame_id) == (
            want["header"]["stamp"]["sec"], 250_000_000, want["header"]["frame_id"])
        assert len(got.status) == 2
        for g, w in zip(got.status, want["status"]):
            assert (int(g.level), g.name, g.message, g.hardware_id) == (
                w["level"], w["name"], w["message"], w["hardware_id"])
            assert [(kv.key, kv.value) for kv in g.values] == [
                (kv["key"], kv["value"]) for kv in w["values"]]


@pytest.mark.parametrize("compression", ["zstd", "lz4", None])
def test_every_message_reads_back_with_ours_rosbags_and_mcap_ros2(tmp_path, compression):
    bag = tmp_path / "run"
    written = write_reference_bag(bag, compression=compression)
    total = sum(len(v) for v in written.values())

    ours = list(read_bag(bag))
    assert len(ours) == total
    assert [m.log_time_ns for m in ours] == sorted(m.log_time_ns for m in ours)
    conns, theirs = anyreader_messages(bag)
    assert len(theirs) == total
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(bag / "run_0.mcap", "rb") as f:
        foxglove = list(make_reader(f, decoder_factories=[DecoderFactory()])
                        .iter_decoded_messages())
    assert len(foxglove) == total

    for topic, items in written.items():
        mine = [m for m in ours if m.topic == topic]
        other = [(t, m) for tp, t, m in theirs if tp == topic]
        fox = [m for m in foxglove if m.channel.topic == topic]
        assert len(mine) == len(other) == len(fox) == len(items), topic
        for (t, want), a, (tb, b), c in zip(items, mine, other, fox):
            assert a.log_time_ns == tb == c.message.log_time == t
            assert a.msg_type == conns[topic].msgtype == c.schema.name
            assert_same(topic, a.message, want)
            assert_same(topic, b, want)
            assert_same(topic, c.decoded_message, want)
        assert conns[topic].digest == type_hash(conns[topic].msgtype)
    assert conns["/inertia_estimate"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
    assert conns["/clock"].ext.offered_qos_profiles[0].reliability.name == "BEST_EFFORT"
    assert conns["/diagnostics"].ext.offered_qos_profiles[0].depth == 5
    default = conns["/drive/signals"].ext.offered_qos_profiles[0]
    assert (default.history.name, default.depth, default.reliability.name,
            default.durability.name) == ("KEEP_LAST", 10, "RELIABLE", "VOLATILE")

    raw = list(read_bag(bag / "run_0.mcap", topics="/inertia_estimate", raw=True))
    assert [m.message for m in raw] == [serialize("std_msgs/msg/Float64", w)
                                        for _, w in written["/inertia_estimate"]]


def test_metadata_yaml_and_mcap_records_as_rosbag2_writes_them(tmp_path):
    bag = tmp_path / "run"
    written = write_reference_bag(bag)
    counts = {k: len(v) for k, v in written.items()}
    times = [t for v in written.values() for t, _ in v]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["message_count"] == sum(counts.values())
    assert info["starting_time"]["nanoseconds_since_epoch"] == min(times)
    assert info["duration"]["nanoseconds"] == max(times) - min(times)
    assert info["relative_file_paths"] == ["run_0.mcap"]
    assert info["files"] == [{"path": "run_0.mcap",
                              "starting_time": {"nanoseconds_since_epoch": min(times)},
                              "duration": {"nanoseconds": max(times) - min(times)},
                              "message_count": sum(counts.values())}]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {k: v["message_count"] for k, v in topics.items()} == counts
    for t in topics.values():
        md = t["topic_metadata"]
        assert md["serialization_format"] == "cdr"
        assert md["type_description_hash"] == type_hash(md["type"])
        q = md["offered_qos_profiles"]
        assert isinstance(q, list) and len(q) == 1 and set(q[0]) == set(QOS_KEYS)
    assert topics["/inertia_estimate"]["topic_metadata"]["offered_qos_profiles"][0][
        "durability"] == "transient_local"
    assert read_metadata(bag) == info

    from mcap.reader import make_reader
    with open(bag / "run_0.mcap", "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header = reader.get_header()
        summary = reader.get_summary()
        assert header.profile == "ros2"
        assert summary.statistics.message_count == sum(counts.values())
        assert len(summary.chunk_indexes) >= 4
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            assert ch.message_encoding == "cdr" and schema.encoding == "ros2msg"
            assert schema.data.decode() == message_definition(schema.name)
            assert ch.metadata["topic_type_hash"] == type_hash(schema.name)
            assert yaml.safe_load(ch.metadata["offered_qos_profiles"]) == \
                topics[ch.topic]["topic_metadata"]["offered_qos_profiles"]
        (meta,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert yaml.safe_load(meta.metadata["serialized_metadata"]) == info
        assert sum(1 for _ in reader.iter_messages()) == sum(counts.values())  # CRCs checked


def test_writer_rejects_misuse(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(FileExistsError, match="full"):
        BagWriter(tmp_path / "full")
    with pytest.raises(ValueError, match="compression"):
        BagWriter(tmp_path / "c", compression="gzip")
    bag = BagWriter(tmp_path / "ok")
    bag.add_topic("/x", "std_msgs/Float64")
    bag.add_topic("/x", "std_msgs/msg/Float64")  # same again: fine
    with pytest.raises(ValueError, match="already added"):
        bag.add_topic("/x", SIGNALS)
    with pytest.raises(RecordingError, match="add_topic"):
        bag.write("/y", {"data": 1.0}, 1)
    with pytest.raises(TypeError, match="nanoseconds"):
        bag.write("/x", {"data": 1.0}, 1.5)
    with pytest.raises(ValueError, match="not a CDR payload"):
        bag.write("/x", b"\x07\x07\x07\x07", 1)
    with pytest.raises(ValueError, match="QoS reliability"):
        bag.add_topic("/z", "std_msgs/msg/Float64", qos={"reliability": "sometimes"})
    bag.write("/x", {"data": 2.0}, 5)
    bag.close()
    bag.close()  # idempotent
    with pytest.raises(RecordingError, match="closed"):
        bag.write("/x", {"data": 1.0}, 6)
    assert [m.message.data for m in read_bag(tmp_path / "ok")] == [2.0]


# ---------------------------------------------------------------- crash behaviour
def salvage_count(mcap: Path, out: Path) -> tuple[int, dict]:
    """Salvage a copy of a file that may still be open for writing."""
    copy = out.with_suffix(".mcap")
    copy.write_bytes(mcap.read_bytes())
    report = salvage(copy, out)
    return report["messages_recovered"], report


def test_flush_puts_complete_chunks_on_disk(tmp_path):
    bag = BagWriter(tmp_path / "live", flush_age_s=0.2, chunk_size=1 << 20)
    bag.add_topic("/drive/signals", SIGNALS)
    for i in range(5):
        bag.write("/drive/signals", batch(i), i)
    assert salvage_count(bag.mcap_path, tmp_path / "s0")[0] == 0   # all in the open chunk
    bag.flush()
    assert salvage_count(bag.mcap_path, tmp_path / "s1")[0] == 5
    bag.write("/drive/signals", batch(5), 5)
    time.sleep(0.25)
    bag.write("/drive/signals", batch(6), 6)   # the open chunk is older than flush_every_s
    assert salvage_count(bag.mcap_path, tmp_path / "s2")[0] == 7
    bag.write("/drive/signals", batch(7), 7)
    time.sleep(0.25)
    bag.maybe_flush()                             # what a node's timer calls
    n, report = salvage_count(bag.mcap_path, tmp_path / "s3")
    assert n == 8 and report["chunks_recovered"] == 3 and not report["data_section_complete"]
    bag.close()
    values = [m.message.data[0] for m in read_bag(tmp_path / "s3")]
    assert values == [i * 1000.0 for i in range(8)]


@pytest.mark.parametrize("signum, exit_code, inherited", [
    (signal.SIGTERM, -signal.SIGTERM, "default"), (signal.SIGINT, 130, "default"),
    (signal.SIGINT, 130, "ignored"), (signal.SIGTERM, -signal.SIGTERM, "ignored")])
def test_signal_finalises_the_bag(tmp_path, signum, exit_code, inherited):
    """Also when the signal was ignored before install_signal_handlers (SIGINT of a background job of a
    script): it still finalises the bag and stops the process."""
    proc = run_child(tmp_path, """
        bag = BagWriter(sys.argv[1], flush_age_s=None)
        install_signal_handlers(bag)
        bag.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray")
        bag.add_topic("/inertia_estimate", "std_msgs/msg/Float64", qos="transient_local")
        try:
            for i in range(110):
                bag.write("/drive/signals", data(i), 10**9 + i)
                if i % 25 == 24:
                    bag.flush()
            bag.write("/inertia_estimate", {"data": 1.073}, 10**9 + 200)
            print("ready", flush=True)   # 100 flushed, 11 in the open chunk
            time.sleep(60)
        except KeyboardInterrupt:
            sys.exit(130)
        """, ignored=signum if inherited == "ignored" else None)
    wait_for(proc, "ready")
    proc.send_signal(signum)
    try:
        assert proc.wait(timeout=20) == exit_code
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError(f"signal {signum} ({inherited} before): the child did not stop") from None
    bag = tmp_path / "bag"
    info = read_metadata(bag)
    assert info["message_count"] == 111
    conns, msgs = anyreader_messages(bag)
    assert [float(m.data[0]) for tp, _, m in msgs if tp == "/drive/signals"] == list(range(110))
    assert [m.data for tp, _, m in msgs if tp == "/inertia_estimate"] == [1.073]
    assert len(list(read_bag(bag))) == 111


def test_sigkill_loses_only_the_open_chunk_and_salvage_recovers_the_rest(tmp_path):
    proc = run_child(tmp_path, """
        bag = BagWriter(sys.argv[1], flush_age_s=None, chunk_size=1 << 20)
        bag.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray")
        for i in range(110):
            bag.write("/drive/signals", data(i), 10**9 + i)
            if i % 25 == 24:
                bag.flush()
        print("ready", flush=True)   # 100 flushed, 10 in the open chunk
        time.sleep(60)
        """)
    wait_for(proc, "ready")
    proc.kill()
    proc.wait(timeout=20)
    mcap = tmp_path / "bag" / "bag_0.mcap"
    assert not (tmp_path / "bag" / "metadata.yaml").exists()
    with pytest.raises(RecordingError, match="jident salvage"):
        list(read_bag(mcap))
    assert salvage_main([str(mcap), str(tmp_path / "rec")]) == 0
    info = read_metadata(tmp_path / "rec")
    assert info["message_count"] == 100
    conns, msgs = anyreader_messages(tmp_path / "rec")
    assert [float(m.data[0]) for _, _, m in msgs] == list(range(100))
    assert conns["/drive/signals"].digest == type_hash(SIGNALS)


def test_signal_during_a_write_closes_after_that_write(tmp_path):
    calls = []
    previous = signal.signal(signal.SIGUSR1, lambda s, f: calls.append(s))
    try:
        bag = BagWriter(tmp_path / "b")
        handlers = install_signal_handlers(bag, signals=[signal.SIGUSR1])
        bag.add_topic("/inertia_estimate", "std_msgs/msg/Float64")
        bag.write("/inertia_estimate", {"data": 1.0}, 1)

        class Interrupting:  # the signal arrives while the writer encodes this message
            @property
            def data(self):
                os.kill(os.getpid(), signal.SIGUSR1)
                for _ in range(1000):  # let Python run the handler inside the write
                    pass
                assert not bag.closed and calls == []   # neither closed nor chained yet
                return 2.0

        bag.write("/inertia_estimate", Interrupting(), 2)
        assert bag.closed and calls == [signal.SIGUSR1]   # closed after, then chained
        assert [m.message.data for m in read_bag(tmp_path / "b")] == [1.0, 2.0]
        signal.signal(signal.SIGUSR1, handlers[signal.SIGUSR1])
    finally:
        signal.signal(signal.SIGUSR1, previous)


# ---------------------------------------------------------------- salvage
def chunk_layout(mcap: Path):
    from mcap.reader import make_reader
    with open(mcap, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def write_in_chunks_of_ten(bag: Path, n: int, **writer_args) -> Path:
    """A finalised bag of ``n`` batches (batch i at log time 1000 + i), ten per chunk."""
    with BagWriter(bag, flush_age_s=None, **writer_args) as w:
        w.add_topic("/drive/signals", SIGNALS)
        for i in range(n):
            w.write("/drive/signals", batch(i), 1000 + i)
            if i % 10 == 9:
                w.flush()
    return bag


def test_salvage_of_a_file_truncated_anywhere_recovers_the_complete_chunks(tmp_path):
    bag = write_in_chunks_of_ten(tmp_path / "full", 100)
    mcap = bag / "full_0.mcap"
    data = mcap.read_bytes()
    chunks = chunk_layout(mcap)
    assert len(chunks) == 10
    c4 = chunks[4]
    cases = {  # cut offset -> messages that must come back
        c4.chunk_start_offset + 5: 40,                                     # in the record header
        c4.chunk_start_offset + c4.chunk_length // 2: 40,                  # mid chunk
        c4.chunk_start_offset + c4.chunk_length - 1: 40,                   # one byte short
        c4.chunk_start_offset + c4.chunk_length: 50,                       # chunk complete
        c4.chunk_start_offset + c4.chunk_length + c4.message_index_length // 2: 50,
        chunks[0].chunk_start_offset: 0,
        len(data) - 20: 100,                                               # only the footer cut
    }
    for k, (cut, expected) in enumerate(sorted(cases.items())):
        src = tmp_path / f"cut{k}.mcap"
        src.write_bytes(data[:cut])
        report = salvage(src, tmp_path / f"out{k}")
        assert report["messages_recovered"] == expected, (cut, report)
        assert report["chunks_recovered"] == expected // 10
        if expected == 40:
            assert report["bytes_lost"] == cut - c4.chunk_start_offset
            assert report["bytes_recovered"] == c4.chunk_start_offset
            assert report["stop_reason"] == (
                f"file ends inside the record at offset {c4.chunk_start_offset}")
        values = [m.message.data[0] for m in read_bag(tmp_path / f"out{k}")]
        assert values == [i * 1000.0 for i in range(expected)]
        assert len(anyreader_messages(tmp_path / f"out{k}")[1]) == expected


def test_salvage_stops_at_a_damaged_chunk(tmp_path):
    bag = write_in_chunks_of_ten(tmp_path / "full", 60, compression=None)
    mcap = bag / "full_0.mcap"
    c3 = chunk_layout(mcap)[3]
    data = bytearray(mcap.read_bytes())
    data[c3.chunk_start_offset + c3.chunk_length - 100] ^= 0xFF   # a float of one message
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    report = salvage(damaged, tmp_path / "out")
    assert report["messages_recovered"] == 30 and "CRC" in report["stop_reason"]
    assert report["bytes_recovered"] == c3.chunk_start_offset


def test_salvage_errors_are_one_line_naming_the_file(tmp_path, capsys):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(np.random.default_rng(1).bytes(5000))
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    nodir = tmp_path / "nothing"
    nodir.mkdir()
    for src, why in ((garbage, "not an MCAP file"), (empty, "not an MCAP file"),
                     (tmp_path / "missing.mcap", "no such file"),
                     (nodir, "no metadata.yaml and no .mcap file")):
        assert salvage_main([str(src), str(tmp_path / "out")]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1
        assert err.startswith("jident salvage: error: ") and str(src) in err and why in err
        assert not (tmp_path / "out").exists()
    bag = tmp_path / "ok"
    with BagWriter(bag) as w:
        w.add_topic("/clock", "rosgraph_msgs/msg/Clock")
        w.write("/clock", {"clock": {"sec": 1}}, 1)
    assert salvage_main([str(bag), str(nodir.parent / "ok")]) == 2      # output exists
    assert "already exists" in capsys.readouterr().err
    assert salvage_main([str(bag), str(tmp_path / "copy")]) == 0          # complete file
    line = capsys.readouterr().out
    assert line.count("\n") == 1 and "1 messages in 1 complete chunks" in line
    assert "0 of" in line and "complete data section" in line
    with pytest.raises(RecordingError, match="not an MCAP file"):
        list(read_bag(garbage))


@pytest.mark.parametrize("split", [False, True])
def test_metadata_yaml_is_the_dump_of_the_bag_metadata(tmp_path, split):
    """metadata.yaml reuses the YAML of the last file's rosbag2 record when the content is the same (one file);
    either way its text is what dumping the bag's metadata under rosbag2_bagfile_information gives, also with
    multi-line and quoted custom data."""
    w = BagWriter(tmp_path / "b", custom_data={"note": "two\nlines", "empty": "", "k": "a: b"})
    w.add_topic("/drive/signals", SIGNALS)
    w.write("/drive/signals", batch(0), 10**18)
    if split:
        w.split()
        w.write("/drive/signals", batch(1), 10**18 + 25_000_000)
    w.close()
    text = (tmp_path / "b" / "metadata.yaml").read_text(encoding="utf-8")
    assert text == dump_yaml({"rosbag2_bagfile_information": w.bag_metadata()})
    info = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert info["custom_data"]["note"] == "two\nlines" and len(info["relative_file_paths"]) == (2 if split else 1)
