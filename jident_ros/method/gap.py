"""J1 from the backlash gap itself: while the drive is inside the zone the load
moment is zero, so the motor side is a single mass,

    J1 dω1/dt = m_el − b1 ω1          (b1 = bearing friction, 0 in the paper's model)

and J1 follows from signals the window already holds, by least squares over the
gap samples.  Plain numpy/scipy; never imports rclpy.

Gap interval
------------
* ``"angles"``: when α1 and α2 are measured, the gap is the first run of
  samples from the entry sample on with |α1 − α2| < K2/r (inequality 1).
* ``"signature"``: with no angles, the gap ends at the first sample after the
  entry where the load moment reappears.  In the gap, m_el/a1 = J1/r is constant;
  the flank impact makes a1 drop sharply while m_el cannot (the flux is
  continuous), so the gap ends where a1 falls below ``drop`` (default 0.6) times
  a1 at the entry sample; the sample just before that drop is left out too (the
  impact happens between samples).  ω1-only drives use the same test on the smoothed
  derivative of ω1.

Fits
----
* ``"acceleration"`` (a1 and m_el measured): m_el is smooth through the gap and
  constant before it, so it is first estimated as m0 + b t + c t^2 (m0 = the
  pre-entry mean, b and c fitted over the gap); then a1_k = (r/J1) m_hat_k is fitted
  through the origin.  Anchoring on the 48 pre-entry samples keeps torque noise
  out of the ratio.
* ``"speed"`` (ω1 and m_el measured, no accelerometer): integral form, no
  differentiation: ∫_{t0}^{tk} m_el dt = J1 (ω1_k − ω1_0) + c, with c absorbing the
  noise of ω1 at the first gap sample.
Both report J1, its standard error from the residuals, a 95 % confidence interval
(Student t) and the residual RMS.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats


#: Gaps shorter than this fit m_el with a straight line (fewer free parameters, less noise).
GAP_QUADRATIC_MIN = 12


#: A gap fit whose standard error exceeds this fraction of J1 is refused (NoGapError): such a
#: window carries no free acceleration (e.g. a steady state mistaken for an entry).
MAX_RELATIVE_STD_ERROR = 0.25


class NoGapError(ValueError):
    """The window holds no usable backlash gap."""


@dataclass(frozen=True)
class GapEstimate:
    """J1 from the gap.

    Attributes
    ----------
    inertia_kgm2 : float            J1 estimate, kg m^2
    std_error_kgm2 : float          standard error, kg m^2
    ci95_kgm2 : (float, float)      95 % confidence interval, kg m^2
    residual_rms : float            RMS of the fit residual (N m for 'acceleration', N m s for 'speed')
    gap_start, gap_end : int        sample indices, end exclusive
    method : str                    'acceleration' or 'speed'
    interval : str                  'angles' or 'signature'
    """

    inertia_kgm2: float
    std_error_kgm2: float
    ci95_kgm2: tuple
    residual_rms: float
    gap_start: int
    gap_end: int
    method: str
    interval: str

    @property
    def n_samples(self) -> int:
        return self.gap_end - self.gap_start


def gap_interval(window: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                 drop: float = 0.6, min_samples: int = 3) -> tuple[int, int, str]:
    """(start, end, how) of the first gap run from the entry sample."""
    n = len(next(iter(window.values())))
    if not 0 <= entry_index < n - 1:
        raise NoGapError(f"entry_index: must be inside the window [0, {n - 2}], got {entry_index}")
    if "alpha1" in window and "alpha2" in window:
        rel = np.abs(np.asarray(window["alpha1"], float) - np.asarray(window["alpha2"], float))
        inside = rel[entry_index:] < backlash_width_m / wheel_radius_m
        if not inside[0]:
            raise NoGapError(f"no backlash gap: |alpha1 - alpha2| = {rel[entry_index]:.4g} rad at the entry sample "
                             f"is not below K2/r = {backlash_width_m / wheel_radius_m:.4g} rad")
        if inside.all():
            raise NoGapError(f"no re-contact: |alpha1 - alpha2| stays below K2/r = "
                             f"{backlash_width_m / wheel_radius_m:.4g} rad to the end of the window (a wrong K2, "
                             f"or not a backlash entry)")
        end = entry_index + int(np.argmin(inside))
        how = "angles"
    else:
        if "a1" in window:
            acc = np.asarray(window["a1"], float)
        elif "omega1" in window:
            from scipy.signal import savgol_filter
            acc = savgol_filter(np.asarray(window["omega1"], float), 7, 2, deriv=1)
        else:
            raise NoGapError("no gap signal: the window needs alpha1+alpha2, a1 or omega1")
        a0 = acc[entry_index]
        if not a0 > 0:
            raise NoGapError(f"no backlash gap: the drive does not accelerate at the entry sample (a1 = {a0:.4g})")
        below = acc[entry_index:] < drop * a0
        if not below.any():
            raise NoGapError(f"no re-contact: the acceleration never drops below {drop:g} x its entry value "
                             f"to the end of the window (not a backlash entry?)")
        end = entry_index + int(np.argmax(below))
        end -= 1  # the flanks meet between samples: the last sample before the drop may already carry load
        how = "signature"
    if end - entry_index < min_samples:
        raise NoGapError(f"gap too short: {end - entry_index} samples inside the zone, need >= {min_samples}")
    return entry_index, end, how


def estimate_inertia(window: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                     sample_period_s: float, method: str | None = None,
                     bearing_friction_nms_per_rad: float = 0.0) -> GapEstimate:
    """Least-squares J1 over the gap; raises :class:`NoGapError` with a reason."""
    if "m_el" not in window:
        raise NoGapError("no electromagnetic torque: the gap fit needs m_el")
    start, end, how = gap_interval(window, entry_index, backlash_width_m, wheel_radius_m)
    m = np.asarray(window["m_el"], float)[start:end]
    if bearing_friction_nms_per_rad and "omega1" in window:
        m = m - bearing_friction_nms_per_rad * np.asarray(window["omega1"], float)[start:end]
    if method is None:
        method = "acceleration" if "a1" in window else "speed"
    n = end - start
    if method == "acceleration":
        # m_el is smooth through the gap (the fluxes are continuous) and constant before
        # the entry (steady state): anchor it with the pre-entry mean and a quadratic in
        # time over the gap, then fit a1 = (r/J1) m_el_hat through the origin.
        mf = np.asarray(window["m_el"], float)
        a = np.asarray(window["a1"], float)[start:end]
        t = np.arange(n) * sample_period_s
        pre = mf[:start]
        m0 = float(pre.mean()) if pre.size else float(m[0])
        T = t[:, None] if n < GAP_QUADRATIC_MIN else np.column_stack([t, t * t])
        coef, *_ = np.linalg.lstsq(T, m - m0, rcond=None)
        m_hat = m0 + T @ coef
        smm = float(m_hat @ m_hat)
        kappa = float(a @ m_hat) / smm
        if not kappa > 0:
            raise NoGapError(f"gap fit gave a non-physical a1/m_el ratio {kappa!r}")
        j = wheel_radius_m / kappa
        res = a - kappa * m_hat
        dof = n - 1
        var_k = (res @ res) / dof / smm if dof > 0 else np.inf
        # uncertainty of m_hat: pre-entry mean and the quadratic's coefficients
        res_m = (m - m0) - T @ coef
        s2m = float(res_m @ res_m) / max(n - 2, 1)
        var_m0 = float(pre.var(ddof=1)) / pre.size if pre.size > 1 else s2m
        cov = s2m * np.linalg.pinv(T.T @ T)
        var_mhat = var_m0 + np.einsum("ij,jk,ik->i", T, cov, T)
        rel_m = float(np.sqrt(np.mean(var_mhat))) / float(np.mean(m_hat))
        se = float(np.sqrt(var_k * (wheel_radius_m / kappa ** 2) ** 2 + (j * rel_m) ** 2))
    elif method == "speed":
        if "omega1" not in window:
            raise NoGapError("method 'speed' needs omega1")
        w = np.asarray(window["omega1"], float)[start:end]
        y = np.concatenate([[0.0], np.cumsum(0.5 * (m[1:] + m[:-1])) * sample_period_s])
        x = w - w[0]
        A = np.column_stack([x, np.ones(n)])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        j = float(coef[0])
        res = y - A @ coef
        dof = n - 2
        cov = (res @ res) / dof * np.linalg.inv(A.T @ A) if dof > 0 else np.full((2, 2), np.inf)
        se = float(np.sqrt(cov[0, 0]))
    else:
        raise ValueError(f"method: expected 'acceleration' or 'speed', got {method!r}")
    if not np.isfinite(j) or j <= 0:
        raise NoGapError(f"gap fit gave a non-physical J1 = {j!r}")
    if not se <= MAX_RELATIVE_STD_ERROR * j:
        raise NoGapError(f"gap fit undetermined: J1 = {j:.4g} kg m^2 with standard error {se:.3g} kg m^2 "
                         f"(> {MAX_RELATIVE_STD_ERROR:.0%}); the window shows no free acceleration of the motor")
    half = float(stats.t.ppf(0.975, max(dof, 1))) * se
    return GapEstimate(j, se, (j - half, j + half), float(np.sqrt(np.mean(res ** 2))), start, end, method, how)


def nearest_class(inertia_kgm2: float, classes_kgm2) -> int:
    """Index of the J1 class nearest to a continuous estimate."""
    return int(np.argmin(np.abs(np.asarray(classes_kgm2, float) - inertia_kgm2)))


@dataclass(frozen=True)
class WidthEstimate:
    """Backlash zone width at the wheel circumference, m, with its standard uncertainty."""

    width_m: float
    std_m: float
    recontact_index: int


def estimate_backlash_width(window: dict, gap_end: int, wheel_radius_m: float) -> WidthEstimate:
    """Width from the relative angle at re-contact.

    The flanks meet where |alpha1 - alpha2| (measured from the zone centre, the
    reading of inequality 1) reaches K2/r, somewhere between the last gap sample
    and the first contact sample.  Within that sample interval the relative angle
    is nearly linear in time, and the contact instant is taken uniformly
    distributed: width = r (|d_last| + |d_first|)/2, standard uncertainty
    r (|d_first| - |d_last|)/sqrt(12).
    """
    if "alpha1" not in window or "alpha2" not in window:
        raise NoGapError("backlash width: needs both angles alpha1 and alpha2")
    rel = np.abs(np.asarray(window["alpha1"], float) - np.asarray(window["alpha2"], float))
    if not 1 <= gap_end < rel.size:
        raise NoGapError(f"backlash width: no re-contact inside the window (gap end {gap_end})")
    a, b = rel[gap_end - 1], rel[gap_end]
    return WidthEstimate(float(wheel_radius_m * 0.5 * (a + b)), float(wheel_radius_m * abs(b - a) / np.sqrt(12.0)),
                         int(gap_end))
