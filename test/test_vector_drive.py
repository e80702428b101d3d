"""The third validation drive (jident_ros.research.vector_drive, motulator): physics sanity and the recorder.

Skipped, with the reason, when motulator (0.5.x API) is not installed (``pip install -e '.[zoo]'``).
"""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from jident_ros.research.vector_drive.model import (
    DriveParams,
    coupling_torque,
    gaps,
    motor_friction,
    motulator_available,
    scenario,
    simulate,
)

REASON = motulator_available()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

#: a short run: 50 ms pre-roll, the speed step at 0.1 s, 0.16 s after it (the first traversal takes ~25 ms)
SHORT = replace(DriveParams(), preroll_s=0.05)


@pytest.fixture(scope="module")
def step_down():
    return simulate(SHORT, scenario(SHORT, "speed_step_down", "forward", event_time_s=0.1), 0.26)


def _first_traversal(run):
    m = run.params.mechanics
    d = run.data
    delta = d["theta_M"] - m.gear_ratio * d["theta_L"]
    gl = gaps(delta, m.half_zone_rad)
    assert gl, "no gap after the speed step down"
    return delta, gl


def test_steady_before_the_event_and_a_gap_after(step_down):
    d = step_down.data
    delta, gl = _first_traversal(step_down)
    ts = step_down.params.controller.control_period_s
    k_ev = int(round(0.1 / ts))
    assert all(b > k_ev for b, _ in gl), "a gap before the event (the steady stretch is not steady)"
    assert np.all(d["tau_c"][:k_ev] > 0), "forward motoring must load the + flank"
    b, e = gl[0]
    assert delta[b - 1] > 0 > delta[e], "the first gap must traverse the zone from the + to the - flank"


def test_the_gap_is_free_motion(step_down):
    d = step_down.data
    m = step_down.params.mechanics
    _, gl = _first_traversal(step_down)
    b, e = gl[0]
    assert np.all(d["tau_c"][b:e] == 0.0)
    # J1 dw/dt = tau_M - friction inside the gap (finite differences of the true speed, trapezoidal torque)
    ts = step_down.params.controller.control_period_s
    acc = np.diff(d["w_M"][b:e]) / ts
    rhs = 0.5 * ((d["tau_M"] - d["tau_f1"])[b:e - 1] + (d["tau_M"] - d["tau_f1"])[b + 1:e])
    j1 = np.sum(rhs * acc) / np.sum(acc * acc)
    assert j1 == pytest.approx(m.motor_inertia_kgm2, rel=0.01)
    # the friction is the configured law (Coulomb + viscous), and it is on
    assert d["tau_f1"][b] == pytest.approx(float(motor_friction(m, d["w_M"][b])))
    assert abs(d["tau_f1"][b]) > m.motor_coulomb_nm * 0.9


def test_the_backlash_is_traversed_flank_to_flank(step_down):
    m = step_down.params.mechanics
    delta, gl = _first_traversal(step_down)
    b, e = gl[0]
    th = m.half_zone_rad
    # from the + flank to the - flank: 2 K2/r of free travel (the contact penetration is small)
    assert delta[b - 1] - delta[e] == pytest.approx(2 * th, rel=0.1)
    assert delta[b - 1] >= th and delta[e] <= -th
    # the coupling law: zero in the zone, k pen outside
    assert coupling_torque(m, 0.9 * th, 1.0) == 0.0
    assert coupling_torque(m, th + 1e-3, 0.0) == pytest.approx(m.stiffness_nm_per_rad * 1e-3)
    assert coupling_torque(m, -th - 1e-3, 0.0) == pytest.approx(-m.stiffness_nm_per_rad * 1e-3)


def test_torque_estimate_error_is_nonzero_but_small(step_down):
    d = step_down.data
    k_ev = int(round(0.1 / step_down.params.controller.control_period_s))
    rel = np.mean(d["tau_est"][40:k_ev] - d["tau_M"][40:k_ev]) / np.mean(d["tau_M"][40:k_ev])
    assert 0.002 < abs(rel) < 0.05, rel
    # the speed feedback lags the true speed in the deceleration (filter + difference)
    i = int(np.argmin(d["w_ref"] > 99.0)) + 40
    assert d["w_fbk"][i] > d["w_M"][i]


def test_recording_quantisation_offsets_and_truth(step_down, tmp_path):
    from jident_ros.research.vector_drive.record import CHANNELS, Sensors, build, decimate, write

    # build() on the fixture's run (no second simulation): patch the cache with the decimated run
    st = decimate(step_down)
    st["motulator_version"] = step_down.motulator_version
    import jident_ros.research.vector_drive.record as rec_mod
    orig = rec_mod.simulate_cached
    rec_mod.simulate_cached = lambda *a, **k: st
    try:
        rec = build(SHORT, "speed_step_down", "forward", Sensors(encoder_counts=8192), seed=3, duration_s=0.26,
                    event_time_s=0.1)
    finally:
        rec_mod.simulate_cached = orig
    q = 2 * math.pi / 8192
    a1 = rec.signals["alpha1"]
    assert np.allclose(a1 / q, np.round(a1 / q), atol=1e-6), "alpha1 is not on the 2^13 grid"
    o1 = rec.truth["encoder"]["alpha1_offset_rad"]
    assert np.all((a1 - st["theta_M"] - o1 <= 1e-9) & (a1 - st["theta_M"] - o1 > -q - 1e-9))
    rel = rec.truth["encoder"]["relative_offset_rad"]
    assert abs((rel + math.pi) % (2 * math.pi) - math.pi) >= 0.5
    assert rec.signals["t"][1] - rec.signals["t"][0] == pytest.approx(5e-4)
    tr = rec.truth
    assert tr["event"]["type"] == "speed_step_down" and tr["gaps"][0]["traversal"]
    g = tr["gaps"][0]      # the gap's torques: braking at the limit, the estimate a few % off, friction on
    assert g["true_torque_mean_nm"] < -200 and 0 < abs(g["torque_estimate_error_mean_nm"]) < 0.05 * 360
    assert g["bearing_friction_mean_nm"] > 1.0
    assert tr["entry_index"] > tr["steady_rows"]
    # the torque channel is the drive's estimate, not the truth
    assert not np.allclose(rec.signals["m_el"], st["tau_M"])
    rel_csv = write(tmp_path, rec, "csv")
    header = (tmp_path / rel_csv).read_text().splitlines()[0].split(",")
    assert tuple(header) == CHANNELS
    assert json.loads((tmp_path / f"{rec.name}.truth.json").read_text())["inertia_kgm2"] == 1.16


def _delta_and_gaps(event, direction, duration_s):
    """The coupling's twist delta = theta_M - N theta_L of SHORT after ``event`` at 0.1 s, and its gaps."""
    p = SHORT
    run = simulate(p, scenario(p, event, direction, event_time_s=0.1), duration_s)
    m = p.mechanics
    delta = run.data["theta_M"] - m.gear_ratio * run.data["theta_L"]
    return delta, gaps(delta, m.half_zone_rad)


@pytest.mark.slow
@pytest.mark.parametrize("event", ["speed_step_up", "load_step_same_flank", "steady"])
def test_same_flank_events_open_no_gap(event):
    delta, gl = _delta_and_gaps(event, "forward", 0.6)
    assert gl == []


@pytest.mark.slow
@pytest.mark.parametrize("event", ["speed_reversal", "load_reversal_light", "load_reversal_heavy"])
def test_reversals_traverse(event):
    delta, gl = _delta_and_gaps(event, "reverse", 0.7)
    assert gl and delta[gl[0][0] - 1] < 0 < delta[gl[0][1]], "reverse: from the - flank to the + flank"


@pytest.mark.slow
def test_the_small_drive_traverses_its_backlash():
    from jident_ros.research.vector_drive.model import small_drive
    p = replace(small_drive(), preroll_s=0.05)
    run = simulate(p, scenario(p, "speed_step_down", "forward", event_time_s=0.1), 0.3)
    m = p.mechanics
    delta = run.data["theta_M"] - m.gear_ratio * run.data["theta_L"]
    gl = gaps(delta, m.half_zone_rad)
    assert gl and delta[gl[0][0] - 1] > 0 > delta[gl[0][1]]
    assert delta[gl[0][0] - 1] - delta[gl[0][1]] == pytest.approx(2 * m.half_zone_rad, rel=0.15)


def test_jittered_instants_stamps_and_reported_units(step_down, monkeypatch):
    """Sensors' jitter and units (zoo_variants' 'sampling jitter', 'stamping jitter', 'CiA 402 units'): jittered
    instants move the samples with their stamps; stamp jitter moves the stamps alone; the torque estimate and the
    speeds land on their units."""
    import jident_ros.research.vector_drive.record as rec_mod
    st = rec_mod.decimate(step_down)
    st["motulator_version"] = step_down.motulator_version
    monkeypatch.setattr(rec_mod, "simulate_cached", lambda *a, **k: st)

    def build(**kw):
        return rec_mod.build(SHORT, "speed_step_down", "forward", rec_mod.Sensors(**kw), seed=3, duration_s=0.26,
                             event_time_s=0.1).signals
    base = build()
    ts = SHORT.sample_period_s
    np.testing.assert_allclose(np.diff(base["t"]), ts)
    inst = build(sample_jitter_s=25e-6)
    dev = inst["t"] - base["t"]
    assert 15e-6 < np.std(dev) < 35e-6 and np.max(np.abs(dev)) <= 75e-6 + 1e-12
    moved = np.abs(inst["alpha1"] - base["alpha1"])[10:-10]
    assert np.median(moved) > 5 * 2 * math.pi / 65536                    # the angle went with its instant
    stamped = build(stamp_jitter_s=25e-6)
    assert np.array_equal(stamped["alpha1"], base["alpha1"]) and np.std(np.diff(stamped["t"])) > 10e-6
    units = build(torque_quantum_rel_rated=1e-3, speed_quantum_rad_s=2 * math.pi / 60)
    q = 1e-3 * SHORT.machine.rated_torque_nm
    np.testing.assert_allclose(units["m_el"] / q, np.round(units["m_el"] / q), atol=1e-9)
    np.testing.assert_allclose(units["omega1"] * 60 / (2 * math.pi), np.round(units["omega1"] * 60 / (2 * math.pi)),
                               atol=1e-9)
    assert np.max(np.abs(units["m_el"] - base["m_el"])) <= q / 2 + 1e-9
    rev = build(load_encoder_sign=-1.0)                                   # a load encoder counting the other way
    np.testing.assert_array_equal(rev["omega2"], -base["omega2"])
    d_base, d_rev = np.diff(base["alpha2"]), np.diff(rev["alpha2"])
    assert np.max(np.abs(d_rev + d_base)) <= 2 * 2 * math.pi / 65536 + 1e-12 and np.abs(d_base).sum() > 0
    # a disc off centre (zoo_variants' 'encoder disc errors'): the reading departs from the ideal one by up to 1.5
    # the once-per-revolution amplitude, periodic in the angle, and the load encoder's error is its own
    disc = build(encoder_error_rad=2e-4)
    err1 = disc["alpha1"] - base["alpha1"]
    assert 1.2e-4 < np.max(np.abs(err1)) <= 1.5 * 2e-4 + 2 * 2 * math.pi / 65536
    assert np.std(err1) > 5e-5 and not np.allclose(err1[:50], (disc["alpha2"] - base["alpha2"])[:50], atol=2e-5)
    # the torque estimate reported a sample late ('torque one sample late'): the same series one row later
    late = build(torque_delay_samples=1)
    np.testing.assert_array_equal(late["m_el"][1:], base["m_el"][:-1])
    assert late["m_el"][0] == base["m_el"][0] and np.array_equal(late["alpha1"], base["alpha1"])
    # the torque estimate smoothed by the drive ('smoothed torque 2 ms'): a first-order lag that starts at rest
    smooth = build(torque_filter_s=2e-3)
    a = math.exp(-ts / 2e-3)
    assert smooth["m_el"][0] == pytest.approx(base["m_el"][0])
    np.testing.assert_allclose(smooth["m_el"][1:], a * smooth["m_el"][:-1] + (1 - a) * base["m_el"][1:], rtol=1e-12,
                               atol=1e-9)
    assert np.max(np.abs(smooth["m_el"] - base["m_el"])) > 1.0          # the event's torque step is smoothed


def test_the_separation_is_where_a_damped_contacts_torque_reaches_zero():
    """record._separation: the first sample of the run of zero coupling torque that ends at the zone entry b (a damped
    contact lets go when k x + c x' reaches zero, before x does); b itself when the torque is not zero right before b;
    the search stops SEPARATION_SEARCH_SAMPLES before b."""
    from jident_ros.research.vector_drive.record import SEPARATION_SEARCH_SAMPLES, _separation
    tau = np.r_[np.linspace(300.0, 10.0, 50), np.zeros(5), np.zeros(30)]      # zone entry at 55: zero from 50 on
    assert _separation(tau, 55) == 50
    tau2 = np.r_[np.linspace(300.0, 10.0, 55), np.zeros(30)]                  # an undamped contact: zero from 55
    assert _separation(tau2, 55) == 55
    tau3 = np.r_[np.full(10, 5.0), np.zeros(100)]
    assert _separation(tau3, 100) == 100 - SEPARATION_SEARCH_SAMPLES
    tau4 = np.r_[np.linspace(300.0, 10.0, 50), np.full(5, 1e-12), np.zeros(30)]   # interpolated: zero to 1e-9
    assert _separation(tau4, 55) == 50
