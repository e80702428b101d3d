"""The distribution functions the runtime needs, from ``scipy.special`` instead of ``scipy.stats``.

``scipy.stats``' generic distribution methods check and broadcast their arguments on every call:
``stats.f.sf`` costs ~210 us and ``stats.t.ppf`` ~260 us a call here, for two numbers that ``scipy.stats`` itself
takes from ``scipy.special`` (``t._ppf`` is ``stdtrit``, ``f._sf`` is ``fdtrc``), which cost 3-6 us.  And
``import scipy.stats`` costs ~40 MiB of resident memory (it imports ``scipy.optimize``, ``interpolate`` and
``spatial``), a third of the diagnostic node's (issue 25).  Each function here returns the same float as the
``scipy.stats`` call it names, bit for bit: it is the ``scipy.special`` function that ``scipy.stats`` 1.17 calls
(``_norm_cdf`` is ``ndtr``, ``_norm_ppf`` is ``ndtri``, ``_norm_isf`` is ``-ndtri``, ``chi2._ppf`` is
``2 gammaincinv(df/2, q)``), with loc 0 and scale 1 (test_distributions.py compares them with ``scipy.stats``).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.special import fdtrc, gammaincinv, ndtr, ndtri, stdtrit

_SQRT_2PI = float(np.sqrt(2 * np.pi))      # scipy.stats' _norm_pdf_C


def t_quantile(q: float, dof: float) -> float:
    """Student t quantile: the x with P(T <= x) = q for T ~ t(dof); as ``scipy.stats.t.ppf(q, dof)``
    for 0 < q < 1 and dof > 0."""
    return float(stdtrit(dof, q))


def f_survival(x: float, dfn: float, dfd: float) -> float:
    """Survival function P(F > x) of the F(dfn, dfd) distribution; as ``scipy.stats.f.sf(x, dfn, dfd)``
    for x >= 0 and dfn, dfd > 0."""
    return float(fdtrc(dfn, dfd, x))


def normal_cdf(x):
    """Standard normal P(Z <= x); as ``scipy.stats.norm.cdf(x)`` (scalar or array)."""
    return ndtr(x)


def normal_sf(x):
    """Standard normal P(Z > x); as ``scipy.stats.norm.sf(x)``."""
    return ndtr(np.negative(x))


def normal_pdf(x):
    """Standard normal density; as ``scipy.stats.norm.pdf(x)``."""
    x = np.asarray(x, dtype=float)
    return np.exp(-x ** 2 / 2.0) / _SQRT_2PI


def normal_ppf(q):
    """Standard normal quantile: the x with P(Z <= x) = q; as ``scipy.stats.norm.ppf(q)`` for 0 < q < 1."""
    return ndtri(q)


def normal_isf(q):
    """The x with P(Z > x) = q; as ``scipy.stats.norm.isf(q)`` for 0 < q < 1."""
    return -ndtri(q)


def chi2_ppf(q: float, dof: float) -> float:
    """χ² quantile: the x with P(X <= x) = q for X ~ χ²(dof); as ``scipy.stats.chi2.ppf(q, dof)`` for
    0 < q < 1 and dof > 0."""
    if not (0.0 < q < 1.0 and dof > 0 and math.isfinite(dof)):
        raise ValueError(f"chi2_ppf: need 0 < q < 1 and dof > 0, got q={q!r}, dof={dof!r}")
    return float(2 * gammaincinv(dof / 2, q))
