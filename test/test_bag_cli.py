"""Damaged, killed and out-of-order recordings through `jident diagnose`, `jident salvage` and the
replay node (issue 15 items 1, 2, 6, 8; issue 11 part 4: split bags).

Each case is one line naming the file and the problem, no traceback: exit 2 where nothing could be done
(diagnose or replay of a damaged or garbage file); a killed recorder's bag is read by salvaging it on the
fly, saying so in one line.  The diagnosis runs with --no-image (the gap estimate), which is enough to see
the windows.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_offline import TRUE_J1, configs, write_recording  # noqa: F401  (fixture)

from jident_ros.bag.reader import read_bag
from jident_ros.bag.writer import BagWriter

REPO = Path(__file__).resolve().parents[1]


def jident(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "jident_ros.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ, PYTHONPATH=str(REPO)))


def one_line(r, code):
    lines = r.stderr.strip().splitlines()
    assert r.returncode == code and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    return lines


@pytest.fixture(scope="module")
def run(configs, tmp_path_factory):  # noqa: F811
    return write_recording(tmp_path_factory.mktemp("rec") / "run", configs[0])


def flip_in_chunk(src: Path, dst: Path, k: int = 2) -> Path:
    from mcap.reader import make_reader
    with open(src, "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(src.read_bytes())
    c = chunks[k]
    data[c.chunk_start_offset + c.chunk_length // 2] ^= 0x5A     # inside the compressed data
    dst.write_bytes(bytes(data))
    return dst


def kill_copy(src: Path, dst_dir: Path) -> Path:
    """The bag as a killed recorder leaves it: no metadata.yaml, the file cut inside its last chunks."""
    dst_dir.mkdir()
    data = (src / f"{src.name}_0.mcap").read_bytes()
    (dst_dir / f"{dst_dir.name}_0.mcap").write_bytes(data[:int(len(data) * 0.8)])
    return dst_dir


def small_chunks_recording(path: Path, configs):  # noqa: F811
    """write_recording with a chunk every 20 batches (as flush_age_s gives at real time)."""
    real = BagWriter.__init__

    def init(self, *a, **k):
        real(self, *a, **{**k, "chunk_size": 64 * 1024})
    BagWriter.__init__ = init
    try:
        return write_recording(path, configs[0])
    finally:
        BagWriter.__init__ = real


def test_diagnose_and_salvage_of_a_bit_flipped_chunk(configs, tmp_path):  # noqa: F811
    run = small_chunks_recording(tmp_path / "run", configs)
    bad = flip_in_chunk(run / "run_0.mcap", tmp_path / "flipped.mcap")
    r = jident("diagnose", bad, "--no-image")
    (line,) = one_line(r, 2)
    assert line.startswith("jident: error: recording ") and str(bad) in line and "damaged" in line, line
    assert "jident salvage" in line
    # salvage writes the readable part and its one line names the file and the damage
    r = jident("salvage", bad, tmp_path / "out")
    assert r.returncode == 0 and r.stderr == "" and "Traceback" not in r.stdout, r
    (line,) = r.stdout.strip().splitlines()
    assert str(bad) in line and "damaged record at offset" in line, line
    assert 0 < sum(1 for _ in read_bag(tmp_path / "out")) < sum(1 for _ in read_bag(run))


def test_diagnose_reads_a_killed_bag_by_salvaging_it(configs, run, tmp_path):  # noqa: F811
    killed = kill_copy(small_chunks_recording(tmp_path / "full", configs), tmp_path / "killed")
    r = jident("diagnose", killed, "--no-image", "--quiet")
    assert r.returncode in (0, 1) and "Traceback" not in r.stderr, r.stderr
    notes = [x for x in r.stderr.splitlines() if "not finalised" in x]
    assert len(notes) == 1 and "salvaging" in notes[0] and "killed_0.mcap" in notes[0], r.stderr


def test_diagnose_accepts_a_split_bag(configs, run, tmp_path):  # noqa: F811
    from jident_ros.cli.offline import diagnose_recording
    whole = diagnose_recording(run, image_method=False)
    split = tmp_path / "split"
    with BagWriter(split, chunk_size=64 * 1024) as w:
        msgs = list(read_bag(run, raw=True))
        for topic in dict.fromkeys(m.topic for m in msgs):
            w.add_topic(topic, next(m.msg_type for m in msgs if m.topic == topic))
        for i, m in enumerate(msgs):
            if i and i % 30 == 0:
                w.split()
            w.write(m.topic, m.message, m.log_time_ns)
    assert len(list(split.glob("*.mcap"))) >= 3
    got = diagnose_recording(split, image_method=False)
    assert got.estimates == whole.estimates and len(got.estimates) == len(TRUE_J1)


def test_diagnose_orders_by_the_t_column_not_by_receive_time(configs, run, tmp_path):  # noqa: F811
    """A recorder whose clock jumped (another drive's /clock): receive times that go back and forth.
    The windows are those of the drive's own time line."""
    from jident_ros.cli.offline import diagnose_recording
    whole = diagnose_recording(run, image_method=False)
    msgs = list(read_bag(run, raw=True))
    rng = np.random.default_rng(3)
    jumps = rng.integers(0, 2, len(msgs)) * 10**12   # half the messages stamped 1000 s later
    scrambled = tmp_path / "scrambled"
    with BagWriter(scrambled) as w:
        for topic in dict.fromkeys(m.topic for m in msgs):
            w.add_topic(topic, next(m.msg_type for m in msgs if m.topic == topic))
        for m, j in zip(msgs, jumps):
            w.write(m.topic, m.message, m.log_time_ns + int(j))
    order = [m.topic for m in read_bag(scrambled, raw=True)]
    assert order != [m.topic for m in msgs]
    got = diagnose_recording(scrambled, image_method=False)
    assert got.estimates == whole.estimates and len(got.estimates) == len(TRUE_J1)


def test_diagnose_drops_a_malformed_first_batch_and_goes_on(configs, run, tmp_path):  # noqa: F811
    from jident_ros.cli.offline import diagnose_recording
    whole = diagnose_recording(run, image_method=False)
    msgs = list(read_bag(run, raw=True))
    first = next(i for i, m in enumerate(msgs) if m.topic.endswith("drive/signals"))
    bad = tmp_path / "badfirst"
    with BagWriter(bad) as w:
        for topic in dict.fromkeys(m.topic for m in msgs):
            w.add_topic(topic, next(m.msg_type for m in msgs if m.topic == topic))
        for i, m in enumerate(msgs):
            if i == first:  # a malformed batch before the first good one (1-D layout), also one that is not CDR
                w.write(m.topic, {"layout": {"dim": [{"label": "x", "size": 3, "stride": 3}]}, "data": [1.0, 2, 3]},
                        m.log_time_ns - 2)
                w.write(m.topic, b"\x00\x01\x00\x00\xff", m.log_time_ns - 1)
            w.write(m.topic, m.message, m.log_time_ns)
    notes = []
    got = diagnose_recording(bad, image_method=False, log=notes.append)
    assert got.estimates == whole.estimates
    assert got.dropped.get("layout") == 2 and got.batches == whole.batches
    assert any("2 unreadable batch(es)" in n for n in got.notes), got.notes
    r = jident("diagnose", bad, "--no-image", "--quiet")
    assert r.returncode == 0 and "unreadable batch" in r.stderr and "Traceback" not in r.stderr, r.stderr


# ------------------------------------------------------------------ replay node
@pytest.mark.ros
@pytest.mark.parametrize("case", ["garbage", "flipped", "killed"])
def test_replay_on_a_bad_bag(configs, run, tmp_path, case):  # noqa: F811
    from test_nodes import node_env as _  # noqa: F401  (documents where the env comes from)

    from jident_ros.resources import node_command
    if case == "garbage":
        bag = tmp_path / "garbage.mcap"
        bag.write_bytes(np.random.default_rng(1).bytes(4000))
    elif case == "flipped":
        bag = flip_in_chunk(small_chunks_recording(tmp_path / "r", configs) / "r_0.mcap", tmp_path / "flipped.mcap")
    else:
        bag = kill_copy(small_chunks_recording(tmp_path / "full", configs), tmp_path / "killed")
    env = dict(os.environ, PYTHONPATH=str(REPO), ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", "61"),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    cmd = node_command("replay", require_index=False)
    r = subprocess.run([*cmd, str(bag), "--ros-args", "-p", "rate:=0.0", "-p", "max_lead_s:=0.0",
                        "-p", "fast_sleep_s:=0.0", "-p", "publish_clock:=false"],
                       capture_output=True, text=True, timeout=120, env=env)
    out = r.stdout + r.stderr
    assert "Traceback" not in out, out
    if case == "killed":
        assert r.returncode == 0, out
        assert "not finalised" in out and "salvaging" in out, out
        return
    lines = [x for x in r.stderr.strip().splitlines() if x and not x.startswith("[INFO]")]
    assert r.returncode == 2 and len(lines) == 1, out
    assert str(bag) in lines[0] and ("not an MCAP file" if case == "garbage" else "damaged") in lines[0], lines
