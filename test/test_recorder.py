"""The recorder (jident_ros.bag.rotating_recorder): rosbag2-named bags under a root, split, retention, failures.

Issue 11 part 4 (recording by default: split by size and duration, retention) and issue 15 items 1, 2, 5
(close idempotent and signal-safe, an unfinalised bag always recoverable, wall-clock stamps, unusable
root and disk full).  Small limits; no ROS.  Every bag written here is read back by rosbags.
"""
from __future__ import annotations

import errno
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.reader import is_finalised, read_bag, read_metadata
from jident_ros.bag.rotating_recorder import Recorder, RecorderError, bag_name, default_record_root
from jident_ros.bag.writer import BagWriter
from jident_ros.cli.salvage import salvage_main

REPO = Path(__file__).resolve().parents[1]
SIGNALS = "std_msgs/msg/Float64MultiArray"
CHANNELS = "t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2"


def batch(i: int, n: int = 50) -> dict:
    data = np.random.default_rng(i).random((n, 9))
    data[:, 0] = (i * n + np.arange(n)) * 5e-4
    return {"layout": {"dim": [{"label": "sample", "size": n, "stride": n * 9},
                               {"label": CHANNELS, "size": 9, "stride": 9}], "data_offset": 0},
            "data": data.reshape(-1)}


def rosbags_count(bag: Path) -> int:
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:   # checks each topic's type hash against its definition
        return sum(1 for _ in reader.messages())


# ------------------------------------------------------------------ naming, root
def test_bag_named_as_rosbag2_names_it_under_the_root(tmp_path):
    rec = Recorder(tmp_path / "root")
    rec.write("/drive/signals", SIGNALS, batch(0))
    rec.close()
    (bag,) = [p for p in (tmp_path / "root").iterdir() if p.is_dir()]
    assert (tmp_path / "root" / ".jident_ros_bags").read_text() == bag.name + "\n"   # the manifest
    assert re.fullmatch(r"rosbag2_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d", bag.name), bag.name
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", f"{bag.name}_0.mcap"]
    assert rosbags_count(bag) == 1
    assert rec.status()["state"] == "closed" and rec.status()["messages_written"] == 1
    # two recorders starting in the same second never share a bag
    a, b = Recorder(tmp_path / "two"), Recorder(tmp_path / "two")
    assert a.bag_dir != b.bag_dir and b.bag_dir.name.startswith(a.bag_dir.name)
    a.close(), b.close()
    assert bag_name(0.0).startswith("rosbag2_19")


def test_default_root_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("JIDENT_DATA_DIR", str(tmp_path / "data"))
    assert default_record_root() == tmp_path / "data" / "bags"
    monkeypatch.delenv("JIDENT_DATA_DIR")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_record_root() == tmp_path / "xdg" / "jident_ros" / "bags"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert default_record_root() == Path("~/.local/share/jident_ros/bags").expanduser()


def _readonly_mount(path: Path) -> bool:
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(path)], capture_output=True)
    return r.returncode == 0


def test_unusable_root_or_bag_dir_is_a_clear_error(tmp_path):
    (tmp_path / "afile").write_text("x")
    with pytest.raises(RecorderError, match=r"record root .*afile: is a file"):
        Recorder(tmp_path / "afile")
    with pytest.raises(RecorderError, match=r"afile/sub: cannot create it"):
        Recorder(tmp_path / "afile" / "sub")
    full = tmp_path / "full"
    full.mkdir()
    (full / "x").write_text("x")
    with pytest.raises(RecorderError, match=r"bag directory .*full: is a non-empty directory"):
        Recorder(bag_dir=full)
    with pytest.raises(RecorderError, match=r"bag directory .*afile: is a file"):
        Recorder(bag_dir=tmp_path / "afile")
    with pytest.raises(ValueError, match="max_bag_size_bytes"):
        Recorder(tmp_path / "r", max_bag_size_bytes=-1)
    ro = tmp_path / "ro"
    if os.geteuid() != 0:
        ro.mkdir()
        ro.chmod(0o555)
    elif not _readonly_mount(ro):
        pytest.skip("running as root and cannot mount a read-only tmpfs: the unwritable case is not testable")
    try:
        with pytest.raises(RecorderError, match=r"record root .*ro: not writable \((Read-only file system|Permission denied)\)"):
            Recorder(ro)
    finally:
        if os.geteuid() == 0:
            subprocess.run(["umount", str(ro)], capture_output=True)


# ------------------------------------------------------------------ split, retention
def test_split_by_size_keeps_one_bag_with_several_files(tmp_path):
    rec = Recorder(tmp_path, max_bag_size_bytes=20_000, chunk_size=8_000, compression=None)
    for i in range(40):
        assert rec.write("/drive/signals", SIGNALS, batch(i), t_ns=10**18 + i)
    rec.close()
    bag = rec.bag_dir
    files = sorted(bag.glob("*.mcap"), key=lambda p: int(p.stem.rsplit("_", 1)[1]))
    assert len(files) >= 3 and rec.status()["splits"] == len(files) - 1
    assert [p.name for p in files] == [f"{bag.name}_{k}.mcap" for k in range(len(files))]
    info = read_metadata(bag)
    assert info["relative_file_paths"] == [p.name for p in files]
    assert [f["path"] for f in info["files"]] == [p.name for p in files]
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"] == 40
    for p in files[:-1]:   # a split happens at a chunk boundary once the file holds the limit
        assert 20_000 <= p.stat().st_size < 20_000 + 2 * 8_000 + 4_000
    assert rosbags_count(bag) == 40
    t = [m.message.data[0] for m in read_bag(bag)]
    assert t == [batch(i)["data"][0] for i in range(40)]


def test_split_by_duration_also_without_messages(tmp_path):
    rec = Recorder(tmp_path, max_bag_duration_s=0.3)
    rec.write("/drive/signals", SIGNALS, batch(0))
    time.sleep(0.35)
    rec.maybe_flush()          # the node's timer: splits although no message arrived
    rec.write("/drive/signals", SIGNALS, batch(1))
    rec.close()
    assert len(list(rec.bag_dir.glob("*.mcap"))) == 2
    assert [f["message_count"] for f in read_metadata(rec.bag_dir)["files"]] == [1, 1]
    assert rosbags_count(rec.bag_dir) == 2


def _age(bag: Path, age_s: float) -> Path:
    t = time.time() - age_s
    for p in [bag, *bag.iterdir()]:
        os.utime(p, (t, t))
    return bag


def _old_bag(root: Path, name: str, size: int, age_s: float) -> Path:
    """A foreign bag (BagWriter directly, not a Recorder): never ours to delete."""
    with BagWriter(root / name, compression=None) as w:
        w.add_topic("/x", "std_msgs/msg/UInt8MultiArray")
        w.write("/x", {"data": np.zeros(size, dtype=np.uint8)}, 1)
    return _age(root / name, age_s)


def _our_old_bag(root: Path, size: int, age_s: float) -> Path:
    """A bag a Recorder made under ``root`` (in the manifest, marked), then aged."""
    rec = Recorder(root, compression=None)
    rec.write("/x", "std_msgs/msg/UInt8MultiArray", {"data": np.zeros(size, dtype=np.uint8)})
    rec.close()
    return _age(rec.bag_dir, age_s)


def test_retention_deletes_the_oldest_complete_bags_never_the_open_one(tmp_path):
    old = [_our_old_bag(tmp_path, 30_000, 3600 * (9 - k)) for k in range(1, 5)]
    crashed = tmp_path / "rosbag2_2019_01_01-00_00_00"    # no metadata.yaml: left for salvage
    crashed.mkdir()
    (crashed / "crashed_0.mcap").write_bytes(b"\x89MCAP0\r\n" + bytes(100))
    other = Recorder(tmp_path, compression=None)         # another recorder's open bag
    other.add_topic("/x", "std_msgs/msg/UInt8MultiArray")
    other.bag_writer.flush_age_s = None
    t = time.time() - 10 * 3600
    os.utime(other.bag_dir, (t, t))
    logs = []
    from jident_ros.bag.rotating_recorder import _bag_size
    ours = sum(_bag_size(p) for p in [*old, other.bag_dir])
    # the new recorder's bag: its 64 KiB reserve (room to finalise on a full disk) and a few records;
    # a limit that the two oldest complete bags must go for, at start already
    limit = ours + 64 * 1024 + 4096 - _bag_size(old[0]) - _bag_size(old[1])
    rec = Recorder(tmp_path, retention_max_total_bytes=limit, compression=None, chunk_size=20_000, log=logs.append)
    assert [p.name for p in old if not p.exists()] == [old[0].name, old[1].name]
    assert crashed.exists() and other.bag_dir.exists() and rec.bag_dir.exists()
    assert rec.status()["bags_deleted"] == 2 and rec.status()["bytes_deleted"] > 60_000
    assert any("retention: deleted" in line for line in logs)
    assert old[0].name not in (tmp_path / ".jident_ros_bags").read_text().split()   # the manifest follows
    # while recording (after a split) the open bag is never deleted, even when it alone is over the limit
    rec.max_bag_size_bytes = 30_000
    for i in range(60):
        rec.write("/x", "std_msgs/msg/UInt8MultiArray", {"data": np.full(5_000, i % 256, dtype=np.uint8)})
    assert rec.bag_dir.exists() and not any(p.exists() for p in old)
    assert crashed.exists() and other.bag_dir.exists()
    rec.close()
    other.close()
    assert rosbags_count(rec.bag_dir) == 60


def test_retention_by_age(tmp_path):
    young = _our_old_bag(tmp_path, 100, 60)
    old = _our_old_bag(tmp_path, 100, 7200)
    unrelated = tmp_path / "notes"
    unrelated.mkdir()
    rec = Recorder(tmp_path, retention_max_age_s=3600)
    rec.close()
    assert not old.exists() and young.exists() and unrelated.exists()


# ---- issue 24 item 1: retention touches only bags this recorder family wrote
def _foreign_things(root: Path) -> list[Path]:
    """What a user keeps beside our bags: an old rosbag2 bag of another tool (rosbag2-like name too),
    a plain old folder, an old file; all very old and big."""
    things = [_old_bag(root, "experiment_march", 200_000, 8 * 86400),
              _old_bag(root, "rosbag2_2001_01_01-00_00_00", 200_000, 30 * 86400)]
    plain = root / "user_dir"
    plain.mkdir()
    (plain / "data.bin").write_bytes(bytes(300_000))
    (root / "notes.txt").write_text("mine")
    things += [_age(plain, 9 * 86400), root / "notes.txt"]
    return things


@pytest.mark.parametrize("rule", ["size", "age", "both"])
def test_a_foreign_bag_beside_ours_survives_every_retention_rule(tmp_path, rule):
    foreign = _foreign_things(tmp_path)
    ours = [_our_old_bag(tmp_path, 1000, 8 * 86400) for _ in range(2)]
    kw = {"size": {"retention_max_total_bytes": 1}, "age": {"retention_max_age_s": 3600},
          "both": {"retention_max_total_bytes": 1, "retention_max_age_s": 1}}[rule]
    logs = []
    rec = Recorder(tmp_path, log=logs.append, **kw)
    rec.write("/x", "std_msgs/msg/Float64", {"data": 1.0})
    rec.close()
    assert all(p.exists() for p in foreign), [line for line in logs if "retention" in line]
    assert not any(p.exists() for p in ours)           # ours went: the rules did act
    assert rec.status()["bags_deleted"] == 2
    assert not any("experiment_march" in line or "user_dir" in line for line in logs)
    # a foreign bag whose name got into the manifest (a user copied a bag in under a listed name) has no
    # marker in its metadata.yaml: still never deleted
    intruder = _old_bag(tmp_path, ours[0].name, 1000, 9 * 86400)
    rec2 = Recorder(tmp_path, retention_max_total_bytes=1, retention_max_age_s=1)
    rec2.close()
    assert intruder.exists() and all(p.exists() for p in foreign)


def test_record_dir_never_sweeps_its_parent(tmp_path):
    foreign = _foreign_things(tmp_path)
    logs = []
    rec = Recorder(bag_dir=tmp_path / "run1", retention_max_total_bytes=1, retention_max_age_s=1, log=logs.append)
    rec.write("/x", "std_msgs/msg/Float64", {"data": 1.0})
    rec.close()
    assert all(p.exists() for p in foreign) and rosbags_count(tmp_path / "run1") == 1
    assert rec.status()["bags_deleted"] == 0
    assert any("retention off" in line for line in logs)
    assert not (tmp_path / ".jident_ros_bags").exists()


_KILLED = textwrap.dedent("""
    import os, signal, sys, numpy as np
    from jident_ros.bag.rotating_recorder import Recorder
    rec = Recorder(sys.argv[1], max_bag_size_bytes=20_000, chunk_size=4_000, compression=None)
    for i in range(int(sys.argv[2])):
        rec.write("/x", "std_msgs/msg/UInt8MultiArray", {"data": np.full(3_000, i % 256, dtype=np.uint8)})
    rec.flush()
    print(rec.bag_dir, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
""")


@pytest.mark.parametrize("messages", [3, 30])   # killed before any split (no metadata.yaml), and after splits
def test_a_killed_bag_survives_retention_unless_the_user_opts_in(tmp_path, messages):
    r = subprocess.run([sys.executable, "-c", _KILLED, str(tmp_path), str(messages)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == -signal.SIGKILL, r.stderr
    killed = Path(r.stdout.strip())
    assert killed.is_dir() and killed.name in (tmp_path / ".jident_ros_bags").read_text().split()
    _age(killed, 30 * 86400)
    logs = []
    rec = Recorder(tmp_path, retention_max_total_bytes=1, retention_max_age_s=1, log=logs.append)
    rec.close()
    assert killed.exists(), logs
    assert rec.status()["bags_kept_unfinalised"] == 1
    assert sum(f"kept {killed}: not finalised" in line for line in logs) == 1
    # salvage still works on it; then the user opts in and retention may delete it
    salvaged = tmp_path.parent / f"{tmp_path.name}_salvaged"
    from jident_ros.bag.salvage import salvage
    report = salvage(killed, salvaged)
    assert report["messages_recovered"] >= 1
    rec = Recorder(tmp_path, retention_max_total_bytes=1, retention_max_age_s=1, retention_delete_unfinalised=True)
    rec.close()
    assert not killed.exists() and salvaged.exists()


# ------------------------------------------------------------------ failures: disk full, I/O errors
def test_enospc_finalises_what_was_written_and_counts_the_drops(tmp_path, monkeypatch):
    rec = Recorder(tmp_path, chunk_size=10_000, compression=None)
    for i in range(10):
        rec.write("/drive/signals", SIGNALS, batch(i))
    rec.flush()
    real_write = os.write
    calls = []

    def full(fd, data):               # the next chunk: half goes to disk, then the disk is full
        calls.append(len(data))
        if len(calls) == 1:
            return real_write(fd, bytes(data[:len(data) // 2]))
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)   # the cut-back chunk made room for the summary

    monkeypatch.setattr(os, "write", full)
    results = [rec.write("/drive/signals", SIGNALS, batch(i)) for i in range(10, 30)]
    monkeypatch.setattr(os, "write", real_write)
    st = rec.status()
    assert st["state"] == "error" and "disk full" in st["error"], st
    written = sum(results)
    assert st["messages_dropped"] == sum(st["drop_reasons"].values()) and written < 20
    assert st["drop_reasons"]["disk full"] >= 1 and st["drop_reasons"]["lost in the unwritten chunk"] >= 1
    assert st["messages_written"] + st["messages_dropped"] == 30
    rec.close()
    rec.close()   # idempotent
    assert rec.status()["state"] == "error"
    # the part already written is a finalised bag: summary, metadata.yaml, read by rosbags
    info = read_metadata(rec.bag_dir)
    assert info["message_count"] == st["messages_written"] >= 10
    assert is_finalised(next(rec.bag_dir.glob("*.mcap")))
    assert rosbags_count(rec.bag_dir) == st["messages_written"]


def test_disk_full_on_a_real_tiny_filesystem(tmp_path):
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a 200 kB tmpfs here ({r.stderr.strip() or 'not root'})")
    try:
        rec = Recorder(mnt, chunk_size=20_000, compression=None)
        results = [rec.write("/drive/signals", SIGNALS, batch(i)) for i in range(200)]   # ~720 kB
        rec.close()
        st = rec.status()
        assert "disk full" in st["error"] and st["messages_dropped"] > 0
        assert st["messages_written"] + st["messages_dropped"] == 200 and sum(results) >= st["messages_written"]
        bag = rec.bag_dir
        assert is_finalised(next(bag.glob("*.mcap"))), "the written part was not finalised"
        assert rosbags_count(bag) == st["messages_written"] > 0
        assert read_metadata(bag)["message_count"] == st["messages_written"]
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


def test_unrecordable_message_is_counted_not_raised(tmp_path):
    rec = Recorder(tmp_path)
    assert not rec.write("/x", "std_msgs/msg/Float64", {"data": "abc"})
    assert not rec.write("/y", "no_such/msg/Type", {})
    assert rec.write("/x", "std_msgs/msg/Float64", {"data": 1.0})
    rec.close()
    assert not rec.write("/x", "std_msgs/msg/Float64", {"data": 2.0})
    st = rec.status()
    assert st["drop_reasons"] == {"unrecordable message": 2, "recorder closed": 1}
    assert "expected a number" in st["error"] or "no definition" in st["error"]


# ------------------------------------------------------------------ time stamps
def test_messages_are_stamped_with_the_wall_clock(tmp_path):
    before = time.time_ns()
    rec = Recorder(tmp_path)
    rec.write("/drive/signals", SIGNALS, batch(0))
    rec.write("/drive/signals", SIGNALS, batch(1), t_ns=5)   # an explicit stamp is kept
    rec.close()
    after = time.time_ns()
    stamps = [m.log_time_ns for m in read_bag(rec.bag_dir)]
    assert stamps[0] == 5 and before <= stamps[1] <= after


# ------------------------------------------------------------------ stops
CHILD = """
import sys, time, signal
sys.path.insert(0, {repo!r})
import numpy as np
from jident_ros.bag.rotating_recorder import Recorder
from jident_ros.bag.close_on_signal import install_signal_handlers
rec = Recorder(sys.argv[1], flush_age_s=None)
install_signal_handlers(rec)
msg = {{"layout": {{"dim": [{{"label": "sample", "size": 2, "stride": 18}}, {{"label": "t", "size": 9, "stride": 9}}]}},
       "data": np.zeros(18)}}
i = 0
while True:
    rec.write("/drive/signals", "std_msgs/msg/Float64MultiArray", msg)
    i += 1
    if i == 50:
        print("ready", flush=True)
"""


@pytest.mark.parametrize("sig, inherited", [("SIGTERM", "default"), ("SIGINT", "default"),
                                            ("SIGINT", "ignored"), ("SIGTERM", "ignored")])
def test_signal_under_load_finalises_the_bag(tmp_path, sig, inherited):
    """The signal finalises the bag and ends the process, also when the child inherited it ignored
    (before the fix, SIGINT then closed the bag and the write loop spun on, dropping every message)."""
    script = tmp_path / "child.py"
    script.write_text(CHILD.format(repo=str(REPO)))
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path / "root")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            # "ignored": inherited SIG_IGN, as SIGINT in a background job of a script
                            preexec_fn=(lambda: signal.signal(getattr(signal, sig), signal.SIG_IGN))
                            if inherited == "ignored" else None)
    assert proc.stdout.readline().startswith("ready"), proc.stderr.read()
    time.sleep(0.2)
    proc.send_signal(getattr(signal, sig))
    try:
        rc = proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError(f"{sig} ({inherited} before): the child did not stop") from None
    assert rc == -getattr(signal, sig)   # SIGINT: an uncaught KeyboardInterrupt ends Python by SIGINT
    assert sig != "SIGINT" or "KeyboardInterrupt" in proc.stderr.read()
    (bag,) = [p for p in (tmp_path / "root").iterdir() if p.is_dir()]
    assert (tmp_path / "root" / ".jident_ros_bags").read_text() == bag.name + "\n"   # the manifest
    info = read_metadata(bag)
    assert info["message_count"] >= 50
    assert rosbags_count(bag) == info["message_count"]


def test_close_from_atexit_finalises(tmp_path):
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(REPO)!r})
        from jident_ros.bag.rotating_recorder import Recorder
        rec = Recorder({str(tmp_path / 'root')!r}, flush_age_s=None)
        rec.write("/x", "std_msgs/msg/Float64", {{"data": 1.5}})
        """)   # no close: the interpreter's exit does it
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
    (bag,) = [p for p in (tmp_path / "root").iterdir() if p.is_dir()]
    assert (tmp_path / "root" / ".jident_ros_bags").read_text() == bag.name + "\n"   # the manifest
    assert [m.message.data for m in read_bag(bag)] == [1.5]


def test_an_unfinalised_split_bag_is_read_by_salvaging_it(tmp_path):
    """SIGKILL after a split: metadata.yaml lists the finished file, the open one has no summary.
    read_bag (diagnose, replay) salvages it on the fly and says so in one line; `jident salvage` makes a
    finalised copy of the whole split bag."""
    code = textwrap.dedent(f"""
        import sys, os, signal
        sys.path.insert(0, {str(REPO)!r})
        from jident_ros.bag.rotating_recorder import Recorder
        rec = Recorder({str(tmp_path / 'root')!r}, max_bag_size_bytes=1500, chunk_size=1000, flush_age_s=None)
        for i in range(40):
            rec.write("/x", "std_msgs/msg/Float64", {{"data": float(i)}})
            if i % 4 == 3:
                rec.flush()
        os.kill(os.getpid(), signal.SIGKILL)
        """)
    subprocess.run([sys.executable, "-c", code], timeout=60)
    (bag,) = [p for p in (tmp_path / "root").iterdir() if p.is_dir()]
    assert (tmp_path / "root" / ".jident_ros_bags").read_text() == bag.name + "\n"   # the manifest
    files = sorted(bag.glob("*.mcap"))
    assert len(files) >= 2
    listed = read_metadata(bag)["relative_file_paths"]
    assert len(listed) == len(files) - 1        # the open file was not listed yet
    with pytest.raises(RecordingError, match="jident salvage"):
        list(read_bag(bag))
    notes = []
    values = [m.message.data for m in read_bag(bag, on_salvage=notes.append)]
    assert values == [float(i) for i in range(40)]
    assert len(notes) == 1 and "not finalised" in notes[0] and "salvaging" in notes[0]
    assert salvage_main([str(bag), str(tmp_path / "copy")]) == 0
    assert rosbags_count(tmp_path / "copy") == 40
    assert len(yaml.safe_load((tmp_path / "copy" / "metadata.yaml").read_text())[
        "rosbag2_bagfile_information"]["relative_file_paths"]) == len(files)


def test_memory_of_a_huge_message_is_given_back(tmp_path):
    """Issue 15 item 11: after a 200 MB message the writer keeps no buffer of it."""
    code = textwrap.dedent(f"""
        import sys, numpy as np
        sys.path.insert(0, {str(REPO)!r})
        from jident_ros.bag.rotating_recorder import Recorder
        def rss():
            return int(open("/proc/self/statm").read().split()[1]) * 4096
        rec = Recorder({str(tmp_path / 'root')!r}, compression=None)
        rec.write("/x", "std_msgs/msg/Float64", {{"data": 1.0}})
        rec.flush()
        base = rss()
        big = np.ones(25_000_000).tobytes()
        cdr = b"\\x00\\x01\\x00\\x00" + (0).to_bytes(4, "little") * 2 + (25_000_000).to_bytes(4, "little") + big
        del big
        rec.write("/big", "std_msgs/msg/Float64MultiArray", cdr)
        rec.flush()
        del cdr
        print(base, rss())
        rec.close()
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True).stdout
    base, after = map(int, out.split())
    assert after - base < 20e6, (base, after)
