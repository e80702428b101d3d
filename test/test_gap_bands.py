"""The torque estimate's offset and lag as bounded terms of the gap interval, the interval-width cap of the
verdict, and what the zoo declares per drive (issue 20 items 3 and 6)."""
import numpy as np
import pytest

from jident_ros.identify import gap_a1
from jident_ros.identify.gap import GapEstimate, estimate_inertia
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.verdict import MAX_CI95_HALF_WIDTH_REL, VerdictPolicy, decide_gap
from jident_ros.research.evaluation.gap_stress import StressDrive, simulate

TS, R = 5e-4, 0.08
CLASSES = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)


def _angle(rec, model, m_el=None):
    w = dict(rec["window"])
    w.pop("a1", None)
    if m_el is not None:
        w["m_el"] = m_el
    return estimate_inertia(w, rec["entry"], 0.005, R, TS, method="angle", recontact_index=rec["recontact"],
                            model=model)


def _covers(g, j1):
    return g.ci95_kgm2[0] <= j1 <= g.ci95_kgm2[1]


@pytest.fixture(scope="module")
def reversal():
    return simulate(StressDrive(j1_kgm2=1.16), "speed_reversal", seed=3)


@pytest.fixture(scope="module")
def light():
    return simulate(StressDrive(j1_kgm2=1.16), "load_reversal", seed=3)


def test_a_torque_offset_inside_its_band_is_covered(reversal):
    """The drive's torque estimate 5 N m high through the gap (an offset, not a scale error): J1 is biased and its
    interval misses the truth; with the offset band ± 6 N m declared it covers it, J1 itself unchanged.  (3 N m
    before stop 27: the change-point term's trims at both ends now hold it without the band.)"""
    m = np.asarray(reversal["window"]["m_el"], float) + 5.0
    bare = _angle(reversal, GapModel(coulomb_friction_max_nm=1.5), m)
    assert not _covers(bare, 1.16)
    banded = _angle(reversal, GapModel(coulomb_friction_max_nm=1.5, torque_offset_nm=6.0), m)
    assert _covers(banded, 1.16)
    assert banded.inertia_kgm2 == pytest.approx(bare.inertia_kgm2, rel=1e-12)
    t6 = dict(banded.std_error_terms)["torque_offset"]
    t12 = dict(_angle(reversal, GapModel(coulomb_friction_max_nm=1.5, torque_offset_nm=12.0), m).std_error_terms)
    assert t12["torque_offset"] == pytest.approx(2 * t6, rel=1e-9)         # linear in the band (a uniform term)
    assert "torque_offset" not in dict(bare.std_error_terms)


def test_a_lagging_torque_estimate_inside_its_band_is_covered(light, monkeypatch):
    """The torque estimate lags the shaft's torque by 0.7 ms (the vector drive's): on a load reversal, whose torque
    changes through the gap, J1 is 4-5 % high and the bare interval misses; torque_lag_s = 1 ms covers it.  Undeclared,
    the angle shows the lag (gap._lag_beyond_declared) and the interval takes it: covered too, and said."""
    from jident_ros.identify import gap
    m = np.asarray(light["window"]["m_el"], float)
    t = np.arange(m.size) * TS
    lagged = np.interp(t - 7e-4, t, m)
    seen = _angle(light, GapModel(coulomb_friction_max_nm=1.5), lagged)
    assert _covers(seen, 1.16) and "beyond the declared 0 ms" in seen.model_choice, seen.model_choice
    banded = _angle(light, GapModel(coulomb_friction_max_nm=1.5, torque_lag_s=1e-3), lagged)
    assert _covers(banded, 1.16)
    # the declared term alone (the check off): the bare interval misses, the term is linear in the declared lag
    monkeypatch.setattr(gap, "LAG_Z", np.inf)
    bare = _angle(light, GapModel(coulomb_friction_max_nm=1.5), lagged)
    assert not _covers(bare, 1.16)
    half = _angle(light, GapModel(coulomb_friction_max_nm=1.5, torque_lag_s=5e-4), lagged)
    banded = _angle(light, GapModel(coulomb_friction_max_nm=1.5, torque_lag_s=1e-3), lagged)
    assert dict(half.std_error_terms)["torque_lag"] == pytest.approx(0.5 * dict(banded.std_error_terms)["torque_lag"],
                                                                     rel=1e-9)


def test_the_a1_fits_carry_the_bands_too(reversal):
    """With an accelerometer (the model choice cross-checks the a1 fit and the angle fit) the offset and lag terms
    are in the published interval as well."""
    w = dict(reversal["window"])
    g0 = estimate_inertia(w, reversal["entry"], 0.005, R, TS, recontact_index=reversal["recontact"],
                          model=GapModel())
    g = estimate_inertia(w, reversal["entry"], 0.005, R, TS, recontact_index=reversal["recontact"],
                         model=GapModel(torque_offset_nm=4.0, torque_lag_s=1e-3))
    terms = dict(g.std_error_terms)
    # the offset is bounded (a term) or fitted beside J1 where that is the more precise (_gap_only_constant)
    assert (terms.get("torque_offset", 0) > 0 or g.friction.startswith("fitted: a constant torque")) \
        and terms["torque_lag"] > 0
    assert g.std_error_kgm2 > g0.std_error_kgm2
    # the torque estimate 3 N m high through the gap: covered with the band declared, missed without it
    w["m_el"] = np.asarray(w["m_el"], float) + 3.0
    off = estimate_inertia(w, reversal["entry"], 0.005, R, TS, recontact_index=reversal["recontact"],
                           model=GapModel(torque_offset_nm=4.0))
    bare = estimate_inertia(w, reversal["entry"], 0.005, R, TS, recontact_index=reversal["recontact"], model=GapModel())
    assert off.ci95_kgm2[0] <= 1.16 <= off.ci95_kgm2[1] and not bare.ci95_kgm2[0] <= 1.16 <= bare.ci95_kgm2[1]


def test_policy_scales_the_offset_band_by_the_base_torque():
    p = VerdictPolicy(torque_offset_rel_base=0.01, torque_lag_max_s=1e-3)
    m = p.gap_model(212.0)
    assert m.torque_offset_nm == pytest.approx(2.12) and m.torque_lag_s == 1e-3
    assert VerdictPolicy().gap_model(212.0).torque_offset_nm == pytest.approx(2.12)     # the default, 1 % of M_b
    assert VerdictPolicy(torque_offset_rel_base=0.0).gap_model(212.0).torque_offset_nm == 0.0
    assert ("torque_offset_rel_base", "a fraction in [0, 1)") in VerdictPolicy(torque_offset_rel_base=-0.1).problems()
    assert any(n == "torque_lag_max_s" for n, _ in VerdictPolicy(torque_lag_max_s=2.0).problems())
    assert any(n == "torque_offset_nm" for n, _ in GapModel(torque_offset_nm=-1.0).problems())


def _estimate(j1, half_rel):
    h = half_rel * j1
    return GapEstimate(j1, h / 1.96, (j1 - h, j1 + h), 0.0, 10, 40, "angle", "detector")


def test_an_interval_wider_than_ten_percent_is_not_published():
    """A J1 whose 95 % interval is ± 11 % of it could be 10 % off inside its own interval: refused as
    undetermined even when the interval holds one class only (the vector drive's heavy load reversal was
    published at −30 %, ± 14 %); ± 9 % goes on to the class test."""
    assert MAX_CI95_HALF_WIDTH_REL == 0.10
    wide = decide_gap(_estimate(0.81, 0.11), CLASSES, 1.16, VerdictPolicy(), None, 0.005)
    assert wide.status == "ambiguous" and wide.reason.startswith("undetermined")     # nothing published
    narrow = decide_gap(_estimate(0.81, 0.09), CLASSES, 1.16, VerdictPolicy(), None, 0.005)
    assert narrow.status != "refused" and not narrow.reason.startswith("undetermined")
    ok = decide_gap(_estimate(1.16, 0.005), CLASSES, 1.16, VerdictPolicy(), None, 0.005)
    assert ok.status == "accepted"


def test_the_zoo_declares_each_drive_as_a_user_would():
    """The zoo configures each model's friction and torque estimate as its documentation gives them (docs/
    vector_drive.md, docs/second_drive.md); ours is config/system.yaml as it is, its torque exact."""
    from jident_ros.research.evaluation.zoo import declared
    from jident_ros.research.second_drive.model import DriveParams as SecondParams
    from jident_ros.research.vector_drive.model import DriveParams as VectorParams
    assert declared("ours") == {"assume_typical_drive": False, "coupling_release_max_s": 0.0}  # exact torque, rigid contact
    assert declared("second drive") == {"bearing_friction_nms_per_rad": SecondParams().motor.bearing_friction_nms}
    v = declared("vector drive")
    mech = VectorParams().mechanics
    assert v["bearing_friction_nms_per_rad"] == mech.motor_viscous_nms_per_rad
    assert v["coulomb_friction_max_nm"] >= mech.motor_coulomb_nm
    assert v["torque_accuracy"] > 0 and v["torque_offset_rel_base"] > 0 and v["torque_lag_max_s"] > 0


def test_the_oracle_reads_j1_and_its_sensitivities_off_an_exact_gap():
    """zoo_oracle.gap_oracle on a single mass under a known ramping torque (exact double integral): J1 exact with
    and without the extra columns, the fitted lag 0, and the sensitivities the ones of the interval's terms."""
    from jident_ros.research.evaluation.zoo_oracle import gap_oracle
    n, j1 = 60, 1.16
    t = np.arange(n) * TS
    m = 300.0 - 4.0e6 * t ** 2                          # a torque ramping through the gap
    z = 300.0 * t ** 2 / 2 - 4.0e6 * t ** 4 / 12
    alpha = 2.0 + 100.0 * t + z / j1
    o = gap_oracle(t, alpha, m, np.full(n, 100.0), 0, n)
    assert o["j1"] == pytest.approx(j1, rel=1e-3) and o["j1_lag"] == pytest.approx(j1, rel=2e-3)   # trapezoid
    assert abs(o["lag_s"]) < 5e-5
    assert o["per_nm"] > 0 and o["per_ms"] > 0
    # b1 taken off: a viscous torque added to m_el and declared leaves J1
    o2 = gap_oracle(t, alpha, m + 0.02 * 100.0, np.full(n, 100.0), 0, n, b1=0.02)
    assert o2["j1"] == pytest.approx(o["j1"], rel=1e-9)


def _ramp_window(drift_nm, n=400, s=48, gap=156, j1=1.16):
    """A motor free in [s, s + gap) under a torque ramping 20 -> 30 N m (a low-torque gap: the vector drive's
    return traversal), steady before and after; the torque estimate off by an error drifting -drift..+drift across
    the gap."""
    m_true = np.full(n, 60.0)
    e = s + gap
    m_true[s:e] = 20.0 + 10.0 * np.arange(gap) / gap
    acc = np.zeros(n)
    acc[s:e] = m_true[s:e] / j1
    omega = 50.0 + np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * TS)])
    alpha = 0.3 + np.concatenate([[0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * TS)])
    err = np.zeros(n)
    err[s:e] = np.linspace(-drift_nm, drift_nm, gap)
    err[:s], err[e:] = -drift_nm, drift_nm
    return alpha, m_true + err, s, e


def test_a_torque_error_drifting_across_the_gap_is_a_term_of_the_interval():
    """The torque estimate's error may move across the gap (with the slip: the vector drive's return traversals,
    19 N m of gap torque, published J1 +12 % before this term): with the offset band declared, the free angle fit
    carries the J1 change an error drifting from -T to +T causes (torque_drift; J1 |r_κ · col| T / sqrt 3). Checked
    against the change it really causes: inject the drift, refit the same interval."""
    from jident_ros.identify.gap_free import free_angle_fit
    a0, m0, s, e = _ramp_window(0.0)
    a1, m1, _, _ = _ramp_window(0.5)
    model = GapModel(torque_offset_nm=0.5)
    f0 = free_angle_fit(a0, m0, TS, s, e, model, fixed=True)
    f1 = free_angle_fit(a1, m1, TS, s, e, model, fixed=True)
    assert f0["j1"] == pytest.approx(1.16, rel=1e-6)
    moved = abs(f1["j1"] - f0["j1"])
    assert moved > 1e-4 * 1.16                                     # the drift does bias the gap
    assert f0["terms"]["torque_drift"] * np.sqrt(3.0) == pytest.approx(moved, rel=0.15)    # first order: 0.91x
    assert "torque_drift" not in free_angle_fit(a0, m0, TS, s, e, GapModel(), fixed=True)["terms"]
    # linear in the band, like the offset term
    f2 = free_angle_fit(a0, m0, TS, s, e, GapModel(torque_offset_nm=1.0), fixed=True)
    assert f2["terms"]["torque_drift"] == pytest.approx(2 * f0["terms"]["torque_drift"], rel=1e-9)


@pytest.mark.parametrize("method", [None, "gap_only", "acceleration", "anchored", "angle"])
@pytest.mark.parametrize("noise", [0.0, 0.5])
@pytest.mark.parametrize("banded", [False, True])
def test_the_parts_of_the_standard_error_account_for_it_on_every_fit_path(method, noise, banded):
    """std_error_terms add up (in quadrature) to the standard error on every path: the a1 fits' own parts
    ('statistical', 'model_form' or 'change_points'), gap_free's floor ('model_floor'), the bands.  An 'undetermined'
    names the largest (verdict.widest_term): a missing part once named a 0.8 % term of a ± 19 % interval."""
    import numpy as np
    from gap_windows import N_PRE, TS, R, exact_window, motor_angles
    w, k2 = exact_window(1.16, acc_noise=noise)
    window = {k: v for k, v in w.items() if k != "alpha_motor"}
    if method == "angle":
        window = motor_angles(w)
        window["alpha1"] = window["alpha1"] + noise * 1e-4 * np.random.default_rng(1).standard_normal(window["alpha1"].size)
    model = GapModel(torque_accuracy=0.02, coulomb_friction_max_nm=1.0, torque_offset_nm=2.0, torque_lag_s=1e-3) \
        if banded else GapModel()
    k = 1 if method == "gap_only" else 0          # the entry row known to ± 1 (the dynamics detector): a part too
    g = estimate_inertia(window, N_PRE + k, k2, R, TS, method=method, model=model, entry_uncertainty_samples=k)
    total = float(np.sqrt(sum(v * v for _, v in g.std_error_terms)))
    assert total == pytest.approx(g.std_error_kgm2, rel=1e-9), (g.std_error_terms, g.std_error_kgm2)


def _constant_torque_window(f_nm: float, seed: int = 4) -> dict:
    """A gap of 200 rows whose torque swings (a DOL motor's slip dynamics, zoo_draws d1-01) and an unknown constant
    torque ``f_nm`` (Coulomb friction + the estimate's offset): m_el exact (a quantised estimate reads as exact),
    a1 with a little noise; 48 steady rows before the entry."""
    rng = np.random.default_rng(seed)
    t = np.arange(248) * TS
    tg = t[48:] - t[48]
    m = np.concatenate([np.full(48, -30.0), -30.0 + 29.0 * np.sin(np.pi * tg / 0.1) ** 2 + 60.0 * tg])
    acc = np.concatenate([np.zeros(48), (m[48:] - f_nm) / 1.16])
    return {"m_el": m, "a1": R * (acc + rng.normal(0.0, 0.05, t.size))}


def test_a_constant_torque_the_gap_only_fit_does_not_model_is_fitted_or_bounded_through_its_own_estimator(monkeypatch):
    """J1 through the origin misses a constant torque F: with m_el exact its Deming slope is the reverse regression,
    biased by ~F²/(J1 mean acc²) -- 17 % on zoo_draws' d1-01 inside a ± 8 % interval, because the band's term was the
    least-squares slope's first order F Σx/Σx².  Now the constant is fitted beside J1 where that is the more precise
    (exact here), and where it is not taken, the band's term comes from refitting with the torque moved (covers)."""
    w = _constant_torque_window(-2.5)
    model = GapModel(coulomb_friction_max_nm=2.6)
    g = estimate_inertia(w, 48, 0.005, R, TS, method="gap_only", recontact_index=248, model=model)
    assert g.friction.startswith("fitted: a constant torque -2.5") and g.inertia_kgm2 == pytest.approx(1.16, rel=2e-3)
    assert g.ci95_kgm2[0] <= 1.16 <= g.ci95_kgm2[1]
    # the constant not fitted: the band's term through the Deming estimator itself holds the bias
    monkeypatch.setattr(gap_a1, "_constant_fit", lambda *a: None)
    b = estimate_inertia(w, 48, 0.005, R, TS, method="gap_only", recontact_index=248, model=model)
    assert abs(b.inertia_kgm2 / 1.16 - 1) > 0.03 and b.ci95_kgm2[0] <= 1.16 <= b.ci95_kgm2[1]
    assert not b.friction.startswith("fitted")


def test_a_drifting_torque_error_in_a_ramping_gap_keeps_the_bounded_fit():
    """A gap whose acceleration ramps (the vector drive's traversal back) with the estimate's error drifting inside its
    declared offset band: with the constant free, only the acceleration's variation holds J1, and a drift correlates
    with it.  The free fit's drift term is that of the centred acceleration; it keeps the bounded fit here and the
    interval covers (with the drift term of the uncentred acceleration the free fit read +6.4 % inside ± 0.6 %: the zoo's
    vector drive, its traversals back published +6/+10 %)."""
    t = np.arange(248) * TS
    tg = t[48:] - t[48]
    acc = np.concatenate([np.zeros(48), 20.0 + 400.0 * tg])            # rad/s^2, ramping through the gap
    drift = np.concatenate([np.full(48, -1.5), -1.5 + 3.0 * tg / tg[-1]])  # N m, inside a 2 N m offset band
    m = 1.16 * acc + 1.0 + drift
    w = {"m_el": m, "a1": R * (acc + np.random.default_rng(5).normal(0.0, 0.02, t.size))}
    g = estimate_inertia(w, 48, 0.005, R, TS, method="gap_only", recontact_index=248,
                         model=GapModel(coulomb_friction_max_nm=1.5, torque_offset_nm=2.0))
    assert not g.friction.startswith("fitted"), g.friction
    assert g.ci95_kgm2[0] <= 1.16 <= g.ci95_kgm2[1], (g.inertia_kgm2, g.ci95_kgm2)


@pytest.mark.parametrize("centred", [False, True])
def test_the_a1_fits_standard_error_counts_the_noise_on_the_acceleration(centred):
    """_deming_se (Fuller's errors-in-variables variance): with an exact regressor it is the least-squares standard
    error; where the acceleration's variation is barely above its noise (vector set 27's s27-10: m_ξξ 28 % of m_xx)
    it matches the spread of the Deming slope over noise draws, which the least-squares formula understates."""
    rng = np.random.default_rng(5)
    n, j_true, sy, sx = 220, 1.2, 7.6, 6.2
    xi = 5.9 * np.sin(np.linspace(0.0, 9.0, n)) + (0.0 if centred else 1.5)
    xi = xi - xi.mean() if centred else xi
    y0 = j_true * xi
    # exact regressor: the least-squares formula
    y = y0 + sy * rng.standard_normal(n)
    yc = y - y.mean() if centred else y
    j = gap_a1._origin_slope(yc, xi, sy, 0.0)
    dof = n - 2 if centred else n - 1
    ols = np.sqrt(float((yc - j * xi) @ (yc - j * xi)) / dof / float(xi @ xi))
    assert gap_a1._deming_se(yc, xi, j, sy, 0.0, centred) == pytest.approx(ols, rel=1e-9)
    # noisy regressor: Fuller's variance against the spread over draws
    js, fuller, ls = [], [], []
    for _ in range(400):
        x = xi + sx * rng.standard_normal(n)
        y = y0 + sy * rng.standard_normal(n)
        if centred:
            x, y = x - x.mean(), y - y.mean()
        jj = gap_a1._origin_slope(y, x, sy, sx)
        js.append(jj)
        fuller.append(gap_a1._deming_se(y, x, jj, sy, sx, centred))
        ls.append(np.sqrt(float((y - jj * x) @ (y - jj * x)) / dof / float(x @ x)))
    spread = float(np.diff(np.percentile(js, [15.9, 84.1]))[0]) / 2.0     # heavy tails: the central 68 %
    assert np.median(fuller) == pytest.approx(spread, rel=0.3)
    assert np.median(ls) < 0.6 * spread          # the least-squares formula the a1 fits used before stop 46
    # nothing to fit: a regressor of noise alone has no variance left, the slope no standard error
    x = sx * rng.standard_normal(n)
    y = sy * rng.standard_normal(n)
    jj = abs(gap_a1._origin_slope(y, x, sy, sx))
    assert gap_a1._deming_se(y, x, jj, sy, sx, centred) > 0.5 * jj or not np.isfinite(
        gap_a1._deming_se(y, x, jj, sy, sx, centred))


def test_the_a1_fits_interval_holds_a_torque_noise_the_samples_misread():
    """The 'noise_ratio' term: the Deming slope rests on (sy/sx)^2 read off second differences, which assume white
    noise.  A torque estimate with coloured noise (first-order, pole 0.3: its variance read 0.63 x) biases the slope
    where the acceleration barely rises above its noise; the term widens the interval there to cover, and stays
    below 2 % of J1 where the acceleration is well excited."""
    from scipy.signal import lfilter
    rng = np.random.default_rng(3)
    n, j_true = 220, 1.2
    for amp, least_with, terms_below in ((5.9, 0.9, None), (30.0, 0.85, 0.02)):
        xi = amp * np.sin(np.linspace(0.0, 9.0, n)) + 1.5
        cover_with = cover_without = 0
        rel = []
        for _ in range(200):
            ey = lfilter([1.0], [1.0, -0.3], rng.standard_normal(n + 50))[50:] * 7.6 * np.sqrt(1 - 0.09)
            y, x = j_true * xi + ey, xi + 6.2 * rng.standard_normal(n)
            sy, sx = gap_a1._robust_noise(y), gap_a1._robust_noise(x)
            j = gap_a1._origin_slope(y, x, sy, sx)
            se = gap_a1._deming_se(y, x, j, sy, sx, False)
            term = gap_a1._noise_ratio_term(y, x, j, sy, sx)
            cover_without += abs(j - j_true) <= 1.96 * se
            cover_with += abs(j - j_true) <= 1.96 * np.hypot(se, term)
            rel.append(term / j)
        assert cover_with / 200 >= least_with
        if terms_below is None:
            assert cover_without / 200 < 0.7              # without the term the interval misses
        else:
            assert np.median(rel) < terms_below
    # an exact variable: no ratio to misread
    assert gap_a1._noise_ratio_term(y, xi, j_true, sy, 0.0) == 0.0


def test_the_joint_a1_fit_tells_a_ratio_within_its_noise_from_a_sign_error(reversal):
    """The 'acceleration' (joint) fit with no positive a1/m_el: m_el's sign reversed is non-physical and says what to
    check; a gap whose motor runs at constant speed (a1 noise around 0) is undetermined, resolution-limited -- not an
    ERROR naming the signs of a healthy drive (vector set 22's s22-11 before stop 46)."""
    from jident_ros.identify.gap import NoGapError, resolution_limited
    w = dict(reversal["window"])
    s, e = reversal["entry"], reversal["recontact"]

    def joint(window):
        return estimate_inertia(window, s, 0.005, R, TS, method="acceleration", recontact_index=e,
                                model=GapModel(changepoint_search_samples=0))
    assert joint(w).inertia_kgm2 == pytest.approx(1.16, rel=0.1)     # (its pre-entry torque ramps here)
    with pytest.raises(NoGapError) as exc:
        joint(dict(w, m_el=-np.asarray(w["m_el"], float)))
    assert "non-physical a1/m_el ratio -" in str(exc.value) and "sign of m_el" in str(exc.value)
    assert not resolution_limited(str(exc.value))
    a1 = np.asarray(w["a1"], float)
    scale = float(np.abs(a1[s:e]).max())
    for seed in range(12):                       # the noise's draw gives either sign: find a negative ratio
        quiet = dict(w, a1=a1.copy())
        quiet["a1"][s:e] = np.random.default_rng(seed).normal(0.0, 0.05 * scale, e - s)
        try:
            joint(quiet)
        except NoGapError as err:
            if "a1/m_el" in str(err) and "= -" in str(err):
                assert str(err).startswith("gap fit undetermined") and "not distinguishable from 0" in str(err)
                assert resolution_limited(str(err))
                break
    else:
        pytest.fail("no negative ratio drawn")


def test_the_a1_fits_standard_error_never_falls_below_its_first_term():
    """Fuller's variance less a term that the sample's residual can make exceed the rest (σ_vv below J² σ_uu):
    _deming_se keeps the first term, σ_vv / (n m_ξξ), rather than a zero or an imaginary standard error."""
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    y = 2.0 * x + np.array([0.01, -0.01, 0.01, -0.01, 0.01, -0.01])      # residual far below J² sx²
    j = float(x @ y / (x @ x))
    se = gap_a1._deming_se(y, x, j, 0.01, 1.0, centred=False)
    res = y - j * x
    first = np.sqrt(float(res @ res) / 5 / 6 / (float(x @ y) / 6 / j))
    assert se == pytest.approx(first, rel=1e-12) and se > 0
