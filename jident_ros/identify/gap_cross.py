"""The cross-check of a window's two fits (issue 20; the model choice with a1 and α1, gap._cross_checked): the
standard error of their difference (:func:`_difference_se`: the torque terms both fits share taken as a difference,
not in quadrature), the z above which they disagree (:data:`CROSS_CHECK_Z`, the steady-entry angle fit's check of the
free fit too), and which fit the trend reads (:func:`_trend_choice`: the smaller standard error without the drive's
constant terms, :func:`within_drive_se`).  Moved out of gap.py (its 600-line limit); the numbers are the same.
Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.gap_types import GapEstimate

#: Cross-check of two fits of one window (a1 and the motor angle): they disagree when their J1 differ by more
#: than this many combined standard errors (without the torque-accuracy term, which both share).  Read as
#: gap_cross.CROSS_CHECK_Z by gap._cross_checked and by gap_angle._anchored_angle (the steady-entry fit against the
#: free fit), so that one patch here reaches both.
CROSS_CHECK_Z = 3.0


def _stat_se(g: GapEstimate, model: GapModel) -> float:
    return float(np.sqrt(max(g.std_error_kgm2 ** 2 - (g.inertia_kgm2 * model.torque_rel_se()) ** 2, 0.0)))


#: The bounded terms of the torque both fits of a window read (a constant torque beside m_el: friction, the
#: estimate's offset; the estimate's lag): one such error moves both J1 the same way (the same m_el over overlapping
#: rows), so their difference by the difference of the two terms, not by their sum in quadrature.  Taken in
#: quadrature, a friction band of 3 % of M_b (tried as the typical drive's in stop 31) and the typical 1 ms lag let the
#: second drive's a1 fit, 25 % off, pass at 2.9 standard errors (scripts/golden.py, second_drive_signals: the a1 fit's
#: lag term 0.049, the angle fit's 0.046 kg m^2); as their difference, 4.5: refused.
COMMON_TORQUE_TERMS = ("coulomb_band", "viscous_band", "torque_offset", "torque_lag", "torque_lag_seen")


def _difference_se(a: GapEstimate, b: GapEstimate, model: GapModel) -> float:
    """The standard error of J1_a − J1_b of two fits of one window: each without the torque-accuracy term (both
    share it), the :data:`COMMON_TORQUE_TERMS` as their difference, the other terms in quadrature."""
    ta, tb = dict(a.std_error_terms), dict(b.std_error_terms)
    common = [k for k in COMMON_TORQUE_TERMS if k in ta and k in tb]
    var = _stat_se(a, model) ** 2 + _stat_se(b, model) ** 2
    var -= sum(float(ta[k]) ** 2 + float(tb[k]) ** 2 for k in common)
    var += sum((float(ta[k]) - float(tb[k])) ** 2 for k in common)
    return float(np.sqrt(max(var, 0.0)))


#: The parts of a gap J1's standard error (``GapEstimate.std_error_terms``) that are constants of the drive, not of
#: the window: the torque estimate's scale error ('torque_accuracy'), its bounded offset ('torque_offset') and lag
#: ('torque_lag', and 'torque_lag_seen': the lag the angle shows beyond the declared one), and the Coulomb band
#: ('coulomb_band': the drive's friction).  Each moves the drive's J1 estimates alike (the same window shape, the same
#: bias) and cancels in J1 relative to the drive's own baseline (the trend: trend_status).
DRIVE_CONSTANT_TERMS = ("torque_accuracy", "torque_offset", "torque_lag", "torque_lag_seen", "coulomb_band")


def within_drive_se(se: float, std_error_terms) -> float:
    """``se`` (kg m^2) without the :data:`DRIVE_CONSTANT_TERMS` among ``std_error_terms`` ((term, kg m^2), ...), in
    quadrature: what scatters from window to window of one drive; ``se`` itself where they are all of it."""
    terms = dict(std_error_terms or ())
    common = 0.0
    for name in DRIVE_CONSTANT_TERMS:
        v = terms.get(name, 0.0)
        if v and math.isfinite(float(v)) and float(v) > 0.0:
            common += float(v) ** 2
    if 0.0 < common < float(se) ** 2:
        return math.sqrt(float(se) ** 2 - common)
    return float(se)


def _trend_choice(best: GapEstimate, other: GapEstimate) -> GapEstimate:
    """``best`` (the cross-check's published fit) with the trend's fit (GapEstimate.trend_fit) the other's where that
    one's standard error without the drive's constant terms (:func:`within_drive_se`) is the smaller: the a1 fit's
    Coulomb band term (first order, F Σx/Σx²) is larger than the angle fit's and can make it lose the publication,
    while its J1 scatters less from window to window."""
    mine = best.trend_fit or (best.inertia_kgm2, best.std_error_kgm2, best.std_error_terms)
    theirs = other.trend_fit or (other.inertia_kgm2, other.std_error_kgm2, other.std_error_terms)
    if within_drive_se(theirs[1], theirs[2]) < within_drive_se(mine[1], mine[2]):
        return replace(best, trend_fit=tuple(theirs))
    return best
