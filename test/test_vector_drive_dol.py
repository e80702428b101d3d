"""The vector drive's DOL mode (jident_ros.research.vector_drive.dol, motulator): the machine on a stiff grid, its
steady slip and torque, the slip's gap, the voltage-model torque estimate and the recorder's truth.

Skipped, with the reason, when motulator (0.5.x API) is not installed (``pip install -e '.[zoo]'``).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from jident_ros.research.vector_drive import record
from jident_ros.research.vector_drive.dol import (
    DolParams,
    TorqueEstimate,
    dol_scenario,
    estimate_error_nm,
    simulate_dol,
    slip_for_torque,
    steady_fluxes,
    steady_speed,
)
from jident_ros.research.vector_drive.model import gaps, load_friction, motor_friction, motulator_available

REASON = motulator_available()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

#: short runs: 50 ms pre-roll, the event at 0.05 s
SHORT = replace(DolParams(), preroll_s=0.05)
EVENT_S = 0.05


@pytest.fixture(scope="module")
def steady():
    return simulate_dol(SHORT, dol_scenario(SHORT, "steady", "forward", EVENT_S), 0.1)


@pytest.fixture(scope="module")
def slip():
    return simulate_dol(SHORT, dol_scenario(SHORT, "slip_drop", "forward", EVENT_S), 0.1)


def test_steady_slip_and_torque_match_the_load(steady):
    """motulator's machine on the grid holds the steady state we start it in: its torque is the load plus both
    frictions, its speed the slip at which the equivalent circuit gives that torque."""
    p, d = steady.params, steady.data
    m = p.mechanics
    load = p.base_load_ratio * p.machine.rated_torque_nm
    w = steady_speed(p, load)
    torque = load + float(load_friction(m, w)) + float(motor_friction(m, w))
    assert np.allclose(d["w_M"], w, rtol=0, atol=1e-6)
    assert np.allclose(d["tau_M"], torque, rtol=1e-6)
    slip = (p.grid_w_rad_s - p.machine.pole_pairs * w) / p.grid_w_rad_s
    assert slip == pytest.approx(slip_for_torque(p, torque) / p.grid_w_rad_s, rel=1e-9)
    assert 0.003 < slip < 0.02                     # a 37 kW machine at 0.3 rated
    assert np.all(d["tau_c"] > 0) and np.all(d["theta_M"] - d["theta_L"] > m.half_zone_rad)


def test_torque_estimate_error_is_the_stator_resistance_term(steady):
    """The recorded m_el (the voltage-model estimate) is off the true torque by the copper-loss term the nameplate
    R_s misses, +1.5 n_p dR |i_s|^2 / w_g, to 0.1 N m; a sign flip or a missing correction at 50 Hz fails."""
    p, d = steady.params, steady.data
    err = d["tau_est"] - d["tau_M"]
    pred = estimate_error_nm(p, d["i_s_abs"], +1)
    assert np.all(pred > 0.5)
    assert np.max(np.abs(err - pred)) < 0.1


def test_estimator_is_exact_with_the_true_resistance():
    """TorqueEstimate on an exact steady machine (its fluxes from the equivalent circuit, rotating at 50 Hz) gives the
    machine's torque: the leaky integrator's gain and phase are corrected at the grid frequency."""
    p = DolParams()
    from jident_ros.research.vector_drive.dol import gamma_pars
    g = gamma_pars(p)
    psi_s, _, i_s, tau = steady_fluxes(p, slip_for_torque(p, 150.0))
    w = p.grid_w_rad_s
    est = TorqueEstimate(g["R_s"], g["n_p"], p.control_period_s, 2 * math.pi * p.flux_highpass_hz, w)
    u = p.grid_peak_phase_v
    est.start(u, i_s)
    out = [est(u * np.exp(1j * w * k * p.control_period_s), i_s * np.exp(1j * w * k * p.control_period_s))
           for k in range(400)]
    assert tau == pytest.approx(150.0)
    assert np.allclose(out, tau, rtol=2e-3)
    uncorrected = TorqueEstimate(g["R_s"], g["n_p"], p.control_period_s, 2 * math.pi * 10.0, w)
    uncorrected.correction = 1.0
    uncorrected.start(u, i_s)
    assert abs(uncorrected(u, i_s) / tau - 1) > 0.01


def test_the_slip_opens_a_gap_of_free_motion_back_to_the_same_flank(slip):
    p, d = slip.params, slip.data
    m = p.mechanics
    delta = d["theta_M"] - d["theta_L"]
    gl = gaps(delta, m.half_zone_rad)
    ts = p.control_period_s
    k_ev = int(round(EVENT_S / ts))
    assert gl and all(b > k_ev for b, _ in gl)
    b, e = gl[0]
    assert delta[b - 1] > 0 and delta[e] > 0, "slip_drop: out of the driving flank and back to it"
    assert (e - b) * ts > 4e-3                                  # the paper's 4.5-16 ms
    assert np.all(d["tau_c"][b:e] == 0.0)
    assert np.mean(d["tau_M"][b:e]) > 0.5 * p.machine.rated_torque_nm      # the motor at full torque in the gap
    acc = np.diff(d["w_M"][b:e]) / ts
    rhs = 0.5 * ((d["tau_M"] - d["tau_f1"])[b:e - 1] + (d["tau_M"] - d["tau_f1"])[b + 1:e])
    assert np.sum(rhs * acc) / np.sum(acc * acc) == pytest.approx(m.motor_inertia_kgm2, rel=0.01)
    # the estimate the recording carries stays within what the user declares (zoo_dol.declared): 1 % scale +
    # 1 % of M_b (212 N m)
    err = np.abs(d["tau_est"] - d["tau_M"])[b:e]
    assert np.all(err <= 0.01 * np.abs(d["tau_M"][b:e]) + 0.01 * 212.0)


def test_reverse_mirrors_forward():
    f = dol_scenario(SHORT, "slip_reversal", "forward")
    r = dol_scenario(SHORT, "slip_reversal", "reverse")
    assert r.load_before_nm == -f.load_before_nm and r.load_after_nm == -f.load_after_nm
    assert r.speed_rad_s == -f.speed_rad_s > -200


@pytest.fixture(scope="module")
def recorded():
    p = replace(SHORT, preroll_s=0.05)
    return record.build_dol(p, "slip_reversal", "forward", record.Sensors(65536, None), seed=3, duration_s=0.2,
                            event_time_s=EVENT_S), p


def test_truth_gaps_are_where_the_recorded_angles_cross_the_zone(recorded):
    rec, p = recorded
    tr = rec.truth
    th = tr["half_zone_rad"]
    enc = tr["encoder"]
    rel = (rec.signals["alpha1"] - enc["alpha1_offset_rad"]) - (rec.signals["alpha2"] - enc["alpha2_offset_rad"])
    q = 2 * math.pi / 65536
    assert tr["gaps"] and tr["gaps"][0]["event_gap"] and tr["gaps"][0]["traversal"]
    for g in tr["gaps"]:
        b, e = g["entry_index"], g["recontact_index"]
        assert np.all(np.abs(rel[b:e]) < th + 2 * q)
        assert abs(rel[b - 1]) >= th - 2 * q
        if e is not None:
            assert abs(rel[e]) >= th - 2 * q
        assert (g["from_flank"] != g["to_flank"]) == g["traversal"]
    assert sum(g["event_gap"] for g in tr["gaps"]) == 1
    # the first gap is flank to flank: + before, - after
    g = tr["gaps"][0]
    assert rel[g["entry_index"] - 1] > 0 > rel[g["recontact_index"]]
    assert tr["entry_index"] == g["entry_index"] and tr["event"]["slip"]


def test_recorded_m_el_is_the_estimate_and_its_error_is_in_the_truth(recorded):
    rec, p = recorded
    tr = rec.truth
    e = tr["torque_estimate_error"]
    assert 0.002 < e["steady_relative"] < 0.02
    assert e["max_abs_minus_resistance_term_nm"] < 0.5
    assert tr["gaps"][0]["torque_estimate_error_mean_nm"] > 0
    assert rec.name.startswith("dol_slip_reversal_fwd_J1.160")


def test_the_vector_modes_cache_keys_are_unchanged():
    """The DOL mode leaves the vector mode's parameters alone: the zoo's cached vector-drive simulations
    (out/zoo/vector_drive_cache, keyed by every parameter) stay valid and its recordings bit-identical."""
    from dataclasses import asdict

    from jident_ros.research.vector_drive.model import DriveParams, scenario
    p = DriveParams()
    for ev, key in (("steady", "2aa0086af90b0146"), ("load_reversal_heavy", "e3c2ebec3e6f242c")):
        assert record.params_key(p, ev, "forward", 2.2, 0.6, asdict(scenario(p, ev, "forward", 0.6))) == key


def test_cli_refuses_a_vector_event_in_dol_mode(tmp_path, capsys):
    from jident_ros.research.vector_drive.__main__ import main
    with pytest.raises(SystemExit) as exc:
        main(["--mode", "dol", "--out", str(tmp_path), "--events", "speed_step_down"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--events" in err[0] and "speed_step_down" in err[0] and "slip_drop" in err[0]
