"""Tests of the identification method (paper section 4): normalisation (eqs. 2-23,
34-35), batched KHM (eqs. 26-30), pipeline (eq. 33), pattern library, method config.

Cost: one simulate_grid call (the 42 pattern runs at eta_k = 0.025 plus 3 test
runs, EXTRA_CASES) and one pattern library (default method), both module-scoped: the fixtures ``windows``
and ``library`` of conftest.py.
"""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from jident_ros.config import ConfigError, load_method_config, load_system_config, method_config_from_dict
from jident_ros.method import khm as khm_module
from jident_ros.method import normalise as nz
from jident_ros.method import pipeline as pl
from jident_ros.method.khm import khm_fit_batch
from jident_ros.method.patterns import LibraryMismatch, PatternLibrary, identify_window
from jident_ros.method.pipeline import SIGNALS, MethodConfig
from jident_ros.research.khm_reference import ConvergenceWarning, KHarmonicMeans
from jident_ros.sim import Case, simulate_grid

REPO = Path(__file__).resolve().parents[1]

PAPER_WAVELETS = {"a1": "sym5", "m_el": "db6", "omega1": "sym5", "a2": "db6", "v2": "sym5"}

#: Off-pattern test runs (simulated together with the pattern runs, one call).
EXTRA_CASES = [Case(0.957, 0.00375, 0.0375), Case(1.131, 0.01, 0.0375), Case(1.218, 0.005, 0.0125)]
#: Windows whose histograms feed the KHM comparisons: 5 pattern runs + the 3 extra runs.
#: Index 3 = Case(1.16, 0.0075, 0.025): its a1 histogram is one where batch and class differ at p = 3.
HIST_WINDOWS = (0, 3, 13, 27, 41, 42, 43, 44)


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def method():
    return MethodConfig()


@pytest.fixture(scope="module")
def hists(pattern_cases, method):
    """signal -> (values (B, 64), counts (B, 64), init (B,)) of the HIST_WINDOWS, as the pipeline makes them.

    Pinned to the heavy-film profile's windows: the KHM-equivalence test below excludes a1 at p = 3 (the class
    and the batch function settle in different local optima there, docs/method.md); that list was measured on
    these histograms.  On the default drive's windows a2 at p = 3 settles in different optima as well."""
    windows = simulate_grid(load_system_config("heavy_film"), pattern_cases + EXTRA_CASES)
    out = {}
    for name in SIGNALS:
        x = windows.signals[name][list(HIST_WINDOWS)]
        levels, counts, lo, hi = pl.image_levels(x, name, method)
        rps = [nz.range_params(x[b], name, method.eq12) for b in range(x.shape[0])]
        values = np.stack([nz.map_levels(levels, float(lo[b]), float(hi[b]), rps[b]) for b in range(x.shape[0])])
        init = np.array([nz.initial_centre(r) for r in rps])
        out[name] = (values, counts.astype(float), init)
    return out


def synthetic_histograms(n=4, n_levels=64, seed=7):
    """Smooth multimodal 64-level histograms on [0.5, 1.7] and an initial value inside the range."""
    r = np.random.default_rng(seed)
    g = np.arange(n_levels)
    counts = []
    for _ in range(n):
        cnt = sum(r.uniform(100, 5000) * np.exp(-0.5 * ((g - r.uniform(0, n_levels - 1)) / r.uniform(1, 8)) ** 2)
                  for _ in range(int(r.integers(2, 6))))
        counts.append(np.round(cnt) + 1.0)
    levels = np.linspace(0.5, 1.7, n_levels)
    return np.tile(levels, (n, 1)), np.array(counts), r.uniform(0.6, 1.6, n)


def class_fit(values, counts, init, p):
    keep = counts > 0
    km = KHarmonicMeans(n_clusters=7, p=p, init="paper", init_value=float(init), tol=1e-12, max_iter=20000)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConvergenceWarning)
        km.fit_histogram(values[keep], counts[keep])
    return km


def data_range(values, counts):
    v = values[counts > 0]
    return float(v.max() - v.min())


def khm_update(x, c, s, p):
    """One plain eq. 30 update with eqs. 26-27, on data normalised to [0, 1]."""
    d = np.abs(x[:, None] - s[None, :])
    a = d ** (-p - 2.0)
    b = d ** (-p)
    W = a.sum(1) / b.sum(1) ** 2                     # eq. 26
    M = a / a.sum(1, keepdims=True)                  # eq. 27
    q = c[:, None] * M * W[:, None]
    return (q * x[:, None]).sum(0) / q.sum(0)        # eq. 30


# =================================================================== 1. normalise
def test_first_case_h4_k4_min_max():
    x = np.array([-3.0, 1.0, 4.0, -1.0, 5.0])
    for sig in ("a1", "v2"):
        rp = nz.range_params(x, sig)
        assert (rp.h4, rp.k4) == (-8.0, 2.0)        # eqs. (10)-(11): min-max, min+max
        assert (rp.h3, rp.k3) == (-8.0, 2.0)        # eqs. (8)-(9)
    rp = nz.range_params(np.array([-5.0, -2.0, -3.0]), "a1")
    assert (rp.h4, rp.k4) == (-3.0, -7.0)
    assert (rp.h3, rp.k3) == (-7.0, -3.0)           # h3 = min(h4, k4), k3 = max


def _step_window(seed=1):
    """2048 samples: 700 x 10, 400 x 6, 500 x 2, 448 x -4, shuffled."""
    x = np.concatenate([np.full(700, 10.0), np.full(400, 6.0), np.full(500, 2.0), np.full(448, -4.0)])
    return np.random.default_rng(seed).permutation(x)


# By hand, sorted descending (eq. 22): positions 1-700 are 10, 701-1100 are 6, 1101-1600 are 2, rest -4.
STEP_ME = [6.0, 6.0, 2.0, 2.0]                                  # value at position L
STEP_MD = [(7000 + 68 * 6) / 768, (7000 + 324 * 6) / 1024,      # mean of the first L
           (7000 + 2400 + 180 * 2) / 1280, (7000 + 2400 + 436 * 2) / 1536]


def test_sorted_prefix_stats_by_hand():
    me, md = nz.sorted_prefix_stats(_step_window())
    np.testing.assert_allclose(me, STEP_ME, rtol=0, atol=1e-12)
    np.testing.assert_allclose(md, STEP_MD, rtol=1e-13)
    # a shuffled ramp 0..2047: m_e,L = 2048 - L, m_d,L = (4095 - L) / 2
    ramp = np.random.default_rng(2).permutation(np.arange(2048.0))
    me, md = nz.sorted_prefix_stats(ramp)
    L = np.array([768, 1024, 1280, 1536])
    np.testing.assert_allclose(me, 2048 - L, rtol=0, atol=0)
    np.testing.assert_allclose(md, (4095 - L) / 2, rtol=1e-13)


@pytest.mark.parametrize("sig", ["m_el", "omega1", "a2"])
def test_second_case_h4_k4_by_hand(sig):
    d = np.array(STEP_ME) - np.array(STEP_MD)
    x = _step_window()
    rp = nz.range_params(x, sig, eq12="corrected")
    assert rp.h4 == pytest.approx(d[0] + d[1] + d[2], rel=1e-12)            # corrected eq. (12)
    assert rp.h4 == pytest.approx(-3.6458333333333 - 2.734375 - 5.625, rel=1e-10)
    assert rp.k4 == pytest.approx(d[0] - d[1] - d[2] - d[3], rel=1e-12)     # eq. (13)
    assert rp.k4 == pytest.approx(-3.6458333333333 + 2.734375 + 5.625 + 4.6875, rel=1e-10)
    assert (rp.h3, rp.k3) == (min(rp.h4, rp.k4), max(rp.h4, rp.k4))
    lit = nz.range_params(x, sig, eq12="literal")
    assert lit.h4 == pytest.approx(2 * d[1] + d[2], rel=1e-12)              # printed eq. (12)
    assert lit.h4 == pytest.approx(-11.09375, rel=1e-12)
    assert lit.k4 == rp.k4
    # the ramp: d_L = (1 - L) / 2
    ramp = np.random.default_rng(2).permutation(np.arange(2048.0))
    rp = nz.range_params(ramp, sig)
    assert (rp.h4, rp.k4) == (pytest.approx(-1534.5), pytest.approx(1535.0))
    assert (rp.h3, rp.k3) == (pytest.approx(-1534.5), pytest.approx(1535.0))
    assert nz.range_params(ramp, sig, eq12="literal").h4 == pytest.approx(-1662.5)


def test_h3_k3_are_min_max_of_h4_k4():
    for h4, k4 in [(-1.0, 2.0), (3.0, -2.0), (5.0, 5.0)]:
        rp = nz.RangeParams(h4, k4)
        assert rp.h3 == min(h4, k4) and rp.k3 == max(h4, k4)


def test_map_to_range_endpoints_and_eqs_2_5_compose():
    img = np.array([[0.2, 0.5, 0.7], [0.9, 0.2, 0.3]])
    rp = nz.RangeParams(-8.0, 2.0)              # h3 = -8, k3 = 2: range [2, 12]
    out = nz.map_to_range(img, rp)
    assert out.shape == img.shape
    assert out[0, 0] == pytest.approx(2.0) and out[1, 1] == pytest.approx(2.0)     # min -> k3
    assert out[1, 0] == pytest.approx(12.0)                                          # max -> 2 k3 - h3
    assert out[0, 1] == pytest.approx(2.0 + 10.0 * 0.3 / 0.7)
    # eq. (5) then eq. (2), literally
    h3, k3 = rp.h3, rp.k3
    x2 = (img - img.min()) / (img.max() - img.min()) * (k3 - h3) + k3
    x3 = (x2 - x2.min()) / (x2.max() - x2.min()) * (k3 - h3) + k3
    np.testing.assert_allclose(out, x3, rtol=1e-13)
    # affine in the image: collinear, and invariant to a positive affine change of the image
    t = (img - img.min()) / (img.max() - img.min())
    np.testing.assert_allclose(out, k3 + t * (k3 - h3), rtol=1e-13)
    np.testing.assert_allclose(nz.map_to_range(3.0 * img - 7.0, rp), out, rtol=1e-12)
    # map_levels is the same map on level values
    np.testing.assert_allclose(nz.map_levels(img.ravel(), img.min(), img.max(), rp), out.ravel(), rtol=1e-13)
    # a range with h4 > k4 (k3 = h4)
    out2 = nz.map_to_range(img, nz.RangeParams(1.0, -3.0))
    assert out2.min() == pytest.approx(1.0) and out2.max() == pytest.approx(5.0)


def test_constant_image_maps_to_k3():
    rp = nz.RangeParams(-8.0, 2.0)
    np.testing.assert_array_equal(nz.map_to_range(np.full((4, 5), 0.3), rp), np.full((4, 5), 2.0))
    np.testing.assert_array_equal(nz.map_levels([0.1, 0.3], 0.3, 0.3, rp), [2.0, 2.0])


def test_initial_centre_is_one_minus_k3():
    assert nz.initial_centre(nz.RangeParams(-8.0, 2.0)) == -1.0
    assert nz.initial_centre(nz.RangeParams(-3.0, -7.0)) == 4.0


def test_h5_factor_by_hand_positive_and_order_invariant():
    S = np.array([[0.5, 3.0], [1.0, 2.0], [-1.0, 0.0]])
    ranges = [nz.RangeParams(-8.0, 2.0), nz.RangeParams(-3.0, -7.0), nz.RangeParams(-4.0, 6.0)]
    # S1 = 1 - h3 = 9, 8, 5 -> numerator max(3, 9) = 9; denominator min(|h3|, |k3|) = min(2, 3, 4) = 2
    assert nz.h5_factor(S, ranges) == pytest.approx(4.5)
    for perm in ([1, 0, 2], [2, 1, 0], [2, 0, 1]):
        h5 = nz.h5_factor(S[perm], [ranges[i] for i in perm])
        assert h5 == pytest.approx(4.5) and h5 > 0
    # a negative ratio is made positive
    h5 = nz.h5_factor(np.array([[-50.0]]), [nz.RangeParams(2.0, 60.0)])   # S1 = -1, num -1, den 2
    assert h5 == pytest.approx(0.5)


def test_normalise_bad_input_raises_naming_argument():
    good = np.arange(2048.0)
    bad = good.copy()
    bad[5] = np.nan
    for sig in ("a1", "m_el"):
        with pytest.raises(ValueError, match=rf"{sig}.*NaN"):
            nz.range_params(bad, sig)
        with pytest.raises(ValueError, match=rf"{sig}.*1-D"):
            nz.range_params(good.reshape(2, 1024), sig)
    with pytest.raises(ValueError, match="NaN"):
        nz.sorted_prefix_stats(bad)
    with pytest.raises(ValueError, match=r"signal.*'torque'"):
        nz.range_params(good, "torque")
    with pytest.raises(ValueError, match=r"eq12.*'bogus'"):
        nz.range_params(good, "m_el", eq12="bogus")


@pytest.mark.parametrize("sig", ["a1", "v2"])
def test_bad_eq12_raises_for_first_case_signals_too(sig):
    with pytest.raises(ValueError, match="eq12"):
        nz.range_params(np.arange(2048.0), sig, eq12="bogus")


# =================================================================== 2. khm_fit_batch
@pytest.mark.parametrize("sig,p", [(s, 2.0) for s in SIGNALS] + [(s, 3.0) for s in SIGNALS if s != "a1"])
def test_khm_batch_equals_class_realistic(hists, sig, p):
    # the plain (unaccelerated) batch iteration is the class's iteration; SQUAREM may reach
    # another local optimum (test_khm_batch_is_fixed_point covers the accelerated default)
    values, counts, init = hists[sig]
    batch, info = khm_fit_batch(values, counts, init, n_clusters=7, p=p, tol=1e-12, max_iter=20000,
                                accelerate=False)
    assert batch.shape == (len(HIST_WINDOWS), 7)
    assert info["converged"].all()
    for b in range(len(HIST_WINDOWS)):
        km = class_fit(values[b], counts[b], init[b], p)
        assert km.converged_
        tol = 1e-5 * data_range(values[b], counts[b])
        np.testing.assert_allclose(batch[b], km.cluster_centers_, rtol=0, atol=tol,
                                   err_msg=f"{sig} window {HIST_WINDOWS[b]} p={p}")





@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # see test_khm_batch_centre_on_a_level_no_warning
@pytest.mark.parametrize("p", [2.0, 3.0])
def test_khm_batch_equals_class_synthetic(p):
    levels, counts, init = synthetic_histograms()
    # also an initial value outside the data range and a sparse histogram (zero counts)
    counts = np.vstack([counts, counts[0] * (np.arange(64) % 3 == 0)])
    levels = np.vstack([levels, levels[0]])
    init = np.append(init, 0.9)
    init[1] = 2.4
    batch, info = khm_fit_batch(levels, counts, init, p=p, tol=1e-12, max_iter=20000, accelerate=False)
    assert info["converged"].all()
    for b in range(len(init)):
        km = class_fit(levels[b], counts[b], init[b], p)
        np.testing.assert_allclose(batch[b], km.cluster_centers_, rtol=0, atol=1e-5 * data_range(levels[b], counts[b]))


def _midpoint_case():
    """Initial value at the middle of the data: in khm_fit_batch's [0, 1] units the spread initial
    centres are 0, 1/6, ..., 1, exactly on the end levels (distance 0)."""
    levels, counts, _ = synthetic_histograms(n=1)
    return levels[0], counts[0], 0.5 * (levels[0, 0] + levels[0, -1])


@pytest.mark.parametrize("p", [2.0, 3.0, 6.0])
def test_khm_batch_centre_on_a_level(p):
    levels, counts, v = _midpoint_case()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        batch, info = khm_fit_batch(levels, counts[None], [v], p=p, tol=1e-12, max_iter=20000, accelerate=False)
    assert info["converged"].all() and np.all(np.isfinite(batch))
    if p <= 3:
        km = class_fit(levels, counts, v, p)
        np.testing.assert_allclose(batch[0], km.cluster_centers_, rtol=0, atol=1e-5 * data_range(levels, counts))


def test_khm_batch_centre_on_a_level_no_warning():
    levels, counts, v = _midpoint_case()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        khm_fit_batch(levels, counts[None], [v], p=2.0, tol=1e-12, max_iter=20000)


def test_khm_batch_of_B_equals_B_single_calls(hists):
    values, counts, init = hists["omega1"]
    for p in (2.0, 6.0):
        batch, _ = khm_fit_batch(values, counts, init, p=p, tol=1e-12, max_iter=20000)
        for b in range(len(init)):
            one, info = khm_fit_batch(values[b], counts[b:b + 1], init[b:b + 1], p=p, tol=1e-12, max_iter=20000)
            assert one.shape == (1, 7) and info["converged"].all()
            np.testing.assert_allclose(one[0], batch[b], rtol=0, atol=1e-7 * data_range(values[b], counts[b]))


def test_khm_batch_result_independent_of_batch_composition(hists, method):
    values, counts, init = hists["v2"]
    batch, _ = khm_fit_batch(values, counts, init, p=2.0, tol=method.khm_tol, max_iter=method.khm_max_iter)
    for b in range(len(init)):
        one, _ = khm_fit_batch(values[b:b + 1], counts[b:b + 1], init[b:b + 1], p=2.0, tol=method.khm_tol,
                               max_iter=method.khm_max_iter)
        np.testing.assert_array_equal(one[0], batch[b])


@pytest.mark.parametrize("p", [2.0, 3.0, 6.0, 9.0])
@pytest.mark.parametrize("sig", SIGNALS)
def test_khm_batch_is_fixed_point(hists, sig, p):
    values, counts, init = hists[sig]
    batch, info = khm_fit_batch(values, counts, init, p=p, tol=1e-10, max_iter=20000)
    assert info["converged"].all()
    assert np.all(np.diff(batch, axis=1) >= 0)
    for b in range(len(init)):
        keep = counts[b] > 0
        x, c = values[b][keep], counts[b][keep]
        lo, R = x.min(), x.max() - x.min()
        s = (batch[b] - lo) / R
        with np.errstate(divide="raise", over="raise", invalid="raise"):
            new = khm_update((x - lo) / R, c, s, p)
        assert np.all(np.isfinite(new))
        assert np.max(np.abs(new - s)) < 1e-5, f"{sig} window {HIST_WINDOWS[b]} p={p}"


def test_khm_batch_sorted_converged_default_tol(hists, method):
    for sig in SIGNALS:
        values, counts, init = hists[sig]
        for p in method.p_values:
            c, info = khm_fit_batch(values, counts, init, p=p, tol=method.khm_tol, max_iter=method.khm_max_iter)
            assert info["converged"].all(), (sig, p)
            assert np.all(np.diff(c, axis=1) >= 0)
            lo = np.where(counts > 0, values, np.inf).min(1)
            hi = np.where(counts > 0, values, -np.inf).max(1)
            assert np.all(c >= lo[:, None] - 1e-9) and np.all(c <= hi[:, None] + 1e-9)   # convex combinations


def test_khm_batch_bad_input_raises():
    levels, counts, init = synthetic_histograms(n=2)
    for p in (1.9, 0.0, -2.0, float("nan")):
        with pytest.raises(ValueError, match="p must be >= 2"):
            khm_fit_batch(levels, counts, init, p=p)
    neg = counts.copy()
    neg[1, 3] = -1.0
    with pytest.raises(ValueError, match="counts"):
        khm_fit_batch(levels, neg, init)
    with pytest.raises(ValueError, match="counts"):
        khm_fit_batch(levels, np.zeros_like(counts), init)
    bad = levels.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        khm_fit_batch(bad, counts, init)


def squarem_reference(xn, c, s, p, lam, tol, max_iter):
    """The SQUAREM loop before converged rows were compacted out: every row is updated every
    cycle and converged rows are frozen with np.where (kept here as the reference)."""
    B = s.shape[0]
    converged = np.zeros(B, dtype=bool)
    lam_ = lam[:, None]
    evals = 0

    def g(x):
        return x + lam_ * (khm_module._khm_update(xn, c, x, p) - x)

    while evals < max_iter:
        s1 = g(s)
        res0 = np.abs(s1 - s).max(axis=1) / lam
        evals += 1
        done = res0 <= tol
        converged |= done
        if np.all(converged):
            s = np.where(done[:, None], s1, s)
            break
        s2 = g(s1)
        evals += 1
        r = s1 - s
        v = s2 - 2.0 * s1 + s
        nr = np.sqrt((r * r).sum(axis=1))
        nv = np.sqrt((v * v).sum(axis=1))
        a = np.where(nv > 0, -nr / np.where(nv > 0, nv, 1.0), -1.0)
        a = np.minimum(a, -1.0)[:, None]
        ext = s - 2.0 * a * r + a * a * v
        new = g(ext)
        evals += 1
        res_new = np.abs(new - ext).max(axis=1) / lam
        bad = ~np.all(np.isfinite(new), axis=1) | (res_new > res0)
        new = np.where(bad[:, None], s2, new)
        s = np.where(converged[:, None], s, new)
    return s, evals, converged


@pytest.mark.parametrize("budget", ["enough", "half"])
@pytest.mark.parametrize("p", [2.0, 3.0, 6.0, 9.0])
def test_khm_batch_compacting_converged_rows_changes_nothing(hists, monkeypatch, p, budget):
    # all 40 histograms in one batch: rows converge at very different iterations; with half
    # the budget some stop unconverged (converged rows then return their s_c, not g(s_c))
    values = np.concatenate([hists[s][0] for s in SIGNALS])
    counts = np.concatenate([hists[s][1] for s in SIGNALS])
    init = np.concatenate([hists[s][2] for s in SIGNALS])
    max_iter = 3000
    if budget == "half":
        alone = [khm_fit_batch(values[b], counts[b:b + 1], init[b:b + 1], p=p, tol=1e-7)[1]["n_iter"]
                 for b in range(len(init))]
        max_iter = int(np.median(alone))
    got, info = khm_fit_batch(values, counts, init, p=p, tol=1e-7, max_iter=max_iter)
    monkeypatch.setattr(khm_module, "_squarem", squarem_reference)
    want, want_info = khm_fit_batch(values, counts, init, p=p, tol=1e-7, max_iter=max_iter)
    np.testing.assert_array_equal(got, want)
    assert info["n_iter"] == want_info["n_iter"]
    np.testing.assert_array_equal(info["converged"], want_info["converged"])
    if budget == "half":
        assert 0 < info["converged"].sum() < len(init)


@pytest.mark.parametrize("p", [2.0, 3.0, 9.0])
def test_khm_update_equals_eqs_26_27_30(hists, p):
    rng = np.random.default_rng(11)
    for sig in SIGNALS:
        values, counts, _ = hists[sig]
        lo = values.min(axis=1, keepdims=True)
        xn = (values - lo) / (values.max(axis=1, keepdims=True) - lo)
        c = counts / counts.sum(axis=1, keepdims=True)
        s = np.sort(rng.uniform(-0.3, 1.3, (xn.shape[0], 7)), axis=1)
        got = khm_module._khm_update(xn, c, s, p)
        assert got.shape == s.shape
        for b in range(xn.shape[0]):
            keep = c[b] > 0
            np.testing.assert_allclose(got[b], khm_update(xn[b][keep], c[b][keep], s[b], p), rtol=1e-12, atol=0)


def test_khm_batch_of_five_signals_equals_each_signal_alone(hists, method):
    # the per-window hot path clusters the five signals of one window in one batch
    for b in range(len(HIST_WINDOWS)):
        values = np.stack([hists[s][0][b] for s in SIGNALS])
        counts = np.stack([hists[s][1][b] for s in SIGNALS])
        init = np.array([hists[s][2][b] for s in SIGNALS])
        for p in (2.0, 6.0):
            batch, _ = khm_fit_batch(values, counts, init, p=p, tol=method.khm_tol, max_iter=method.khm_max_iter)
            for j in range(len(SIGNALS)):
                one, _ = khm_fit_batch(values[j], counts[j:j + 1], init[j:j + 1], p=p, tol=method.khm_tol,
                                       max_iter=method.khm_max_iter)
                np.testing.assert_array_equal(one[0], batch[j])


# =================================================================== 3. pipeline
@pytest.mark.parametrize("field,value", [("scale_reading", "octave"), ("eq12", "printed"),
                                         ("variant", "scaled"), ("p_values", (2.0, 1.5))])
def test_method_config_validation(field, value):
    with pytest.raises(ValueError, match=rf"method\.{field}"):
        MethodConfig(**{field: value})
    with pytest.raises(ValueError, match=rf"method\.{field}"):
        MethodConfig().replace(**{field: value})


def test_method_config_needs_all_wavelets():
    with pytest.raises(ValueError, match=r"method\.wavelets"):
        MethodConfig(wavelets=(("a1", "sym5"),))


def test_batch_features_shape_and_equals_signal_features(windows, method):
    idx = [0, 27, 43]
    ps = (2.0, 9.0)
    for sig in ("a1", "m_el"):
        x = windows.signals[sig][idx]
        cen, ranges, info = pl.batch_features(x, sig, method, ps)
        assert cen.shape == (len(ps), len(idx), method.n_clusters)
        assert np.all(np.diff(cen, axis=2) >= 0)
        assert set(info) == set(ps) and all(info[p]["converged"].all() for p in ps)
        for b, i in enumerate(idx):
            feat = pl.signal_features(windows.signals[sig][i], sig, method, ps)
            assert feat.ranges == ranges[b] == nz.range_params(windows.signals[sig][i], sig)
            for k, p in enumerate(ps):
                # same up to the KHM tolerance (see the xfail below for exact equality)
                tol = 1e-4 * (ranges[b].k3 - ranges[b].h3)
                np.testing.assert_allclose(feat.centres[p], cen[k, b], rtol=0, atol=tol)
                assert feat.khm_info[p]["converged"]


def test_batch_features_exactly_equals_signal_features(windows, method):
    idx = [0, 27, 43]
    cen, _, _ = pl.batch_features(windows.signals["v2"][idx], "v2", method, (2.0,))
    for b, i in enumerate(idx):
        feat = pl.signal_features(windows.signals["v2"][i], "v2", method, (2.0,))
        np.testing.assert_array_equal(feat.centres[2.0], cen[0, b])


def test_batch_features_rejects_bad_windows(method):
    with pytest.raises(ValueError, match="windows"):
        pl.batch_features(np.zeros(2048), "a1", method)
    with pytest.raises(ValueError, match="signal"):
        pl.batch_features(np.random.default_rng(0).normal(size=(1, 2048)), "torque", method)


def test_h_vector_and_margin_by_hand():
    n2 = np.array([[0.0, 1.0], [1.0, 2.0], [3.0, 3.0]])
    n3 = np.array([1.0, 1.0])
    h = pl.h_vector(n2, n3, 2.0)                    # eq. (33): 2 * [1 + 0, 0 + 1, 2 + 2]
    np.testing.assert_allclose(h, [2.0, 2.0, 8.0])
    assert pl.margin(h) == 1.0
    assert pl.h_vector(n2, np.array([3.0, 3.5]), 0.5).tolist() == [0.5 * 5.5, 0.5 * 3.5, 0.5 * 0.5]
    assert pl.margin([3.0, 1.0, 4.0]) == 3.0
    assert pl.margin([0.0, 5.0]) == float("inf")
    assert pl.margin([2.0]) == float("inf")


def test_identical_windows_give_zero_h_for_their_class(windows, method):
    idx = [0, 7, 14]                                # 3 classes at the same width
    for sig in ("omega1", "a2"):
        cen, ranges, _ = pl.batch_features(windows.signals[sig][idx], sig, method, (3.0,))
        n2 = cen[0]
        for f in range(len(idx)):
            h = pl.h_vector(n2, n2[f], 1.7)
            assert h[f] == 0.0
            assert np.argmin(h) == f and h[np.arange(3) != f].min() > 0
            assert pl.margin(h) == float("inf")


@pytest.mark.parametrize("reading", ["dyadic", "linear", "swt"])
def test_image_levels_equal_the_rendered_image(windows, method, reading):
    from jident_ros.method.image import level_histogram, render_intensity
    from jident_ros.method.scalogram import wavelet_scalogram
    cfg = method.replace(scale_reading=reading)
    x = windows.signals["omega1"][[3, 43]]
    levels, counts, lo, hi = pl.image_levels(x, "omega1", cfg)
    img = render_intensity(wavelet_scalogram(x, "sym5", reading), shape=(cfg.image_rows, cfg.image_cols),
                           n_colors=cfg.n_colors)
    want_levels, want_counts = level_histogram(img, cfg.n_colors)
    np.testing.assert_array_equal(levels, want_levels)
    np.testing.assert_array_equal(counts, want_counts)
    np.testing.assert_array_equal(lo, img.min(axis=(-2, -1)))
    np.testing.assert_array_equal(hi, img.max(axis=(-2, -1)))


def test_window_features_equal_batch_features(windows, method):
    ps = (2.0, 9.0)
    for i in (5, 42):
        win = windows.case(i)
        ref = pl.pre_entry_reference(win, windows.entry_index)
        for cfg in (method, method.replace(variant="load_scaled")):
            centres, ranges = pl.window_features(win, cfg, ps, SIGNALS, ref, windows.entry_index)
            assert centres.shape == (len(ps), len(SIGNALS), cfg.n_clusters)
            for j, sig in enumerate(SIGNALS):
                cen, rps, _ = pl.batch_features(win[sig][None], sig, cfg, ps, [ref], windows.entry_index)
                np.testing.assert_array_equal(centres[:, j], cen[:, 0])
                assert ranges[j] == rps[0]


def test_prepare_signal_variants():
    rng = np.random.default_rng(4)
    x = rng.normal(3.0, 1.0, 2048)
    assert pl.prepare_signal(x, "m_el", None, "paper") is x
    y = pl.prepare_signal(x, "m_el", 12.5, "load_scaled")
    np.testing.assert_allclose(y, (x - x[:48].mean()) / 12.5, rtol=1e-13)
    assert abs(y[:48].mean()) < 1e-14
    y = pl.prepare_signal(x, "a1", -4.0, "load_scaled", entry_index=100)
    np.testing.assert_allclose(y, (x - x[:100].mean()) / -4.0, rtol=1e-13)
    for ref in (0.0, None, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="reference"):
            pl.prepare_signal(x, "m_el", ref, "load_scaled")
    for e in (0, 2048):
        with pytest.raises(ValueError, match="entry_index"):
            pl.prepare_signal(x, "m_el", 1.0, "load_scaled", entry_index=e)
    # batch_features applies it (and needs the references)
    cfg = MethodConfig(variant="load_scaled")
    with pytest.raises(ValueError, match="reference"):
        pl.batch_features(x[None], "a1", cfg, (2.0,))
    _, ranges, _ = pl.batch_features(x[None], "a1", cfg, (2.0,), references=[12.5])
    assert ranges[0] == nz.range_params((x - x[:48].mean()) / 12.5, "a1")


def test_pre_entry_reference():
    m = np.concatenate([np.full(48, 7.0), np.full(2000, 100.0)])
    assert pl.pre_entry_reference({"m_el": m}, 48) == 7.0
    with pytest.raises(ValueError, match="entry_index"):
        pl.pre_entry_reference({"m_el": m}, 0)


# =================================================================== 4. patterns
def test_library_shapes(library, system, method):
    g = system.grid
    nps, nw, nc = len(method.p_values), len(g.backlash_widths_m), len(g.inertia_classes_kgm2)
    assert library.centres.shape == (nps, nw, len(SIGNALS), nc, method.n_clusters)
    assert library.h5.shape == (nps, nw, len(SIGNALS)) and np.all(library.h5 > 0)
    assert library.ranges.shape == (nw, len(SIGNALS), nc, 2)
    assert np.all(library.ranges[..., 0] <= library.ranges[..., 1])
    assert library.signals == SIGNALS and library.p_values == tuple(method.p_values)
    assert np.all(np.diff(library.centres, axis=-1) >= 0)


@pytest.mark.parametrize("i", [0, 16, 41])
def test_library_identifies_its_own_pattern_runs(library, windows, system, i):
    case = windows.cases[i]
    f = system.grid.inertia_classes_kgm2.index(case.inertia_kgm2)
    for p in (2.0, 9.0):
        idn = identify_window(windows.case(i), windows.entry_index, case.backlash_width_m, library,
                              MethodConfig(), p)
        assert set(idn.answers) == set(SIGNALS)
        assert idn.width_index == system.grid.backlash_widths_m.index(case.backlash_width_m)
        for sig, a in idn.answers.items():
            assert a.class_index == f, (sig, p, a.h)
            assert a.inertia_kgm2 == case.inertia_kgm2
            assert a.h[f] < 0.05 * np.sort(a.h)[1], (sig, p, a.h)
        assert idn.fused_class_index == f and idn.fused_inertia_kgm2 == case.inertia_kgm2


def test_library_pattern_runs_at_distance_zero(library, windows, system):
    for i in (0, 16, 41):
        case = windows.cases[i]
        f = system.grid.inertia_classes_kgm2.index(case.inertia_kgm2)
        for p in (2.0, 9.0):
            idn = identify_window(windows.case(i), windows.entry_index, case.backlash_width_m, library,
                                  MethodConfig(), p)
            for sig, a in idn.answers.items():
                assert a.h[f] == 0.0, (i, p, sig, a.h[f])


def test_identify_window_result(library, windows, system):
    i = 42                                          # Case(0.957, 0.00375, 0.0375): an off-pattern run
    idn = identify_window(windows.case(i), windows.entry_index, 0.00375, library, MethodConfig(), 3)
    assert idn.p == 3.0 and idn.width_index == 1
    assert list(idn.answers) == list(SIGNALS)
    classes = system.grid.inertia_classes_kgm2
    for sig, a in idn.answers.items():
        assert a.signal == sig and a.p == 3.0
        assert a.h.shape == (7,) and np.all(a.h >= 0)
        assert a.class_index == int(np.argmin(a.h)) and a.inertia_kgm2 == classes[a.class_index]
        assert a.margin == pl.margin(a.h) and a.margin >= 1.0
    assert 0 <= idn.fused_class_index < 7 and idn.fused_inertia_kgm2 == classes[idn.fused_class_index]
    assert idn.fused_margin >= 1.0
    sub = identify_window(windows.case(i), windows.entry_index, 0.00375, library, MethodConfig(), 3.0,
                          signals=("a1", "v2"))
    assert list(sub.answers) == ["a1", "v2"]
    np.testing.assert_array_equal(sub.answers["a1"].h, idn.answers["a1"].h)


def test_identify_window_load_scaled_uses_entry_index(library, windows):
    cfg = MethodConfig(variant="load_scaled")
    win, entry = windows.case(43), 100
    idn = identify_window(win, entry, 0.01, library, cfg, 2.0, signals=("a1",))
    ref = pl.pre_entry_reference(win, entry)
    cen, _, _ = pl.batch_features(win["a1"][None], "a1", cfg, (2.0,), [ref], entry_index=entry)
    e, s = library.width_index(0.01), SIGNALS.index("a1")
    want = pl.h_vector(library.centres[0, e, s], cen[0, 0], library.h5[0, e, s])
    np.testing.assert_allclose(idn.answers["a1"].h, want, rtol=1e-6)


def test_library_from_features_equals_from_windows(library, windows, system, method):
    from jident_ros.research.evaluation.evaluate import _pattern_order
    ps = method.p_values
    n = len(windows.cases)
    refs = np.array([pl.pre_entry_reference(windows.case(i), windows.entry_index) for i in range(n)])
    centres = np.zeros((len(ps), n, len(SIGNALS), method.n_clusters))
    ranges = np.zeros((n, len(SIGNALS), 2))
    for s, sig in enumerate(SIGNALS):           # all 45 windows at once, the pattern runs among them
        centres[:, :, s], rps, _ = pl.batch_features(windows.signals[sig], sig, method, ps, refs, windows.entry_index)
        ranges[:, s] = [(r.h3, r.k3) for r in rps]
    order = _pattern_order(system, windows)
    assert order == list(range(42))
    lib = PatternLibrary.from_features(centres, ranges, order, system, method)
    for name in ("centres", "h5", "ranges"):
        np.testing.assert_array_equal(getattr(lib, name), getattr(library, name))
    assert lib.p_values == library.p_values and lib.widths_m == library.widths_m
    with pytest.raises(ValueError, match="order"):
        PatternLibrary.from_features(centres, ranges, order[:5], system, method)


def test_evaluation_feature_tasks_equal_evaluate_grid(library, windows, system, method):
    from jident_ros.research.evaluation.evaluate import _feature_task, evaluate_grid, grid_result
    n = len(windows.cases)
    refs = np.array([pl.pre_entry_reference(windows.case(i), windows.entry_index) for i in range(n)])
    parts = [_feature_task((windows.signals[sig], sig, method, refs, windows.entry_index)) for sig in SIGNALS]
    feats = np.stack([centres for centres, _, _ in parts], axis=2)
    assert feats.shape == (len(method.p_values), n, len(SIGNALS), method.n_clusters)
    res = grid_result(system, method, library, windows, feats, "tasks", 1.0)
    want = evaluate_grid(system, method, windows, windows, "grid", library)
    np.testing.assert_array_equal(res.h, want.h)
    np.testing.assert_array_equal(res.notes["centres"], want.notes["centres"])
    np.testing.assert_array_equal(res.true_class, want.true_class)
    np.testing.assert_array_equal(res.pattern_mask, want.pattern_mask)


def test_library_save_load_round_trip(library, system, method, tmp_path):
    path = library.save(tmp_path / "sub" / "patterns.npz")
    assert path.is_file() and not path.with_suffix(".npz.tmp").exists()
    lib = PatternLibrary.load(path, system, method)
    for name in ("centres", "h5", "ranges"):
        np.testing.assert_array_equal(getattr(lib, name), getattr(library, name))
        assert getattr(lib, name).dtype == np.float64
    assert lib.p_values == library.p_values and lib.widths_m == library.widths_m
    assert lib.classes_kgm2 == library.classes_kgm2 and lib.signals == library.signals
    assert lib.metadata == library.metadata
    assert PatternLibrary.load(path).metadata["method_hash"] == library.metadata["method_hash"]


def test_library_load_refuses_other_configuration(library, system, method, tmp_path):
    path = library.save(tmp_path / "patterns.npz")
    with pytest.raises(LibraryMismatch, match=r"method\.eq12: library 'corrected', configuration 'literal'"):
        PatternLibrary.load(path, system, method.replace(eq12="literal"))
    other = dataclasses.replace(system, load=dataclasses.replace(system.load, mass_kg=60.0))
    with pytest.raises(LibraryMismatch, match=r"system\.load\.mass_kg") as exc:
        PatternLibrary.load(path, other, method)
    assert "jident build-patterns" in str(exc.value) and "eq12" not in str(exc.value)
    with pytest.raises(LibraryMismatch, match=r"method\.p_values"):
        library.check_matches(system, method.replace(p_values=(2.0, 3.0)))


def test_library_load_missing_or_foreign_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="jident build-patterns"):
        PatternLibrary.load(tmp_path / "none.npz")
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(LibraryMismatch, match="not a jident pattern library"):
        PatternLibrary.load(foreign)


def test_width_and_p_index(library):
    # widths 0.0025, 0.00375, 0.005, 0.0075, 0.009, 0.01
    assert library.width_index(0.005) == 2
    assert library.width_index(0.0061) == 2        # |0.0011| < |0.0014|
    assert library.width_index(0.0064) == 3
    assert library.width_index(0.0095 + 1e-6) == 5
    assert library.width_index(1e-9) == 0 and library.width_index(1.0) == 5
    for bad in (0.0, -0.005, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="backlash_width_m"):
            library.width_index(bad)
    assert library.p_index(2) == 0 and library.p_index(9.0) == 3
    with pytest.raises(ValueError, match=r"p: .*got 4\.0"):
        library.p_index(4.0)


# =================================================================== 5. config
def test_load_method_config_matches_yaml_and_defaults():
    cfg = load_method_config()
    assert cfg.wavelet == PAPER_WAVELETS
    data = yaml.safe_load((REPO / "config" / "method.yaml").read_text())["/**"]["ros__parameters"]["method"]
    defaults = MethodConfig()
    for f in dataclasses.fields(MethodConfig):
        got = getattr(cfg, f.name)
        if f.name not in data:
            assert got == getattr(defaults, f.name), f.name
        elif f.name == "wavelets":
            assert dict(got) == data["wavelets"]
        elif isinstance(got, tuple):
            assert got == tuple(float(v) for v in data[f.name]), f.name
        else:
            assert got == type(got)(data[f.name]), f.name
    assert cfg == defaults                      # the shipped file restates the defaults
    assert MethodConfig().wavelet == PAPER_WAVELETS


def test_method_config_from_dict_errors():
    with pytest.raises(ConfigError, match=r"method\.colour_depth: unknown parameter"):
        method_config_from_dict({"method": {"colour_depth": 8}})
    w = dict(PAPER_WAVELETS, a1="sym55")
    with pytest.raises(ConfigError, match=r"method\.wavelets\.a1: unknown discrete wavelet 'sym55'"):
        method_config_from_dict({"method": {"wavelets": w}})
    with pytest.raises(ConfigError, match=r"method\.eq12"):
        method_config_from_dict({"method": {"eq12": "printed"}})
    with pytest.raises(ConfigError, match=r"method\.p_values"):
        method_config_from_dict({"method": {"p_values": [2.0, 1.0]}})
    with pytest.raises(ConfigError, match=r"method\.n_clusters"):
        method_config_from_dict({"method": {"n_clusters": 2.5}})
    cfg = method_config_from_dict({"method": {"eq12": "literal", "p_values": [2, 3], "khm_tol": "1.0e-9"}})
    assert cfg.eq12 == "literal" and cfg.p_values == (2.0, 3.0) and cfg.khm_tol == 1e-9


def test_load_method_config_file(tmp_path):
    p = tmp_path / "m.yaml"
    p.write_text("/**:\n  ros__parameters:\n    method:\n      variant: load_scaled\n      bogus: 1\n")
    with pytest.raises(ConfigError, match=r"method\.bogus"):
        load_method_config(p)
    p.write_text("/**:\n  ros__parameters:\n    method:\n      variant: load_scaled\n")
    assert load_method_config(p) == MethodConfig(variant="load_scaled")


def test_equal_load_grid_equalises_the_load_and_keeps_the_pattern_runs(windows):
    """The ablation of docs/method.md: every eta_k group at the pattern group's steady load.  On the heavy-film
    profile, where the groups' loads differ by ~15 % (on the default drive by 0.015 %)."""
    from jident_ros.research.evaluation.evaluate import equal_load_grid
    system = load_system_config("heavy_film")
    g = system.grid
    # two pattern runs (they fix the line speed) and the EXTRA_CASES, at eta_k 0.0375 and 0.0125
    sub = [0, 41, 42, 43, 44]
    clean = simulate_grid(system, [windows.cases[i] for i in sub])
    eq = equal_load_grid(system, clean)
    assert eq.cases == clean.cases
    pre = slice(0, clean.entry_index)
    load_pattern = clean.signals["m_el"][0, pre].mean()
    forces = eq.metadata["equal_load_process_force_n"]
    assert forces[g.pattern_consistency_pa_sn] == system.load.process_force_n
    assert forces[0.0125] > system.load.process_force_n > forces[0.0375]
    for i, c in enumerate(eq.cases):
        # steady-state load torque equal to the pattern group's (it differs by ~15 % per group in clean)
        assert eq.signals["m_el"][i, pre].mean() == pytest.approx(load_pattern, rel=1e-4)
        if c.consistency_pa_sn == g.pattern_consistency_pa_sn:
            np.testing.assert_array_equal(eq.signals["a1"][i], clean.signals["a1"][i])
        else:
            assert abs(clean.signals["m_el"][i, pre].mean() / load_pattern - 1) > 0.1
    with pytest.raises(ValueError, match="no pattern run"):
        equal_load_grid(system, dataclasses.replace(clean, signals={k: v[2:] for k, v in clean.signals.items()},
                                                    cases=clean.cases[2:], initial_slip=clean.initial_slip[2:]))
