"""stream/filters.py (issue 25): the Savitzky-Golay filter and coefficients and the first-order low-pass give
the same floats as the scipy.signal calls they replace, bit for bit, so no estimate or entry moves."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss

from jident_ros.stream.filters import first_order_lowpass, savgol_coeffs, savgol_filter


@pytest.mark.parametrize("n", [7, 8, 13, 50, 2048])
@pytest.mark.parametrize("deriv", [0, 1, 2])
def test_savgol_filter_equals_scipy_bit_for_bit(n, deriv):
    rng = np.random.default_rng(n * 10 + deriv)
    for scale in (1e-6, 1.0, 1e4):
        x = np.cumsum(rng.normal(size=n)) * scale + rng.normal() * 100.0
        np.testing.assert_array_equal(savgol_filter(x, 7, 2, deriv=deriv), ss.savgol_filter(x, 7, 2, deriv=deriv))


def test_savgol_filter_edges_and_values():
    # a quadratic is reproduced exactly by a quadratic fit, its edges included (a wrong edge fit or a flipped
    # kernel would fail here): x = t^2 has x' = 2t and x'' = 2
    t = np.arange(20.0)
    np.testing.assert_allclose(savgol_filter(t ** 2, 7, 2, deriv=1), 2 * t, atol=1e-9)
    np.testing.assert_allclose(savgol_filter(t ** 2, 7, 2, deriv=2), np.full(20, 2.0), atol=1e-9)
    np.testing.assert_allclose(savgol_filter(t ** 2, 7, 2, deriv=2, delta=0.5), np.full(20, 8.0), atol=1e-9)
    with pytest.raises(ValueError):
        savgol_filter(np.zeros(6), 7, 2)


@pytest.mark.parametrize("use", ["conv", "dot"])
@pytest.mark.parametrize("w,p,d", [(7, 2, 2), (5, 2, 2), (9, 2, 2), (7, 2, 1), (11, 3, 2), (7, 2, 0), (5, 1, 2)])
def test_savgol_coeffs_equal_scipy(w, p, d, use):
    np.testing.assert_array_equal(savgol_coeffs(w, p, deriv=d, use=use), ss.savgol_coeffs(w, p, deriv=d, use=use))


def test_savgol_coeffs_textbook():
    # the 7-point quadratic second derivative: (5, 0, -3, -4, -3, 0, 5) / 42
    np.testing.assert_allclose(savgol_coeffs(7, 2, deriv=2, use="dot"), np.array([5, 0, -3, -4, -3, 0, 5]) / 42,
                               atol=1e-15)


@pytest.mark.parametrize("alpha", [0.01, 0.3, 0.5, 0.77, 0.999])
def test_first_order_lowpass_equals_lfilter(alpha):
    rng = np.random.default_rng(int(alpha * 1000))
    x = rng.normal(size=300) * rng.uniform(1e-4, 10.0)
    initial = float(rng.normal())
    ref = ss.lfilter([alpha], [1.0, alpha - 1.0], x, zi=[(1.0 - alpha) * initial])[0]
    np.testing.assert_array_equal(first_order_lowpass(x, alpha, initial), ref)
    assert first_order_lowpass(np.empty(0), alpha, initial).shape == (0,)


def test_first_order_lowpass_recursion():
    # y0 = a x0 + (1 - a) y_init: a swapped alpha or initial value fails
    y = first_order_lowpass([1.0, 1.0], 0.25, 3.0)
    assert y[0] == pytest.approx(0.25 * 1.0 + 0.75 * 3.0)
    assert y[1] == pytest.approx(0.25 + 0.75 * y[0])
