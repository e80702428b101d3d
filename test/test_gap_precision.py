"""The gap estimator's documented precision and interval rules (docs/method.md "Variant gap", gap.py docstring).

Tests that a plausible wrong one-line change of gap.py fails (issue 11 part 5, scripts/mutation.py):

* noise-free simulated windows: each fit within a small multiple of what docs/results.md reports
  (speed 0.003 %, the others 0.03 %), so a 0.2 % bias cannot hide behind a 0.5 % tolerance;
* synthetic windows on which a fit's model is exact: J1 to 1e-9;
* the 95 % interval = J1 ± t_0.975(dof) · standard error with the documented degrees of freedom, compared with
  scipy.stats.t directly; the anchored fit's standard error against a direct least-squares computation;
* the gap interval's rules (strict inequality 1, the signature's drop and the sample left out, >= 3 samples),
  the bearing-friction correction, the backlash-width bracket.

Cost: one simulate_grid call of 3 cases (about 0.5 s); the rest is synthetic and fast.
"""
from __future__ import annotations

import numpy as np
import pytest
from gap_windows import CFG, N_PRE, TS, R, exact_window, motor_angles
from scipy import stats

from jident_ros.identify.gap import (
    ANGLE_REL_SE_FLOOR,
    GAP_QUADRATIC_MIN,
    MAX_RELATIVE_STD_ERROR,
    GapEstimate,
    NoGapError,
    estimate_backlash_width,
    estimate_inertia,
    gap_interval,
    nearest_class,
)
from jident_ros.sim import Case, simulate_grid


def _half_width(g):
    lo, hi = g.ci95_kgm2
    assert (g.inertia_kgm2 - lo) == pytest.approx(hi - g.inertia_kgm2, rel=1e-9)   # symmetric
    return 0.5 * (hi - lo)


# --------------------------------------------------------------------------- simulated, noise-free
@pytest.fixture(scope="module")
def simulated():
    cases = [Case(0.957, 0.0025, 0.0125), Case(1.16, 0.005, 0.025), Case(1.218, 0.01, 0.05)]
    return simulate_grid(CFG, cases)


@pytest.mark.parametrize("keys, method, rel_tol", [
    (("omega1", "m_el"), "speed", 1e-4),                           # results.md: max 0.003 % over 168 windows
    (("alpha1", "alpha2", "a1", "m_el"), "acceleration", 5e-4),    # max 0.031 %
    (("a1", "m_el"), "acceleration", 5e-4),                        # max 0.029 % (signature interval)
    (("alpha1", "alpha2", "m_el"), "angle", 5e-4),                 # max 0.032 %
    (("alpha1", "alpha2", "a1", "m_el"), "anchored", 1e-3),        # max 0.072 %
])
def test_noise_free_simulated_windows_within_the_documented_error(simulated, keys, method, rel_tol):
    for i, c in enumerate(simulated.cases):
        w = simulated.case(i)
        g = estimate_inertia({k: w[k] for k in keys}, simulated.entry_index, c.backlash_width_m, R,
                             simulated.sample_period_s, method)
        assert g.method == method
        assert abs(g.inertia_kgm2 / c.inertia_kgm2 - 1) < rel_tol, (c, method, g.inertia_kgm2)
        assert g.interval == ("angles" if "alpha2" in keys else "signature")
        assert 9 <= g.n_samples <= 32                                # docs/model.md: the gap spans 9-32 samples


def test_default_fit_follows_the_channels(simulated):
    """gap_method auto: 'acceleration' with a1 (cross-checked with 'angle' when alpha1 is there too: the one with
    the smaller standard error), else 'angle' with alpha1, else 'speed'."""
    w, c = simulated.case(1), simulated.cases[1]
    for keys, method in ((("a1", "m_el"), ("acceleration",)), (("alpha1", "alpha2", "a1", "m_el"), ("acceleration", "angle")),
                         (("alpha1", "alpha2", "m_el"), ("angle",)), (("omega1", "m_el"), ("speed",))):
        g = estimate_inertia({k: w[k] for k in keys}, simulated.entry_index, c.backlash_width_m, R, TS)
        assert g.method in method
        assert ("cross-checked" in g.model_choice) == (len(method) == 2), g.model_choice


# --------------------------------------------------------------------------- synthetic exact windows
@pytest.mark.parametrize("j1", [0.957, 1.218])
def test_speed_fit_is_exact_for_a_linear_torque(j1):
    """∫ m_el dt = J1 Δω1: with m_el linear in t the trapezoid rule is exact, so J1 comes out to 1e-9."""
    w, width = exact_window(j1, torque=(150.0, 4000.0, 0.0, 0.0))
    g = estimate_inertia({k: w[k] for k in ("omega1", "m_el", "alpha1", "alpha2")}, N_PRE, width, R, TS, "speed")
    assert g.inertia_kgm2 == pytest.approx(j1, rel=1e-9)
    assert (g.gap_start, g.gap_end) == (N_PRE, N_PRE + 20)


@pytest.mark.parametrize("n_gap", [8, 20])           # below and above GAP_QUADRATIC_MIN (straight line / quadratic)
def test_anchored_fit_is_exact_when_m_el_is_its_model(n_gap):
    """'anchored': m0 = pre-entry mean, m_el = m0 + b t (+ c t^2 from GAP_QUADRATIC_MIN samples on), then a1 =
    (r/J1) m_hat through the origin: exact when m_el is that model."""
    torque = (150.0, -3000.0, 0.0, 0.0) if n_gap < GAP_QUADRATIC_MIN else (150.0, -3000.0, 9.0e4, 0.0)
    w, width = exact_window(1.16, n_gap=n_gap, torque=torque)
    g = estimate_inertia(w, N_PRE, width, R, TS, "anchored")
    assert g.inertia_kgm2 == pytest.approx(1.16, rel=1e-9)
    assert g.n_samples == n_gap


@pytest.mark.parametrize("method", ["acceleration", "angle"])
def test_cubic_torque_fits_are_exact(method):
    w, width = exact_window(1.073)
    keys = ("alpha1", "alpha2", "a1", "m_el") if method == "acceleration" else ("alpha1", "alpha2", "m_el")
    if method == "angle":
        w = motor_angles(w)
    g = estimate_inertia({k: w[k] for k in keys}, N_PRE, width, R, TS, method)
    # the free angle fit integrates the sampled torque by the trapezoid rule (no torque model): 3e-6
    assert g.inertia_kgm2 == pytest.approx(1.073, rel=1e-5 if method == "angle" else 1e-7)
    assert g.n_samples == 20


@pytest.mark.parametrize("method, rel_tol", [
    ("acceleration", 1e-4),     # b1 omega1 adds a linear term the torque model does not have: 1.4e-5
    ("angle", 1e-4),
    ("speed", 1e-7),
    ("anchored", 1e-9),         # m0 anchors m_el - b1 omega1 too: the model is exact
])
def test_known_bearing_friction_is_taken_off_m_el(method, rel_tol):
    """docs/method.md: with motor.bearing_friction_nms_per_rad every fit subtracts b1 omega1 from m_el."""
    b1 = 0.05
    torque = (150.0, -3000.0, 9.0e4, 0.0) if method == "anchored" else \
        (150.0, 4000.0, 0.0, 0.0) if method == "speed" else (150.0, 0.0, -8000.0, 2.0e5)
    w, width = exact_window(1.16, torque=torque, friction=b1)
    if method == "angle":
        w = dict(motor_angles(w), omega1=w["omega1"])
    g = estimate_inertia(w, N_PRE, width, R, TS, method, bearing_friction_nms_per_rad=b1)
    assert g.inertia_kgm2 == pytest.approx(1.16, rel=rel_tol)
    biased = estimate_inertia(w, N_PRE, width, R, TS, method)
    assert abs(biased.inertia_kgm2 / 1.16 - 1) > 1e-3            # b1 omega1 = 7.5 N m of 150: not negligible


# --------------------------------------------------------------------------- intervals: Student t, dof
def test_acceleration_interval_uses_t_with_pre_entry_samples_minus_one_dof():
    """docs/method.md: 'The interval uses Student t with (pre-entry samples − 1) degrees of freedom.'"""
    for n_pre in (48, 20):
        w, width = exact_window(1.16, n_pre=n_pre, acc_noise=0.2, seed=5)
        g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, n_pre, width, R, TS)
        assert g.method == "acceleration" and g.std_error_kgm2 > 0
        assert _half_width(g) == pytest.approx(stats.t.ppf(0.975, n_pre - 1) * g.std_error_kgm2, rel=1e-12)


@pytest.mark.parametrize("n_gap", [10, 20])
def test_anchored_interval_uses_t_with_gap_samples_minus_one_dof(n_gap):
    """'anchored': one parameter (r/J1) fitted through the origin on the n gap a1 samples: n - 1 degrees of
    freedom."""
    w, width = exact_window(1.16, n_gap=n_gap, acc_noise=0.2, seed=7)
    g = estimate_inertia(w, N_PRE, width, R, TS, "anchored")
    assert g.n_samples == n_gap
    assert _half_width(g) == pytest.approx(stats.t.ppf(0.975, n_gap - 1) * g.std_error_kgm2, rel=1e-12)


def _anchored_reference(w, n_gap):
    """The anchored fit by hand, with m_el exactly its model (no m_el error term): ordinary least squares of a1 on
    m_hat through the origin, s^2 = RSS/(n - 1), se(r/J1) = s / |m_hat|, and J1 = r/kappa by the delta method."""
    gap = slice(N_PRE, N_PRE + n_gap)
    m, a = w["m_el"][gap], w["a1"][gap]
    kappa = float(a @ m) / float(m @ m)
    rss = float(np.sum((a - kappa * m) ** 2))
    se_kappa = np.sqrt(rss / (n_gap - 1) / float(m @ m))
    return R / kappa, R / kappa ** 2 * se_kappa


def test_anchored_fit_is_the_least_squares_one():
    """J1, its standard error and the residual RMS of the anchored fit equal the textbook least squares (m_el exact,
    a1 noisy): the standard error is r/kappa^2 se(kappa), not the relative one (issue 11's bug: 1/kappa too wide)."""
    n_gap = 20
    w, width = exact_window(1.16, n_gap=n_gap, torque=(150.0, -3000.0, 9.0e4, 0.0), acc_noise=0.2, seed=11)
    g = estimate_inertia(w, N_PRE, width, R, TS, "anchored")
    j_ref, se_ref = _anchored_reference(w, n_gap)
    assert g.inertia_kgm2 == pytest.approx(j_ref, rel=1e-12)
    assert g.std_error_kgm2 == pytest.approx(se_ref, rel=1e-9)
    assert g.residual_rms == pytest.approx(np.sqrt(np.mean(((w["a1"] - R / j_ref * w["m_el"])[N_PRE:N_PRE + n_gap]
                                                            * j_ref / R) ** 2)), rel=1e-9)


@pytest.mark.parametrize("torque_noise, acc_noise", [(1.5, 0.02), (0.1, 0.2), (1.5, 0.2)])
def test_anchored_standard_error_matches_the_spread_over_noise_draws(torque_noise, acc_noise):
    """'anchored': the standard error (a1 residual, and m_hat's error by the delta method) is the spread of J1 over
    noise draws, whichever channel carries the noise: median se / empirical sd in [0.85, 1.2] over 300 windows
    (measured 1.07, 0.98, 1.03), and the 95 % interval covers 1.16 in 92-99 % of them (measured 97.7, 96.7, 97.3 %).
    Before the fix of issue 11 the ratio was 3.7, 11.4 and 10.3 and the interval covered in 100 %."""
    js, ses, covered = [], [], 0
    for seed in range(300):
        w, width = exact_window(1.16, torque=(150.0, -3000.0, 9.0e4, 0.0))
        rng = np.random.default_rng(seed)
        w["m_el"] = w["m_el"] + torque_noise * rng.standard_normal(len(w["m_el"]))
        w["a1"] = w["a1"] + acc_noise * rng.standard_normal(len(w["a1"]))
        g = estimate_inertia(w, N_PRE, width, R, TS, "anchored")
        js.append(g.inertia_kgm2)
        ses.append(g.std_error_kgm2)
        covered += g.ci95_kgm2[0] <= 1.16 <= g.ci95_kgm2[1]
    ratio = np.median(ses) / np.std(js)
    assert 0.85 <= ratio <= 1.2, ratio
    assert 0.92 <= covered / 300 <= 0.99, covered


def test_speed_interval_uses_t_with_gap_samples_minus_three_dof():
    """'speed': ω1 = ω1_0 + ∫m_el dt / J1 - (τ/J1) m_el (the feedback's lag τ), ω1 regressed on the integral and
    the torque (n - 3 dof), the slope's variance
    inflated by the residual's lag-1 autocorrelation (1 + rho)/(1 - rho), rho >= 0, and the larger change of J1 when
    one or two samples are dropped at each end added in quadrature (gap.speed_fit)."""
    n_gap = 20
    w, width = exact_window(1.16, torque=(150.0, 4000.0, 0.0, 0.0))
    w["omega1"] = w["omega1"] + 2e-4 * np.random.default_rng(3).standard_normal(len(w["omega1"]))
    g = estimate_inertia({k: w[k] for k in ("omega1", "m_el", "alpha1", "alpha2")}, N_PRE, width, R, TS, "speed")
    gap = slice(N_PRE, N_PRE + n_gap)
    m, om = w["m_el"][gap], w["omega1"][gap]
    y = np.concatenate([[0.0], np.cumsum((m[1:] + m[:-1]) / 2) * TS])
    A = np.column_stack([np.ones(n_gap), y, m])       # the speed feedback's lag: the torque is a regressor
    coef, rss, *_ = np.linalg.lstsq(A, om, rcond=None)
    res = om - A @ coef
    rho = max(float(res[1:] @ res[:-1]) / float(res @ res), 0.0)
    se_k = np.sqrt(rss[0] / (n_gap - 3) * np.linalg.inv(A.T @ A)[1, 1] * (1 + rho) / (1 - rho))
    trims = [np.linalg.lstsq(A[k:-k] - [0, y[k], 0], om[k:-k], rcond=None)[0] for k in (1, 2)]
    se = np.hypot(se_k / coef[1] ** 2, max(abs(1 / c[1] - 1 / coef[1]) for c in trims))
    se = max(se, 5e-4 / coef[1])                       # FREE_REL_SE_FLOOR: every fit's floor
    assert g.inertia_kgm2 == pytest.approx(1 / coef[1], rel=1e-12)
    assert g.std_error_kgm2 == pytest.approx(se, rel=1e-7)
    assert _half_width(g) == pytest.approx(stats.t.ppf(0.975, n_gap - 3) * se, rel=1e-7)
    assert g.residual_rms == pytest.approx(np.sqrt(rss[0] / n_gap) / coef[1], rel=1e-9)


def test_angle_fit_standard_error_has_its_floor():
    """FREE_REL_SE_FLOOR: every fit's standard error is at least 0.05 % of J1 (noise-free: the floor, the model's
    own error); a declared torque accuracy a adds J1 a/sqrt(3) in quadrature (issue 20)."""
    from jident_ros.identify.gap_free import FREE_REL_SE_FLOOR, GapModel
    w, width = exact_window(1.16)
    g = estimate_inertia(motor_angles(w), N_PRE, width, R, TS, "angle")
    assert g.std_error_kgm2 == pytest.approx(5e-4 * g.inertia_kgm2, rel=1e-9)      # "floored at 0.05 % of J1"
    assert FREE_REL_SE_FLOOR == 5e-4
    assert ANGLE_REL_SE_FLOOR == 2e-4
    g2 = estimate_inertia(motor_angles(w), N_PRE, width, R, TS, "angle", model=GapModel(torque_accuracy=0.02))
    assert g2.std_error_kgm2 == pytest.approx(np.hypot(5e-4, 0.02 / np.sqrt(3)) * g2.inertia_kgm2, rel=1e-9)


def test_noisy_interval_is_not_refused_below_the_refusal_limit():
    w, width = exact_window(1.16, acc_noise=2.0, seed=1)
    g = estimate_inertia(w, N_PRE, width, R, TS)
    assert g.std_error_kgm2 < MAX_RELATIVE_STD_ERROR * g.inertia_kgm2
    assert g.ci95_kgm2[0] < g.inertia_kgm2 < g.ci95_kgm2[1]


# --------------------------------------------------------------------------- the gap interval
def _angles(rel):
    return {"alpha1": np.asarray(rel, float), "alpha2": np.zeros(len(rel))}


def test_angle_interval_is_the_first_run_with_strict_inequality_1():
    """|alpha1 - alpha2| < K2/r, strictly: a sample exactly at K2/r is outside (K2 = 0.05 m, r = 0.1 m)."""
    r, k2 = 0.1, 0.05          # K2/r = 0.5 exactly
    rel = [0.7, 0.6, 0.1, 0.2, 0.3, 0.4, 0.5, 0.2, 0.1, 0.9]
    assert gap_interval(_angles(rel), 2, k2, r) == (2, 6, "angles")
    assert gap_interval(_angles(rel), 3, k2, r) == (3, 6, "angles")
    with pytest.raises(NoGapError, match="no backlash gap"):
        gap_interval(_angles(rel), 6, k2, r)                    # at K2/r: not inside
    with pytest.raises(NoGapError, match="gap too short"):
        gap_interval(_angles(rel), 4, k2, r)                    # 2 samples < 3
    with pytest.raises(NoGapError, match="no re-contact"):
        gap_interval(_angles([0.7, 0.1, 0.2, 0.3, 0.4]), 1, k2, r)
    assert gap_interval(_angles([0.1, 0.1, 0.1, 0.9]), 0, k2, r) == (0, 3, "angles")   # first sample, 3 samples
    with pytest.raises(NoGapError, match="need >= 4"):
        gap_interval(_angles([0.1, 0.1, 0.1, 0.9]), 0, k2, r, min_samples=4)


@pytest.mark.parametrize("entry", [-1, 9, 10])
def test_entry_index_must_leave_a_sample_after_it(entry):
    with pytest.raises(NoGapError, match=r"\[0, 8\]"):
        gap_interval(_angles([0.1] * 10), entry, 0.05, 0.1)


def test_last_possible_entry_index_is_inside_the_window():
    with pytest.raises(NoGapError, match="gap too short: 1 samples"):     # entry 8 of 10 is inside [0, 8]
        gap_interval(_angles([0.9] * 8 + [0.1, 0.9]), 8, 0.05, 0.1)


def test_signature_interval_ends_before_the_drop_and_leaves_out_one_sample():
    """Without angles: the gap ends where a1 < drop x a1(entry) (drop = 0.6), and the sample before the drop is
    left out too (the impact happens between samples)."""
    a1 = np.array([0.0, 0.0, 10.0, 10.0, 9.0, 8.0, 7.0, 6.0, 5.0, -3.0])   # 6.0 = 0.6 x 10 is not below
    assert gap_interval({"a1": a1}, 2, 0.005, R) == (2, 7, "signature")
    assert gap_interval({"a1": a1}, 2, 0.005, R, drop=0.75) == (2, 5, "signature")
    with pytest.raises(NoGapError, match="does not accelerate"):
        gap_interval({"a1": a1}, 0, 0.005, R)                   # a1 = 0 at the entry: not > 0
    with pytest.raises(NoGapError, match="never drops"):
        gap_interval({"a1": np.full(10, 3.0)}, 2, 0.005, R)
    with pytest.raises(NoGapError, match="gap too short"):
        gap_interval({"a1": np.array([0.0, 10.0, 9.0, 8.0, 1.0, 0.0])}, 1, 0.005, R)   # 2 samples left
    assert gap_interval({"a1": np.array([0.0, 10.0, 9.0, 8.0, 7.0, 1.0])}, 1, 0.005, R) == (1, 4, "signature")


def test_signature_from_a_speed_or_a_motor_angle():
    """Drives without a1: the same test on the smoothed derivative of omega1, or second derivative of alpha1."""
    w, width = exact_window(1.16)
    for keys in (("omega1", "m_el"), ("alpha1", "m_el")):
        d = {k: w[k] for k in keys}
        if keys[0] == "alpha1":     # a motor encoder
            d["alpha1"] = w["alpha_motor"]
        start, end, how = gap_interval(d, N_PRE, width, R)
        assert how == "signature" and start == N_PRE and 14 <= end - start <= 20
    with pytest.raises(NoGapError, match="no gap signal"):
        gap_interval({"m_el": w["m_el"]}, N_PRE, width, R)


# --------------------------------------------------------------------------- width bracket, nearest class
def test_width_bracket_is_the_midpoint_with_a_uniform_uncertainty():
    """Bracket: width = r (|d_last| + |d_first|)/2, standard uncertainty r (|d_first| - |d_last|)/sqrt(12)."""
    rel = np.array([0.7, 0.1, 0.3, 0.46, 0.54, 0.9])
    est = estimate_backlash_width(_angles(rel), 4, 0.1)
    assert est.method == "bracket" and est.recontact_index == 4
    assert est.width_m == pytest.approx(0.1 * 0.5, rel=1e-12)
    assert est.std_m == pytest.approx(0.1 * 0.08 / np.sqrt(12.0), rel=1e-12)
    with pytest.raises(NoGapError, match="no re-contact"):
        estimate_backlash_width(_angles(rel), 6, 0.1)
    with pytest.raises(NoGapError, match="no re-contact"):
        estimate_backlash_width(_angles(rel), 0, 0.1)


def test_nearest_class():
    classes = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)
    assert [nearest_class(j, classes) for j in (0.5, 1.0, 1.116, 1.118, 1.2, 2.0)] == [4, 4, 2, 1, 5, 6]


def test_cubic_term_from_eight_gap_samples_on():
    """docs/method.md: c3 is dropped for gaps shorter than 8 samples; at 8 the cubic torque is fitted exactly."""
    w, width = exact_window(1.16, n_gap=8, torque=(150.0, 0.0, -2.0e5, 2.0e8))
    g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, N_PRE, width, R, TS)
    assert g.n_samples == 8 and g.inertia_kgm2 == pytest.approx(1.16, rel=1e-7)
    w, width = exact_window(1.16, n_gap=7, torque=(150.0, 0.0, -2.0e5, 2.0e8))
    g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, N_PRE, width, R, TS)
    assert g.n_samples == 7 and abs(g.inertia_kgm2 / 1.16 - 1) > 1e-6          # quadratic model only


def test_five_pre_entry_samples_still_give_the_noise_levels_and_dof():
    """The pre-entry samples give the noise levels and the t degrees of freedom (pre-entry samples - 1), down to 5."""
    w, width = exact_window(1.16, n_pre=5, acc_noise=0.2, seed=5)
    g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, 5, width, R, TS, "acceleration")
    assert _half_width(g) == pytest.approx(stats.t.ppf(0.975, 4) * g.std_error_kgm2, rel=1e-12)


def test_negative_speed_fit_is_refused_as_non_physical():
    w, width = exact_window(1.16, torque=(150.0, 4000.0, 0.0, 0.0))
    d = {k: w[k] for k in ("omega1", "m_el", "alpha1", "alpha2")}
    d["omega1"] = 2 * d["omega1"][0] - d["omega1"]                  # decelerating under a positive torque
    with pytest.raises(NoGapError, match="non-physical J1"):
        estimate_inertia(d, N_PRE, width, R, TS, "speed")


@pytest.mark.parametrize("torque_noise, acc_noise", [(1.5, 0.02), (0.1, 0.2), (1.5, 0.2)])
def test_joint_fit_standard_error_matches_the_spread_over_noise_draws(torque_noise, acc_noise):
    """The joint fit's standard error (sandwich covariance, each block's own residual variance, plus the model
    error) is the spread of J1 over noise draws: median standard error / empirical sd in [0.85, 1.4] over 200
    windows, whichever channel carries the noise (measured 1.13, 1.04, 1.10)."""
    js, ses = [], []
    for seed in range(200):
        w, width = exact_window(1.16)
        rng = np.random.default_rng(seed)
        w["m_el"] = w["m_el"] + torque_noise * rng.standard_normal(len(w["m_el"]))
        w["a1"] = w["a1"] + acc_noise * rng.standard_normal(len(w["a1"]))
        g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, N_PRE, width, R, TS)
        js.append(g.inertia_kgm2)
        ses.append(g.std_error_kgm2)
    ratio = np.median(ses) / np.std(js)
    assert 0.85 <= ratio <= 1.4, ratio
    assert abs(np.mean(js) / 1.16 - 1) < 3 * np.std(js) / np.sqrt(200) / 1.16 + 1e-6


def test_contact_fit_does_not_use_the_first_contact_sample(simulated):
    """docs/method.md: the contact regression starts at the second contact sample (the first holds the impact's
    transition), so a1 and m_el at the first contact sample do not change the width."""
    i = 1
    w, c = dict(simulated.case(i)), simulated.cases[i]
    g = estimate_inertia(w, simulated.entry_index, c.backlash_width_m, R, simulated.sample_period_s)
    ref = estimate_backlash_width(w, g.gap_end, R, simulated.sample_period_s, g.inertia_kgm2)
    assert ref.method == "contact"
    for k in ("a1", "m_el"):
        w[k] = w[k].copy()
        w[k][g.gap_end] *= 1.5
    got = estimate_backlash_width(w, g.gap_end, R, simulated.sample_period_s, g.inertia_kgm2)
    assert (got.width_m, got.std_m, got.method) == (ref.width_m, ref.std_m, ref.method)


def test_model_error_is_the_change_of_j1_with_a_linear_torque_term():
    """GapEstimate.model_error_kgm2 ('acceleration'): |J1 with a linear torque term - J1|, in the standard error.
    With a gap torque that has a linear term the extended model is exact, so the model error is the fit's error."""
    w, width = exact_window(1.16, torque=(150.0, 3000.0, -8000.0, 0.0))
    g = estimate_inertia({k: w[k] for k in ("alpha1", "alpha2", "a1", "m_el")}, N_PRE, width, R, TS)
    assert g.model_error_kgm2 > 1e-6
    assert g.model_error_kgm2 == pytest.approx(abs(g.inertia_kgm2 - 1.16), rel=1e-6)
    assert g.std_error_kgm2 >= g.model_error_kgm2
    assert GapEstimate(1.0, 0.1, (0.8, 1.2), 0.0, 48, 60, "speed", "angles").model_error_kgm2 == 0.0
    for method in ("anchored", "speed"):                                           # "0 for the other fits"
        assert estimate_inertia(w, N_PRE, width, R, TS, method).model_error_kgm2 == 0.0
    ga = estimate_inertia(motor_angles(w), N_PRE, width, R, TS, "angle")   # the angle fit: its change-point term
    assert ga.method == "angle" and ga.model_error_kgm2 == ga.change_point_error_kgm2


def test_a_gap_too_short_says_by_what_its_end_was_found():
    """The refusal names the rule that ended the gap: the angles (K2), the detector's re-contact row, or the
    motor's acceleration (a motor that hardly accelerates, as in a load-driven traversal, ends it at once)."""
    with pytest.raises(NoGapError, match=r"gap too short: 2 samples inside the zone \(while \|alpha1 - alpha2\|"):
        gap_interval(_angles([0.7, 0.6, 0.1, 0.2, 0.3, 0.4, 0.5, 0.2, 0.1, 0.9]), 4, 0.05, 0.1)
    with pytest.raises(NoGapError, match=r"2 samples inside the zone \(to the detector's re-contact row\)"):
        gap_interval(_angles([0.1] * 10), 4, 0.05, 0.1, recontact_index=6)
    with pytest.raises(NoGapError, match=r"2 samples inside the zone \(until the motor's acceleration falls below 0.6 x"):
        gap_interval({"a1": np.array([0.0, 10.0, 9.0, 8.0, 1.0, 0.0])}, 1, 0.005, R)
