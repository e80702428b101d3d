"""identify/distributions.py (issue 23): the gap estimator's Student t quantile and F survival function from
scipy.special equal scipy.stats' to 1e-12 (they are the functions scipy.stats calls, so bit for bit here)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from jident_ros.identify.distributions import f_survival, t_quantile


@pytest.mark.parametrize("q", [0.5, 0.9, 0.975, 0.995, 0.025, 1e-6])
def test_t_quantile_equals_scipy_stats(q):
    dofs = list(range(1, 400)) + [0.5, 2.5, 1e3, 1e5, 1e7]
    mine = np.array([t_quantile(q, d) for d in dofs])
    ref = stats.t.ppf(q, dofs)
    np.testing.assert_allclose(mine, ref, rtol=1e-12, atol=1e-300 if q != 0.5 else 1e-15)
    np.testing.assert_array_equal(mine, ref)     # the same cephes/boost function: bit for bit


def test_t_quantile_has_the_textbook_values():
    # a flipped tail (q vs 1 - q) or dof off by one would fail these table values
    assert t_quantile(0.975, 1) == pytest.approx(12.7062047362, rel=1e-10)
    assert t_quantile(0.975, 10) == pytest.approx(2.2281388520, rel=1e-10)
    assert t_quantile(0.975, 1e9) == pytest.approx(1.9599639845, rel=1e-8)
    assert t_quantile(0.025, 10) == pytest.approx(-2.2281388520, rel=1e-10)


def test_f_survival_equals_scipy_stats():
    xs = [0.0, 1e-9, 0.1, 0.5, 1.0, 2.0, 3.1, 10.0, 100.0, 1e6, math.inf]
    for dfd in (1, 2, 3, 7, 20, 45, 200, 2000):
        mine = np.array([f_survival(x, 2, dfd) for x in xs])
        ref = stats.f.sf(xs, 2, dfd)
        np.testing.assert_allclose(mine, ref, rtol=1e-12, atol=1e-300)
    assert f_survival(0.0, 2, 10) == 1.0 and f_survival(math.inf, 2, 10) == 0.0
    # F(2, d) has the closed form (1 + 2x/d)^(-d/2)
    assert f_survival(3.0, 2, 12) == pytest.approx((1 + 2 * 3.0 / 12) ** -6, rel=1e-12)


def test_gap_calls_no_scipy_stats():
    """The estimator's hot path uses these functions, not scipy.stats' (~0.2 ms of argument checks a call)."""
    import ast
    from pathlib import Path
    src = Path(__file__).resolve().parents[1] / "jident_ros" / "identify" / "gap.py"
    names = [a.name for n in ast.walk(ast.parse(src.read_text())) if isinstance(n, (ast.Import, ast.ImportFrom))
             for a in n.names] + [n.module or "" for n in ast.walk(ast.parse(src.read_text()))
                                  if isinstance(n, ast.ImportFrom)]
    assert not [x for x in names if x == "stats" or x.startswith("scipy.stats")], names


def test_normal_and_chi2_equal_scipy_stats():
    # issue 25: the trend and the change-point search take these from scipy.special (no scipy.stats import)
    from jident_ros.identify.distributions import chi2_ppf, normal_cdf, normal_isf, normal_pdf, normal_ppf, normal_sf
    xs = np.array([-40.0, -8.0, -2.5, -1.0, -1e-9, 0.0, 0.3, 1.96, 2.5, 8.0, 40.0])
    np.testing.assert_array_equal(normal_cdf(xs), stats.norm.cdf(xs))
    np.testing.assert_array_equal(normal_sf(xs), stats.norm.sf(xs))
    np.testing.assert_array_equal(normal_pdf(xs), stats.norm.pdf(xs))
    assert normal_sf(2.5) == stats.norm.sf(2.5) and normal_pdf(2.5) == stats.norm.pdf(2.5)
    qs = np.array([1e-12, 1e-3, 0.01, 0.025, 0.5, 0.975, 0.99, 1 - 1e-9])
    np.testing.assert_array_equal(normal_ppf(qs), stats.norm.ppf(qs))
    np.testing.assert_array_equal(normal_isf(qs), stats.norm.isf(qs))
    for dof in (1, 2, 3, 4.5, 7, 30, 199, 5000):
        for q in (0.01, 0.5, 0.99):
            assert chi2_ppf(q, dof) == stats.chi2.ppf(q, dof)
    assert normal_isf(0.025) == pytest.approx(1.959963984540054, rel=1e-14)   # the upper, not the lower tail
    assert chi2_ppf(0.99, 1) == pytest.approx(6.634896601021214, rel=1e-12)
    with pytest.raises(ValueError):
        chi2_ppf(1.0, 3)
