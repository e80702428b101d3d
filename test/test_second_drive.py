"""The second, independent drive model (issue 12 part 5): physics, sensors, recordings, CLI.

Kept fast (< 30 s for the file): one module-scoped vectorised run of 8 cases,
a few tiny extra runs.
"""
from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from jident_ros.research.second_drive import model as M
from jident_ros.research.second_drive import record as R

PKG = Path(M.__file__).resolve().parent
P = M.DriveParams()
TS = P.sample_period_s
CASES = R.grid_cases(("forward", "reverse"), (1.16, 0.957), (0.0025, 0.01))
STEADY_S = 0.5


@pytest.fixture(scope="module")
def run():
    res, n_steady, drive = R.simulate_grid(P, CASES, steady_s=STEADY_S, post_s=1.3)
    return res, n_steady, drive


@pytest.fixture(scope="module")
def recs():
    return R.build_grid(P, CASES[:2] + CASES[4:5], R.SensorConfig(), steady_s=0.2, post_s=1.25, seed=7)


def _first_gap(res, c, start):
    g = M.gaps(res.delta[:, c], res.theta_b[:, c], start)
    assert g, f"no entry for case {CASES[c]}"
    return g[0]


# ---------------------------------------------------------------------------------------------- independence
def test_no_module_imports_our_simulator():
    files = sorted(PKG.glob("*.py"))
    assert {f.name for f in files} >= {"__init__.py", "model.py", "record.py", "__main__.py"}
    for f in files:
        tree = ast.parse(f.read_text(), str(f))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                if node.level >= 2:                  # from ..x import y  ->  jident_ros.x
                    mod = "jident_ros." + mod if mod else "jident_ros"
                names = [mod] + [f"{mod}.{a.name}" for a in node.names]
            else:
                continue
            for n in names:
                assert not (n == "jident_ros.sim" or n.startswith("jident_ros.sim.")), f"{f.name} imports {n}"
                assert not n.startswith("jident_ros.") or n.startswith("jident_ros.research.second_drive"), \
                    f"{f.name} imports product code {n}"


# ---------------------------------------------------------------------------------------------- physics
def test_coupling_transmits_exactly_zero_inside_the_zone(run):
    res, n_steady, drive = run
    inside = np.abs(res.delta) < res.theta_b
    assert inside.sum() > 100
    assert np.all(res.coupling_torque[inside] == 0.0)
    assert np.all(res.coupling_torque[np.abs(res.delta) > res.theta_b + 1e-6] != 0.0)
    # also the law itself, with any relative speed (the damping term must not act in the zone)
    rng = np.random.default_rng(1)
    th = np.full(1000, 0.05)
    d = rng.uniform(-0.05, 0.05, 1000)
    assert np.all(drive.coupling_torque(d, rng.normal(0, 50, 1000), th) == 0.0)
    # Hertz law on the flank: k pen^1.5 at zero penetration rate
    t = drive.coupling_torque(np.array([0.06, -0.06]), np.zeros(2), np.array([0.05, 0.05]))
    np.testing.assert_allclose(t, [P.coupling.hertz_stiffness * 0.01 ** 1.5, -P.coupling.hertz_stiffness * 0.01 ** 1.5])


def test_motor_equation_holds_in_the_gap_and_j1_is_identifiable(run):
    res, n_steady, _ = run
    sens = R.SensorConfig(encoder_counts=0)
    b1, r = P.motor.bearing_friction_nms, P.coupling.reference_radius_m
    for c, (_, j1, _) in enumerate(CASES):
        sig = R.measure(res, c, P, sens, np.random.default_rng(0), (0.0, 0.0))
        b, e = _first_gap(res, c, n_steady)
        assert e - b >= 20
        m = sig["m_el"][b:e] - b1 * sig["omega1"][b:e]
        a = sig["a1"][b:e] / r
        assert abs((m @ a) / (a @ a) / j1 - 1) < 1e-9          # accelerometer (model derivative)
        idx = np.arange(b + 1, e - 1)                          # central differences inside the gap only
        dw = (sig["omega1"][idx + 1] - sig["omega1"][idx - 1]) / (2 * TS)
        m = sig["m_el"][idx] - b1 * sig["omega1"][idx]
        assert abs((m @ dw) / (dw @ dw) / j1 - 1) < 1e-3
        # and the m_el of the gap is large: the event gives J1 something to act on
        assert np.median(np.abs(sig["m_el"][b:e])) > 0.5 * P.motor.rated_torque_nm


@pytest.mark.parametrize("direction,k2,gear", [("forward", 0.0025, 1.0), ("reverse", 0.01, 1.0),
                                               ("forward", 0.0062, 4.0), ("reverse", 0.0044, 4.0)])
def test_flank_to_flank_travel_is_twice_k2_over_r(direction, k2, gear):
    """Sampled finely (25 us) so that the travel between the first and last gap
    samples brackets 2 K2/r to 1 %; measured on the recorded (offset, quantised)
    encoder angles: alpha1 - N alpha2 minus the truth's relative offset."""
    p = replace(P, gear_ratio=gear, sample_period_s=2.5e-5, substeps=1)
    res, n_steady, _ = R.simulate_grid(p, [(direction, 1.1, k2)], steady_s=0.02, post_s=0.12)
    off = R.draw_offsets(np.random.default_rng(3), gear)
    sig = R.measure(res, 0, p, R.SensorConfig(encoder_counts=2 ** 20), np.random.default_rng(0), off)
    rel = sig["alpha1"] - gear * sig["alpha2"] - (off[0] - gear * off[1])
    b, e = _first_gap(res, 0, n_steady)
    travel = abs(rel[b] - rel[e - 1])
    assert travel == pytest.approx(2 * k2 / p.coupling.reference_radius_m, rel=0.01)
    # the flanks: left from +K2/r (forward) or -K2/r (reverse), hit the opposite one
    s = 1 if direction == "forward" else -1
    assert s * rel[b - 1] >= k2 / 0.08 - 2e-5 and -s * rel[e] >= k2 / 0.08 - 2e-5


def test_both_directions_enter_and_cross_both_ways(run):
    res, n_steady, _ = run
    for c, (direction, _, _) in enumerate(CASES):
        g = M.gaps(res.delta[:, c], res.theta_b[:, c], n_steady)
        s = 1.0 if direction == "forward" else -1.0
        assert np.sign(res.omega1[n_steady:, c]).min() == s and np.sign(res.omega1[:, c]).max() == s
        flanks = [np.sign(res.delta[b - 1, c]) for b, _ in g]
        assert flanks[0] == s                              # leaves the driving flank first
        assert -s in flanks                                # and the zone is crossed back later
        assert (res.t.size - 1 - g[0][0]) * TS >= 1.2 - 1e-9
        # settled at the new speed by the end of the run
        np.testing.assert_allclose(res.omega1[-200:, c], s * 80.0, rtol=2e-3)


def test_steady_state_is_steady_no_spurious_entry():
    res, n_steady, _ = R.simulate_grid(P, [("forward", 1.218, 0.0025), ("reverse", 0.957, 0.0025)],
                                       steady_s=3.0, post_s=0.0)
    assert n_steady == res.t.size - 1
    assert not np.any(np.abs(res.delta) < res.theta_b)     # no entry anywhere in 3 s
    for k in ("omega1", "m_el", "delta", "coupling_torque"):
        x = getattr(res, k)
        assert np.ptp(x, axis=0).max() <= 1e-9 * max(1.0, np.abs(x).max()), k
    assert np.abs(res.domega1).max() < 1e-9


def test_halving_the_step_changes_little():
    case = [("forward", 1.16, 0.005)]
    a, n, _ = R.simulate_grid(P, case, steady_s=0.05, post_s=0.4)
    b, _, _ = R.simulate_grid(replace(P, substeps=4), case, steady_s=0.05, post_s=0.4)
    assert M.gaps(a.delta[:, 0], a.theta_b[:, 0], n)[0] == M.gaps(b.delta[:, 0], b.theta_b[:, 0], n)[0]
    for k in ("omega1", "m_el", "domega1"):
        x, y = getattr(a, k)[:, 0], getattr(b, k)[:, 0]
        assert np.abs(x - y).max() < 0.03 * np.ptp(y), k


# ---------------------------------------------------------------------------------------------- sensors
def test_encoder_offsets_are_arbitrary_and_quantised(recs):
    offs = [(r.truth["encoder"]["alpha1_offset_rad"], r.truth["encoder"]["alpha2_offset_rad"]) for r in recs]
    assert len(set(offs)) == len(offs)
    q = 2 * math.pi / 65536
    for r in recs:
        enc = r.truth["encoder"]
        assert abs(R._wrap_pi(enc["relative_offset_rad"])) >= 0.5        # not zone-centred
        for k in ("alpha1", "alpha2"):
            x = r.signals[k] / q
            np.testing.assert_allclose(x, np.round(x), atol=1e-6)
        # recorded angles start at the offset, not at 0
        assert abs(r.signals["alpha1"][0] - enc["alpha1_offset_rad"]) < q + 1e-12
    res, _, _ = R.simulate_grid(P, CASES[:1], steady_s=0.05, post_s=0.0)
    sig = R.measure(res, 0, P, R.SensorConfig(encoder_counts=1000, wrap_encoders=True),
                    np.random.default_rng(0), (1.0, 2.0))
    x = sig["alpha1"] / (2 * math.pi / 1000)
    np.testing.assert_allclose(x, np.round(x), atol=1e-6)
    assert sig["alpha1"].min() >= 0 and sig["alpha1"].max() < 2 * math.pi


def test_noise_is_awgn_measured():
    rng = np.random.default_rng(0)
    x = np.sin(np.linspace(0, 50, 200000)) * 3 + 1
    y = R.awgn_measured(x, 20.0, rng)
    assert np.mean((y - x) ** 2) == pytest.approx(np.mean(x * x) / 100, rel=0.02)


# ---------------------------------------------------------------------------------------------- recordings
def test_jointstate_bag_reads_back(tmp_path, recs):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    rec = recs[0]
    R.write_recording(tmp_path, rec, "jointstate", namespace="press3", imu=True)
    n = rec.signals["t"].size
    with AnyReader([tmp_path / rec.name], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as rd:
        topics = {c.topic: c for c in rd.connections}
        assert set(topics) == {"/press3/joint_states", "/press3/imu"}
        assert topics["/press3/joint_states"].msgcount == n and topics["/press3/imu"].msgcount == n
        stamps, pos, eff, acc = [], [], [], []
        for conn, t_log, raw in rd.messages():
            m = rd.deserialize(raw, conn.msgtype)
            st = m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec
            assert st == t_log
            if conn.topic.endswith("joint_states"):
                assert list(m.name) == ["motor", "load"]
                stamps.append(st)
                pos.append(m.position)
                eff.append(m.effort)
            else:
                acc.append(m.linear_acceleration.x)
    stamps = np.array(stamps)
    assert len(stamps) == n and np.all(np.diff(stamps) == round(TS * 1e9))
    np.testing.assert_array_equal(np.array(pos)[:, 0], rec.signals["alpha1"])
    np.testing.assert_array_equal(np.array(pos)[:, 1], rec.signals["alpha2"])
    np.testing.assert_array_equal(np.array(eff)[:, 0], rec.signals["m_el"])
    assert np.all(np.isnan(np.array(eff)[:, 1]))
    np.testing.assert_array_equal(acc, rec.signals["a1"])


def test_signals_bag_layout_and_no_width_topic(tmp_path, recs):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    rec = recs[1]
    R.write_recording(tmp_path, rec, "signals")
    rows, label = [], None
    with AnyReader([tmp_path / rec.name], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as rd:
        assert [c.topic for c in rd.connections] == ["/drive/signals"]
        for conn, t_log, raw in rd.messages():
            m = rd.deserialize(raw, conn.msgtype)
            d0, d1 = m.layout.dim
            label = d1.label
            assert d0.label == "sample" and d0.stride == d0.size * d1.size and d1.stride == d1.size
            assert m.layout.data_offset == 0 and d0.size <= 50
            block = m.data.reshape(d0.size, d1.size)
            assert t_log == round(block[-1, 0] * 1e9)
            rows.append(block)
    assert label == ",".join(R.SIGNAL_CHANNELS)
    data = np.vstack(rows)
    for i, ch in enumerate(R.SIGNAL_CHANNELS):
        np.testing.assert_array_equal(data[:, i], rec.signals[ch])


def test_csv_round_trips(tmp_path, recs):
    rec = recs[2]
    rel = R.write_recording(tmp_path, rec, "csv")
    header = (tmp_path / rel).read_text().splitlines()[0]
    assert header == "t,alpha1,alpha2,omega1,omega2,m_el,a1,a2,v2"
    back = R.read_csv(tmp_path / rel)
    for k, v in rec.signals.items():
        np.testing.assert_allclose(back[k], v, rtol=1e-14, atol=1e-300)


# ---------------------------------------------------------------------------------------------- CLI
def test_cli_writes_recordings_and_truth(tmp_path, capsys):
    from jident_ros.research.second_drive.__main__ import main
    out = tmp_path / "grid"
    assert main(["--out", str(out), "--format", "csv", "--quick", "--direction", "reverse",
                 "--steady-s", "0.2", "--snr-db", "30", "--seed", "5"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 5                                   # 4 recordings + summary
    truth = json.loads((out / "truth.json").read_text())
    assert len(truth["recordings"]) == 4
    for tr in truth["recordings"]:
        for k in ("name", "file", "direction", "inertia_kgm2", "backlash_width_m", "reference_radius_m",
                  "half_zone_rad", "gear_ratio", "entry_time_s", "entry_index", "gaps", "encoder", "event",
                  "sample_period_s", "n_samples"):
            assert k in tr, k
        assert tr["direction"] == "reverse" and tr["entry_from_flank"] == -1
        assert tr["half_zone_rad"] == pytest.approx(tr["backlash_width_m"] / 0.08)
        sig = R.read_csv(out / tr["file"])
        assert set(sig) == set(R.CSV_CHANNELS)               # no width/truth columns in the signal file
        assert sig["t"][tr["entry_index"]] == pytest.approx(tr["entry_time_s"])
        assert tr["entry_time_s"] > tr["event"]["time_s"] >= 0.2 - 1e-12
        assert tr["n_samples"] == sig["t"].size
    assert {tr["inertia_kgm2"] for tr in truth["recordings"]} == {1.16, 0.957}


@pytest.mark.parametrize("args,name", [(["--snr-db", "abc"], "--snr-db"), (["--gear-ratio", "3"], "--gear-ratio"),
                                       (["--encoder-counts", "-4"], "--encoder-counts"),
                                       (["--widths", "0.005,x"], "--widths"), (["--format", "hdf5"], "--format")])
def test_cli_bad_input_one_line_exit_2(tmp_path, capsys, args, name):
    from jident_ros.research.second_drive.__main__ import main
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "x")] + args)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0] and args[1] in err[0]
    assert not (tmp_path / "x").exists()


def test_cli_bad_input_in_a_real_process_has_no_traceback(tmp_path):
    p = subprocess.run([sys.executable, "-m", "jident_ros.research.second_drive", "--out", str(tmp_path / "o"),
                        "--steady-s", "-1"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [p.stderr.strip()] and "--steady-s" in p.stderr and "-1" in p.stderr


def test_wear_scenario_one_entry_per_event_with_changing_width():
    """The zone widens between two events (on-grid 2.5 mm, then off-grid 6.2 mm):
    each event has its entry shortly after the step, the first gap spans the
    event's own width, and neither the step back up nor the wear ramp makes a gap."""
    widths = (0.0025, 0.0062)
    (rec,) = R.build_wear(P, ("reverse",), (1.131,), R.SensorConfig(), widths=widths, steady_s=0.2, seed=2)
    tr = rec.truth
    enc = tr["encoder"]
    rel = rec.signals["alpha1"] - rec.signals["alpha2"] - enc["relative_offset_rad"]
    assert [e["backlash_width_m"] for e in tr["events"]] == list(widths)
    assert [e["on_paper_grid"] for e in tr["events"]] == [True, False]
    for ev in tr["events"]:
        assert 0 < ev["entry_time_s"] - ev["time_s"] < 0.01
        g0 = ev["gaps"][0]
        assert (g0["from_flank"], g0["to_flank"]) == (-1, 1)
        b, e = g0["entry_index"], g0["end_index"]
        two = 2 * ev["half_zone_rad"]
        assert rel[e] - rel[b - 1] >= two - 2e-4 and rel[e - 1] - rel[b] <= two + 2e-4
        assert all(g["entry_time_s"] < ev["time_s"] + 0.5 for g in ev["gaps"])   # none from step-up or wear
