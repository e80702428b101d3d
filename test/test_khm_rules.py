"""K-harmonic means on a hand-computable example: paper eqs. (26), (27), (29), (30) and the performance function
(khm.py docstring, docs/method.md "Eqs. (23)-(30)").

Data x = (0, 1, 3), centres s = (0.5, 2.5): every distance is a binary fraction, so the reference values are
computed exactly with fractions.Fraction straight from the paper's formulas:

    W(x)   = sum_i d_i^(-p-2) / (sum_i d_i^(-p))^2                       (26)
    M(i|x) = d_i^(-p-2) / sum_j d_j^(-p-2)                                (27)
    s_i    = sum_x c_x M(i|x) W(x) x / sum_x c_x M(i|x) W(x)              (30)
    KHM    = sum_x c_x K / sum_i d_i^(-p)

Also: one update of the class and of the batch function is exactly eq. (30); the performance function does not
increase over plain p = 2 iterations; the documented initialisations (eq. 23 with the duplicates spread, the
quantile one).  Milliseconds.
"""
from __future__ import annotations

import warnings
from fractions import Fraction as F

import numpy as np
import pytest

from jident_ros.method.khm import khm_fit_batch
from jident_ros.research.khm_reference import ConvergenceWarning, KHarmonicMeans, khm_objective

X = (F(0), F(1), F(3))
S = (F(1, 2), F(5, 2))


def ref_terms(x, s, p):
    """(W, M) of eqs. (26)-(27), exact."""
    W, M = [], []
    for xv in x:
        d = [abs(xv - sv) for sv in s]
        a = [di ** -(p + 2) for di in d]
        b = [di ** -p for di in d]
        W.append(sum(a) / sum(b) ** 2)
        M.append([ai / sum(a) for ai in a])
    return W, M


def ref_update(x, s, p, c=None):
    """Eq. (30), exact."""
    c = c or [F(1)] * len(x)
    W, M = ref_terms(x, s, p)
    return [sum(c[k] * M[k][i] * W[k] * x[k] for k in range(len(x))) /
            sum(c[k] * M[k][i] * W[k] for k in range(len(x))) for i in range(len(s))]


def ref_objective(x, s, p, c=None):
    c = c or [F(1)] * len(x)
    return sum(ck * len(s) / sum(abs(xv - sv) ** -p for sv in s) for xv, ck in zip(x, c))


def fitted(p, centres=S):
    m = KHarmonicMeans(n_clusters=len(centres), p=p)
    m.cluster_centers_ = np.array([float(v) for v in centres])      # evaluate at known centres
    return m


def one_update(x, p, init, weights=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        m = KHarmonicMeans(n_clusters=len(init), p=p, init=np.array(init, float), max_iter=1, damping=None,
                           compress=False).fit(np.array(x, float), weights)
    assert m.n_iter_ == 1 and not m.converged_
    return m


@pytest.mark.parametrize("p", [2, 3, 4])
def test_weights_and_memberships_are_eqs_26_27(p):
    W, M = ref_terms(X, S, p)
    m = fitted(float(p))
    x = np.array([0.0, 1.0, 3.0])
    np.testing.assert_allclose(m.weights(x), [float(w) for w in W], rtol=1e-14)
    got = m.membership(x)
    np.testing.assert_allclose(got, [[float(v) for v in row] for row in M], rtol=1e-14)
    np.testing.assert_allclose(got.sum(axis=1), 1.0, rtol=0, atol=1e-15)          # eq. (29)
    assert np.all((got >= 0) & (got <= 1))                                          # eq. (28)
    np.testing.assert_array_equal(m.predict(x), [0, 0, 1])


@pytest.mark.parametrize("p", [2, 3])
def test_one_update_is_eq_30(p):
    m = one_update([0.0, 1.0, 3.0], float(p), [0.5, 2.5])
    np.testing.assert_allclose(m.cluster_centers_, [float(v) for v in ref_update(X, S, p)], rtol=1e-14)
    np.testing.assert_array_equal(m.init_centers_, [0.5, 2.5])


def test_one_update_with_sample_weights_is_eq_30_with_counts():
    """c_x = 2 for x = 0: the same as the sample repeated."""
    c = [F(2), F(1), F(1)]
    want = [float(v) for v in ref_update(X, S, 2, c)]
    m = one_update([0.0, 1.0, 3.0], 2.0, [0.5, 2.5], np.array([2.0, 1.0, 1.0]))
    np.testing.assert_allclose(m.cluster_centers_, want, rtol=1e-14)
    m = one_update([0.0, 0.0, 1.0, 3.0], 2.0, [0.5, 2.5])
    np.testing.assert_allclose(m.cluster_centers_, want, rtol=1e-14)


@pytest.mark.parametrize("p", [2, 3])
def test_batch_function_one_update_is_eq_30(p):
    """khm_fit_batch (plain iteration, relaxation 1 at p = 2): one update from the spread paper initialisation.
    Levels (0, 1, 3) map to (0, 1/3, 1); init 1.5 with spread 2/3 of the range gives the centres 0.5 and 2.5."""
    lam = 1.0 if p == 2 else min(1.0, 1.8 / (p - 1))
    centres, info = khm_fit_batch(np.array([0.0, 1.0, 3.0]), np.array([[1.0, 1.0, 1.0]]), [1.5], n_clusters=2,
                                  p=float(p), max_iter=1, duplicate_spread=2.0 / 3.0, accelerate=False)
    f = [float(v) for v in ref_update(X, S, p)]
    want = [0.5 + lam * (f[0] - 0.5), 2.5 + lam * (f[1] - 2.5)]
    np.testing.assert_allclose(centres[0], want, rtol=1e-13)
    assert info["n_iter"] == 1 and not info["converged"][0]


@pytest.mark.parametrize("p", [2, 3])
def test_objective_is_the_performance_function(p):
    want = float(ref_objective(X, S, p))
    assert khm_objective(np.array([0.0, 1.0, 3.0]), np.array([0.5, 2.5]), float(p)) == pytest.approx(want, rel=1e-14)
    c = [F(2), F(1), F(3)]
    got = khm_objective(np.array([0.0, 1.0, 3.0]), np.array([0.5, 2.5]), float(p), np.array([2.0, 1.0, 3.0]))
    assert got == pytest.approx(float(ref_objective(X, S, p, c)), rel=1e-14)
    m = one_update([0.0, 1.0, 3.0], float(p), [0.5, 2.5])
    assert m.objective_ == pytest.approx(float(ref_objective(X, [F(v) for v in m.cluster_centers_], p)), rel=1e-12)
    assert m.score(np.array([0.0, 1.0, 3.0])) == pytest.approx(-m.objective_, rel=1e-14)


def test_performance_function_does_not_increase_over_plain_iterations():
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.normal(0.0, 0.3, 60), rng.normal(2.0, 0.3, 60), rng.normal(5.0, 0.5, 60)])
    values = []
    for it in range(1, 25):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            m = KHarmonicMeans(n_clusters=3, p=2.0, init=np.array([-1.0, 0.5, 1.0]), max_iter=it, damping=None).fit(x)
        values.append(m.objective_)
    assert np.all(np.diff(values) <= 1e-12 * values[0])
    assert values[-1] < 0.9 * values[0]
    np.testing.assert_allclose(m.cluster_centers_, [0.0, 2.0, 5.0], atol=0.3)


def test_converges_to_a_fixed_point_of_eq_30():
    m = KHarmonicMeans(n_clusters=2, p=2.0, init=np.array([0.5, 2.5]), tol=1e-12).fit(np.array([0.0, 1.0, 3.0]))
    assert m.converged_ and m.n_iter_ > 1
    s = [F(v) for v in m.cluster_centers_]
    np.testing.assert_allclose([float(v) for v in ref_update(X, s, 2)], m.cluster_centers_, rtol=0, atol=3e-12 * 3)


def test_paper_initialisation_spreads_duplicates_as_documented():
    """Module docstring: 7 centres at v = 0.2, data range 1.3, spread 1.0 -> -0.45, -0.2333, -0.0167, 0.2, 0.4167,
    0.6333, 0.85."""
    x = np.linspace(0.5, 1.8, 14)                     # range 1.3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        m = KHarmonicMeans(n_clusters=7, p=2.0, init="paper", init_value=0.2, max_iter=1).fit(x)
    np.testing.assert_allclose(m.init_centers_, 0.2 + 1.3 * (np.arange(7) / 6 - 0.5), rtol=1e-13)
    np.testing.assert_allclose(m.init_centers_, [-0.45, -0.2333, -0.0167, 0.2, 0.4167, 0.6333, 0.85], atol=1e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        half = KHarmonicMeans(n_clusters=7, p=2.0, init="paper", init_value=0.2, max_iter=1, duplicate_spread=0.5).fit(x)
    np.testing.assert_allclose(half.init_centers_, 0.2 + 0.65 * (np.arange(7) / 6 - 0.5), rtol=1e-13)


def test_quantile_initialisation_uses_midpoint_levels():
    """init='quantile': weighted quantiles at (k + 1/2)/K, midpoint-CDF interpolation between the levels."""
    x = np.array([0.0, 1.0, 2.0, 3.0])               # midpoint CDF of the levels: 1/8, 3/8, 5/8, 7/8
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        m = KHarmonicMeans(n_clusters=2, p=2.0, init="quantile", max_iter=1).fit(x)
    np.testing.assert_allclose(m.init_centers_, [0.5, 2.5], rtol=1e-14)         # levels 1/4, 3/4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        m = KHarmonicMeans(n_clusters=4, p=2.0, init="quantile", max_iter=1).fit(x)
    np.testing.assert_allclose(m.init_centers_, [0.0, 1.0, 2.0, 3.0], rtol=1e-14)


@pytest.mark.parametrize("X, shown", [("abc", "'abc'"), (["a", "b"], "array with shape (2,)"),
                                      ([[1.0, 2.0], [3.0, 4.0]], "shape (2, 2)")])
def test_bad_data_is_named_with_its_value_or_shape(X, shown):
    with pytest.raises(ValueError, match="X must be") as exc:
        KHarmonicMeans(n_clusters=2, init="quantile").fit(X)
    assert shown in str(exc.value)


def test_duplicates_over_all_equal_data_spread_over_max_abs_v_1():
    """Module docstring: with all data equal the spread interval's width uses R = max(|v|, 1)."""
    for v, width in ((0.2, 1.0), (4.0, 4.0)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            m = KHarmonicMeans(n_clusters=3, p=2.0, init="paper", init_value=v, max_iter=1).fit(np.full(6, 0.3))
        np.testing.assert_allclose(m.init_centers_, v + width * np.array([-0.5, 0.0, 0.5]), rtol=1e-14)


def test_documented_defaults():
    m = KHarmonicMeans()
    assert (m.n_clusters, m.p, m.init, m.max_iter, m.tol, m.damping, m.duplicate_spread, m.compress) == \
        (7, 2.0, "paper", 3000, 1e-10, "auto", 1.0, "auto")


# --------------------------------------------------------------------------- numerics and damping
def test_scalar_data_is_one_sample():
    """A scalar X is one sample (shape (1,)): the performance function of x = 1 and the labels of one value."""
    assert khm_objective(1.0, np.array([0.5, 2.5]), 2.0) == pytest.approx(float(ref_objective([F(1)], S, 2)),
                                                                          rel=1e-14)
    m = fitted(2.0)
    np.testing.assert_array_equal(m.predict(3.0), [1])
    assert m.membership(0.0).shape == (1, 2)


def test_convergence_threshold_is_relative_to_the_data_range():
    """khm.py: converged when max |F(S) - S| <= tol x the data range R (not max(|x|, 1)): data of range 0.01 around
    100 converge as tightly as the same data around 0 -- KHM is equivariant under a shift, and so is the fit -- and
    the returned centres are a fixed point of eq. (30) to tol x R."""
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.normal(0.002, 0.0005, 80), rng.normal(0.008, 0.0005, 80)])
    r = float(x.max() - x.min())
    tol = 1e-6
    near0 = KHarmonicMeans(n_clusters=2, init=np.array([0.003, 0.006]), tol=tol, damping=None).fit(x)
    near100 = KHarmonicMeans(n_clusters=2, init=np.array([100.003, 100.006]), tol=tol, damping=None).fit(x + 100.0)
    assert near0.converged_ and near100.converged_
    np.testing.assert_allclose(near100.cluster_centers_ - 100.0, near0.cluster_centers_, rtol=0, atol=1e-9)
    for m, data in ((near0, x), (near100, x + 100.0)):
        again = one_update(data, 2.0, m.cluster_centers_)                     # F(S) at the returned centres
        assert np.max(np.abs(again.cluster_centers_ - m.cluster_centers_)) <= tol * r


def test_auto_damping_halves_down_to_1_1024_and_no_further():
    """damping='auto': each detected cycle halves lambda, never below 1/1024 (module docstring).  At p = 3000 the
    update's Jacobian has an eigenvalue near -(p - 2), so even lambda = 1/1024 oscillates: lambda ends at the floor
    after ten halvings."""
    x = np.array([0.0, 0.1, 0.2, 0.5, 0.55, 0.9, 1.0, 0.3, 0.35, 0.75])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        m = KHarmonicMeans(n_clusters=3, p=3000.0, init="quantile", max_iter=400).fit(x)
    assert m.cycle_detected_
    assert [lam for _, lam in m.damping_history_][:11] == [0.5 ** k for k in range(1, 11)]
    assert m.damping_used_ == 1.0 / 1024.0


def test_batch_relaxation_starts_at_1_8_over_p_minus_1_capped_at_1():
    """khm_fit_batch: relaxation lam = min(1, 1.8/(p - 1)); one plain update from the spread initialisation at
    p = 2.5 (lam = 1, the cap) and p = 4 (lam = 0.6)."""
    for p, lam in ((2.5, 1.0), (4.0, 0.6)):
        centres, info = khm_fit_batch(np.array([0.0, 1.0, 3.0]), np.array([[1.0, 1.0, 1.0]]), [1.5], n_clusters=2,
                                      p=p, max_iter=1, duplicate_spread=2.0 / 3.0, accelerate=False)
        m = one_update([0.0, 1.0, 3.0], p, [0.5, 2.5])                        # F(S), eq. (30)
        want = np.array([0.5, 2.5]) + lam * (m.cluster_centers_ - np.array([0.5, 2.5]))
        np.testing.assert_allclose(centres[0], want, rtol=1e-13)
        assert info["damping"][0] == lam


def test_batch_with_no_iterations_returns_the_spread_initial_centres():
    centres, info = khm_fit_batch(np.array([0.0, 1.0, 3.0]), np.array([[1.0, 1.0, 1.0]]), [1.5], n_clusters=2,
                                  max_iter=0, duplicate_spread=2.0 / 3.0, accelerate=False)
    np.testing.assert_allclose(centres[0], [0.5, 2.5], rtol=1e-14)
    assert info["n_iter"] == 0 and not info["converged"][0]


def test_batch_halves_the_relaxation_of_an_oscillating_histogram():
    """khm_fit_batch (plain): a histogram whose iteration reverses its step without decaying at the starting
    lam = 1.8/(p - 1) gets lam halved once (this seeded 64-level histogram at p = 9), then converges to a fixed
    point of eq. (30)."""
    levels = np.linspace(0.0, 1.0, 64)
    rng = np.random.default_rng(64)
    counts = rng.integers(0, 50, 64).astype(float) * (rng.random(64) < 0.5)
    counts[0] += 1
    init = rng.uniform(0.0, 1.0)
    centres, info = khm_fit_batch(levels, counts[None], [init], p=9.0, accelerate=False)
    assert info["converged"][0]
    assert info["damping"][0] == pytest.approx(1.8 / 8.0 / 2.0, rel=1e-15)
    again = one_update(levels, 9.0, centres[0], counts)
    np.testing.assert_allclose(again.cluster_centers_, centres[0], rtol=0, atol=1e-7)
