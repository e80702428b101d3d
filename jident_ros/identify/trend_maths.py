"""The statistics of the trend tracker (:mod:`jident_ros.identify.trend`): the CUSUM's design (its average run
length from the integral equation, Siegmund's approximation, the threshold for a target ARL), the two-sided
CUSUM itself, and the robust (Huber) inverse-variance weighted means of the baselines.  Pure numpy/scipy.
Equations and the false-alarm rates: ``docs/trend.md``.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.special import ndtri, stdtr

from jident_ros.identify.distributions import normal_cdf, normal_pdf, normal_ppf, normal_sf

#: Siegmund's correction of the threshold for the overshoot: b = h + 2 * 0.583 (unit-variance increments).
SIEGMUND_OVERSHOOT = 1.166


def siegmund_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0) -> float:
    """Average run length (windows) of a one-sided upper CUSUM S = max(0, S + z - k) > h whose
    increments z are N(shift, 1): Siegmund's approximation
    ARL = (exp(-2 D b) + 2 D b - 1) / (2 D^2), D = shift - k, b = h + 1.166 (b^2 when D = 0)."""
    d = shift_sd - reference_sd
    b = threshold_sd + SIEGMUND_OVERSHOOT
    if abs(d) < 1e-9:
        return b * b
    return (math.exp(-2.0 * d * b) + 2.0 * d * b - 1.0) / (2.0 * d * d)


def two_sided_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0) -> float:
    """ARL of the two-sided CUSUM (upper and lower, same k and h): 1/ARL = 1/ARL+ + 1/ARL-."""
    return 1.0 / (1.0 / siegmund_arl(threshold_sd, reference_sd, shift_sd)
                  + 1.0 / siegmund_arl(threshold_sd, reference_sd, -shift_sd))


def cusum_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0, sd: float = 1.0,
              two_sided: bool = True, nodes: int = 64) -> float:
    """Average run length of the CUSUM whose increments are N(shift, sd^2), from the integral equation
    L(u) = 1 + L(0) P(z <= k - u) + int_0^h L(x) f(x + k - u) dx (Page; Brook & Evans' continuous form),
    solved by Nystrom's method on ``nodes`` Gauss-Legendre points: exact up to the quadrature (the
    clipping of the increments at +-innovation_clip_sd is neglected).  Two-sided: 1/ARL = 1/ARL+ + 1/ARL-."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x = 0.5 * threshold_sd * (x + 1.0)
    w = 0.5 * threshold_sd * w
    u = np.concatenate(([0.0], x))

    def one(mu):
        arg = (x[None, :] + reference_sd - u[:, None] - mu) / sd
        A = np.zeros((nodes + 1, nodes + 1))
        A[:, 0] = -normal_cdf((reference_sd - u - mu) / sd)
        A[:, 1:] = -w[None, :] * normal_pdf(arg) / sd
        A[np.arange(nodes + 1), np.arange(nodes + 1)] += 1.0
        return float(np.linalg.solve(A, np.ones(nodes + 1))[0])

    up = one(shift_sd)
    if not two_sided:
        return up
    return 1.0 / (1.0 / up + 1.0 / one(-shift_sd))


@functools.lru_cache(maxsize=64)
def cusum_threshold_for_arl(arl_windows: float, reference_sd: float, two_sided: bool = True,
                            method: str = "integral") -> float:
    """The threshold h (in standard deviations) whose in-control ARL (N(0, 1) increments) is
    ``arl_windows`` windows: ``method="integral"`` (default) from :func:`cusum_arl`, ``"siegmund"``
    from Siegmund's closed form (which overestimates the ARL for large k: at k = 2 by ~1.7x at 2e4)."""
    if not arl_windows > 1.0:
        raise ValueError(f"arl_windows: must be > 1, got {arl_windows!r}")
    if method == "siegmund":
        arl = lambda h: two_sided_arl(h, reference_sd) if two_sided else siegmund_arl(h, reference_sd)  # noqa: E731
        hi = min(1.0e4, 340.0 / reference_sd)      # keeps exp(2 k b) finite
    elif method == "integral":
        arl = lambda h: cusum_arl(h, reference_sd, two_sided=two_sided)  # noqa: E731
        hi = cusum_threshold_for_arl(arl_windows, reference_sd, two_sided, "siegmund") + 5.0
    else:
        raise ValueError(f"method: 'integral' or 'siegmund', got {method!r}")
    f = lambda h: math.log(arl(h)) - math.log(arl_windows)  # noqa: E731
    # imported here: scipy.optimize costs ~14 MiB of a node's memory and is needed once per threshold design
    from scipy.optimize import brentq
    return float(brentq(f, 1e-6, hi, xtol=1e-9))


def t_normal_score(z: float, dof: float) -> float:
    """The standard normal quantile of a Student-t variate: Φ⁻¹(T_dof(z)), computed from the tail on z's side
    (exact far out; ±inf when the t tail underflows, which the caller clips).  A t_dof variate becomes exactly
    N(0, 1): the CUSUM's N(0, 1) design holds for standardised innovations whose scale is itself estimated."""
    if z >= 0.0:
        return -float(ndtri(stdtr(dof, -z)))
    return float(ndtri(stdtr(dof, z)))


def coverage_to_se_scale(coverage: float) -> float:
    """True standard deviation / reported standard error for which the reported 95 % interval
    (+-1.96 se) covers the truth with probability ``coverage`` (Gaussian errors)."""
    return float(normal_ppf(0.975) / normal_ppf(0.5 + coverage / 2.0))



class Cusum:
    """Two-sided CUSUM on clipped standardised innovations; remembers the onset of each excursion."""

    __slots__ = ("pos", "neg", "pos_start", "neg_start")

    def __init__(self):
        self.reset(0)

    def reset(self, next_index: int):
        self.pos = self.neg = 0.0
        self.pos_start = self.neg_start = next_index

    def step(self, z: float, k: float, h: float, index: int) -> int:
        p = self.pos + z - k
        if p <= 0.0:
            p = 0.0
            self.pos_start = index + 1
        n = self.neg - z - k
        if n <= 0.0:
            n = 0.0
            self.neg_start = index + 1
        self.pos, self.neg = p, n
        if p > h or n > h:
            return 1 if p >= n else -1
        return 0

    @property
    def stat(self) -> float:
        return self.pos if self.pos >= self.neg else self.neg

    def to_list(self):
        return [self.pos, self.neg, self.pos_start, self.neg_start]

    @classmethod
    def from_list(cls, v):
        c = cls()
        c.pos, c.neg = float(v[0]), float(v[1])
        c.pos_start, c.neg_start = int(v[2]), int(v[3])
        return c


def weighted_mean(points) -> tuple[float, float, float]:
    """Weighted mean of (index, t, y, se) points: (mean, 1/sum w, chi^2 about the mean)."""
    sw = swy = 0.0
    for p in points:
        w = 1.0 / (p[3] * p[3])
        sw += w
        swy += w * p[2]
    m = swy / sw
    c2 = 0.0
    for p in points:
        r = (p[2] - m) / p[3]
        c2 += r * r
    return m, 1.0 / sw, c2


#: The commissioning scatter scales the reported standard errors only when significant at this level.
SE_SCALE_TEST_LEVEL = 0.99
#: Huber's tuning constant (standardised residuals) for the robust baseline means and the se-scale estimate.
HUBER_C = 2.5
#: E[min(Z^2, c^2)] for Z ~ N(0, 1): consistency of Huber's proposal-2 scale.
_HUBER_KAPPA = float((2 * normal_cdf(HUBER_C) - 1) - 2 * HUBER_C * normal_pdf(HUBER_C)
                     + 2 * HUBER_C ** 2 * normal_sf(HUBER_C))


def m_scale(r: np.ndarray, dof_factor: float = 1.0) -> float:
    """Robust scale of standardised residuals r (Huber's proposal 2, started from the MAD): ~1 when
    the reported standard errors are right, insensitive to a few outliers."""
    r = np.asarray(r, dtype=float)
    if not np.any(r):
        return 0.0
    s = 1.4826 * float(np.median(np.abs(r)))
    if not s > 0.0:
        s = math.sqrt(float(np.mean(r * r))) or 1.0
    for _ in range(50):
        s_new = s * math.sqrt(float(np.mean(np.minimum((r / s) ** 2, HUBER_C ** 2))) / _HUBER_KAPPA * dof_factor)
        if abs(s_new - s) <= 1e-10 * s:
            break
        s = s_new
    return s


def huber_mean(points, estimate_scale: bool = False) -> tuple[float, float, float]:
    """Huber M-estimate of the level of (index, t, y, se) points.  Returns (mean, 1 / sum(1/se^2),
    scale) where scale is the robust scale of the standardised residuals when ``estimate_scale``
    (else 1): one outlier moves the mean by at most ~HUBER_C * se / n."""
    y = np.array([p[2] for p in points])
    se = np.array([p[3] for p in points])
    w0 = 1.0 / (se * se)
    n = y.size
    m = float(np.median(y)) if n > 2 else float(w0 @ y / w0.sum())
    s = 1.0
    for _ in range(50):
        r = (y - m) / se
        if estimate_scale and n > 2:
            s = m_scale(r, n / (n - 1.0))
        a = np.abs(r) / max(s, 1e-300)
        wt = w0 * np.minimum(1.0, HUBER_C / np.maximum(a, 1e-300))
        m_new = float(wt @ y / wt.sum())
        if abs(m_new - m) <= 1e-13 * max(abs(m), 1e-300):
            m = m_new
            break
        m = m_new
    return m, 1.0 / float(w0.sum()), s
