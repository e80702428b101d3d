"""The diagnostic node's recording under SIGTERM and SIGKILL in the middle of a run (issue 4).

* SIGTERM while signals stream in: the node exits 0, the MCAP is finalised (summary, metadata.yaml), an
  independent reader (rosbags) reads every message, and nothing the node had received is missing.
* SIGKILL while signals stream in: the file has no summary; `jident salvage` recovers every complete chunk:
  a gap-free prefix of the stream, losing at most the chunk that was open (flushed every 0.5 s).
"""
from __future__ import annotations

import re
import signal
import subprocess
import sys

import numpy as np
import pytest
from test_nodes import Proc, Ros, library, logs, node_env  # noqa: F401  (fixtures)

TS = 5e-4


def _run_until_mid_stream(node_env, library, tmp_path, ns, sig):
    from std_msgs.msg import Float64MultiArray

    from jident_ros.nodes.ros_io import array_from_multiarray, qos_signals
    bag = tmp_path / "bag"
    ros = Ros(f"jident_test_{ns}")
    got = ros.collect(Float64MultiArray, f"/{ns}/drive/signals", qos_signals())
    nsarg = ["-r", f"__ns:=/{ns}"]
    procs = []
    try:
        diag = Proc(node_env, tmp_path, "diagnostic", *nsarg, "-p", f"pattern_library:={library}",
                    "-p", f"record_dir:={bag}", "-p", "stale_after_s:=0.0")
        win = Proc(node_env, tmp_path, "windowing", *nsarg)
        procs += [diag, win]
        # 6 cases at 1x real time: about 7 s of streaming; the signal comes after about 2.5 s of it
        sim = Proc(node_env, tmp_path, "simulator", *nsarg, "-p", "cases:=product",
                   "-p", "inertias_kgm2:=[1.16, 1.073, 1.218, 1.131, 1.102, 1.189]",
                   "-p", "real_time_factor:=1.0", "-p", "wait_for_subscribers:=3", "-p", "publish_clock:=false")
        procs.append(sim)
        assert ros.spin_until(lambda: len(got) >= 100, 60), logs(*procs)
        assert sim.alive(), logs(sim)
        rc = diag.stop(sig)
        received = [array_from_multiarray(m)[0] for m in got]
        return bag, rc, received, logs(diag)
    finally:
        for p in procs:
            p.stop()
        ros.close()


def _check_prefix(batches, reference, ahead_max: int | None = 5 * 50):
    """The recorded batches are gap-free from the first sample the test received on and equal to what the
    test received where both have samples.  ``ahead_max``: how many samples more than the test had received
    when it sent the signal the recorder may hold (both listen to the same stream; the test stops listening
    first); None: no bound (the test's own subscriber may lag behind under load)."""
    t = np.concatenate([b[:, 0] for b in batches])
    assert np.all(np.abs(np.diff(t) - TS) < 1e-9), "samples missing inside the recording"
    ref = np.concatenate([b[:, 0] for b in reference])
    assert t[0] == ref[0], (t[0], ref[0])
    assert ahead_max is None or t.size <= ref.size + ahead_max, (t.size, ref.size)
    n = min(t.size, ref.size)
    assert np.array_equal(t[:n], ref[:n])
    return n, ref.size


@pytest.mark.ros
def test_sigterm_mid_run_finalises_the_recording(node_env, library, tmp_path):
    from rosbags.highlevel import AnyReader

    from jident_ros.bag.reader import read_bag
    bag, rc, received, log = _run_until_mid_stream(node_env, library, tmp_path, "sigterm", signal.SIGTERM)
    assert rc == 0, log
    assert (bag / "metadata.yaml").is_file(), log
    ours = [m for m in read_bag(bag) if m.topic == "/sigterm/drive/signals"]
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/sigterm/drive/signals"]
        theirs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
    assert len(theirs) == len(ours) > 0
    # nothing the node had taken in is missing: its own count (logged at close) is what the bag holds
    (line,) = [x for x in log.splitlines() if "recording finalised: " in x]
    written, dropped = map(int, re.search(r"(\d+) message\(s\) written, (\d+) dropped", line).groups())
    assert dropped == 0 and written == len(list(read_bag(bag))), line
    # gap-free from the start of the stream; how far the node and this test's own subscriber are apart at
    # the signal depends on the load (a diagnosis callback holds the node's single thread; a busy machine
    # starves this process), so it is printed, not bounded by a few batches as before
    n_rec, n_ref = _check_prefix([np.asarray(m.message.data).reshape(-1, 9) for m in ours], received,
                                 ahead_max=None)
    print(f"SIGTERM: {n_rec} samples recorded; this test had received {n_ref} at the signal")
    assert n_rec >= 10 * 50, (n_rec, n_ref)   # recorded while it streamed, not only at the end


@pytest.mark.ros
def test_sigkill_mid_run_then_salvage_recovers_the_complete_chunks(node_env, library, tmp_path):
    from jident_ros.bag.errors import RecordingError
    from jident_ros.bag.reader import read_bag
    bag, rc, received, log = _run_until_mid_stream(node_env, library, tmp_path, "sigkill", signal.SIGKILL)
    assert rc == -signal.SIGKILL
    mcap = next(bag.glob("*.mcap"))
    with pytest.raises(RecordingError):
        list(read_bag(bag))
    out = tmp_path / "salvaged"
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "salvage", str(mcap), str(out)],
                       capture_output=True, text=True, timeout=60, env=node_env)
    assert r.returncode == 0, r.stderr
    sig = [m for m in read_bag(out) if m.topic == "/sigkill/drive/signals"]
    assert sig, r.stdout
    # how far the recorder ran ahead of this test's own subscriber depends on the load (a fresh clone's run: 900
    # samples, 18 batches, against the 5 allowed before): not bounded, as for SIGTERM; what salvage must give back is
    # bounded below
    n_rec, n_ref = _check_prefix([np.asarray(m.message.data).reshape(-1, 9) for m in sig], received, ahead_max=None)
    # chunks are flushed every 0.5 s (node timer): at 1x real time at most ~0.5 s + in flight is lost
    print(f"SIGKILL: {n_rec} of {n_ref} samples recovered")
    assert n_ref - n_rec <= int(1.0 / TS), (n_rec, n_ref)


# --------------------------------------------------------------------------- many stops (issue 15, item 1)


def _stop_many(node_env, library, tmp_path, n_stops: int, concurrency: int, seed: int = 0):
    """Start recording diagnostic nodes under load (this process streams drive/signals batches and
    windows into their namespaces), stop each with SIGINT or SIGTERM at a random moment after its
    recording began (during the library load, the subscriptions' creation or the spin), and return
    [(signal, returncode, bag finalised, messages, log)]."""
    import random
    import threading
    import time

    from std_msgs.msg import Float64MultiArray
    from test_nodes import _good_stream

    from jident_ros.bag.reader import read_bag
    from jident_ros.nodes.ros_io import multiarray_from_array, qos_latched, qos_signals, window_to_msg
    from jident_ros.stream.detector import BacklashDetector
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    rng = random.Random(seed)
    _, (stream, _) = _good_stream()
    (ev,) = BacklashDetector(0.005, 0.1, 5e-4).push(stream, DEFAULT_CHANNELS)
    window = window_to_msg(ev.window)
    batches = [multiarray_from_array(stream[s:s + 50], DEFAULT_CHANNELS) for s in range(0, len(stream), 50)]
    ros = Ros("jident_test_stops")
    namespaces = [f"/stop{k}" for k in range(concurrency)]
    sig_pubs = [ros.node.create_publisher(Float64MultiArray, f"{ns}/drive/signals", qos_signals()) for ns in namespaces]
    win_pubs = [ros.node.create_publisher(Float64MultiArray, f"{ns}/drive/window", qos_latched(10))
                for ns in namespaces]
    stop_load = threading.Event()

    def load():  # ~40 batches/s and a window every 0.5 s into every namespace
        k = 0
        while not stop_load.is_set():
            for p in sig_pubs:
                p.publish(batches[k % len(batches)])
            if k % 20 == 0:
                for p in win_pubs:
                    p.publish(window)
            k += 1
            time.sleep(0.025)

    loader = threading.Thread(target=load, daemon=True)
    loader.start()
    results = []
    try:
        done = 0
        while done < n_stops:
            batch = []
            for slot in range(min(concurrency, n_stops - done)):
                bag = tmp_path / f"bag{done + slot}"
                sig = signal.SIGINT if (done + slot) % 2 == 0 else signal.SIGTERM
                p = Proc(node_env, tmp_path, "diagnostic", "-r", f"__ns:={namespaces[slot]}",
                         "-p", f"pattern_library:={library}", "-p", f"record_dir:={bag}", "-p", "stale_after_s:=0.0")
                batch.append((p, bag, sig, rng.uniform(0.0, 1.5)))
            for p, bag, sig, delay in batch:
                end = time.monotonic() + 60
                while time.monotonic() < end and p.alive() and "recording to" not in p.text():
                    time.sleep(0.02)
                time.sleep(delay)
                rc = p.stop(sig, timeout=30)
                try:
                    n = sum(1 for _ in read_bag(bag))
                    ok = (bag / "metadata.yaml").is_file()
                except Exception as exc:  # not finalised
                    n, ok = f"{type(exc).__name__}: {exc}", False
                results.append((sig, rc, ok, n, p.text()[-2000:]))
            done += len(batch)
    finally:
        stop_load.set()
        loader.join(5)
        ros.close()
    return results


def _report(results):
    finalised = sum(ok for _, _, ok, _, _ in results)
    segv = sum(rc == -signal.SIGSEGV for _, rc, _, _, _ in results)
    bad = [(s.name, rc, n, log) for s, rc, ok, n, log in results if not ok or rc != 0]
    print(f"{len(results)} stops (SIGINT and SIGTERM, random moments, under load): {finalised} finalised bags, "
          f"{segv} SIGSEGV, {len(bad)} not clean")
    return finalised, segv, bad


@pytest.mark.ros
def test_four_stops_under_load_finalise_every_bag(node_env, library, tmp_path):
    """The fast variant of the 200-stop test (4 nodes at once; -m slow runs the 200)."""
    results = _stop_many(node_env, library, tmp_path, n_stops=4, concurrency=4, seed=1)
    finalised, segv, bad = _report(results)
    assert finalised == 4 and segv == 0 and not bad, bad[:2]


@pytest.mark.ros
@pytest.mark.slow
def test_200_stops_under_load_finalise_every_bag(node_env, library, tmp_path):
    """Issue 15 target: 200/200 finalised bags, 0 SIGSEGV (about 10 minutes)."""
    results = _stop_many(node_env, library, tmp_path, n_stops=200, concurrency=4, seed=2)
    finalised, segv, bad = _report(results)
    assert finalised == 200 and segv == 0 and not bad, bad[:2]
