"""The model choice's steadiness test (issue 20, the 'auto' fit of gap.py): whether the drive's torque is steady
before the entry, the joint ('acceleration') fit's premise, by an F test of a quadratic in time against a constant
on the pre-entry m_el samples (:func:`pre_entry_steady`; docs/method.md, "The model choice").  The steady-entry angle
fit (gap_angle.py) tests its own pre-entry samples with it too.  Moved out of gap.py (its 600-line limit); the numbers
are the same.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from jident_ros.identify import lapack
from jident_ros.identify.distributions import f_survival
from jident_ros.identify.gap_numerics import _memoised

#: Model choice ('auto'): the pre-entry m_el is steady unless a quadratic in time explains it better
#: than a constant at this significance (F test); then the joint fit's anchoring is not used.
STEADY_P_VALUE = 1e-3
#: ... and the fitted slope and curvature move it by more than this fraction of its level over the
#: pre-entry samples (a practical significance: noise-free windows have no noise to compare with; our
#: simulator's steady state still drifts by 3-6e-6 of the load, far below what biases the joint fit).
STEADY_REL_TOL = 1e-4


@dataclass(frozen=True)
class SteadinessTest:
    """Whether the torque before the entry is steady (the joint fit's assumption), :func:`pre_entry_steady`.

    steady : bool          use the joint fit
    f_statistic : float    F of a quadratic in time against a constant (slope and curvature); 0 for a
                           constant to rounding, inf for an exact non-constant quadratic
    p_value : float        its upper tail probability (F with 2 and n - 3 degrees of freedom)
    n_samples : int        pre-entry samples tested
    reason : str           why not steady ('' when steady)
    """

    steady: bool
    f_statistic: float
    p_value: float
    n_samples: int
    reason: str = ""

    def describe(self) -> str:
        """One phrase for GapEstimate.model_choice and the status."""
        if self.steady:
            return (f"acceleration: pre-entry m_el steady (F = {self.f_statistic:.3g}, p = {self.p_value:.3g} over "
                    f"{self.n_samples} samples)")
        return f"gap_only: {self.reason}"


@lru_cache(maxsize=16)
def _steady_design(n: int) -> np.ndarray:
    """The steadiness test's design (1, t, t²), t from -1 to 1 over n samples (read-only: shared by every call; 16
    lengths kept, 24 bytes a sample each: < 1 MB for windows of 2000 samples)."""
    tt = np.linspace(-1.0, 1.0, n)
    A = np.column_stack([np.ones(n), tt, tt * tt])
    A.flags.writeable = False
    return A


@_memoised
def pre_entry_steady(m_el_pre, p_value: float = STEADY_P_VALUE) -> SteadinessTest:
    """Test the joint fit's assumption on the pre-entry m_el samples: a steady torque, m_el = m0 + white
    noise.  Regress m_el on (1, t, t^2); not steady when the slope and curvature explain more than the noise
    would (F test with 2 and n - 3 degrees of freedom, p < ``p_value``) and move it by more than
    STEADY_REL_TOL of its level (so a noise-free window, with no noise to compare with, is steady when
    its trend stays below that).  Fewer than 6 samples:
    not steady (untestable, so the joint fit's anchoring is not used)."""
    x = np.asarray(m_el_pre, float)
    n = x.size
    if n < 6:
        return SteadinessTest(False, np.nan, np.nan, n, f"{n} pre-entry samples, too few to test a steady torque")
    scale = max(float(np.maximum.reduce(np.abs(x), axis=None)), 1e-300)      # np.max's reduction
    A = _steady_design(n)
    coef = lapack.lstsq(A, x)
    # np.sum and np.mean's own reductions (np.add.reduce over the array; the mean divided by the count)
    rss0 = float(np.add.reduce((x - np.add.reduce(x) / n) ** 2))
    rss2 = float(np.add.reduce((x - A @ coef) ** 2))
    if rss2 <= (1e-12 * scale) ** 2 * n:               # an exact polynomial, no noise to compare with
        f, p = (0.0, 1.0) if rss0 <= (1e-12 * scale) ** 2 * n else (np.inf, 0.0)
    else:
        f = max((rss0 - rss2) / 2.0 / (rss2 / (n - 3)), 0.0)
        p = f_survival(f, 2, n - 3)
    trend = A[:, 1:] @ coef[1:]
    # np.ptp's reductions: slope and curvature move it by next to nothing
    if np.maximum.reduce(trend, axis=None) - np.minimum.reduce(trend, axis=None) <= STEADY_REL_TOL * scale:
        return SteadinessTest(True, float(f), p, n)
    if p < p_value:
        return SteadinessTest(False, float(f), p, n,
                              f"pre-entry m_el not steady: slope and curvature over {n} samples, F = {f:.3g}, "
                              f"p = {p:.2g} < {p_value:g} (range {np.ptp(x):.4g} N m)")
    return SteadinessTest(True, float(f), p, n)
