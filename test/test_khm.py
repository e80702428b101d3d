"""Tests for jident_ros.method.khm (k-harmonic means, paper eqs. 23-30)."""

import time
import warnings

import numpy as np
import pytest

from jident_ros.research import khm_reference as khm
from jident_ros.research.khm_reference import ConvergenceWarning, KHarmonicMeans, khm_objective


# ----------------------------------------------------------------- helpers
def naive_terms(x, s, p):
    """Direct transcription of eqs. 26-27 (valid only for moderate distances)."""
    d = np.abs(np.asarray(x, float)[:, None] - np.asarray(s, float)[None, :])
    a = d ** (-p - 2.0)
    b = d ** (-p)
    W = a.sum(1) / b.sum(1) ** 2
    M = a / a.sum(1, keepdims=True)
    return M, W


def blobs(means, std, n, seed=0):
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.normal(m, std, n) for m in means])
    y = np.repeat(np.arange(len(means)), n)
    return x, y


def smooth_histogram(seed=3, n_levels=64):
    """Smooth multimodal 64-level histogram, like a scalogram's intensities."""
    r = np.random.default_rng(seed)
    g = np.arange(n_levels)
    cnt = sum(r.uniform(100, 5000) * np.exp(-0.5 * ((g - r.uniform(0, n_levels - 1))
                                                   / r.uniform(1, 8)) ** 2)
              for _ in range(r.integers(2, 6)))
    return np.linspace(0.5, 1.7, n_levels), np.round(cnt) + 1.0


def quiet_fit(model, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return model.fit(*args, **kwargs)


# --------------------------------------------------------- cluster recovery
@pytest.mark.parametrize("p", [2.0, 3.0, 6.0, 9.0])
def test_well_separated_clusters_recovered(p):
    means = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    x, y = blobs(means, 0.02, 200)
    m = KHarmonicMeans(n_clusters=7, p=p, init="quantile").fit(x)
    assert m.converged_
    np.testing.assert_allclose(m.cluster_centers_, means, atol=0.02)
    # each blob entirely in its own cluster
    assert np.array_equal(m.labels_, y)
    assert np.array_equal(m.predict(x), y)


def test_paper_init_recovers_clusters_from_outside_the_data():
    # paper: all centres start at 1 - k3, here below the data
    means = [1.0, 1.5, 2.0]
    x, _ = blobs(means, 0.01, 300, seed=1)
    m = KHarmonicMeans(n_clusters=3, p=3.0, init="paper", init_value=0.2).fit(x)
    assert m.converged_
    np.testing.assert_allclose(m.cluster_centers_, means, atol=0.01)


def test_centres_are_a_fixed_point_of_eq30():
    x, c = smooth_histogram()
    for p in (2.0, 6.0):
        m = KHarmonicMeans(p=p, init="quantile").fit(x, c)
        assert m.converged_
        again = khm._update(x, np.log(c), m.cluster_centers_, p)
        assert np.max(np.abs(again - m.cluster_centers_)) <= 1e-9 * np.ptp(x)


def test_centres_sorted_and_input_shape_n_by_1_accepted():
    x, c = smooth_histogram()
    a = KHarmonicMeans(p=2, init="quantile").fit(x, c)
    b = KHarmonicMeans(p=2, init="quantile").fit(x[:, None], c[:, None])
    assert np.all(np.diff(a.cluster_centers_) > 0)
    assert np.array_equal(a.cluster_centers_, b.cluster_centers_)
    assert a.cluster_centers_.shape == (7,)


# ---------------------------------------------------- eqs. 26-29 and objective
@pytest.mark.parametrize("p", [2.0, 3.5, 9.0])
def test_membership_and_weights_match_eqs_26_27(p):
    x, c = smooth_histogram()
    m = KHarmonicMeans(p=p, init="quantile").fit(x, c)
    xt = np.linspace(-1.0, 3.0, 401)          # includes far-away points
    xt = xt[np.min(np.abs(xt[:, None] - m.cluster_centers_), axis=1) > 1e-6]
    M_ref, W_ref = naive_terms(xt, m.cluster_centers_, p)
    np.testing.assert_allclose(m.membership(xt), M_ref, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(m.weights(xt), W_ref, rtol=1e-10)


@pytest.mark.parametrize("p", [2.0, 3.5, 9.0])
def test_memberships_in_unit_interval_and_rows_sum_to_one(p):  # eqs. 28-29
    x, c = smooth_histogram()
    m = KHarmonicMeans(p=p, init="quantile").fit(x, c)
    xt = np.concatenate([np.linspace(-50, 50, 2001), m.cluster_centers_,
                         m.cluster_centers_ + 1e-12])
    M = m.membership(xt)
    assert M.shape == (xt.size, 7)
    assert np.all(np.isfinite(M))
    assert np.all(M >= 0.0) and np.all(M <= 1.0)
    np.testing.assert_allclose(M.sum(axis=1), 1.0, rtol=0, atol=1e-12)


def test_objective_matches_khm_performance_function():
    x, c = smooth_histogram()
    p = 3.0
    m = KHarmonicMeans(p=p, init="quantile").fit(x, c)
    d = np.abs(x[:, None] - m.cluster_centers_[None, :])
    ref = np.sum(c * 7 / np.sum(d ** (-p), axis=1))
    assert m.objective_ == pytest.approx(ref, rel=1e-12)
    assert m.inertia_ == m.objective_
    assert khm_objective(x, m.cluster_centers_, p, c) == pytest.approx(ref, rel=1e-12)
    assert m.score(x, c) == pytest.approx(-ref, rel=1e-12)


# ----------------------------------------------------------------- numerics
@pytest.mark.parametrize("p", [2.0, 3.0, 9.0])
def test_exact_zero_distance_handled(p):
    centres = np.array([0.0, 1.0, 5.0])
    m = quiet_fit(KHarmonicMeans(n_clusters=3, p=p, init=centres, max_iter=1),
                  np.array([0.0, 0.5, 1.0, 4.0, 5.0]))
    m.cluster_centers_ = centres              # evaluate at known centres
    with np.errstate(all="raise"):            # no 0/0, inf/inf, overflow
        M = m.membership(centres)
        W = m.weights(centres)
    np.testing.assert_array_equal(M, np.eye(3))   # fully in its own cluster
    assert np.all(np.isfinite(W))
    # limit d -> 0 of eq. 26: d^(p-2) * ... -> 0 for p > 2, 1 for p = 2
    np.testing.assert_array_equal(W, np.ones(3) if p == 2.0 else np.zeros(3))


@pytest.mark.parametrize("p", [2.0, 3.0, 9.0])
def test_fit_with_data_points_on_the_centres(p):
    # initial centres coincide exactly with data points (d = 0 in eq. 26-27)
    x = np.array([0.0, 0.0, 0.1, 1.0, 1.1, 1.0, 3.0, 3.2])
    m = KHarmonicMeans(n_clusters=3, p=p, init=np.array([0.0, 1.0, 3.0])).fit(x)
    assert np.all(np.isfinite(m.cluster_centers_))
    assert np.isfinite(m.objective_)
    assert m.converged_
    assert np.array_equal(m.labels_, [0, 0, 0, 1, 1, 1, 2, 2])
    # every sample on a centre and p > 2: all weights 0 -> centres unchanged
    y = np.array([0.0, 1.0, 3.0])
    m2 = KHarmonicMeans(n_clusters=3, p=p, init=y).fit(np.repeat(y, 4))
    np.testing.assert_array_equal(m2.cluster_centers_, y)
    assert m2.converged_


def three_tight_clusters():
    rng = np.random.default_rng(7)
    return np.concatenate([rng.normal(0.0, 1e-8, 50), rng.normal(1e3, 1e-8, 50),
                           rng.normal(2.5e3, 1e-8, 50)])


def test_no_overflow_p9_distances_1e_minus8_and_1e3():
    p = 9.0
    x = three_tight_clusters()   # distances ~1e-8 inside, ~1e3 between clusters
    m = KHarmonicMeans(n_clusters=3, p=p, init="quantile")
    with np.errstate(over="raise", invalid="raise"):
        m.fit(x)
        M = m.membership(x)
        W = m.weights(x)
    assert m.converged_
    np.testing.assert_allclose(m.cluster_centers_, [0.0, 1e3, 2.5e3], rtol=0, atol=5e-8)
    assert np.all(np.isfinite(M)) and np.all(np.isfinite(W)) and np.all(W >= 0)
    np.testing.assert_allclose(M.sum(axis=1), 1.0, atol=1e-12)
    assert np.isfinite(m.objective_)
    assert np.array_equal(m.labels_, np.repeat([0, 1, 2], 50))


@pytest.mark.parametrize("scale", [1e-30, 1e-250, 1e25])
def test_no_overflow_p9_extreme_scales_scale_equivariant(scale):
    # KHM is scale-equivariant: fitting x*scale must give centres*scale.
    # At scale 1e-30 the naive d^(-p-2) overflows float64 (d ~ 1e-38).
    p = 9.0
    x = three_tight_clusters()
    ref = KHarmonicMeans(n_clusters=3, p=p, init="quantile").fit(x)
    if scale < 1:
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            M_naive, W_naive = naive_terms(x * scale, ref.cluster_centers_ * scale, p)
        assert not (np.all(np.isfinite(W_naive)) and np.all(np.isfinite(M_naive)))
    m = KHarmonicMeans(n_clusters=3, p=p, init="quantile")
    with np.errstate(over="raise", invalid="raise"):
        m.fit(x * scale)
        M = m.membership(x * scale)
    assert m.converged_
    assert m.n_iter_ == ref.n_iter_
    np.testing.assert_allclose(m.cluster_centers_ / scale, ref.cluster_centers_,
                               rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(M, ref.membership(x), rtol=1e-6, atol=1e-12)
    assert np.array_equal(m.labels_, ref.labels_)


def test_data_points_exactly_on_centres_get_zero_weight_for_p_above_2():
    # eq. 26 in the limit d -> 0 for p > 2: such points do not pull any centre
    x = np.array([0.0, 0.1, 0.2, 5.0, 5.0, 5.0])
    m = KHarmonicMeans(n_clusters=2, p=4.0, init=[0.1, 5.0], max_iter=1)
    quiet_fit(m, x)
    m.cluster_centers_ = np.array([0.1, 5.0])
    W = m.weights(x)
    assert W[1] == 0.0 and np.all(W[3:] == 0.0) and W[0] > 0 and W[2] > 0


def test_centres_far_outside_the_data_do_not_underflow():
    # r = d_min/d ~ 1e-12, r^(p+2) ~ 1e-132 (p = 9): the update must still
    # move every centre (per-cluster rescaling in eq. 30).
    x = np.linspace(0.0, 1.0, 11)
    init = np.array([0.5, 1e11, 2e11])
    m = quiet_fit(KHarmonicMeans(n_clusters=3, p=9.0, init=init, max_iter=1), x)
    assert np.all(np.abs(m.cluster_centers_) <= 1.0 + 1e-12)


# ------------------------------------------------------------ initialisation
def test_duplicate_paper_init_gets_separated():
    x, c = smooth_histogram()                  # data range 1.2
    v = 0.2                                    # paper: S_i = 1 - k3
    m = KHarmonicMeans(p=2.0, init="paper", init_value=v).fit(x, c)
    R = np.ptp(x)
    expected = v + 1.0 * R * (np.arange(7) / 6.0 - 0.5)
    np.testing.assert_allclose(m.init_centers_, expected, rtol=0, atol=1e-15)
    assert np.unique(m.init_centers_).size == 7
    assert m.converged_
    assert np.all(np.diff(m.cluster_centers_) > 1e-3)   # 7 distinct centres
    # duplicate_spread scales the interval
    m2 = KHarmonicMeans(p=2.0, init="paper", init_value=v, duplicate_spread=0.1).fit(x, c)
    np.testing.assert_allclose(m2.init_centers_, v + 0.1 * R * (np.arange(7) / 6.0 - 0.5),
                               atol=1e-15)


def test_literal_paper_init_without_spread_never_separates():
    x, c = smooth_histogram()
    m = KHarmonicMeans(p=3.0, init="paper", init_value=0.2, duplicate_spread=0).fit(x, c)
    assert np.unique(m.cluster_centers_).size == 1
    one = KHarmonicMeans(n_clusters=1, p=3.0, init="paper", init_value=0.2).fit(x, c)
    np.testing.assert_allclose(m.cluster_centers_, one.cluster_centers_[0], rtol=1e-12)


def test_partial_duplicates_in_explicit_init_are_spread_without_collision():
    x = np.linspace(0.0, 1.0, 101)
    m = KHarmonicMeans(n_clusters=3, p=2.0, init=[0.0, 0.0, 0.5], max_iter=1)
    quiet_fit(m, x)
    # width 1.0 would put a copy at 0.5 (collision) -> halved to 0.5
    np.testing.assert_array_equal(m.init_centers_, [-0.25, 0.25, 0.5])


def test_quantile_init_identical_for_raw_samples_and_histogram():
    levels = np.array([0.0, 1.0, 2.0, 5.0])
    counts = np.array([3, 1, 4, 2])
    raw = np.repeat(levels, counts)
    a = KHarmonicMeans(n_clusters=3, init="quantile", compress=False, max_iter=1)
    b = KHarmonicMeans(n_clusters=3, init="quantile", max_iter=1)
    quiet_fit(a, raw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        b.fit_histogram(levels, counts)
    np.testing.assert_array_equal(a.init_centers_, b.init_centers_)


# ----------------------------------------------------------- histogram speed
def test_histogram_equivalent_to_full_data_and_faster():
    rng = np.random.default_rng(42)
    gray = np.sort(rng.choice(256, 64, replace=False)).astype(float)
    X = rng.choice(gray, 343 * 436)            # 149,548 pixels, 64 gray values
    levels, counts = np.unique(X, return_counts=True)
    assert levels.size == 64
    kw = dict(p=3.0, init="paper", init_value=float(gray.mean()), tol=0.0, max_iter=12)

    full = KHarmonicMeans(compress=False, **kw)
    t0 = time.perf_counter()
    quiet_fit(full, X)
    t_full = time.perf_counter() - t0

    hist = KHarmonicMeans(**kw)
    reps = 20
    t0 = time.perf_counter()
    for _ in range(reps):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            hist.fit_histogram(levels, counts)
    t_hist = (time.perf_counter() - t0) / reps

    auto = quiet_fit(KHarmonicMeans(**kw), X)   # compress="auto" -> histogram

    assert full.n_iter_ == hist.n_iter_ == 12
    np.testing.assert_allclose(hist.cluster_centers_, full.cluster_centers_, rtol=0, atol=1e-12)
    np.testing.assert_allclose(auto.cluster_centers_, full.cluster_centers_, rtol=0, atol=1e-12)
    assert hist.objective_ == pytest.approx(full.objective_, rel=1e-12)
    # labels of the pixels equal the labels of their level
    lab = dict(zip(levels, hist.labels_))
    assert np.array_equal(full.labels_, np.array([lab[v] for v in X]))
    assert np.array_equal(auto.labels_, full.labels_)
    speedup = t_full / t_hist
    print(f"\n[khm] 149548 pixels, 12 iterations: full {t_full * 1e3:.1f} ms, "
          f"histogram {t_hist * 1e3:.3f} ms, speed-up x{speedup:.0f}")
    assert speedup > 20


def test_histogram_equivalent_after_convergence():
    rng = np.random.default_rng(1)
    X = rng.choice(np.arange(0.0, 64.0), 4000)
    levels, counts = np.unique(X, return_counts=True)
    for p in (2.0, 6.0, 9.0):
        full = KHarmonicMeans(p=p, init="quantile", compress=False).fit(X)
        hist = KHarmonicMeans(p=p, init="quantile").fit_histogram(levels, counts)
        assert full.converged_ and hist.converged_
        assert full.n_iter_ == hist.n_iter_
        assert full.damping_history_ == hist.damping_history_
        np.testing.assert_allclose(hist.cluster_centers_, full.cluster_centers_,
                                   rtol=0, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("p", [2.0, 6.0])
def test_histogram_equivalent_to_full_image_converged(p):
    # full 343 x 436 image clustered to convergence (about 10 s per fit)
    rng = np.random.default_rng(42)
    gray = np.sort(rng.choice(256, 64, replace=False)).astype(float)
    X = rng.choice(gray, 343 * 436)
    levels, counts = np.unique(X, return_counts=True)
    kw = dict(p=p, init="paper", init_value=float(gray.mean()))
    full = KHarmonicMeans(compress=False, **kw).fit(X)
    hist = KHarmonicMeans(**kw).fit_histogram(levels, counts)
    assert full.converged_ and hist.converged_ and full.n_iter_ == hist.n_iter_
    np.testing.assert_allclose(hist.cluster_centers_, full.cluster_centers_, rtol=0, atol=1e-12)


# ----------------------------------------------------- 2-cycles and damping
def test_plain_khm_converges_below_threshold_p3():
    x = np.arange(64.0)                        # uniform 64-level histogram
    m = KHarmonicMeans(p=3.0, init="quantile", damping=None).fit(x)
    assert m.converged_ and not m.cycle_detected_ and m.damping_used_ == 1.0
    auto = KHarmonicMeans(p=3.0, init="quantile").fit(x)
    assert not auto.cycle_detected_ and auto.damping_used_ == 1.0
    np.testing.assert_array_equal(auto.cluster_centers_, m.cluster_centers_)


@pytest.mark.parametrize("p", [4.0, 6.0, 9.0])
def test_plain_khm_two_cycle_detected_and_auto_damping_converges(p):
    x = np.arange(64.0)                        # uniform 64-level histogram
    plain = KHarmonicMeans(p=p, init="quantile", damping=None, max_iter=400)
    with pytest.warns(ConvergenceWarning):
        plain.fit(x)
    assert not plain.converged_
    assert plain.cycle_detected_
    assert plain.damping_used_ == 1.0 and plain.damping_history_ == []
    # plain KHM is on a 2-cycle: S_{t+2} == S_t but S_{t+1} far from S_t
    logc = np.zeros(x.size)
    s0 = plain.cluster_centers_
    s1 = khm._update(x, logc, s0, p)
    s2 = khm._update(x, logc, s1, p)
    assert np.max(np.abs(s2 - s0)) < 1e-6
    assert np.max(np.abs(s1 - s0)) > 1.0

    auto = KHarmonicMeans(p=p, init="quantile", damping="auto").fit(x)
    assert auto.converged_
    assert auto.cycle_detected_
    assert auto.damping_used_ < 1.0
    assert auto.damping_used_ <= 2.0 / (p - 1.0)          # stability bound
    assert [lam for _, lam in auto.damping_history_] == \
        [0.5 ** k for k in range(1, len(auto.damping_history_) + 1)]
    assert np.unique(auto.cluster_centers_).size == 7
    # the damped solution is a fixed point of the undamped eq. 30
    s = auto.cluster_centers_
    assert np.max(np.abs(khm._update(x, logc, s, p) - s)) <= 1e-9 * np.ptp(x)
    # and it spreads the 7 centres over the uniform levels
    assert np.all(np.abs(np.diff(s) - 63.0 / 7.0) < 1.0)


def test_plain_two_cycle_at_p3_for_tight_clusters_and_fixed_damping():
    # the threshold depends on the data: very tight clusters cycle at p = 3
    x, _ = blobs(range(7), 0.02, 200)
    plain = KHarmonicMeans(p=3.0, init="quantile", damping=None, max_iter=200)
    with pytest.warns(ConvergenceWarning):
        plain.fit(x)
    assert plain.cycle_detected_ and not plain.converged_
    fixed = KHarmonicMeans(p=3.0, init="quantile", damping=0.5).fit(x)
    assert fixed.converged_ and fixed.damping_used_ == 0.5
    auto = KHarmonicMeans(p=3.0, init="quantile").fit(x)
    np.testing.assert_allclose(auto.cluster_centers_, fixed.cluster_centers_, atol=1e-8)


# ---------------------------------------------------------- determinism etc.
def test_deterministic():
    x, c = smooth_histogram(seed=5)
    for p in (2.0, 9.0):
        a = KHarmonicMeans(p=p, init="paper", init_value=0.2).fit(x, c)
        b = KHarmonicMeans(p=p, init="paper", init_value=0.2).fit(x.copy(), c.copy())
        assert np.array_equal(a.cluster_centers_, b.cluster_centers_)
        assert np.array_equal(a.init_centers_, b.init_centers_)
        assert (a.n_iter_, a.converged_, a.cycle_detected_, a.damping_used_, a.objective_) == \
            (b.n_iter_, b.converged_, b.cycle_detected_, b.damping_used_, b.objective_)
        assert a.damping_history_ == b.damping_history_


@pytest.mark.parametrize("p", [2.0, 6.0])
def test_predict_is_membership_argmax(p):
    x, c = smooth_histogram()
    m = KHarmonicMeans(p=p, init="quantile").fit(x, c)
    xt = np.concatenate([np.linspace(0.0, 2.5, 5001), m.cluster_centers_])
    lab = m.predict(xt)
    assert np.array_equal(lab, np.argmax(m.membership(xt), axis=1))
    # argmax membership == nearest centre (eq. 27 decreases with distance)
    d = np.abs(xt[:, None] - m.cluster_centers_[None, :])
    assert np.array_equal(lab, np.argmin(d, axis=1))
    assert np.array_equal(m.labels_, m.predict(x))
    assert np.array_equal(m.predict(m.cluster_centers_), np.arange(7))


def test_sample_weight_integer_equals_repetition():
    x = np.array([0.0, 0.3, 1.0, 1.4, 3.0])
    w = np.array([2, 1, 3, 1, 2])
    a = KHarmonicMeans(n_clusters=2, p=2.5, init="quantile", compress=False).fit(x, w)
    b = KHarmonicMeans(n_clusters=2, p=2.5, init="quantile", compress=False).fit(np.repeat(x, w))
    np.testing.assert_allclose(a.cluster_centers_, b.cluster_centers_, rtol=0, atol=1e-12)


def test_zero_weight_samples_are_ignored():
    x = np.array([0.0, 0.2, 1.0, 1.2, 100.0])
    a = KHarmonicMeans(n_clusters=2, init="quantile").fit(x, [1, 1, 1, 1, 0])
    b = KHarmonicMeans(n_clusters=2, init="quantile").fit(x[:4])
    np.testing.assert_array_equal(a.cluster_centers_, b.cluster_centers_)


def test_single_cluster_p2_is_the_weighted_mean():
    x, c = smooth_histogram()
    m = KHarmonicMeans(n_clusters=1, p=2.0, init="quantile").fit(x, c)
    assert m.cluster_centers_[0] == pytest.approx(np.average(x, weights=c), rel=1e-12)


def test_not_fitted():
    with pytest.raises(RuntimeError, match="not fitted"):
        KHarmonicMeans().predict([1.0])


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("X, match", [
    ([0.0, np.nan, 1.0], r"X contains non-finite.*nan"),
    ([0.0, np.inf], r"X contains non-finite.*inf"),
    ([], r"X is empty"),
    (np.zeros((3, 2)), r"X must be 1-D.*\(3, 2\)"),
    (["a", "b"], r"X must be numeric"),
])
def test_bad_X(X, match):
    with pytest.raises(ValueError, match=match):
        KHarmonicMeans(init="quantile").fit(X)


@pytest.mark.parametrize("kwargs, match", [
    (dict(p=1.5), r"p must be >= 2.*p=1\.5"),
    (dict(p=np.float64(1.5)), r"p must be >= 2.*got p=1\.5$"),
    (dict(p=0), r"p must be >= 2.*p=0"),
    (dict(p=np.nan), r"p must be a finite.*nan"),
    (dict(p="2"), r"p must be a finite.*'2'"),
    (dict(n_clusters=0), r"n_clusters must be an integer >= 1, got 0"),
    (dict(n_clusters=-3), r"n_clusters must be an integer >= 1, got -3"),
    (dict(n_clusters=2.5), r"n_clusters must be an integer >= 1, got 2\.5"),
    (dict(max_iter=0), r"max_iter must be an integer >= 1, got 0"),
    (dict(tol=-1.0), r"tol must be .* >= 0, got -1\.0"),
    (dict(damping=0.0), r"damping must be 'auto', None or a float in \(0, 1\], got 0\.0"),
    (dict(damping=1.5), r"damping must be .* got 1\.5"),
    (dict(damping="yes"), r"damping must be .* got 'yes'"),
    (dict(duplicate_spread=-1.0), r"duplicate_spread must be .* >= 0, got -1\.0"),
    (dict(compress="sometimes"), r"compress must be .* got 'sometimes'"),
    (dict(init="kmeans++"), r"init must be 'paper', 'quantile' or an array.*'kmeans\+\+'"),
    (dict(init="paper"), r"init='paper' requires init_value.*None"),
    (dict(init="paper", init_value=np.inf), r"init_value must be a finite.*inf"),
    (dict(init=[0.0, 1.0]), r"init array must have n_clusters=7 centres, got 2"),
    (dict(init=[0.0] * 6 + [np.nan]), r"init contains non-finite.*nan"),
])
def test_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        KHarmonicMeans(**kwargs).fit(np.linspace(0, 1, 50))


@pytest.mark.parametrize("w, match", [
    ([1.0, -2.0, 1.0], r"sample_weight must be non-negative, got -2\.0"),
    ([1.0, 1.0], r"sample_weight must have shape \(3,\).*\(2,\)"),
    ([1.0, np.nan, 1.0], r"sample_weight contains non-finite.*nan"),
    ([0.0, 0.0, 0.0], r"sample_weight must contain at least one positive"),
])
def test_bad_sample_weight(w, match):
    with pytest.raises(ValueError, match=match):
        KHarmonicMeans(n_clusters=2, init="quantile").fit([0.0, 1.0, 2.0], w)


def test_bad_histogram_counts():
    with pytest.raises(ValueError, match=r"counts must be non-negative, got -1\.0"):
        KHarmonicMeans(n_clusters=2, init="quantile").fit_histogram([0.0, 1.0], [3, -1])
    with pytest.raises(ValueError, match=r"levels contains non-finite"):
        KHarmonicMeans(n_clusters=2, init="quantile").fit_histogram([0.0, np.nan], [3, 1])
