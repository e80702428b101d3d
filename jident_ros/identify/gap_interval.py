"""The gap interval (issue 20; gap.py's first step): the rows from the entry to the re-contact over which the motor is
a single mass, found by :func:`gap_interval` from the detector's re-contact row, from the angles or from the a1
signature.  Moved out of gap.py (its 600-line limit); the numbers are the same.

* ``"detector"``: the flank detector's first contact row (its windows hold raw encoder
  angles that inequality 1 cannot read).
* ``"angles"``: when α1 and α2 are measured, the gap is the first run of
  samples from the entry sample on with |α1 − α2| < K2/r (inequality 1).
* ``"signature"``: with no angles, the gap ends at the first sample after the
  entry where the load moment reappears.  In the gap, m_el/a1 = J1/r is constant;
  the flank impact makes a1 drop sharply while m_el cannot (the flux is
  continuous), so the gap ends where a1 falls below ``drop`` (default 0.6) times
  a1 at the entry sample; the sample just before that drop is left out too (the
  impact happens between samples).  Drives without a1 use the same test on the
  smoothed second derivative of α1 (a motor encoder) or, failing that, on the
  smoothed derivative of ω1 (Savitzky-Golay, 7 samples, quadratic).

Plain numpy/scipy; never imports rclpy.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.ndimage import convolve1d

from jident_ros.identify.gap_types import NoGapError
from jident_ros.stream.filters import savgol_coeffs, savgol_filter


def gap_interval(window: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                 drop: float = 0.6, min_samples: int = 3, recontact_index: int | None = None) -> tuple[int, int, str]:
    """(start, end, how) of the first gap run from the entry sample.

    ``recontact_index``: the first contact row as the detector found it (the flank detector, whose
    windows hold raw encoder angles that inequality 1 cannot read); how = "detector"."""
    n = len(next(iter(window.values())))
    if not 0 <= entry_index < n - 1:
        raise NoGapError(f"entry_index: must be inside the window [0, {n - 2}], got {entry_index}")
    if recontact_index is not None and recontact_index >= 0:
        end = int(recontact_index)
        if end <= entry_index:
            # the detector placed its entry at or after its re-contact: no free motion between them to fit -- this
            # window's resolution (OK, nothing published), not a fault of the drive or its configuration (ERROR
            # until stop 42: 12 windows of healthy drives over the blind draws)
            raise NoGapError(f"gap too short: the detector's re-contact row {end} is not after the entry row "
                             f"{entry_index} (no free motion between them)")
        if end > n:
            raise NoGapError(f"recontact_index {recontact_index}: beyond the window's {n} rows")
        how = "detector"
    elif "alpha1" in window and "alpha2" in window:
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
        elif "alpha1" in window or "omega1" in window:
            if "alpha1" in window:   # a motor encoder: acceleration per sample^2
                acc = _savgol_for_gap(np.asarray(window["alpha1"], float), 2, entry_index, drop)
            else:
                acc = _savgol_for_gap(np.asarray(window["omega1"], float), 1, entry_index, drop)
        else:
            raise NoGapError("no gap signal: the window needs alpha1+alpha2, a1, alpha1 or omega1")
        a0 = acc[entry_index]
        if a0 == 0 and "a1" not in window:
            # an acceleration from the encoder's counts that is exactly 0: below what the encoder resolves at this
            # row (a light load reversal's slow turn, DOL d1-04 at 2^16 and 2^13 counts, ERROR until stop 43), the
            # window's resolution; an accelerometer reading 0 or a NaN stays an error
            raise NoGapError("gap fit undetermined: the motor's acceleration at the entry sample is below what the "
                             "encoder resolves (the smoothed derivative of alpha1 or omega1 is 0) and the detector gave "
                             "no re-contact row: no gap interval to fit")
        if not abs(a0) > 0:
            raise NoGapError(f"no backlash gap: the motor does not accelerate at the entry sample (a1 = {a0:.4g})")
        # sign-invariant: either direction of rotation, accelerating or braking through the zone
        below = np.sign(a0) * acc[entry_index:] < drop * abs(a0)
        if not below.any():
            raise NoGapError(f"no re-contact: the acceleration never drops below {drop:g} x its entry value "
                             f"to the end of the window (not a backlash entry?)")
        end = entry_index + int(np.argmax(below))
        end -= 1  # the flanks meet between samples: the last sample before the drop may already carry load
        how = "signature"
    if end - entry_index < min_samples:
        by = {"detector": "to the detector's re-contact row",
              "angles": "while |alpha1 - alpha2| < K2/r",
              "signature": f"until the motor's acceleration falls below {drop:g} x its entry value: a short gap, or a "
                           f"motor that hardly accelerates in it, as in a load-driven traversal"}[how]
        raise NoGapError(f"gap too short: {end - entry_index} samples inside the zone ({by}), need >= {min_samples}")
    return entry_index, end, how


@lru_cache(maxsize=4)
def _savgol_7_2(deriv: int) -> np.ndarray:
    return savgol_coeffs(7, 2, deriv=deriv)


def _savgol_for_gap(x: np.ndarray, deriv: int, entry_index: int, drop: float) -> np.ndarray:
    """``savgol_filter(x, 7, 2, deriv=deriv)`` where :func:`gap_interval`'s signature test reads it: the
    interior rows are scipy's own convolution with the same coefficients (bit for bit); the 3 rows at each end,
    which scipy fills with polynomial fits (most of its cost), only when the test reaches them (an entry row
    within 3 rows of an end, or no drop before the last 3 rows): then the whole savgol_filter."""
    half = 3
    n = x.size
    if n < 7 or not half <= entry_index < n - half:
        return savgol_filter(x, 7, 2, deriv=deriv)
    y = convolve1d(x, _savgol_7_2(deriv), axis=-1, mode="constant")
    a0 = y[entry_index]
    if not abs(a0) > 0 or not (np.sign(a0) * y[entry_index:n - half] < drop * abs(a0)).any():
        return savgol_filter(x, 7, 2, deriv=deriv)
    return y
