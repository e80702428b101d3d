"""The backlash zone's width from the relative angle at the re-contact (docs/method.md, "Backlash width"; "Beyond the
paper", item 2): :func:`estimate_backlash_width`, the contact-torque fit or the sample bracket.  Moved out of gap.py
(its 600-line limit); the numbers are the same.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jident_ros.identify.gap_types import NoGapError

#: Contact-torque width fit: samples after the first contact sample that it uses, and the
#: factor by which its standard error must beat the sample bracket's to be preferred.
CONTACT_FIT_SAMPLES = 6
CONTACT_FIT_PREFERENCE = 3.0
#: Relative floor of the contact fit's standard error (its model is a linear spring-damper).
CONTACT_FIT_REL_FLOOR = 1e-3


@dataclass(frozen=True)
class WidthEstimate:
    """Backlash zone width at the wheel circumference, m, with its standard uncertainty.

    method: 'contact' (the clutch-torque fit after re-contact) or 'bracket' (the midpoint of
    the relative angles of the last gap sample and the first contact sample)."""

    width_m: float
    std_m: float
    recontact_index: int
    method: str = "bracket"


def estimate_backlash_width(window: dict, gap_end: int, wheel_radius_m: float, sample_period_s: float | None = None,
                            inertia_kgm2: float | None = None) -> WidthEstimate:
    """Width from the relative angle at re-contact.

    The flanks meet where |alpha1 - alpha2| (measured from the zone centre, the
    reading of inequality 1) reaches K2/r, somewhere between the last gap sample
    and the first contact sample.

    * 'bracket': the contact instant taken uniformly distributed in that sample
      interval: width = r (|d_last| + |d_first|)/2, standard uncertainty
      r (|d_first| - |d_last|)/sqrt(12).  Needs only the angles.
    * 'contact' (with a1, m_el, the sample period and the gap's J1): after re-contact
      the clutch torque on the motor side is T_c = J1 ((r/J1) m_el - a1)/r ∝ (r/J1) m_el - a1,
      and a clutch in contact is a spring-damper, T_c = k_c (d - K2/r) + c_c d', with d the
      relative angle and d' its rate (central differences).  Regressing (r/J1) m_el - a1
      on (d, d', 1) over CONTACT_FIT_SAMPLES samples from the second contact sample on
      (the first may hold the impact's transition) gives K2/r = -intercept/slope without
      knowing k_c or c_c.  Used when it falls inside the bracket and its standard error
      (delta method, floored at CONTACT_FIT_REL_FLOOR) is CONTACT_FIT_PREFERENCE times
      smaller than the bracket's; else the bracket answer (docs/method.md, "Backlash width").
    """
    if "alpha1" not in window or "alpha2" not in window:
        raise NoGapError("backlash width: needs both angles alpha1 and alpha2")
    signed = np.asarray(window["alpha1"], float) - np.asarray(window["alpha2"], float)
    rel = np.abs(signed)
    if not 1 <= gap_end < rel.size:
        raise NoGapError(f"backlash width: no re-contact inside the window (gap end {gap_end})")
    a, b = rel[gap_end - 1], rel[gap_end]
    # the flank met: +1 for delta = +K2/r, -1 for -K2/r (reverse rotation).  The clutch torque on the
    # motor side, (r/J1) m_el - a1, has the flank's sign; times it, it grows with the penetration |delta|
    # - K2/r on either flank (without it the fit's slope was negative in reverse and the coarse bracket
    # was used: issue 12)
    side = 1.0 if signed[gap_end] >= 0 else -1.0
    mid, s_mid = 0.5 * (a + b), abs(b - a) / np.sqrt(12.0)
    post = np.arange(gap_end + 1, gap_end + 1 + CONTACT_FIT_SAMPLES)
    if ("a1" in window and "m_el" in window and sample_period_s and inertia_kgm2 and inertia_kgm2 > 0
            and post[-1] + 1 < rel.size):
        kappa = wheel_radius_m / inertia_kgm2
        drop = side * (kappa * np.asarray(window["m_el"], float)[post] - np.asarray(window["a1"], float)[post])
        rate = (rel[post + 1] - rel[post - 1]) / (2.0 * sample_period_s)
        A = np.column_stack([rel[post], rate, np.ones(post.size)])
        coef, *_ = np.linalg.lstsq(A, drop, rcond=None)
        if coef[0] > 0:
            theta = -coef[2] / coef[0]
            res = drop - A @ coef
            cov = float(res @ res) / (post.size - 3) * np.linalg.pinv(A.T @ A)
            grad = np.array([coef[2] / coef[0] ** 2, 0.0, -1.0 / coef[0]])
            s_fit = float(np.hypot(np.sqrt(max(grad @ cov @ grad, 0.0)), CONTACT_FIT_REL_FLOOR * theta))
            if min(a, b) <= theta <= max(a, b) and CONTACT_FIT_PREFERENCE * s_fit < s_mid:
                return WidthEstimate(float(wheel_radius_m * theta), float(wheel_radius_m * s_fit), int(gap_end),
                                     "contact")
    return WidthEstimate(float(wheel_radius_m * mid), float(wheel_radius_m * s_mid), int(gap_end), "bracket")
