"""Validation of the motor–load simulator (issue: foundation, item 5)."""
import numpy as np
import pytest
from scipy.optimize import brentq

from jident_ros.config import load_system_config
from jident_ros.sim import (
    PAPER_SIGNALS,
    Case,
    SystemConfig,
    add_measurement_noise,
    paper_grid_cases,
    quantise_encoders,
    simulate_grid,
)
from jident_ros.sim.motor import breakdown_slip, equivalent_circuit_torque_pu, steady_state_phasors

CFG = load_system_config()
E = CFG.sampling.samples_before_entry


@pytest.fixture(scope="module")
def small_grid():
    """Two J1, two widths, all four eta_k: 16 cases, one vectorised run."""
    g = CFG.grid
    cases = [Case(j, b, e) for e in g.consistency_indices_pa_sn
             for j in (g.inertia_classes_kgm2[4], g.inertia_classes_kgm2[6])
             for b in (g.backlash_widths_m[0], g.backlash_widths_m[-1])]
    return simulate_grid(CFG, cases)


@pytest.fixture(scope="module")
def steady():
    cases = [Case(1.16, 0.005, e) for e in CFG.grid.consistency_indices_pa_sn]
    return simulate_grid(CFG, cases, event=False)


def _analytic_slip(eta):
    """Slip from the classic equivalent-circuit torque |i_r|^2 r_w / s (scipy brentq)."""
    m, ld, b = CFG.motor, CFG.load, CFG.motor.base

    def f(s):
        v2 = ld.wheel_radius_m * (1 - s) * b.mechanical_speed_rad_s
        load = ld.wheel_radius_m * (ld.process_force_n + ld.film_force_n(v2, eta))
        return float(equivalent_circuit_torque_pu(m, s)) * b.torque_nm - load
    return brentq(f, 1e-6, breakdown_slip(m), xtol=1e-14)


def test_config_file_matches_documented_defaults():
    assert CFG == SystemConfig()


def test_steady_state_torque_and_slip_match_equivalent_circuit(steady):
    b = CFG.motor.base
    for i, case in enumerate(steady.cases):
        s = _analytic_slip(case.consistency_pa_sn)
        torque = float(equivalent_circuit_torque_pu(CFG.motor, s)) * b.torque_nm
        speed = (1 - s) * b.mechanical_speed_rad_s
        m_el, w1 = steady.signals["m_el"][i], steady.signals["omega1"][i]
        # the whole run (no event): still in steady state at every sample
        assert np.max(np.abs(m_el / torque - 1)) < 1e-3
        assert np.max(np.abs(w1 / speed - 1)) < 1e-3
        assert abs(steady.initial_slip[i] / s - 1) < 1e-3
        # and the load really balances
        assert np.max(np.abs(steady.signals["clutch_torque"][i] / torque - 1)) < 1e-3


def test_power_balance_in_steady_state(steady):
    """Electrical input = stator + rotor copper losses + mechanical output."""
    m = CFG.motor
    for s in steady.initial_slip:
        ph = steady_state_phasors(m, s)
        p_in = np.real(m.supply_voltage_pu * np.conj(ph["i_s"]))
        losses = m.stator_resistance_pu * abs(ph["i_s"]) ** 2 + m.rotor_resistance_pu * abs(ph["i_r"]) ** 2
        p_mech = ph["torque_pu"] * (1 - s)
        assert p_in == pytest.approx(losses + p_mech, rel=1e-9)
    # and in the time domain: P_mech = m_el * omega1 matches the phasor figure
    b = m.base
    for i, s in enumerate(steady.initial_slip):
        ph = steady_state_phasors(m, s)
        p_mech_si = ph["torque_pu"] * (1 - s) * b.power_va
        sim = steady.signals["m_el"][i] * steady.signals["omega1"][i]
        assert np.max(np.abs(sim / p_mech_si - 1)) < 1e-3


def test_halving_the_step_changes_the_window_little():
    """RK4 at 2 vs 4 substeps per sample (0.25 vs 0.125 ms).

    Tolerance, relative to each signal's peak deviation from its pre-event value:
    a1 2.5 %, the other four 0.5 % (a1 is the clutch force over J1 and carries
    the impact kinks).
    """
    cases = [Case(0.957, 0.0025, 0.0125), Case(1.218, 0.01, 0.05), Case(1.16, 0.005, 0.025)]
    a = simulate_grid(CFG, cases, substeps=2)
    b = simulate_grid(CFG, cases, substeps=4)
    tol = {"a1": 0.025, "m_el": 0.005, "omega1": 0.005, "a2": 0.005, "v2": 0.005}
    for name in PAPER_SIGNALS:
        x, y = a.signals[name], b.signals[name]
        scale = np.max(np.abs(y - y[:, :1]), axis=1)
        err = np.max(np.abs(x - y), axis=1) / scale
        assert np.all(err < tol[name]), (name, err)


def test_gap_is_a_single_mass(small_grid):
    """Inside the zone J1 dw1/dt = m_el (no load moment), to 1e-6 relative."""
    for i, case in enumerate(small_grid.cases):
        s = small_grid.case(i)
        free = s["clutch_torque"][E:] == 0
        gap = E + np.arange(np.argmin(free))  # the first contiguous run from the entry sample
        assert gap.size >= 5 and free[0]
        lhs = case.inertia_kgm2 * s["a1"][gap] / CFG.load.wheel_radius_m
        assert np.max(np.abs(lhs / s["m_el"][gap] - 1)) < 1e-6
        # independent of the model's derivative: central differences of omega1
        ts = small_grid.sample_period_s
        inner = gap[1:-1]
        fd = (s["omega1"][inner + 1] - s["omega1"][inner - 1]) / (2 * ts)
        assert np.max(np.abs(case.inertia_kgm2 * fd / s["m_el"][inner] - 1)) < 2e-3


def test_backlash_entry_sample_satisfies_inequality_1(small_grid):
    r = CFG.load.wheel_radius_m
    for i, case in enumerate(small_grid.cases):
        s = small_grid.case(i)
        rel = np.abs(s["alpha1"] - s["alpha2"])
        limit = case.backlash_width_m / r
        assert rel[E] < limit          # entry sample: inside the zone
        assert rel[E - 1] >= limit     # the sample before: not
        assert np.all(rel[:E] >= limit)
        assert small_grid.t[E] == 0.0


def test_larger_inertia_gives_smaller_acceleration_in_the_gap(small_grid):
    by = {(c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn): i for i, c in enumerate(small_grid.cases)}
    for (j, b, e), i in by.items():
        if j == 0.957:
            k = by[(1.218, b, e)]
            a_small_j = small_grid.signals["a1"][i][E:E + 3]
            a_large_j = small_grid.signals["a1"][k][E:E + 3]
            assert np.all(a_large_j < a_small_j)


def test_larger_consistency_gives_larger_load_torque(small_grid):
    pre = {}
    for i, c in enumerate(small_grid.cases):
        pre.setdefault(c.consistency_pa_sn, small_grid.signals["clutch_torque"][i][0])
    etas = sorted(pre)
    torques = [pre[e] for e in etas]
    assert all(b > a for a, b in zip(torques, torques[1:]))


def test_window_covers_the_transient(small_grid):
    """Ts justification: the transient has died out before the window ends."""
    for name in ("m_el", "omega1", "v2"):
        x = small_grid.signals[name]
        dev = np.abs(x - x[:, :1])
        peak = dev.max(axis=1)
        tail = dev[:, -200:].max(axis=1)
        assert np.all(tail < 0.02 * peak), name


def test_noise_is_seeded_and_has_the_requested_snr(small_grid):
    a = add_measurement_noise(small_grid, 30.0, seed=7)
    b = add_measurement_noise(small_grid, 30.0, seed=7)
    c = add_measurement_noise(small_grid, 30.0, seed=8)
    for name in PAPER_SIGNALS:
        np.testing.assert_array_equal(a.signals[name], b.signals[name])
        assert not np.array_equal(a.signals[name], c.signals[name])
    x = small_grid.signals["a1"]
    noise = a.signals["a1"] - x
    snr = 10 * np.log10(np.mean(x ** 2, axis=1) / np.mean(noise ** 2, axis=1))
    assert np.all(np.abs(snr - 30.0) < 0.5)
    with pytest.raises(ValueError, match="snr_db"):
        add_measurement_noise(small_grid, float("nan"), seed=1)


def test_same_inputs_same_output():
    cases = [Case(1.102, 0.0075, 0.0375)]
    a, b = simulate_grid(CFG, cases), simulate_grid(CFG, cases)
    for k in a.signals:
        np.testing.assert_array_equal(a.signals[k], b.signals[k])


def test_encoder_quantisation(small_grid):
    q = quantise_encoders(small_grid, 4096)
    step = 2 * np.pi / 4096
    d = q.signals["alpha1"] - small_grid.signals["alpha1"]
    assert np.all(d <= 0) and np.all(d > -step)
    np.testing.assert_array_equal(q.signals["a1"], small_grid.signals["a1"])
    with pytest.raises(ValueError, match="counts_per_rev"):
        quantise_encoders(small_grid, 0)


def test_grid_is_the_papers_168_cases():
    cases = paper_grid_cases(CFG)
    assert len(cases) == 7 * 6 * 4
    assert len(set(cases)) == 168
    assert cases[0] == Case(1.16, 0.0025, 0.0125)


def test_npz_round_trip(tmp_path, small_grid):
    p = tmp_path / "w.npz"
    small_grid.save_npz(p)
    from jident_ros.sim import WindowSet
    w = WindowSet.load_npz(p)
    assert w.cases == small_grid.cases
    np.testing.assert_array_equal(w.signals["v2"], small_grid.signals["v2"])


@pytest.mark.parametrize("bad", [dict(inertia_kgm2=0.0), dict(backlash_width_m=-0.001),
                                 dict(consistency_pa_sn=float("nan"))])
def test_bad_case_is_rejected_with_its_name(bad):
    args = dict(inertia_kgm2=1.16, backlash_width_m=0.005, consistency_pa_sn=0.025)
    args.update(bad)
    (name, value), = bad.items()
    with pytest.raises(ValueError, match=name):
        Case(**args)


def test_fast_rhs_equals_the_reference_rhs():
    """The integrator's matrix form of the model equals Model.rhs (the documented equations)."""
    from jident_ros.sim.model import CaseArrays, Model
    from jident_ros.sim.simulate import steady_state
    cases = [Case(0.957, 0.0025, 0.0125), Case(1.218, 0.01, 0.05)]
    model = Model(CFG)
    y, _ = steady_state(CFG, cases, 0.0123)
    rng = np.random.default_rng(0)
    y = y * (1 + 0.01 * rng.standard_normal(y.shape))
    y[6] = [0.03, -0.2]  # one case inside the zone, one in contact on the far flank
    ca = CaseArrays(np.array([0.957, 1.218]), np.array([0.025, 0.1]), np.array([0.0125, 0.05]))
    ref = model.rhs(0.0123, y, ca)
    fast = model.fast_rhs(ca)(model.bias_table([0.0123])[0], y, np.empty_like(y))
    np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-9 * np.abs(ref).max())
