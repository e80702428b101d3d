"""The relative angle delta = alpha1 - N alpha2 after a flank detector's entry (pure numpy, never imports rclpy):
its travel across the zone, the re-contact row and the backlash width K2 of one window (:func:`estimate_width`,
:class:`WidthResult`); the motor acceleration's re-contact row (:func:`motor_acceleration`,
:func:`recontact_index`); delta's quantum (:func:`_delta_quantum`).  Moved from :mod:`jident_ros.stream.flank` (which
still finds every name here).

**Width estimate** (per window; docs/model.md's convention: theta_b = K2/r is the half-width, the flanks lie
at +-K2/r from the centre):

* **re-contact on the opposite flank** (a traversal: the drive crossed the zone, e.g. it braked off its
  driving flank): delta travels 2 K2/r from the entry flank to the re-contact flank; each end is bracketed
  by the samples on either side of the contact instant (uniform in between), so
  K2 = r |P_recontact - P_entry| / 2 with P the bracket midpoints, se = (r/2) sqrt(b_e^2 + b_g^2)/sqrt(12);
* **re-contact on the same flank** (the simulator's scenario, docs/model.md section 3: the line slips by K2,
  delta jumps from the loaded flank to K2/r nearer the centre, the motor turns freely back to the flank):
  the excursion from the flank level to the entry sample is K2/r — measured against the flank level
  *after* re-contact (the settled end of the window), so that an offset moved by the slip cancels:
  K2 = r |F_after - delta_entry|, se from F_after's spread, one sample's motion and the quantisation.
  (On a real drive a same-flank excursion only bounds K2: it is K2/r exactly in the slip scenario.)

The re-contact row (the first contact sample) comes from the motor's acceleration (a1, else the smoothed
second difference of alpha1, else of omega1): the first sample after the entry whose acceleration has lost
``recontact_drop`` of its entry value toward zero, sign-invariant, less one sample (the flanks meet between
samples) — the rule of :func:`jident_ros.identify.gap.gap_interval`'s "signature".  That rule assumes a motor
that keeps its acceleration across the gap; a line-fed motor's torque falls as it speeds up, and a coarse encoder's
second difference is noise.  So a traversal's row is checked against delta itself (:func:`delta_recontact`): where
delta has not yet come near its farthest travel at that row (still crossing the zone), the contact is where delta's
travel stops and holds, located at the kink there.  Windows in which delta comes back to the flank it left keep the
acceleration's row (a bounce, a slip's excursion before a crossing), except a traversal and its traversal back, read
up to the return (:func:`_before_return`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from jident_ros.stream.filters import savgol_filter
from jident_ros.stream.flank_free import _lstsq_rss, _profile
from jident_ros.stream.rate import REFERENCE_SAMPLE_PERIOD_S, odd_samples, samples

#: :class:`WidthResult`'s ``how`` of an excursion that came back to the flank it left (the window gets FLAG_BOUNCE)
BOUNCE_HOW = "bounce back to the same flank (width not observable)"


@dataclass
class WidthResult:
    """K2 of one traversal: width_m, its standard uncertainty se_m (NaN: none), how ('traversal',
    'same_flank', or why not), the re-contact row (-1: unknown)."""

    width_m: float
    se_m: float
    how: str
    recontact_index: int = -1


def motor_acceleration(window: dict, wheel_radius_m: float, sample_period_s: float):
    """(dω1/dt in rad/s^2 per sample, source) from a1 (a1/r), else the smoothed second difference of
    alpha1, else the smoothed difference of omega1 (Savitzky-Golay, 7 samples at 2 kHz, quadratic); (None, '')
    when the window has none of them.  At another rate the filter spans the same time (odd samples, at least 5:
    15 at 4 kHz, 5 at 1 kHz): a second difference over 7 samples at 4 kHz would carry 2^4 x the noise of an angle
    quantum in rad/s^2 over half the time, the filter over the same 3.5 ms keeps it near 2 kHz's."""
    if "a1" in window:
        return np.asarray(window["a1"], float) / wheel_radius_m, "a1"
    w = odd_samples(7, sample_period_s)
    if "alpha1" in window and len(window["alpha1"]) >= w:
        return savgol_filter(np.asarray(window["alpha1"], float), w, 2, deriv=2) / sample_period_s ** 2, "alpha1"
    if "omega1" in window and len(window["omega1"]) >= w:
        return savgol_filter(np.asarray(window["omega1"], float), w, 2, deriv=1) / sample_period_s, "omega1"
    return None, ""


def recontact_index(acc: np.ndarray, entry_index: int, drop: float = 0.6, min_samples: int = 3) -> int:
    """Row of the first contact sample after the entry, from the motor acceleration (sign-invariant):
    the first row after ``entry_index`` where s·acc < drop·|acc(entry)| (s = the sign of acc at the entry),
    less one (the flanks meet between samples; the row before the drop may already carry load).
    -1 when the acceleration at the entry is 0 or never drops.  (Measured against the largest acceleration
    since the entry instead, a noisy second difference of alpha1 put the re-contact early on our simulator's
    JointState recordings: 8/16 published -> 3/16, two 30 dB ones 28-36 % off; the zoo report.)"""
    a0 = float(acc[entry_index])
    if not abs(a0) > 0 or not math.isfinite(a0):
        return -1
    s = 1.0 if a0 > 0 else -1.0
    below = s * acc[entry_index + min_samples:] < drop * abs(a0)
    if not below.any():
        return -1
    return entry_index + min_samples + int(np.argmax(below)) - 1


#: The re-contact from the relative angle delta (:func:`delta_recontact`): delta's speed across the zone, over
#: RECONTACT_SPAN samples, falls below RECONTACT_DROP of its largest since the entry at the far flank (the coupling
#: takes the impact) ...
RECONTACT_SPAN = 4
#: False: the acceleration's row alone (the rule before stop 23; for comparisons and the tests).
RECONTACT_FROM_DELTA = True
RECONTACT_DROP = 0.5
#: ... a move of at least this many quanta per span (below it delta barely moves: no traversal to read) ...
RECONTACT_MIN_QUANTA = 3.0
#: ... and the contact instant is the kink of delta there: delta = quadratic before row g, plus (k - g)^2 and (k - g)^3
#: terms from g on (position and speed continuous, the coupling's damping and spring acting from g), profiled over g
#: within RECONTACT_SEARCH rows before and after the drop row on the fixed rows RECONTACT_FIT rows around it.
RECONTACT_SEARCH = (8, 4)
RECONTACT_FIT = (24, 10)
#: A speed drop is the contact when delta then holds within RECONTACT_HOLD_SHARE of its travel from the entry for
#: RECONTACT_HOLD samples (the first of at most RECONTACT_MAX_CANDIDATES drops).
RECONTACT_HOLD = 12
RECONTACT_HOLD_SHARE = 0.3
RECONTACT_MAX_CANDIDATES = 400
#: ... at a travel of at least this share of delta's farthest from the entry in the window.
RECONTACT_MIN_TRAVEL_SHARE = 0.6
#: ... and only where delta travels at least this many quanta in the window: below it a quantised delta cannot tell a
#: contact from the coupling's untwist (the DOL sweep's soft coupling, 2^13: a slip's 12-sample excursion of 4 counts
#: beyond a 10-count untwist, read as a 13-row gap, published +11.2 % outside its interval; the narrowest traversal
#: in the zoos, K2 2.5 mm at 2^13, travels 65 counts) -- chosen on the DOL sweep, tested on the other zoos
RECONTACT_MIN_TRAVEL_QUANTA = 30.0
#: delta back within this share of its farthest travel so far is a bounce's return to the flank it left: the search
#: ends there.
RECONTACT_RETURN_SHARE = 0.2
#: delta's travel before its first return at least this share of its farthest in the window: a traversal and its
#: traversal back, whose traversal the delta rule reads (:func:`_before_return`); less, a bounce or a slip's excursion
#: before a crossing, not read -- not tuned: the half of the window's farthest travel
RECONTACT_RETURN_TRAVERSAL_SHARE = 0.5


#: Where delta has not moved over RECONTACT_SPAN rows after the entry, the side it left in is that of its farthest
#: point from the entry in the window (a traversal's far flank, a bounce's deepest point), not of its first move: a
#: coarse encoder's delta dithers a count back toward the flank after a slow departure (DOL draw d21-12's 2^14 heavy
#: load reversal at 30 dB: one count back at the entry's second row turned the travel negative, the acceleration's
#: re-contact 2 rows after the entry stood, the window refused as a gap too short for a 98-row gap) -- chosen there
#: (blind DOL set 21).  False: the first move, as before
TRAVEL_SIDE_FROM_FARTHEST = True


def _travel(d: np.ndarray, e: int, span: int = RECONTACT_SPAN) -> np.ndarray:
    """The travel of delta from the entry row on, positive in the direction it left in (``span`` rows decide:
    RECONTACT_SPAN at 2 kHz; when delta has not moved over them, the side of its farthest point from the entry in the
    rows given (TRAVEL_SIDE_FROM_FARTHEST; off: of its first move).  A coarse encoder's delta creeps off its flank
    within a count for several samples after an entry placed at the contact loss: the side taken from no move turned
    the travel negative, so the acceleration's re-contact row 5 samples after the entry stood (K2 1.9e-5 m for 5 mm on
    the vector drive's 2^13 light load reversal), and so did a first move one count back (d21-12))."""
    ref = d[min(e + span, d.size - 1)]
    if abs(ref - d[e]) <= 1e-9:                     # no move but a float rounding (as _delta_quantum's steps)
        if TRAVEL_SIDE_FROM_FARTHEST and d.size > e + 1:
            ref = d[e + 1 + int(np.argmax(np.abs(d[e + 1:] - d[e])))]
        else:
            moved = np.nonzero(np.abs(d[e + 1:] - d[e]) > 1e-9)[0]
            ref = d[e + 1 + int(moved[0])] if moved.size else ref
    side = 1.0 if ref >= d[e] else -1.0
    return side * (d[e:] - d[e])


def _delta_quantum(d: np.ndarray, e: int, angle_quantum_rad: float, first: int = 0, below: float = math.inf) -> float:
    """The quantum of delta: the configured encoders', else the smallest step delta makes in rows first..e (before the
    entry: whole counts of a quantised angle at rest on its flank; a continuous angle's is tiny and guards nothing),
    not a float rounding, and below ``below`` (not a jump)."""
    if angle_quantum_rad > 0:
        return float(angle_quantum_rad)
    steps = np.abs(np.diff(d[first:e]))
    steps = steps[(steps > 1e-9) & (steps < below)]
    return float(steps.min()) if steps.size else 0.0


def _first_return(D: np.ndarray, angle_quantum_rad: float) -> Optional[int]:
    """The first row (from the entry) where delta comes back near the flank it left (within RECONTACT_RETURN_SHARE of
    its farthest travel so far, that travel beyond RECONTACT_MIN_QUANTA quanta), None when it never does: a bounce (the
    second drive's 2^13 bounce windows, whose traversal back across the zone followed: read as their contact, J1 was
    fitted over 24 contact rows, +2.8 % and another class named), a slip's excursion (the DOL sweep's soft coupling at
    2^13: its slow turning point held still, +11.2 % published), or a traversal and a traversal back."""
    run = np.maximum.accumulate(D)
    back = np.flatnonzero((D <= RECONTACT_RETURN_SHARE * run) & (run > RECONTACT_MIN_QUANTA * max(angle_quantum_rad, 1e-12)))
    return int(back[0]) if back.size else None


def _before_return(D: np.ndarray, angle_quantum_rad: float) -> np.ndarray:
    """The rows of D the delta rule reads: all of them when delta never comes back toward the flank it left
    (:func:`_first_return`); those before the return when the travel before it is a traversal, at least
    RECONTACT_RETURN_TRAVERSAL_SHARE of delta's farthest in the window (a traversal and its traversal back); none
    otherwise (a bounce or a slip's excursion, then a crossing: the acceleration's row stands, as it did for every
    window with a return before stop 37).  Why: a traversal and its traversal back kept the acceleration's row (vector
    set 11's s11-12, a speed step down at 2^14: 68 mrad across, then back; the row 8 samples after the entry, the gap
    fit undetermined, the return scan without edges); read on all its rows, a bounce before a crossing took the
    crossing's far flank for its re-contact (DOL set 3's d3-03: its J1 +1 % lost)."""
    r = _first_return(D, angle_quantum_rad)
    if r is None:
        return D
    return D[:r] if float(np.max(D[:r])) >= RECONTACT_RETURN_TRAVERSAL_SHARE * float(np.max(D)) else D[:0]


def _delta_arrived(d: np.ndarray, e: int, g: int, angle_quantum_rad: float,
                   sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> bool:
    """Whether a re-contact row g found from the motor's acceleration has delta at the far side: its travel from the
    entry at least RECONTACT_MIN_TRAVEL_SHARE of its farthest in the window (False: delta still crossing the zone)."""
    span = samples(RECONTACT_SPAN, sample_period_s)
    if not e < g < d.size or d.size - e < span + 6:
        return True                 # nothing to check against: the acceleration's row (or none) stands
    D = _before_return(_travel(d, e, span), angle_quantum_rad)
    if g - e >= D.size:
        return True                 # a re-contact row after delta came back: the acceleration's row stands
    far = float(np.max(D))
    if not far > RECONTACT_MIN_TRAVEL_QUANTA * max(angle_quantum_rad, 1e-12):
        return True
    return bool(D[g - e] >= RECONTACT_MIN_TRAVEL_SHARE * far)


def delta_recontact(delta: np.ndarray, entry_index: int, angle_quantum_rad: float = 0.0,
                    sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> int:
    """Row of the first contact sample after the entry from the relative angle delta = alpha1 - N alpha2 (raw
    offsets cancel in its differences; RECONTACT_* constants): where delta's travel across the zone is stopped.
    -1 when delta does not move across the zone or never stops in the window (the caller falls back on the motor's
    acceleration, :func:`recontact_index`).  Chosen on the DOL drive's and the vector drive's traversals (the motor's
    acceleration there changes inside the gap: a line-fed motor's torque falls as it speeds up, so the acceleration
    rule put the re-contact 30-140 samples early and K2 73-92 % off), tested on the second drive and ours.
    (Spans, holds and fits: samples at 2 kHz, converted to ``sample_period_s``'s; RECONTACT_MIN_QUANTA is per span,
    a span of the same duration.)"""
    d = np.asarray(delta, float)
    e = int(entry_index)
    span, hold = samples(RECONTACT_SPAN, sample_period_s), samples(RECONTACT_HOLD, sample_period_s)
    fit, search = samples(RECONTACT_FIT, sample_period_s), samples(RECONTACT_SEARCH, sample_period_s)
    if d.size - e < span + 6:
        return -1
    D = _before_return(_travel(d, e, span), angle_quantum_rad)
    if D.size < span + 6 or not float(np.max(D)) > RECONTACT_MIN_TRAVEL_QUANTA * max(angle_quantum_rad, 1e-12):
        return -1
    d = d[:e + D.size]
    v = (D[span:] - D[:-span]) / span                      # v[i]: delta's speed toward the far flank over i..i+span
    vmax = np.maximum.accumulate(v)
    floor = RECONTACT_MIN_QUANTA * max(angle_quantum_rad, 1e-12) / span
    stop = (v < RECONTACT_DROP * vmax) & (vmax > floor)
    stop[:2] = False
    tol_floor = RECONTACT_MIN_QUANTA * max(angle_quantum_rad, 1e-12)
    # delta's farthest travel from the entry in the window is the far flank (plus the coupling's twist): a contact
    # there, not the end of the coupling's untwist at the contact loss (the second drive's slow return traversals hold
    # still for 12 samples after it)
    travel = max(RECONTACT_MIN_TRAVEL_SHARE * float(np.max(D)), tol_floor)
    i0 = -1
    for i in np.flatnonzero(stop)[:RECONTACT_MAX_CANDIDATES]:
        # held: delta stays within RECONTACT_HOLD_SHARE of its travel for RECONTACT_HOLD samples (a contact; not the
        # coupling's untwist at the contact loss, after which delta goes on across the zone, nor a free turning
        # point, after which it goes back)
        at = i + span
        after = D[at:at + hold]
        if after.size < hold:
            break
        tol = max(RECONTACT_HOLD_SHARE * D[at], tol_floor)
        if D[at] >= travel and float(np.max(np.abs(after - D[at]))) <= tol:
            i0 = e + int(i)
            break
    if i0 < 0:
        return -1
    lo, hi = i0 - fit[0], i0 + span + fit[1]
    lo, hi = max(lo, e), min(hi, d.size)
    cands = range(max(i0 - search[0], lo + 4, e + 2), min(i0 + span + search[1], hi - 3))
    if hi - lo < 10 or len(cands) == 0:
        return i0 + span // 2
    k = np.arange(lo, hi, dtype=float)
    y = d[lo:hi] - d[lo]
    base = np.column_stack([np.ones(k.size), k - lo, (k - lo) ** 2])

    def hinge(g):
        h = np.clip(k - g, 0.0, None)
        return _lstsq_rss(np.column_stack([base, h * h, h * h * h]), y)

    best, _, _, _ = _profile(cands, hinge, i0 + span // 2)
    return int(best) - 1           # the flanks meet between samples: the row before the kink may carry load


def estimate_width(window: dict, entry_index: int, wheel_radius_m: float, sample_period_s: float,
                   gear_ratio: float = 1.0, flank_rad: Optional[float] = None, recontact: Optional[int] = None,
                   angle_quantum_rad: float = 0.0, contact_samples: int = 32,
                   contact_tolerance_rad: float = 2e-3) -> WidthResult:
    """K2 of one traversal from raw angles (module docstring), with its standard uncertainty.

    ``flank_rad``: the entry flank's delta level (learnt before the entry; default: the mean of the
    samples before the entry); ``recontact``: the first contact row (default: :func:`recontact_index`
    from the motor acceleration).
    """
    if "alpha1" not in window or "alpha2" not in window:
        return WidthResult(math.nan, math.nan, "no angles")
    d = np.asarray(window["alpha1"], float) - gear_ratio * np.asarray(window["alpha2"], float)
    e = int(entry_index)
    if not 2 <= e < d.size - 2:
        return WidthResult(math.nan, math.nan, "entry at the window's edge")
    f_entry = float(np.mean(d[:e])) if flank_rad is None else float(flank_rad)
    if recontact is None:
        acc, _ = motor_acceleration(window, wheel_radius_m, sample_period_s)
        recontact = recontact_index(acc, e, min_samples=samples(3, sample_period_s)) if acc is not None else -1
    g = int(recontact)
    r = float(wheel_radius_m)
    q2 = angle_quantum_rad ** 2 / 6.0               # two encoders, uniform quantisation error each
    step_in, step_before, step_after = d[e] - d[e - 1], d[e - 1] - d[e - 2], d[e + 1] - d[e]
    # a jump of delta at the entry (the slip scenario), not one quantisation step of a coarse encoder (2^13: the
    # steps around it are 0 and the entry's one count looked like a slip; the vector drive's K2 was 96 % off)
    slip = abs(step_in) > max(4.0 * max(abs(step_before), abs(step_after)), 10.0 * angle_quantum_rad,
                              contact_tolerance_rad, 1e-12)
    if slip:
        # the slip scenario: delta jumped off the flank and the motor turns back to the same flank; the
        # excursion, measured against the settled flank level after re-contact (an offset moved by the
        # slip cancels), is K2/r
        tail = d[-contact_samples:]
        if tail.size < contact_samples or np.ptp(tail) > contact_tolerance_rad:
            return WidthResult(math.nan, math.nan, "window ends out of steady contact", g)
        f_after = float(np.mean(tail))
        width = r * abs(f_after - d[e])
        se = r * math.sqrt(float(np.var(tail, ddof=1)) + step_after ** 2 / 12.0 + q2)
        return _positive(WidthResult(width, se, "same_flank", g))
    if RECONTACT_FROM_DELTA and not _delta_arrived(d, e, g, q_delta := _delta_quantum(d, e, angle_quantum_rad),
                                                   sample_period_s):
        # the motor's acceleration fell while delta was still crossing the zone: delta's own stop
        g_delta = delta_recontact(d, e, q_delta, sample_period_s)
        g = g_delta if g_delta >= 0 else g
    if g <= e + 2:
        return WidthResult(math.nan, math.nan, "no re-contact found", g)
    s = 1.0 if d[e] >= f_entry else -1.0          # direction in which delta left its flank
    if (d[g - 1] - d[g - 3]) * s <= 0:
        return WidthResult(math.nan, math.nan, BOUNCE_HOW, g)
    # a traversal: 2 K2/r from flank to flank, each end bracketed by the samples around the contact instant
    p_e, b_e = 0.5 * (d[e - 1] + d[e]), abs(step_in)
    p_g, b_g = 0.5 * (d[g - 1] + d[g]), abs(d[g] - d[g - 1])
    width = 0.5 * r * abs(p_g - p_e)
    se = 0.5 * r * math.sqrt((b_e ** 2 + b_g ** 2) / 12.0 + 2 * q2)
    return _positive(WidthResult(width, se, "traversal", g))


def _positive(res: WidthResult) -> WidthResult:
    """``res``, or no width where it is not above its own standard uncertainty: delta at the same level at both ends
    (a re-contact a few rows after the entry while delta dithers by a count, the vector drive's light load reversal on
    a 2^17 encoder, s15-11) is no K2; such a window (K2 = 0.0) was refused, ERROR "backlash_width_m: must be a finite
    number > 0, got 0.0", and set the detector's running K2 to 0.  A missing K2 never blocks a J1: the window goes on
    without one (FLANK_WINDOWS_WITHOUT_K2)."""
    se = res.se_m if math.isfinite(res.se_m) else 0.0
    if not math.isfinite(res.width_m) or res.width_m > se:
        return res
    return WidthResult(math.nan, math.nan, f"no width: delta at the same level at the entry and the re-contact ({res.how})",
                       res.recontact_index)
