"""The three filters the detectors and the gap estimator need, without ``scipy.signal`` (issue 25).

``import scipy.signal`` costs about 44 MiB of resident memory and 1-2 s of start-up: it imports
``scipy.stats``, ``optimize``, ``interpolate`` and ``spatial``, none of which a node needs.  What the runtime
used from it are the Savitzky-Golay filter and coefficients and one first-order low-pass.  Here they are
computed by the same calls ``scipy.signal`` 1.17 makes (``scipy.linalg.lstsq`` for the coefficients and the edge
fits, ``scipy.ndimage.convolve1d`` for the interior; both modules together cost about 8 MiB), so the results
are the same floats, bit for bit (test/test_filters.py compares them with ``scipy.signal`` on random data).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lstsq
from scipy.ndimage import convolve1d

__all__ = ["first_order_lowpass", "savgol_coeffs", "savgol_filter"]


def savgol_coeffs(window_length: int, polyorder: int, deriv: int = 0, delta: float = 1.0,
                  use: str = "conv") -> np.ndarray:
    """The Savitzky-Golay filter coefficients; as ``scipy.signal.savgol_coeffs`` with ``pos=None`` for an
    odd ``window_length``."""
    if polyorder >= window_length:
        raise ValueError("polyorder must be less than window_length.")
    halflen, rem = divmod(int(window_length), 2)
    if rem != 1:
        raise ValueError(f"window_length: odd only here, got {window_length}")
    if use not in ("conv", "dot"):
        raise ValueError("`use` must be 'conv' or 'dot'")
    if deriv > polyorder:
        return np.zeros(window_length)
    x = np.arange(-halflen, window_length - halflen, dtype=np.float64)
    if use == "conv":
        x = x[::-1]
    order = np.arange(polyorder + 1, dtype=np.float64).reshape(-1, 1)
    a = x ** order
    y = np.zeros(polyorder + 1)
    y[deriv] = float(math.factorial(deriv)) / (delta ** deriv)
    coeffs, _, _, _ = lstsq(a, y, cond=np.finfo(np.float64).eps * max(a.shape))
    return coeffs


def _polyfit(x: np.ndarray, y: np.ndarray, deg: int) -> np.ndarray:
    """``scipy.signal._polyutils.polyfit`` (numpy's polyfit with full=False, w=None) for 1-D ``y``."""
    order = int(deg) + 1
    powers = np.arange(order, dtype=x.dtype)[::-1]
    lhs = x[:, None] ** powers[None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    c, _, _, _ = lstsq(lhs, y[:, None], cond=x.shape[0] * np.finfo(x.dtype).eps)
    return (c.T / scale).T


def _fit_edge(x: np.ndarray, window: tuple[int, int], interp: tuple[int, int], polyorder: int, deriv: int,
              delta: float, y: np.ndarray) -> None:
    """scipy.signal._savitzky_golay._fit_edge: fit x[window] and write the fit's values on y[interp]."""
    (start, stop), (interp_start, interp_stop) = window, interp
    p = _polyfit(np.arange(0, stop - start, dtype=x.dtype), x[start:stop], polyorder)
    if deriv > 0:        # scipy.signal._savitzky_golay._polyder
        n = p.shape[0]
        if n <= deriv:
            p = np.zeros_like(p[:1, ...])
        else:
            dp = p[:-deriv, ...].copy()
            for k in range(deriv):
                dp *= np.arange(n - k - 1, deriv - k - 1, -1, dtype=p.dtype).reshape((n - deriv, 1))
            p = dp
    i = np.arange(interp_start - start, interp_stop - start, dtype=p.dtype).reshape(-1, 1)
    values = np.zeros_like(i)
    for j in range(p.shape[0]):      # scipy.signal._polyutils.polyval
        values = values * i + p[j, ...]
    y[interp_start:interp_stop] = (values / (delta ** deriv)).reshape(-1)


def savgol_filter(x, window_length: int, polyorder: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """Savitzky-Golay filter of a 1-D array; as ``scipy.signal.savgol_filter`` with its default
    ``mode='interp'`` (the first and last ``window_length // 2`` values from a polynomial fitted to the
    first/last ``window_length`` samples)."""
    x = np.asarray(x)
    if x.dtype != np.float64 and x.dtype != np.float32:
        x = x.astype(np.float64)
    if x.ndim != 1:
        raise ValueError(f"x: 1-D only here, got shape {x.shape}")
    if window_length > x.shape[0]:
        raise ValueError("If mode is 'interp', window_length must be less than or equal to the size of x.")
    coeffs = savgol_coeffs(window_length, polyorder, deriv=deriv, delta=delta)
    y = convolve1d(x, coeffs, axis=-1, mode="constant")
    halflen = window_length // 2
    _fit_edge(x, (0, window_length), (0, halflen), polyorder, deriv, delta, y)
    n = x.shape[0]
    _fit_edge(x, (n - window_length, n), (n - halflen, n), polyorder, deriv, delta, y)
    return y


def first_order_lowpass(x, alpha: float, initial: float) -> np.ndarray:
    """y[n] = alpha x[n] + (1 - alpha) y[n-1] with y[-1] = ``initial``: the same floats as
    ``scipy.signal.lfilter([alpha], [1, alpha - 1], x, zi=[(1 - alpha) * initial])[0]`` (whose direct form II
    transposed does the same two products and one sum per sample), for finite x."""
    a = float(alpha)
    c = 1.0 - a
    prev = float(initial)
    out = []
    append = out.append
    for v in np.asarray(x, dtype=np.float64).tolist():
        prev = c * prev + a * v
        append(prev)
    return np.array(out, dtype=np.float64)
