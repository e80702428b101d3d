"""When a gap fit's J1 at or below zero says the drive's signs are wrong, and when only that the window cannot
resolve J1 (issue 20: "a WARN must mean something"; an ERROR naming the sign of m_el on a healthy drive is a false
alarm).  One home for the decision of both fits that can turn negative: the free angle fit
(:func:`jident_ros.identify.gap_free.free_angle_fit`, 1/J1 from the angle's curvature against the torque's double
integral) and the a1 fit (:func:`jident_ros.identify.gap_a1.gap_only_fit`, J1 from the torque against the
acceleration).  A negative J1 is "non-physical" (ERROR, what to check) only when

* it lies beyond NONPHYSICAL_Z of its own standard errors below zero,
* and, for the a1 fit, m_el and a1 are anti-correlated about their means too (NONPHYSICAL_CENTRED: a constant torque
  the fit does not hold turns the slope through the origin only),
* and, for the a1 fit, over the middle half of its rows too (NONPHYSICAL_MIDDLE: contact rows at the ends of a
  misplaced interval anti-correlate them),
* and the torque errors the drive declares cannot turn it (NONPHYSICAL_BEYOND_DECLARED): an error e(t) of the
  torque estimate moves the fit's 1/J1 to 1/J1 (1 − x(e)), x linear in e; where the declared errors at their bounds
  reach x >= 1 the estimate's error alone can curve the angle (or tilt a1) against m_el on a drive whose signs are
  right (the vector drive's light load reversals: 2-4 N m of gap torque against an estimate off by up to 3 % of
  M_b, 6 N m, that moves with the slip).

Otherwise "gap fit undetermined" (resolution-limited: OK, nothing published).  Moved here from gap_free.py and
gap_a1.py in stop 43 (their 600-line limit).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math

import numpy as np

#: A fit's J1 at or below zero within this many of its standard errors of zero: the gap's torque does not curve the
#: angle (or accelerate the motor) measurably (resolution-limited, no J1 from the window); farther below, the fit
#: runs against the torque (a sign or configuration problem). 3, the cross-check's and the friction band's z (no model
#: was tuned on it).
NONPHYSICAL_Z = 3.0

#: A 'gap_only' J1 at or below zero from m_el and a1 anti-correlated through the origin is "non-physical" only when
#: they are anti-correlated about their means too: a constant torque the fit does not hold (the motor's Coulomb
#: friction, the estimate's offset) larger than the gap's own torque turns the slope through the origin negative while
#: the torque's swing still accelerates the motor the right way (vector draws' light load reversals, Imu, 30 dB: 44
#: ERROR windows over sets 1-20, "check the sign of m_el", on drives whose signs are right), whereas a sign error
#: turns both.  Then it is "gap fit undetermined" -- not tuned: NONPHYSICAL_Z about the means.  False: through the
#: origin only (stop 42).
NONPHYSICAL_CENTRED = True

#: A J1 below zero (beyond NONPHYSICAL_Z) is "non-physical" only where the torque errors the drive declares cannot
#: turn it (the module docstring's x < 1 at their bounds, all one way: the offset torque_offset_rel_base and its
#: drift, the friction bands where not fitted, the lag bound torque_lag_max_s).  1: where the first-order move
#: 1/J1 (1 − x) reaches zero, not a tuned value (the vector draws' ERROR windows on light load reversals, 42 sets,
#: had x = 3.6-17 for the angle fit).  False: the literal check (the fit's own standard error alone, stop 42).
NONPHYSICAL_BEYOND_DECLARED = True

#: A 'gap_only' J1 below zero is "non-physical" only when m_el and a1 are anti-correlated (about their means, beyond
#: NONPHYSICAL_Z) over the middle half of the fitted rows too: contact rows at the ends of a misplaced interval (the
#: speed controller's torque against the load's push) anti-correlate them on a healthy drive -- the vector draws' heavy
#: and light load reversals with an Imu at 30 dB, 7 ERROR windows over 22 sets, each with the middle half's t between
#: +0.4 and +5.7 and m_el up to 370 N m in the fitted rows -- whereas a sign error turns the gap's own torque, which
#: the middle rows hold.  Half: the rows farthest from both change points, not tuned.  False: the rows as fitted.
NONPHYSICAL_MIDDLE = True

_SIGN_CHECK = "check the sign of m_el against"
_LATE = "or a torque estimate smoothed or late beyond torque_lag_max_s"


def _turned(flip: float, n: int, what: str) -> str:
    return (f"gap fit undetermined: {what} over the gap's {n} rows, but the torque errors the drive declares "
            f"(torque_offset_rel_base, its drift, the friction bands, torque_lag_max_s) can move it by {flip:.3g} x "
            "its value: the gap's torque is too small against them to tell a sign")


def _within_resolution(kappa: float, se: float, n: int, flip: float, what: str, effect: str) -> str | None:
    """The reason where a fit's non-positive ``kappa`` (``what``: its phrase, ``effect``: what the torque does not do
    measurably) is this window's resolution -- within NONPHYSICAL_Z standard errors ``se`` of zero, or turned by the
    declared errors (``flip`` >= 1) -- else None (a sign to check)."""
    if np.isfinite(kappa) and kappa >= -NONPHYSICAL_Z * se:
        return (f"gap fit undetermined: {what}, not distinguishable from 0: the gap's torque does not {effect} "
                f"measurably over its {n} rows")
    if NONPHYSICAL_BEYOND_DECLARED and flip >= 1.0:
        return _turned(flip, n, what)
    return None


def no_positive_kappa(kappa: float, se: float, n: int, flip: float = 0.0) -> str:
    """The reason of a free angle fit without a positive 1/J1 ``kappa`` (± ``se``, its statistical standard error,
    over ``n`` rows; ``flip``: x of the declared errors at their bounds, gap_free's ``_SpanFits.declared_flip``)."""
    what = f"1/J1 = {kappa:.3g} ± {se:.2g} 1/(kg m^2) from alpha1"
    return _within_resolution(kappa, se, n, flip, what, "curve the angle") or (
        f"gap fit gave a non-physical 1/J1 = {kappa:.3g} ± {se:.2g} 1/(kg m^2) from alpha1 (the angle curves "
        f"against the torque's double integral over the gap: {_SIGN_CHECK} alpha1, the joint names and gear_ratio, "
        f"{_LATE})")


def no_positive_ratio(kappa: float, se: float, n: int, flip: float = 0.0) -> str:
    """The reason of a joint a1 fit ('acceleration', gap_a1._joint_fit) without a positive ratio ``kappa`` = a1/m_el
    (± ``se``, its standard error, over the gap's ``n`` rows; ``flip``: :func:`slope_flip` of the gap's torque): as
    :func:`no_positive_kappa` -- within NONPHYSICAL_Z standard errors of zero, or turned by the declared errors, the
    window does not resolve J1 (vector set 22's s22-11, a light load reversal with an Imu at 30 dB: a1/m_el -0.009,
    an ERROR naming the signs on a healthy drive before stop 46); beyond, the signs are to check."""
    what = f"a1/m_el = {kappa:.3g} ± {se:.2g} from the joint fit"
    # an infinite standard error tells nothing here (as before the helper: only a finite one makes it undetermined)
    return _within_resolution(kappa, se if np.isfinite(se) else np.nan, n, flip, what, "accelerate the motor") or (
        f"gap fit gave a non-physical a1/m_el ratio {kappa:.4g} ± {se:.2g} (the motor accelerates against the "
        f"torque over the gap: {_SIGN_CHECK} a1 and the joint names, {_LATE})")


def correlation_t(x: np.ndarray, y: np.ndarray) -> float:
    """The t statistic of the correlation of x and y through the origin (their sums of squares and products)."""
    n = y.size
    sxx, syy, sxy = float(x @ x), float(y @ y), float(x @ y)
    r = sxy / np.sqrt(sxx * syy) if sxx > 0 and syy > 0 else 0.0
    return r * np.sqrt(max(n - 1, 1)) / np.sqrt(max(1.0 - r * r, 1e-12))


def slope_flip(torque: np.ndarray, sample_period_s: float, offset_nm: float, lag_s: float) -> float:
    """The a1 fit's x at the declared errors' bounds: the slope of a1 on the centred torque moves by
    −cov(e, m)/var(m) of itself for a torque error e; a drift across the rows from −offset_nm to +offset_nm (a constant
    offset drops out about the means) and a lag τ <= lag_s (e ≈ τ dm/dt), summed.  0 without a declaration."""
    m = np.asarray(torque, float)
    if m.size < 3 or not (offset_nm or lag_s):
        return 0.0
    mc = m - m.mean()
    var = float(mc @ mc)
    if not var > 0:
        return math.inf
    ramp = np.linspace(-1.0, 1.0, m.size)
    x = abs(float(mc @ ramp)) * float(offset_nm) / var
    if lag_s:
        x += abs(float(mc @ np.gradient(m, float(sample_period_s)))) * float(lag_s) / var
    return x


def nonpositive_slope(j: float, torque: np.ndarray, acc: np.ndarray, flip: float = 0.0) -> str:
    """The reason of a 'gap_only' J1 ``j`` at or below zero (``torque``, ``acc``: the fitted rows; ``flip``:
    :func:`slope_flip`): "gap fit undetermined" (resolution-limited) when the torque and the acceleration are not
    correlated beyond NONPHYSICAL_Z (the t statistic of their correlation through the origin), or not about their
    means (NONPHYSICAL_CENTRED), or not over the middle half of the rows (NONPHYSICAL_MIDDLE), or the declared errors
    can turn them (NONPHYSICAL_BEYOND_DECLARED), else
    "non-physical" with what to check."""
    y, x = np.asarray(torque, float), np.asarray(acc, float)
    n = y.size
    t = correlation_t(x, y)
    if math.isfinite(t) and t >= -NONPHYSICAL_Z:
        return (f"gap fit undetermined: m_el and a1 are not correlated over the gap's {n} rows (t = {t:.2g}): the "
                f"gap's torque does not accelerate the motor measurably")
    tc = correlation_t(x - x.mean(), y - y.mean()) if n > 2 else math.nan
    if NONPHYSICAL_CENTRED and math.isfinite(tc) and tc >= -NONPHYSICAL_Z:
        return (f"gap fit undetermined: m_el and a1 over the gap's {n} rows are anti-correlated through the origin "
                f"(t = {t:.2g}) but not about their means (t = {tc:.2g}): a constant torque (friction, the estimate's "
                f"offset) beyond the gap's own swing, which does not resolve J1")
    q = n // 4
    ym, xm = y[q:n - q], x[q:n - q]
    tm = correlation_t(xm - xm.mean(), ym - ym.mean()) if ym.size > 2 else math.nan
    if NONPHYSICAL_MIDDLE and math.isfinite(tm) and tm >= -NONPHYSICAL_Z:
        return (f"gap fit undetermined: m_el and a1 over the gap's {n} rows are anti-correlated (t = {t:.2g}, about "
                f"their means {tc:.2g}) but not over its middle half (t = {tm:.2g}): its ends carry it, rows still in "
                "contact at an entry or re-contact the fit cannot place, not a sign error")
    if NONPHYSICAL_BEYOND_DECLARED and flip >= 1.0:
        return _turned(flip, n, f"m_el and a1 anti-correlated (t = {t:.2g}, about their means {tc:.2g})")
    return (f"gap fit gave a non-physical J1 = {j:.4g} (m_el against a1 over the gap: they are anti-correlated, "
            f"t = {t:.2g}; {_SIGN_CHECK} a1 and the joint names, {_LATE})")
