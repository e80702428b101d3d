"""The gap estimator's shortcuts give the numbers of the plain computation, bit for bit (issue 23, item 3).

`jident evaluate` runs the gap estimator ~40,000 times; three shortcuts cut its cost without changing a number:
the fit cache (identify.gap.fit_cache: the channel sets of one window share its angle fits and steadiness test),
the kink fit's candidates in one stacked solve (gap_kink.kink_fit), and the signature interval's Savitzky-Golay
derivative without scipy's edge fits where they are not read (gap._savgol_for_gap).  Issue 20's per-window budget
(bench/bench_gap.py) added more, each checked here against numpy or its plain form: numpy.linalg's gufuncs without
their wrapper (identify.lapack), np.diff/np.gradient/np.std re-expressed as numpy's own steps, the change-point
scans' closed-form 3 x 3 inverse (a decision, equal to LAPACK's to rounding), the double-trapezoid adjoint, the kink
fit's standard error after its checks.  bench/gap_outputs.py compares every gap estimate of two versions."""
import numpy as np
import pytest
from scipy.signal import savgol_filter

from jident_ros.config import load_system_config
from jident_ros.identify import gap, gap_angle, gap_free, gap_kink, gap_numerics
from jident_ros.identify.gap import NoGapError, estimate_inertia, fit_cache
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.gap_kink import kink_fit
from jident_ros.identify.gap_numerics import _cumtrapz
from jident_ros.research.evaluation.gap_stress import StressDrive, simulate
from jident_ros.research.evaluation.robustness import CHANNEL_SETS
from jident_ros.sim import Case, add_measurement_noise, quantise_encoders, simulate_grid

SYSTEM = load_system_config()
R = SYSTEM.load.wheel_radius_m


@pytest.fixture(scope="module")
def windows():
    cases = [Case(1.16, 0.005, 0.025), Case(0.9, 0.003, 0.1), Case(1.4, 0.0085, 0.4)]
    clean = simulate_grid(SYSTEM, cases)
    return [clean, add_measurement_noise(clean, 30.0, 7), quantise_encoders(clean, 2 ** 14)]


def _all_sets(sets, model=None):
    out = []
    for w in sets:
        for key, (chans, meth, _) in CHANNEL_SETS.items():
            for i, c in enumerate(w.cases):
                win = {k: w.signals[k][i] for k in chans}
                try:
                    out.append(estimate_inertia(win, w.entry_index, c.backlash_width_m, R, w.sample_period_s, meth,
                                                SYSTEM.motor.bearing_friction_nms_per_rad, model=model))
                except NoGapError as exc:
                    out.append(str(exc))
    return out


@pytest.mark.parametrize("model", [None, GapModel(torque_accuracy=0.02, coulomb_friction_max_nm=0.5)])
def test_the_fit_cache_changes_no_number(windows, model, monkeypatch):
    """Every channel set on clean, noisy and quantised windows: the same GapEstimate (every float equal) with the
    cache as without, on the first pass and on a second pass that is all lookups; the 'angle_eq1' fits after the
    cross-checked 'angles' ones are lookups; the cache is off again after the block."""
    plain = _all_sets(windows, model)
    calls = []
    real = gap_angle.free_angle_fit
    monkeypatch.setattr(gap_angle, "free_angle_fit", lambda *a, **k: calls.append(1) or real(*a, **k))
    with fit_cache():
        cached = _all_sets(windows, model)
        n_first = len(calls)
        again = _all_sets(windows, model)
    assert cached == plain
    assert again == plain
    assert len(calls) == n_first                          # the second pass computed no angle fit
    n_windows = sum(len(w.cases) for w in windows)
    assert n_first <= 2 * n_windows                       # 'angles' and 'angle_eq1' share one, 'angle' its own
    assert gap_numerics.FIT_MEMO.memo is None


def _kink_reference(alpha1, torque, ts, entries, end):
    """The kink fit's candidate loop, one entry at a time (its first implementation): (rss, 1/J1, residual)."""
    P = max(0, entries[0] - gap_kink.KINK_PRE_SAMPLES)
    rows = np.arange(P, end)
    y = alpha1[P:end] - alpha1[entries[0]]
    out = []
    for s_row in entries:
        phi = np.zeros(end - P)
        phi[s_row - P:] = _cumtrapz(_cumtrapz(torque[s_row:end], ts), ts)
        scale = max(float(np.max(np.abs(phi))), 1e-300)
        X = np.column_stack([np.ones(end - P), (rows - s_row) * ts / max((end - s_row) * ts, ts), phi / scale])
        pinv = np.linalg.solve(X.T @ X, X.T)
        coef = pinv @ y
        res = y - X @ coef
        out.append((float(res @ res), float(coef[2]) / scale, res))
    return out


def _check_kink(alpha1, m_el, ts, entries, end):
    kf = kink_fit(alpha1, m_el, ts, entries, end)
    ref = _kink_reference(np.asarray(alpha1, float), np.asarray(m_el, float), ts, list(entries), end)
    best = int(np.argmin([r[0] for r in ref]))
    assert kf["start"] == entries[best]
    assert kf["j1"] == 1.0 / ref[best][1]                 # bit for bit
    assert kf["residual"].tobytes() == ref[best][2].tobytes()


@pytest.mark.parametrize("scenario,seed", [("speed_step", 3), ("speed_reversal", 4)])
def test_kink_fit_matches_the_one_entry_at_a_time_loop(scenario, seed):
    rec = simulate(StressDrive(j1_kgm2=1.16), scenario, seed=seed)
    _check_kink(rec["window"]["alpha1"], rec["window"]["m_el"], 5e-4, list(range(rec["entry"] - 4, rec["entry"] + 5)),
                rec["recontact"])


def test_kink_fit_matches_the_loop_on_grid_windows(windows, monkeypatch):
    """The kink fits the steady-entry check makes on clean, noisy and quantised grid windows bit for bit, and its refits
    (the end moved in, gap_kink.kink_best_j1's stacked fits over the plausible entries) to rounding."""
    calls, refits = [], []
    real = gap_kink.kink_fit
    locate = gap_angle.kink_locate    # the steady-entry check's kink fits (their standard error added after its checks)
    best = gap_angle.kink_best_j1
    monkeypatch.setattr(gap_angle, "kink_locate", lambda *a, **k: calls.append((a, k)) or locate(*a, **k))
    monkeypatch.setattr(gap_angle, "kink_best_j1", lambda *a: refits.append((a, best(*a))) or refits[-1][1])
    _all_sets(windows)
    checked = 0
    for (alpha1, m_el, ts, entries, end, *_), kw in calls:
        entries = sorted(int(x) for x in entries if end - int(x) >= gap_kink.KINK_MIN_GAP_SAMPLES)
        if not entries:
            continue
        try:
            real(alpha1, m_el, ts, entries, end)
        except gap_free.FreeFitError:
            continue
        _check_kink(alpha1, m_el, ts, entries, end)
        checked += 1
    assert checked >= 5
    refitted = 0
    for (alpha1, ts, variants), fits in refits:
        for (m_el, pairs, end), j1 in zip(variants, fits):
            entries = sorted(s_ for s_, r_ in pairs if end - s_ >= gap_kink.KINK_MIN_GAP_SAMPLES)
            if isinstance(j1, str) or any(r_ for _, r_ in pairs) or not entries:
                continue
            ref = _kink_reference(np.asarray(alpha1, float), np.asarray(m_el, float), ts, entries, end)
            # the same candidate; its J1 from the stacked normal equations (not (XᵀX)⁻¹Xᵀ): equal to rounding
            assert j1 == pytest.approx(1.0 / ref[int(np.argmin([r[0] for r in ref]))][1], rel=1e-9)
            refitted += 1
    assert refitted >= 10


def test_the_signature_derivative_reads_what_savgol_filter_gives():
    """Where gap_interval reads it (the entry row's value and the first drop after it), the shortcut equals
    scipy's savgol_filter bit for bit, including entries near either end and signals with no drop."""
    rng = np.random.default_rng(3)
    for trial in range(400):
        n = int(rng.integers(7, 300))
        x = np.cumsum(np.cumsum(rng.standard_normal(n))) * 10.0 ** rng.uniform(-6, 3)
        for deriv in (1, 2):
            e = int(rng.integers(0, n))
            full = savgol_filter(x, 7, 2, deriv=deriv)
            fast = gap._savgol_for_gap(x, deriv, e, 0.6)

            def reads(a):
                below = np.sign(a[e]) * a[e:] < 0.6 * abs(a[e])
                return a[e].tobytes(), int(np.argmax(below)) if below.any() else -1

            assert reads(fast) == reads(full), (trial, n, deriv, e)


def test_the_gap_only_sweeps_in_a_process_of_their_own_change_no_number():
    """run_robustness(jobs=2) (what `jident evaluate` runs) and the serial run: the same report, but for the line
    of timings."""
    from jident_ros.config import load_method_config
    from jident_ros.method.patterns import PatternLibrary
    from jident_ros.research.evaluation.report_robustness import render_robustness
    from jident_ros.research.evaluation.robustness import run_robustness

    method = load_method_config().replace(p_values=(2.0,))
    library = PatternLibrary.build(SYSTEM, method)
    kw = dict(library=library, log=None, snr_db=(30.0,), extra_seeds=(3,), offgrid_j1=(("1.00", 1.00),),
              offgrid_widths=(0.006,), encoder_counts=(4096,), sample_periods=(1e-3,), image_stride=8,
              grid_cases=[Case(1.16, 0.005, 0.0125), Case(1.218, 0.0025, 0.05)])
    reports = []
    for jobs in (1, 2):
        res = run_robustness(SYSTEM, method, jobs=jobs, **kw)
        assert len(res.grid_extra) == 1 and len(res.attribution) == 4 and len(res.sample_period) == 2
        reports.append([line for line in render_robustness(res, {}).splitlines() if " s, " not in line
                        and "took" not in line])
    assert reports[0] == reports[1]


def test_the_median_is_numpys_bit_for_bit():
    """gap_numerics._median (the robust noise scale's) against np.median: odd and even sizes, ties, signed zeros, NaN."""
    rng = np.random.default_rng(5)
    for trial in range(3000):
        n = int(rng.integers(1, 120))
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-9, 4)
        if trial % 3 == 0:
            x = np.round(x, 1) * np.where(rng.random(n) < 0.5, -1.0, 1.0)     # ties and ±0.0
        if trial % 97 == 0:
            x[rng.integers(0, n)] = np.nan
        assert np.asarray(gap_numerics._median(x)).tobytes() == np.asarray(np.median(x)).tobytes(), (trial, x)


def test_the_gradient_sign_is_numpys_bit_for_bit():
    """gap_numerics._gradient_sign (the free fit's Coulomb column's sign of ω1) against np.sign(np.gradient(x)): quantised
    angles (flat runs: zero differences), steady ramps, reversals, 2 to 300 samples."""
    rng = np.random.default_rng(11)
    for trial in range(2000):
        n = int(rng.integers(2, 300))
        x = np.cumsum(rng.standard_normal(n)) * 10.0 ** rng.uniform(-6, 2) + rng.uniform(-10, 10)
        if trial % 2:
            q = 2 * np.pi / 2 ** int(rng.integers(8, 17))
            x = np.floor(x / q) * q
        assert gap_numerics._gradient_sign(x).tobytes() == np.sign(np.gradient(x)).tobytes(), (trial, n)


def _double_trapz_adjoint_reference(row, ts):
    """Wᵀ row with W the double trapezoid integral from the first row, as an explicit matrix (column i: the double
    integral of the i-th unit vector)."""
    n = row.size
    W = np.column_stack([_cumtrapz(_cumtrapz(np.eye(n)[i], ts), ts) for i in range(n)])
    return W.T @ row


def test_the_double_trapezoid_adjoint_is_the_transposed_integral():
    rng = np.random.default_rng(12)
    for n in (1, 2, 3, 5, 26, 190):
        row = rng.standard_normal(n)
        got = gap_numerics._double_trapz_adjoint(row, 5e-4)
        want = _double_trapz_adjoint_reference(row, 5e-4)
        assert got.shape == (n,)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * float(np.max(np.abs(want), initial=0.0)))


def test_the_scans_closed_form_inverse_is_lapacks_to_rounding():
    """gap_numerics._sym3_inverse (the change-point scans' normal matrices) against np.linalg.inv of the same regularised
    matrices: scaled designs (1, u, Φ) over short and long row ranges, one of them nearly collinear."""
    rng = np.random.default_rng(13)
    for trial in range(200):
        n = int(rng.integers(3, 200))
        u = np.sort(rng.uniform(-1, 2, n))
        X = np.column_stack([np.ones(n), u, u * u + 1e-3 * rng.standard_normal(n)])
        A = X.T @ X
        U = A[gap_numerics._SYM3_I, gap_numerics._SYM3_J][None, :]
        A_reg = A + np.eye(3) * (1e-12 * np.trace(A) / 3.0)
        np.testing.assert_allclose(gap_numerics._sym3_inverse(U)[0], np.linalg.inv(A_reg), rtol=1e-6,
                                   atol=1e-9 * float(np.max(np.abs(np.linalg.inv(A_reg)))))


def test_the_kink_fit_located_then_its_terms_is_the_kink_fit():
    """kink_locate then kink_terms (the steady-entry check's order: the standard error only for a fit its checks keep)
    gives kink_fit's dict, every number equal."""
    rec = simulate(StressDrive(j1_kgm2=1.16), "speed_step", seed=3)
    args = (rec["window"]["alpha1"], rec["window"]["m_el"], 5e-4, list(range(rec["entry"] - 4, rec["entry"] + 5)),
            rec["recontact"])
    full = kink_fit(*args, 0.5, 0.2, 1e-3)
    part = gap_kink.kink_locate(*args)
    assert "terms" not in part and part["j1"] == full["j1"] and part["start"] == full["start"]
    done = gap_kink.kink_terms(part, 0.5, 0.2, 1e-3)
    assert done.keys() == full.keys()
    for k in full:
        a, b = done[k], full[k]
        assert (a.tobytes() == b.tobytes()) if isinstance(a, np.ndarray) else a == b, k


def test_the_lapack_shortcuts_are_numpy_linalg_bit_for_bit():
    """identify.lapack's solve, inv and lstsq (numpy.linalg's gufuncs without its wrapper) against numpy.linalg: the
    gap stage's shapes (one system, stacks, several right-hand sides, strided views), and LinAlgError on a singular
    matrix."""
    from jident_ros.identify import lapack
    rng = np.random.default_rng(14)
    for trial in range(300):
        p = int(rng.integers(1, 6))
        k = int(rng.integers(1, 9))
        X = rng.standard_normal((k, 30, p)) * 10.0 ** rng.uniform(-3, 3)
        A = X.transpose(0, 2, 1) @ X
        B = rng.standard_normal((k, p, 3))
        assert lapack.solve(A, B).tobytes() == np.linalg.solve(A, B).tobytes()
        assert lapack.solve(A[0], B[0, :, 0]).tobytes() == np.linalg.solve(A[0], B[0, :, 0]).tobytes()
        assert lapack.solve(A, B[:, :, 1:2]).tobytes() == np.linalg.solve(A, B[:, :, 1:2]).tobytes()
        assert lapack.inv(A).tobytes() == np.linalg.inv(A).tobytes()
        y = rng.standard_normal(30)
        assert lapack.lstsq(X[0], y).tobytes() == np.linalg.lstsq(X[0], y, rcond=None)[0].tobytes()
        assert lapack.lstsq(X[0][::2], y[1::2]).tobytes() == np.linalg.lstsq(X[0][::2], y[1::2], rcond=None)[0].tobytes()
    with pytest.raises(np.linalg.LinAlgError):
        lapack.solve(np.zeros((3, 3)), np.ones(3))
    with pytest.raises(np.linalg.LinAlgError):
        lapack.inv(np.ones((2, 2)))


def test_the_joint_fits_standard_deviation_is_numpys_bit_for_bit():
    """gap._std_ddof1 (the joint fit's noise levels) against np.std(x, ddof=1): sizes 5..900, offsets, scales, strided
    views."""
    rng = np.random.default_rng(15)
    for trial in range(3000):
        n = int(rng.integers(5, 900))
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-8, 4) + rng.uniform(-1e3, 1e3)
        if trial % 3 == 0:
            x = x[::2]
        assert np.asarray(gap._std_ddof1(x)).tobytes() == np.asarray(np.std(x, ddof=1)).tobytes(), (trial, n)


def test_lapack_fast_path_checks_itself_and_falls_back(monkeypatch):
    """The private gufuncs are used only when they agree with numpy.linalg on the import-time probe; without them
    every call goes to numpy.linalg (same numbers)."""
    import numpy as np

    from jident_ros.identify import lapack
    if lapack._gufuncs is not None:
        assert lapack._self_check()
    a = np.array([[2.0, 0.3], [0.3, 1.0]])
    b = np.array([1.0, -1.0])
    fast = lapack.solve(a, b)
    monkeypatch.setattr(lapack, "_gufuncs", None)
    assert np.array_equal(lapack.solve(a, b), fast) and np.array_equal(lapack.solve(a, b), np.linalg.solve(a, b))
    assert np.array_equal(lapack.inv(a), np.linalg.inv(a))
    monkeypatch.setattr(lapack, "_SOLVE1", lambda *x, **k: (_ for _ in ()).throw(TypeError("moved")), raising=False)
    monkeypatch.setattr(lapack, "_gufuncs", object())
    assert not lapack._self_check()                       # a moved calling convention is caught by the probe


def test_einsum_without_its_wrapper_and_the_prebuilt_error_state():
    """gap_numerics._einsum (numpy's c_einsum, what np.einsum calls with optimize=False) gives np.einsum's numbers bit for
    bit on the gap stage's subscripts; identify.lapack's prebuilt floating-point error state raises LinAlgError on a
    singular matrix as np.errstate(call=...) did and leaves the caller's error state as it was, after a raise too."""
    from jident_ros.identify import lapack
    rng = np.random.default_rng(5)
    X, A, D = rng.standard_normal((70, 4)), rng.standard_normal((30, 4, 4)), rng.standard_normal((30, 4))
    xt = rng.standard_normal((30, 2, 4))
    for sub, ops in (("ki,kj->kij", (X, X)), ("kij,kj->ki", (A, D)), ("ki,ki->k", (D, D)),
                     ("ckp,cp->ck", (xt, D)), ("ckq,ckq->ck", (xt, xt)), ("ij,ij->i", (X, X))):
        assert np.array_equal(gap_numerics._einsum(sub, *ops), np.einsum(sub, *ops))
    out_a, out_b = np.empty(70), np.empty(70)
    gap_numerics._einsum("ij,ij->i", X, X, out=out_a)
    np.einsum("ij,ij->i", X, X, out=out_b)
    assert np.array_equal(out_a, out_b)
    before = np.geterr()
    with np.errstate(divide="raise"):
        inner = np.geterr()
        with pytest.raises(np.linalg.LinAlgError):
            lapack.solve(np.zeros((3, 3)), np.ones(3))
        with pytest.raises(np.linalg.LinAlgError):
            lapack.inv(np.zeros((2, 3, 3)))
        lapack.lstsq(np.ones((4, 2)), np.ones(4))
        assert np.geterr() == inner
    assert np.geterr() == before


def _plain_disc_error(angle, first, end):
    """stream.flank_disc.disc_error as fe4eda0 computed it (every sine from the angle itself)."""
    import math

    from jident_ros.stream import flank_disc, flank_free
    x = np.asarray(angle, float)
    first, end = max(int(first), 0), min(int(end), x.size)
    if end - first < 4 * (flank_disc.DISC_DEGREE + 5):
        return None
    path = float(np.sum(np.abs(np.diff(x[first:end])))) / (2.0 * math.pi)
    net = abs(float(x[end - 1] - x[first])) / (2.0 * math.pi)
    if not (net >= flank_disc.DISC_MIN_REVOLUTIONS and net >= flank_disc.DISC_MIN_NET_SHARE * path):
        return None
    seg = x[first:end]
    Q = flank_disc._poly_basis(seg.size)
    r = seg - Q @ (Q.T @ seg)
    rss_poly = float(r @ r)
    D = flank_disc._disc_columns(seg)
    D -= Q @ (Q.T @ D)
    try:
        coef = np.linalg.solve(D.T @ D, D.T @ r)
    except np.linalg.LinAlgError:
        return None
    res = r - D @ coef
    rss = float(res @ res)
    steps = np.abs(np.diff(seg, 2))
    steps = steps[steps > 1e-9]
    floor = max(float(steps.min()) / math.sqrt(12.0) if steps.size else 0.0, flank_free.ANGLE_MODEL_FLOOR_RAD)
    if not rss > 0 or not rss_poly >= flank_disc.DISC_MIN_GAIN ** 2 * rss \
            or not math.sqrt(rss / seg.size) <= flank_disc.DISC_MAX_RMS_FLOORS * floor:
        return None
    return coef


def test_the_disc_error_decided_on_double_angle_columns_is_the_plain_fits():
    """stream.flank_disc.disc_error refuses on the double-angle columns only beyond rounding and fits on the sines: the
    plain computation's answer bit for bit (None, or the same coefficients), on angles with disc errors of 0 to 1 mrad
    (quantised at 2^13-2^20 counts, with noise), turning 2-9 revolutions over the rows, and at the gates' edges."""
    from jident_ros.stream import flank_disc
    rng = np.random.default_rng(3)
    seen = {True: 0, False: 0}
    for trial in range(300):
        n = 1000
        revs = float(rng.uniform(2.0, 9.0))
        t = np.linspace(0.0, 1.0, n)
        ang = 2 * np.pi * revs * (t + 0.05 * rng.standard_normal() * t * t) + float(rng.uniform(0, 100))
        amp = float(rng.choice([0.0, 2e-5, 5e-5, 1e-4, 2e-4, 1e-3]))
        meas = ang + amp * np.sin(ang + 0.3) + 0.5 * amp * np.cos(2 * ang - 1.0)
        meas = meas + float(rng.choice([0.0, 1e-6, 1e-5])) * rng.standard_normal(n)
        q = 2 * np.pi / 2 ** int(rng.integers(13, 21))
        meas = np.round(meas / q) * q
        got, plain = flank_disc.disc_error(meas, 0, n), _plain_disc_error(meas, 0, n)
        assert (got is None) == (plain is None), trial
        if got is not None:
            assert np.array_equal(got, plain)
        seen[got is None] += 1
    assert seen[True] > 30 and seen[False] > 30, seen
