"""An encoder's disc error (once and twice per revolution) fitted over a capture's steady last rows and taken off its
angle before the flank detector's rules run (pure numpy, never imports rclpy): :func:`disc_error`,
:func:`disc_corrected` (also the gap stage's, :mod:`jident_ros.identify.gap`); DISC_* constants.  Moved from
:mod:`jident_ros.stream.flank` (which still finds every name here).
"""
from __future__ import annotations

import functools
import math
from typing import Optional

import numpy as np

from jident_ros.stream import flank_free
from jident_ros.stream.rate import samples

#: An encoder's disc errors (a once- and a twice-per-revolution angle error: eccentricity and tilt, 0.2 / 0.1 mrad on
#: the 'encoder disc errors' variant, 4-7 times a 2^16 count's quantisation noise) bend alpha1 and delta over the
#: rules' fits, which take them for the motor's and the coupling's motion (that variant's light load reversal -11, heavy
#: -7, traversal back +24).  The error is a function of the encoder's own angle, the same every revolution: before the
#: rules, each angle (alpha1, alpha2) is fitted over the capture's last DISC_TAIL_SAMPLES rows (the contact after the
#: event, the drive running steadily again) by a polynomial of degree DISC_DEGREE in time plus sin/cos of the angle and
#: of twice the angle (:func:`disc_error`), when those rows turn DISC_MIN_REVOLUTIONS or more one way (the net turn at
#: least DISC_MIN_NET_SHARE of the path: a cubic cannot bend like three periods of a sine), and the harmonics are
#: subtracted over the whole capture where they explain those rows DISC_MIN_GAIN times better (rms without / with
#: them) and leave no more than DISC_MAX_RMS_FLOORS x the encoder's own noise (:func:`angle_noise_rad`: on a grid of
#: counts its quantum / sqrt 12, off a grid what the third differences show; at least ANGLE_MODEL_FLOOR_RAD; the flank
#: detector's the smallest second difference / sqrt 12, DISC_DETECTOR_OFF_GRID): smooth motion plus the disc error,
#: not a transient the harmonics absorb.  With 1.3-2 revolutions they absorbed transients: the rows before the
#: departure of every light load reversal of the vector drive and its variants (1.3-1.4 revolutions, the load torque
#: ramping: 220-400 urad at the noise floor with no disc error), the small drive's speed reversal's last 1000 rows (its
#: load encoder's 2 revolutions 'explained' 1.9 times better by a 38 mrad harmonic; the rms gate refuses that one
#: too).  Chosen on the 'encoder disc errors' variant (its last 1000 rows: 6.4-7.9 revolutions, gain 5.7, rms at the
#: floor); tested on the zoo, the DOL zoo and the other variants (docs/results.md, "Entry placement, eleventh round")
DISC_TAIL_SAMPLES = 1000
DISC_DEGREE = 3
DISC_MIN_REVOLUTIONS = 3.0
DISC_MIN_NET_SHARE = 0.9
DISC_MIN_GAIN = 1.5
DISC_MAX_RMS_FLOORS = 2.0
#: Where the last DISC_TAIL_SAMPLES rows do not qualify, the last DISC_SHORTER_TAILS rows are tried, in order (each
#: still DISC_MIN_REVOLUTIONS or more, the same gates): a slip reversal of a drive on line swings its speed for
#: hundreds of rows after the re-contact, which the cubic cannot follow over 1000 rows, while its last 400-600 turn
#: steadily (DOL set 10's d10-04: the last 1000 rows 295 urad rms about the cubic, refused; the last 600 the disc's
#: 200 / 100 urad at the floor; left on alpha1, the gap fit's 19 rows published J1 -11 %).  Chosen on that window;
#: tested on the zoo, the DOL zoo, the variants and the draws (docs/results.md, stop 36)
DISC_SHORTER_TAILS = (600, 400)
#: The flank detector's disc-error gate counts from the encoder's noise off a grid of counts too (readings resampled
#: from jittered instants: :func:`angle_noise_rad`).  False (stop 48): it keeps stop 47's floor, the smallest second
#: difference, which off a grid is a fraction of a count, so a 2^14 encoder's disc error stays on its angles there;
#: the gap stage takes it off (gap._disc_taken_off).  True on the 56 blind sets: traversals found vector 4894 -> 4889,
#: DOL 4533 -> 4532 (a traversal back's walk ran 17 samples further back, s4-04; a return scan's captures not opened
#: after a bounce, s17-10), entries within ±2 3304 -> 3307 and 2815 -> 2819: the rules were chosen with the disc error
#: on these drives' angles (docs/results.md, stop 48)
DISC_DETECTOR_OFF_GRID = False


def _disc_columns(angle: np.ndarray) -> np.ndarray:
    return np.column_stack([np.sin(angle), np.cos(angle), np.sin(2.0 * angle), np.cos(2.0 * angle)])


def disc_error(angle: np.ndarray, first: int, end: int, off_grid: bool = True) -> Optional[np.ndarray]:
    """The coefficients of sin/cos(angle), sin/cos(2 angle) of an encoder's disc error (DISC_* constants) fitted over
    rows ``first`` .. ``end`` of ``angle``; None when those rows do not qualify or the harmonics do not explain them.
    ``off_grid``: the rms gate's noise is :func:`angle_noise_rad`'s (False: the smallest second difference taken for
    the quantum whatever the readings, stop 47's floor, which the flank detector keeps: DISC_DETECTOR_OFF_GRID)."""
    x = np.asarray(angle, float)
    first, end = max(int(first), 0), min(int(end), x.size)
    if end - first < 4 * (DISC_DEGREE + 5):
        return None
    path = float(np.sum(np.abs(np.diff(x[first:end])))) / (2.0 * math.pi)
    net = abs(float(x[end - 1] - x[first])) / (2.0 * math.pi)
    if not (net >= DISC_MIN_REVOLUTIONS and net >= DISC_MIN_NET_SHARE * path):
        return None
    seg = x[first:end]
    # the polynomial's orthonormal basis (cached per length); the harmonics' coefficients by the Frisch-Waugh-Lovell
    # route: both sides with the polynomial projected out, a 4 x 4 solve (the same least squares as the stacked
    # fit to rounding, a fifth of its cost: the gap stage runs it on every window)
    Q = _poly_basis(seg.size)
    r = seg - Q @ (Q.T @ seg)
    rss_poly = float(r @ r)
    floor = max(angle_noise_rad(seg) if off_grid else _smallest_step_noise(seg), flank_free.ANGLE_MODEL_FLOOR_RAD)
    # first with the twice-per-revolution columns from the once-per-revolution ones (2 sin cos, cos² − sin²: equal
    # to the sines of twice the angle to rounding, two of the four sines saved): a fit its gates refuse beyond
    # rounding (1e-6) is refused; any other is fitted on the sines themselves, the coefficients it returns
    for approx in (True, False):
        got = _disc_fit(seg, Q, r, approx)
        if got is None:
            if approx:
                continue
            return None
        coef, rss = got
        slack = 1.0 + 1e-6 if approx else 1.0
        if rss > 0 and (rss_poly * slack < DISC_MIN_GAIN ** 2 * rss
                        or math.sqrt(rss / seg.size) > DISC_MAX_RMS_FLOORS * floor * slack):
            return None
    if not rss > 0 or not rss_poly >= DISC_MIN_GAIN ** 2 * rss \
            or not math.sqrt(rss / seg.size) <= DISC_MAX_RMS_FLOORS * floor:
        return None
    return coef


def angle_noise_rad(angle: np.ndarray) -> float:
    """The noise of an encoder's angle readings, rad: on a grid of counts (every second difference a whole multiple
    of the smallest, to 1 %) its quantum / sqrt 12, the quantum the smallest second difference; off a grid (the
    readings moved from their jittered instants onto the uniform grid by stamps.py's interpolation, or scaled and
    offset) the noise its third differences show, sqrt(mean(d3²) / 20) (white noise of variance σ² gives d3 of
    variance 20 σ²; smooth motion adds the jerk's T_s³, nanoradians).  Stop 48: off a grid the smallest second
    difference is a fraction of a count, and the rms gate counted from ANGLE_MODEL_FLOOR_RAD: a 2^14 encoder's
    readings under a 10 µs stamp jitter (111 µrad of quantisation noise) never qualified, their 200 / 100 µrad disc
    error was left on alpha1 (DOL draw d4-05's slip reversal: the gap fit stopped at the disc error's bend, J1 +4.9 %
    outside its interval)."""
    x = np.asarray(angle, float)
    d2 = np.diff(x, 2)
    steps = _nonzero_steps(d2)
    if steps.size:
        k = steps / float(steps.min())
        if float(np.abs(k - np.rint(k)).max()) < 0.01:
            return float(steps.min()) / math.sqrt(12.0)
    if x.size < 8:
        return 0.0
    d3 = np.diff(d2)
    return math.sqrt(float(d3 @ d3) / (20.0 * d3.size))


def _nonzero_steps(d2: np.ndarray) -> np.ndarray:
    """|second differences| of an angle beyond float rounding (1e-9 rad)."""
    steps = np.abs(d2)
    return steps[steps > 1e-9]


def _smallest_step_noise(angle: np.ndarray) -> float:
    """Stop 47's noise floor: the smallest non-zero second difference / sqrt 12 (a count only on a grid of counts)."""
    steps = _nonzero_steps(np.diff(np.asarray(angle, float), 2))
    return float(steps.min()) / math.sqrt(12.0) if steps.size else 0.0


def _disc_fit(seg: np.ndarray, Q: np.ndarray, r: np.ndarray, approx: bool):
    """:func:`disc_error`'s harmonics fitted to ``r`` (``seg`` with the polynomial projected out): (coefficients,
    residual sum of squares), None where singular; ``approx``: the twice-per-revolution columns by the double-angle
    formulas."""
    if approx:
        sn, cs = np.sin(seg), np.cos(seg)
        D = np.empty((seg.size, 4))
        D[:, 0], D[:, 1] = sn, cs
        np.multiply(2.0 * sn, cs, out=D[:, 2])
        np.multiply(cs - sn, cs + sn, out=D[:, 3])
    else:
        D = _disc_columns(seg)
    D -= Q @ (Q.T @ D)
    try:
        coef = np.linalg.solve(D.T @ D, D.T @ r)
    except np.linalg.LinAlgError:
        return None
    res = r - D @ coef
    return coef, float(res @ res)


@functools.lru_cache(maxsize=8)
def _poly_basis(n: int) -> np.ndarray:
    """An orthonormal basis (n, DISC_DEGREE + 1) of the polynomials of degree DISC_DEGREE in t over [-1, 1] (read-only:
    shared)."""
    Q = np.linalg.qr(np.vander(np.linspace(-1.0, 1.0, n), DISC_DEGREE + 1, increasing=True))[0]
    Q.flags.writeable = False
    return Q


def disc_corrected(angle: np.ndarray, sample_period_s: float, off_grid: bool = True) -> tuple:
    """(``angle`` with its encoder's disc error taken off, the coefficients (:func:`disc_error` over the last
    DISC_TAIL_SAMPLES rows at 2 kHz, converted to the recording's rows, else over the last DISC_SHORTER_TAILS rows)),
    or (``angle``, None) where it shows none: the gap stage's (jident_ros/identify/gap.py) and the detector's
    (FlankDetector._disc_corrected)."""
    x = np.asarray(angle, float)
    coef = None
    for tail in (DISC_TAIL_SAMPLES, *DISC_SHORTER_TAILS):
        coef = disc_error(x, x.size - samples(tail, sample_period_s), x.size, off_grid)
        if coef is not None:
            break
    return (x, None) if coef is None else (x - _disc_columns(x) @ coef, coef)
