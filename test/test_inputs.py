"""Standard inputs (jident_ros/stream/inputs.py): JointState per sample -> the batched path's windows, IMU a1 by
stamp, NaN = absent, missing joints, period/jitter, CSV with --map."""
from __future__ import annotations

import math

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.research.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector
from jident_ros.stream.detector import stream_batches
from jident_ros.stream.inputs import InputError, JointStateAdapter, parse_map, read_csv

CH = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1")


@pytest.fixture(scope="module")
def recording():
    system = load_system_config()
    rec = raw_recordings(system, (1.102,), (0.005,), snr_db=30.0, steady_s=0.3, seed=4, channels=CH)[0]
    return system, rec


def joint_messages(rec, imu=False):
    col = rec.column
    for k in range(len(rec.data)):
        yield (float(col("t")[k]), ["load", "motor"], [col("alpha2")[k], col("alpha1")[k]],
               [col("omega2")[k], col("omega1")[k]], [math.nan, col("m_el")[k]])


def test_jointstate_per_sample_gives_the_batched_paths_windows(recording):
    system, rec = recording
    ref = [e.window for e in run_detector(flank_detector(system, channels=CH), rec) if e.kind == "window"]
    ad = JointStateAdapter(system.sampling.sample_period_s, use_imu=True, batch_size=37)
    det = flank_detector(system, channels=CH)
    evs = []
    a1 = rec.column("a1")
    for k, msg in enumerate(joint_messages(rec)):
        batches = ad.push(*msg)
        if k % 3 == 0:      # the IMU message sometimes comes first, sometimes after
            batches += ad.push_imu(msg[0] + 1e-6, (a1[k], 0.0, 9.81))
        else:
            batches += ad.push_imu(msg[0] - 1e-6, (a1[k], 0.0, 9.81))
        for arr, ch in batches:
            evs += det.push(arr, ch)
    for arr, ch in ad.flush():
        evs += det.push(arr, ch)
    got = [e.window for e in evs if e.kind == "window"]
    assert len(got) == len(ref) == 1
    assert set(got[0].channels) == set(CH)
    for c in CH:
        np.testing.assert_array_equal(got[0].column(c), ref[0].column(c))
    assert got[0].backlash_width_estimate_m == ref[0].backlash_width_estimate_m
    j = ad.jitter()
    assert j["period_matches"] and j["max_abs_deviation_s"] < 1e-9
    assert ad.counts["imu_unmatched"] == 0


def _chunked(ad, n, first="joint", t0=1.0, ts=5e-4):
    """n JointStates and n Imu messages, one topic's whole backlog before the other's (a node started behind a
    running drive, or stalled); returns the rows handed out."""
    js = [(t0 + k * ts, ["motor", "load"], [0.01 * k, 0.0], [1.0, 1.0], [2.0, 0.0]) for k in range(n)]
    imu = [(t0 + k * ts + 1e-6, (0.1 * k, 0.0, 9.81)) for k in range(n)]
    out = []
    pushes = [lambda m=m: ad.push(*m) for m in js]
    pushes_imu = [lambda m=m: ad.push_imu(*m) for m in imu]
    for f in (pushes + pushes_imu) if first == "joint" else (pushes_imu + pushes):
        out += f()
    return np.vstack([b for b, _ in out + ad.flush()]) if out or ad.waiting_for_imu else np.empty((0, 6))


@pytest.mark.parametrize("first", ["joint", "imu"])
def test_one_topics_backlog_before_the_others_loses_no_sample(first):
    """A JointState waits for its Imu message while the Imu stream has not reached its stamp (and an Imu message for
    its JointState): 1500 of each, one topic's backlog delivered whole before the other's.  With stop 43's bound of
    20 samples, 1480 JointStates were dropped (imu_unmatched) when the JointStates came first."""
    ad = JointStateAdapter(5e-4, batch_size=50, use_imu=True, channels=("alpha1", "omega1", "m_el"))
    rows = _chunked(ad, 1500, first)
    assert ad.imu_wait_samples == 4000                     # IMU_WAIT_S (2 s) at 2 kHz
    assert rows.shape[0] == 1500 and ad.counts["imu_unmatched"] == 0 and ad.counts["imu_unused"] == 0
    np.testing.assert_allclose(rows[:, -1], 0.1 * np.arange(1500))      # each sample got its own a1


def test_a_silent_imu_drops_samples_after_the_bound_and_counts_them():
    """No Imu at all: a sample waits imu_wait_samples samples, then is dropped and counted (never silently), and the
    rest at the end of the input; Imu messages no JointState takes (the joint states stopped) are counted too."""
    ad = JointStateAdapter(5e-4, batch_size=50, use_imu=True, imu_wait_samples=100, channels=("alpha1",))
    for k in range(250):
        assert ad.push(1.0 + k * 5e-4, ["motor", "load"], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]) == []
    assert ad.counts["imu_unmatched"] == 150 and ad.waiting_for_imu == 100
    assert "no Imu message for 100 samples (0.05 s of drive time)" in ad.last_problem
    assert ad.flush() == [] and ad.counts["imu_unmatched"] == 250 and ad.waiting_for_imu == 0
    ad2 = JointStateAdapter(5e-4, use_imu=True, imu_wait_samples=100, channels=("alpha1",))
    for k in range(250):
        ad2.push_imu(1.0 + k * 5e-4, (0.0, 0.0, 9.81))
    assert ad2.counts["imu_unused"] == 150
    with pytest.raises(ValueError, match="imu_wait_samples"):
        JointStateAdapter(5e-4, use_imu=True, imu_wait_samples=0)


def test_channels_from_the_configuration_bad_messages_dropped_missing_joint_named(recording):
    system, rec = recording
    ad = JointStateAdapter(5e-4, motor_joint="m", load_joint="l", batch_size=2,
                           channels=("alpha1", "omega1", "m_el", "alpha2"))
    assert ad.channels == ("t", "alpha1", "omega1", "m_el", "alpha2")     # from the configuration, not a message
    assert ad.push(1.0, ["m", "l"], [1.0, 2.0], [3.0, math.nan], [4.0, 5.0]) == []   # load velocity not used
    out = ad.push(1.0005, ["m", "l"], [1.1, math.nan], [3.0, 0.0], [4.0, 5.0])      # a NaN in a used field
    assert out == [] and ad.counts["nonfinite"] == 1 and "joint 'l' position: nan" in ad.last_problem
    assert ad.push(1.001, ["m"], [1.0], [1.0], [1.0]) == [] and ad.counts["missing_joint"] == 1
    assert "joint 'l' (load_joint) not in the JointState names ['m']" in ad.problems()[-1][0]
    out = ad.push(1.0025, ["m", "l"], [1.0, 2.0], [1.0, 1.0], [1.0, 1.0])
    assert len(out) == 1 and out[0][0].shape == (2, 5) and np.isfinite(out[0][0]).all()
    assert not ad.jitter()["period_matches"] or ad.jitter()["max_abs_deviation_s"] > 1e-4
    with pytest.raises(ValueError, match="imu_axis"):
        JointStateAdapter(5e-4, imu_axis="w")
    with pytest.raises(ValueError, match="motor_joint"):
        JointStateAdapter(5e-4, motor_joint="a", load_joint="a")
    with pytest.raises(ValueError, match="channels"):
        JointStateAdapter(5e-4, channels=("a2",))


def test_csv_with_and_without_map(tmp_path, recording):
    system, rec = recording
    p = tmp_path / "trace.csv"
    cols = ["time_ms", "enc_motor", "alpha2", "m_el", "note"]
    counts = 2 * math.pi / 65536
    with open(p, "w") as f:
        f.write(",".join(cols) + "\n")
        for k in range(5):
            f.write(f"{1000 + k * 0.5},{k * 7},{0.1 * k},{150.5},x\n")
    data, ch, ignored = read_csv(p, parse_map(f"t=time_ms:0.001,alpha1=enc_motor:{counts!r}"))
    assert ch == ("t", "alpha1", "alpha2", "m_el") and ignored == ["note"]
    np.testing.assert_allclose(data[:, 0], 1.0 + 0.0005 * np.arange(5))
    np.testing.assert_allclose(data[:, 1], 7 * counts * np.arange(5))
    with pytest.raises(InputError, match="no time column"):
        read_csv(p)
    with pytest.raises(InputError, match="unknown channel 'torque'"):
        parse_map("torque=x")
    with pytest.raises(InputError, match="scale 'abc'"):
        parse_map("t=time_ms:abc")
    bad = tmp_path / "bad.csv"
    bad.write_text("t,alpha1\n0.0,1.0\n0.0005,oops\n")
    with pytest.raises(InputError, match="line 3: column 'alpha1' value 'oops'"):
        read_csv(bad)
    # the documented names need no map; a CSV of a recording gives the same windows as its array
    full = tmp_path / "full.csv"
    np.savetxt(full, rec.data, delimiter=",", header=",".join(rec.channels), comments="", fmt="%.17g")
    data, ch, _ = read_csv(full)
    assert ch == ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1")
    det = flank_detector(system, channels=CH)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)]
    ref = [e.window for e in run_detector(flank_detector(system, channels=CH), rec) if e.kind == "window"]
    got = [e.window for e in evs if e.kind == "window"]
    np.testing.assert_array_equal(got[0].data, ref[0].data)


def test_an_imu_faster_than_the_joint_states_is_no_drop_offline():
    """An Imu at twice the JointState rate: every sample gets its a1, the other Imu messages are counted
    (jointstate.imu_unused) and said, but not among the drops of `jident diagnose`'s summary (no drive sample lost)."""
    from types import SimpleNamespace

    from jident_ros.cli.offline import _input_counts
    ad = JointStateAdapter(5e-4, batch_size=10, use_imu=True, channels=("alpha1",))
    out = []
    for k in range(40):
        out += ad.push_imu(1.0 + k * 2.5e-4, (0.0, 0.0, 9.81))
        if k % 2 == 0:
            out += ad.push(1.0 + k * 2.5e-4, ["motor", "load"], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    out += ad.flush()
    assert sum(b.shape[0] for b, _ in out) == 20 and ad.counts["imu_unmatched"] == 0
    assert ad.counts["imu_unused"] >= 19
    lines, result = [], SimpleNamespace(dropped={}, jitter=None)
    _input_counts(result, ad, "x.mcap", 5e-4, lines.append)
    assert not any(k.startswith("jointstate.imu_unused") for k in result.dropped) and result.dropped == {}
    assert any("Imu message(s) matched no JointState sample" in line for line in lines)
