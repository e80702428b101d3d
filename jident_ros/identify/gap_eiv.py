"""The errors-in-variables slope of the a1 fits (gap_a1: J1 from the torque m_el − b1 ω1 against the acceleration
dω1/dt, both noisy): the noise levels read off the samples, the Deming slope through the origin, its standard error
with the noise in both variables (Fuller 1987) and the term for a misread noise ratio (issue 20 item 3: "every fit's
standard error has a floor that reflects the model's own error").  Moved out of gap_a1.py in stop 46 (its 600-line
limit).  Written here rather than with scipy.odr: the slope and its variance are closed forms over three sums
(the gap stage's cost budget, 2 ms per window, calls them for every candidate row set), and the noise-ratio term is
ours.

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math

import numpy as np

from jident_ros.identify.gap_numerics import _diff2, _median

#: The a1 fits' errors-in-variables slope rests on the noise ratio (sy/sx)^2 read off the samples' second differences,
#: which assume white noise: a drive's filtered torque estimate or a band-limited accelerometer has coloured noise, and
#: that reading is off by a factor the data do not show (white noise through a first-order filter with pole 0.3 reads
#: its variance 0.63 x, with pole 0.5 0.42 x).  The slope's change with the ratio x and / this factor is the
#: 'noise_ratio' term (uniform, / sqrt 3); it is small wherever the acceleration's variation is well above its noise.
#: Chosen a priori, not on the zoo (its noise is white); test_gap_bands checks it on coloured noise (pole 0.3: 95 %
#: intervals covering 0.58-0.85 of draws without the term, 0.90-0.97 with it).
EIV_NOISE_RATIO_FACTOR = 2.0


def _robust_noise(*segments) -> float:
    """White-noise standard deviation from the second differences of the segments (1.4826 MAD / sqrt 6):
    blind to a smooth signal and to a few samples of a transient."""
    d2 = np.concatenate([_diff2(np.asarray(x, float)) for x in segments if len(x) >= 3] or [np.zeros(0)])
    if d2.size < 3:
        return 0.0
    return float(1.4826 * _median(np.abs(d2 - _median(d2))) / np.sqrt(6.0))


def _origin_slope(y: np.ndarray, x: np.ndarray, sy: float, sx: float) -> float:
    """Slope J of y = J x through the origin with errors in both variables (Deming regression with the
    error-variance ratio (sy/sx)^2); ordinary least squares of y on x when x is exact (sx = 0)."""
    sxx, syy, sxy = float(x @ x), float(y @ y), float(x @ y)
    if not sxy:
        return np.nan
    if not sx > 0:
        return sxy / sxx
    if not sy > 0:
        return syy / sxy
    d = (sy / sx) ** 2
    q = syy - d * sxx
    # The maximum-likelihood root: the numerator is positive, so the slope has the sign of x . y (an
    # anti-correlated gap gives a negative J1, which gap_only_fit refuses as non-physical).
    return (q + np.sqrt(q * q + 4.0 * d * sxy * sxy)) / (2.0 * sxy)


def _deming_se(y: np.ndarray, x: np.ndarray, j: float, sy: float, sx: float, centred: bool) -> float:
    """Standard error of :func:`_origin_slope`'s J for y = J x (``centred``: y and x are deviations from their means,
    a constant fitted beside J), with the noise in both variables (Fuller 1987, Measurement Error Models, Theorem
    1.3.1; moments about zero without the constant): V = (m_ξξ σ_vv + σ_uu σ_vv − J² σ_uu²) / (n' m_ξξ²), where
    m_ξξ = m_xy / J is the second moment of the noise-free regressor, σ_uu = sx², σ_vv the residual variance of
    y − J x and n' = n − 1 centred, n otherwise.  With an exact regressor (sx = 0) it is the least-squares
    σ_vv / Σx²; where the regressor's variation is not well above its noise (m_ξξ small against σ_uu) it is much
    wider than that, as it must be: the slope then rests on the noise ratio (sy/sx)² read off the samples (vector set
    27's s27-10 with an Imu at 30 dB: the speed step's traversal back, the motor held at speed, m_ξξ 28 % of m_xx;
    J1 2.32 against 1.19 with the least-squares 0.15, Fuller's 0.37, the jackknife's 0.35).  inf where m_ξξ is not
    positive; at least σ_vv / (n' m_ξξ)."""
    n = x.size
    n_m = n - 1 if centred else n
    dof = n - 2 if centred else n - 1
    if dof < 1 or not (math.isfinite(j) and j > 0):
        return np.inf
    m_xi = float(x @ y) / n_m / j
    if not m_xi > 0:
        return np.inf
    res = y - j * x
    s_vv = float(res @ res) / dof
    s_uu = sx * sx
    # σ_vv = σ_ee + J² σ_uu in expectation, so the last two terms add σ_uu σ_ee >= 0; where the sample's residual
    # variance falls short of J² σ_uu they would subtract: the first term alone then (never below least squares' form)
    v = max((m_xi * s_vv + s_uu * s_vv - j * j * s_uu * s_uu) / (n_m * m_xi * m_xi), s_vv / (n_m * m_xi))
    return float(np.sqrt(v))


def _noise_ratio_term(y: np.ndarray, x: np.ndarray, j: float, sy: float, sx: float) -> float:
    """The 'noise_ratio' term of :func:`_origin_slope`'s J (EIV_NOISE_RATIO_FACTOR): the largest change of J with the
    ratio (sy/sx)^2 x or / the factor, / sqrt 3; 0 where either variable is exact (sy or sx 0)."""
    if not (sx > 0 and sy > 0 and EIV_NOISE_RATIO_FACTOR > 1):
        return 0.0
    f = math.sqrt(EIV_NOISE_RATIO_FACTOR)
    moved = [_origin_slope(y, x, sy * g, sx) for g in (f, 1.0 / f)]
    return max((abs(m - j) if math.isfinite(m) else np.inf) for m in moved) / math.sqrt(3.0)
