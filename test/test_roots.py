"""identify/roots.py (issue 25): Brent's method as scipy.optimize.brentq, the same float for the same call."""
from __future__ import annotations

import math

import pytest
from scipy.optimize import brentq as scipy_brentq

from jident_ros.identify.roots import brentq
from jident_ros.identify.trend_maths import cusum_arl

CASES = [(lambda x: x ** 3 - 2 * x - 5, 2, 3), (lambda x: math.cos(x) - x, 0, 1), (lambda x: math.exp(x) - 1e3, 0, 20),
         (lambda x: x - 1e-7, 0, 1), (lambda x: math.log(x) - 3.3, 1, 1e4), (lambda x: (x - 0.3) ** 5, 0, 1),
         (lambda x: math.tanh(50 * (x - 0.123)), -3, 2), (lambda x: x * x - 2, 0, 2)]


def _outcome(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except (ValueError, RuntimeError) as e:
        return type(e).__name__


@pytest.mark.parametrize("i", range(len(CASES)))
@pytest.mark.parametrize("xtol", [2e-12, 1e-9, 1e-3])
@pytest.mark.parametrize("maxiter", [100, 5])
def test_brentq_equals_scipy(i, xtol, maxiter):
    f, a, b = CASES[i]
    assert _outcome(brentq, f, a, b, xtol=xtol, maxiter=maxiter) == \
        _outcome(scipy_brentq, f, a, b, xtol=xtol, maxiter=maxiter)


def test_brentq_on_the_cusum_design():
    # the one runtime use: the CUSUM threshold whose ARL is 2000 windows at k = 0.5
    f = lambda h: math.log(cusum_arl(h, 0.5)) - math.log(2000.0)  # noqa: E731
    assert brentq(f, 1e-6, 12.0, xtol=1e-9) == scipy_brentq(f, 1e-6, 12.0, xtol=1e-9)


def test_brentq_bracket_and_root():
    assert brentq(lambda x: x * x - 2, 0, 2) == pytest.approx(math.sqrt(2), abs=1e-11)
    assert brentq(lambda x: x - 1.0, 1.0, 2.0) == 1.0
    with pytest.raises(ValueError):
        brentq(lambda x: x * x + 1, -1, 1)
