"""Backlash-zone entries found without a known backlash width (pure numpy, never imports rclpy).

A real drive knows neither K2 nor where the zone's centre lies: its encoders have arbitrary offsets (the
load encoder's moves each time the line slips on the wheel) and K2 is the very quantity that changes.
:class:`FlankDetector` therefore works on the **relative angle**

    delta = alpha1 - N alpha2          (N = ``gear_ratio``, motor turns per load turn; any offsets)

and on what the clutch does, not on inequality (1):

* **Contact** (the clutch on a flank, transmitting the load torque): delta is nearly constant (a steady
  torque twists the coupling by a few mrad at most).  A run of ``contact_samples`` samples whose spread
  (max - min) is at most ``contact_tolerance_rad`` is taken as contact; the **flank level** F is their mean
  and the contact noise sigma their standard deviation.  F then follows slow drifts (wear, a load change)
  with a first-order filter of time constant ``flank_time_constant_s``.
* **Entry** (paper section 2: the backlash zone is entered): the first sample with |delta - F| above the
  **departure threshold** max(``k_sigma`` sigma, ``min_departure_rad``) — the clutch has left its flank.
  A slip of the line (alpha2 jumps, the load encoder's offset moves with it) moves delta by the same jump
  and is caught by the same test.  After an entry, F is forgotten and learnt again from the next contact
  (a slip is re-baselined there).
* **Entry sample** (where the window is centred): the first sample in the zone.  When the window holds
  ``m_el`` and a motor acceleration (``a1``, else the smoothed second difference of ``alpha1`` or the derivative
  of ``omega1``: :func:`motor_acceleration`) and ``nominal_inertia_kgm2`` is given,
  the departure sample is moved forward (:func:`single_mass_run`; with ``a1`` also back, :func:`back_to_load`) while
  the load-torque estimate T_L = m_el - J1_nom a1 / r still carries more than ``load_drop_fraction`` of the
  steady load torque: a coupling that unloads gradually (a drive that decelerates off its flank) is still in
  contact while delta starts to move (at most ``refine_samples`` samples).  In the simulator's slip
  scenario the departure sample is the entry sample already: without a1, a departure where delta jumps (a slip)
  is not moved at all.  Without a1, a departure that delta reached by drifting off its flank at a good share of its
  speed (a coupling untwisting as its torque ramps through zero: a light load reversal, whose departure comes 22-24
  samples after the contact loss) moves back to where delta's free curvature starts (:func:`free_departure`).  A
  traversal back inside another window, without a1 (delta may rest near the flank it left with no relative speed and
  look like a contact), moves back to where the motor equation in angle form starts to explain alpha1
  (:func:`free_motion_walk`).  Then, without a1 (and for a traversal back with a1 too), the entry is placed at the
  contact loss of a coupling model (:func:`coupling_entry`: the motor equation with a spring-damper torque acting
  while delta is beyond the edge it leaves, the double integrals in alpha1): a coupling that untwists off its flank
  under a falling load crosses the departure threshold before the contact is lost (the second drive's speed steps
  3-4 samples, the vector drive's heavy load reversals 8-9; a soft coupling's 22-23, beyond one search: a best
  candidate on the search's forward edge at a clear gain searches on from there, COUPLING_FORWARD_ROUNDS).  A window's
  own entry that nothing moved, without a1, goes back to where a spring carrying the steady m_el loses its contact
  (:func:`spring_entry`: a fast departure crosses the threshold after the contact loss, the vector drive's speed
  reversals 3 samples); with a1 it goes forward to the end of the load torque's ramp (:func:`load_hinge`: a noisy run
  starts early) -- both at a clear gain (SPRING_*, LOAD_HINGE_*), the spring also at a lower gain when its J lies
  within 2 % of J1_nom (SPRING_TIGHT_*: a light motor's speed reversal, whose motor equation hardly changes there).
  Without a1, a window's own entry then goes to a damped spring's contact loss (:func:`damped_spring_entry`: the torque
  scale and damping fitted, a re-contact on the flank it left inside the fit) when that explains alpha1 clearly better
  and lies 3 samples or more away (DAMPED_*;
  the DOL drive's slip drop, whose departure precedes its contact loss and whose gap lasts 17 samples).  On a coarse
  encoder (2^13), where those models are off, a window's own entry without a1 goes instead to the end of the
  coupling's untwist (:func:`untwist_entry`: delta at rest, untwisting at a constant rate, then free) when that model
  clearly beats one kink (UNTWIST_*).  With a1, a traversal back takes the angle walk's entry (the no-a1 path) when that
  lies RETURN_ANGLE_WALK_MIN_LEAD samples or more before the a1 path's (back_to_load's J, fitted over a gap of nearly
  constant torque, stops late).  Before all these rules an encoder's disc error (once and twice per revolution), fitted
  over the capture's last rows where the drive turns steadily, is subtracted from its angle (:func:`disc_error`), and,
  without a1, a torque estimate that reads a sample late is advanced by that sample (:func:`torque_late_gain`).  After
  them a window's own traversal moves forward from a damped coupling's separation (its torque k x + c x' at zero, about
  c/k before the zone) to where delta crosses the zone's edge, the steady twist |T0| / k from the flank level, k and c/k
  from the re-contact on the far flank (:func:`zone_edge_entry`; with a1 from its torque balance there,
  :func:`far_contact_model_a1`, and T0 less J1_nom a1).
* **Window**: ``samples_before_entry`` samples before the entry sample, the entry sample and
  ``samples_from_entry - 1`` after it, exactly as :class:`~jident_ros.stream.detector.BacklashDetector`'s
  (the entry at row 48 of 48 + 2000).  While a window is captured no new window starts; another entry
  inside the window sets :data:`~jident_ros.stream.layout.FLAG_SECOND_ENTRY` (information); it gets a window of
  its own only when its excursion ends in a contact across the zone (a traversal back: at least
  RETURN_MIN_SPAN_SHARE of the way to the running windows' other flank; a soft coupling's swing on the flank it
  reached is not one).  On a coarse encoder a window's edge scan takes an excursion back near the far flank that
  leaves it again at once for a bounce, not for the start of the traversal back (RETURN_TURN_SHARE).  A window whose
  own excursion comes back to the flank it left for fewer than ``contact_samples`` samples (no contact learnt, no
  departure seen) and then crosses the zone gives the crossing a capture of its own, as a traversal back, from delta's
  deepest return toward that flank after the window's entry (:meth:`FlankDetector._scan_rebound`, REBOUND_*: a DOL
  slip reversal's bounce and its crossing).  A window's own excursion that ends in a contact on the flank it left short
  of ``min_travel_rad`` (a same-flank torque change) keeps its window when, with m_el, delta passed the coupling's
  zero-twist point of the two contacts (SHALLOW_*: a slip drop's short gap), its entry and re-contact at that point.
  With m_el, a move deeper into the flank (with the torque its contact carries) needs ``deeper_travel_factor`` x
  ``min_travel_rad``, and is no entry however far it went when it ends in a contact carrying at least twice the torque
  of the same sign (DEEPER_CONTACTS: a soft coupling twisting under a speed step up); the moves back count their
  travel from the level before it while the contacts stay deeper.

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

Same batch API, events and drop reasons as :class:`~jident_ros.stream.detector.BacklashDetector` (which it
extends), so the windowing node and ``jident diagnose`` take either.  The result does not depend on how a
stream is cut into batches (tested).

Every sample count below that is a duration (the module constants, ``contact_samples``, ``refine_samples``) is
given in samples at 2 kHz, where it was chosen, and converted to the detector's ``sample_period_s``
(:mod:`jident_ros.stream.rate`: identical at 0.5 ms); noise quanta, shares, factors and counts of rounds stay as they
are.
"""
from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Sequence

import numpy as np

from jident_ros.stream.detector import BacklashDetector, Event, _positive
from jident_ros.stream.filters import first_order_lowpass, savgol_filter
from jident_ros.stream.layout import DEFAULT_CHANNELS, FLAG_BOUNCE, FLAG_SECOND_ENTRY, FLAG_SHALLOW_GAP, Window
from jident_ros.stream.rate import REFERENCE_SAMPLE_PERIOD_S, odd_samples, samples, samples_float

#: Detector names of the ``detector`` parameter.
DETECTORS = ("flank", "paper", "dynamics")


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


class _Tent(NamedTuple):
    """The excursion of the tracker's last entry: it counts as travelled once delta is ``need_rad`` beyond
    ``ref_rad`` on ``side``; ``deeper_from_nm``: the m_el of the contact it left when it moves deeper into the flank
    (with that torque; DEEPER_CONTACTS), else None."""

    ref_rad: float
    side: float
    need_rad: float
    deeper_from_nm: Optional[float] = None


@dataclass
class _FlankCapture:
    rows: list                 # arrays of rows from (departure - samples_before_entry) on
    count: int
    departure_row: int         # row of the departure sample inside the capture
    flank_rad: float           # the entry flank's level (delta)
    flank_sigma_rad: float
    second_entry_rows: list = field(default_factory=list)   # departures seen while capturing (capture rows)
    skip: bool = False         # short history: the transient is skipped, not captured
    pending: bool = False      # an entry inside another window: its own window only once its excursion ends on the
                               # other flank (a traversal), decided at the next contact
    start_row: int = 0         # stream row of the capture's first row
    returning: bool = False    # a traversal back inside another window (its flank: the other window's re-contact)
    after_row: int = -1        # a crossing after a bounce (REBOUND_*): its entry must lie after this stream row ...
    turn_row: int = -1         # ... and not before the bounce's re-contact (its deepest return, stream row); else at
    level_row: int = -1        # this stream row, where delta passes the window's entry level again (REBOUND_*)
    shallow: bool = False      # its excursion ended in a contact short of min_travel_rad (SHALLOW_*): a window only
                               # when it passed the zero-twist point, decided when it is complete


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


#: An entry inside a running window gets its own window only when its excursion took at least this many samples
#: to the contact on the other flank (a traversal takes time; a jump of delta -- the line's slip, an encoder glitch
#: -- is at its new level at once).
MIN_TRAVERSAL_SAMPLES = 4

#: With m_el and a1 (an accelerometer), the entry sample may move back this many samples before the departure, to
#: where the motor equation starts to hold (:func:`back_to_load`; the vector drive's return traversal
#: rests at the flank for 54 samples after the contact loss).  Without a1 the second difference of alpha1 is too
#: noisy for it (2^16 counts at 2 kHz: ~20 N m of torque noise): the gap estimator's change points refine it.
REFINE_BACK_SAMPLES = 128

#: Without a1, the entry sample may move back this many samples before the departure to the start of delta's free
#: curvature (:func:`free_departure`: a light load reversal leaves its flank with little relative speed, so delta
#: crosses the departure threshold 22-24 samples after the contact loss on the vector drive's 2^16 recordings) ...
DRIFT_BACK_SAMPLES = 40
#: ... fitted over this many samples before the earliest candidate and ...
DRIFT_PRE_SAMPLES = 10
#: ... this many from the departure on
DRIFT_POST_SAMPLES = 32
#: The move is taken only when delta was already drifting off its flank, in the departure's direction, at this share
#: of its speed at the departure (the coupling untwisting as its torque ramps through zero: 0.24-0.35 on the vector
#: drive's light load reversals; at most 0.05 on its speed steps, speed reversals and heavy load reversals and on
#: the second drive's speed steps, whose delta rests flat before a curvature onset that lies 8-26 samples before the
#: contact loss) -- chosen on the vector drive, checked on the second drive and ours (zoo report) ...
DRIFT_MIN_SPEED_SHARE = 0.15
#: ... significantly (z of the drift speed) ...
DRIFT_MIN_Z = 3.0
#: ... and the fit explains delta within this many times its noise (the flank's contact sigma, at least one
#: quantum / sqrt 12): a jump of delta (our simulator's slip) is not a curvature
DRIFT_MAX_RMS_SIGMAS = 3.0


#: free_departure's least squares at the first candidate of its search (DRIFT_BACK_SAMPLES before the departure, the
#: history allowing) locates no turn: the line runs through the whole search, whatever lies before it (the DOL drive's
#: light load reversal d6-03: delta flickers one count on its flank, untwists from 23 samples before the contact loss,
#: and the fit's edge, 40 before the departure, put the entry 33 early, a false entry, the traversal missed); the
#: departure stands.  Chosen on d6-03; over the thirty blind sets (docs/results.md, stop 38) found +7 vector and +9 DOL,
#: false entries -7 and -9, no J1 changed; vector s5-03's light load reversal went from 8 early to 32 late.  (A search
#: twice as far back at the edge gave the same entries on four drives: not kept.)  False: the edge taken, as before
DRIFT_NOT_AT_EDGE = True


def free_departure(delta: np.ndarray, departure: int, first: int, noise_rad: float,
                   back: Optional[int] = None, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> int:
    """The entry row moved back from ``departure`` (not before ``first``) to where delta's free curvature starts,
    without a1 (module docstring): delta over [e - DRIFT_PRE_SAMPLES, departure + DRIFT_POST_SAMPLES) is fitted by a
    line that turns C1 into a parabola at e (delta = a + v (t - e) + c/2 (t - e)_+^2: in contact a torque ramping
    through zero untwists the coupling at a constant rate; in the gap the relative motion is free, constant relative
    acceleration), e by least squares over [departure - back, departure]; the move is taken when the line's speed v
    is at least DRIFT_MIN_SPEED_SHARE of the departure speed v + c (departure - e), in its direction, with
    z >= DRIFT_MIN_Z, and the fit's rms is within DRIFT_MAX_RMS_SIGMAS x ``noise_rad``.  Else ``departure``.
    (Durations: samples at 2 kHz, converted to ``sample_period_s``'s; ``back`` default DRIFT_BACK_SAMPLES.)"""
    back = samples(DRIFT_BACK_SAMPLES, sample_period_s) if back is None else back
    pre, post = samples(DRIFT_PRE_SAMPLES, sample_period_s), samples(DRIFT_POST_SAMPLES, sample_period_s)
    lo_e = max(departure - back, first, pre + 2)
    lo, hi = lo_e - pre, min(departure + post, delta.size)
    if lo_e >= departure or hi - departure < post // 2:
        return departure
    t = np.arange(lo, hi, dtype=float)
    y = np.asarray(delta[lo:hi], float)
    y0 = float(y.mean())                          # centred: the normal equations stay well conditioned
    cand = np.arange(lo_e, departure + 1, dtype=float)
    X = np.stack([np.ones((cand.size, t.size)), t[None, :] - cand[:, None],
                  np.clip(t[None, :] - cand[:, None], 0.0, None) ** 2], axis=2)      # (candidates, samples, 3)
    XtX = np.einsum("kni,knj->kij", X, X)
    Xty = np.einsum("kni,n->ki", X, y - y0)
    try:
        coefs = np.linalg.solve(XtX, Xty[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return departure
    rss_all = np.sum((y - y0 - np.einsum("kni,ki->kn", X, coefs)) ** 2, axis=1)
    k = int(np.argmin(rss_all))                   # the first of equal ones, as a loop over the candidates would
    rss, e, coef, X = float(rss_all[k]), int(cand[k]), coefs[k], X[k]
    if e >= departure or not math.sqrt(rss / y.size) <= DRIFT_MAX_RMS_SIGMAS * noise_rad:
        return departure
    if DRIFT_NOT_AT_EDGE and k == 0 and lo_e > first:
        return departure                          # the least squares at the search's edge: no turn located (below)
    v, c2 = float(coef[1]), float(coef[2])
    v_dep = v + 2.0 * c2 * (departure - e)
    side = 1.0 if v_dep >= 0 else -1.0
    try:
        se_v = math.sqrt(float(np.linalg.inv(X.T @ X)[1, 1]) * rss / (y.size - 3))
    except np.linalg.LinAlgError:
        return departure
    if side * v >= DRIFT_MIN_SPEED_SHARE * abs(v_dep) and side * v >= DRIFT_MIN_Z * se_v:
        return e
    return departure


#: A slip that leaves part of the load on the coupling (the line slips on the wheel; the wheel stays) lets the coupling
#: untwist toward a new, smaller twist on the same flank without opening the gap: delta moves by (T0 - T1) / k and
#: settles there, the coupling torque never 0.  A real one-sided excursion carries delta past the zero-twist point
#: into the zone and back.  So a window's own entry (not a traversal back) whose excursion settles on the flank it
#: left, the coupling now carrying the same sign of torque and at most UNTWIST_MAX_TORQUE_SHARE of the steady T0
#: (a slip drop, not a return to the load it had), is dropped as a same-flank torque change (``flank_shifts``) when
#: delta's farthest travel never passes the zero-twist point z by UNTWIST_PAST_SHARE of z.  z comes from the two
#: steady contacts, the SPRING_TORQUE_ROWS before the departure (T0, the flank level F0) and the capture's last
#: UNTWIST_TAIL_ROWS (T1, F1): k = (T0 - T1) / (F1 - F0), z = T0 / k = (F1 - F0) T0 / (T0 - T1) (m_el's gain cancels;
#: on DOL set 1's d1-07 and set 2's untwists within 1 % of the truth's T0 / k).  The share: DOL set 1's untwist
#: d1-07 peaks 9-12 % short of z, its real slip gap d1-11 14 % past it, the DOL zoo's slip drops 40-66 % past it and
#: its slip sweep's soft coupling 7-11 % past it: 0.05, the order of the torque estimate's accuracy and of the motor
#: friction that z leaves in T0 -- chosen on DOL set 1 and the DOL zoo (slip sweep included)
UNTWIST_PAST_SHARE = 0.05
UNTWIST_MAX_TORQUE_SHARE = 0.5
UNTWIST_TAIL_ROWS = 200

#: A window's own excursion that ends in a contact on the flank it left short of min_travel_rad (the tracker's
#: same-flank torque change) runs on as a capture (with m_el) and, when complete, keeps its window when delta's
#: farthest travel passed the two contacts' zero-twist point z (UNTWIST_*'s z, its torque share and settled contact)
#: by SHALLOW_PAST_SHARE of z and by SHALLOW_PAST_QUANTA quanta of delta (its smallest step before the departure, at
#: least ANGLE_MODEL_FLOOR_RAD): the coupling let go and the motor ran into the zone, a slip drop's short gap, the
#: paper's case.  Else it is dropped (``flank_shifts``), as before; a later entry while it runs drops it too.  Chosen
#: on DOL set 1: its shallow slip drops' gaps (d1-01 30 dB, d1-05, d1-12: 7-8 samples) passed z by 20-40 %, its shallow
#: untwists (d1-02, d1-03, d1-09, d1-10: no gap) stayed 9-25 % short of it; the share is UNTWIST_PAST_SHARE's, the
#: quanta a floor for a coarse encoder, not tuned (delta's max is one quantum off at most; on the DOL zoo's slip sweep
#: at 2^13, a 0.77 mrad step, it refuses slip drops 20-34 % past z: no window there, as before).  False: every such
#: excursion dropped at its contact, as before
SHALLOW_GAPS = True
SHALLOW_PAST_SHARE = 0.05
SHALLOW_PAST_QUANTA = 2.0
#: ... its entry where delta first reaches z after the departure, its re-contact no later than where delta comes back
#: inside z (the coupling's twist is zero at both; DOL set 1's d1-05 without a1: the rules' entry +7 (the damped
#: spring's, DAMPED_*, fitted to a 17-sample gap), at z 0; DOL set 2's d2-11 with a1: the acceleration's and delta's
#: re-contact 37 samples late, the gap fit then lay in contact, a J1 published +37 %, with z's 1213 (truth 1213)
#: +1.3 %).  Only a bound: taken as the re-contact also where the rules put it earlier, it gave the DOL zoo's stiff
#: coupling (8-sample gap, 30 dB) the true re-contact and a J1 published +22.9 % by the gap fit.  False: the rules'
#: entry and re-contact
SHALLOW_AT_ZERO_TWIST = True


#: With m_el, a move deeper into the flank (delta moving with the torque its contact carries) that ends in a contact
#: deeper on that flank carrying m_el of the same sign, the contact it left at most UNTWIST_MAX_TORQUE_SHARE of it (the
#: untwist rule's share, mirrored: the torque at least doubled), is a same-flank torque change however far delta went:
#: the coupling twisted more under more torque (the tracker's deeper_travel_factor x min_travel_rad alone let a soft
#: coupling's 24 mrad twist under a speed step up through: vector set 14's s14-01, k 1.57e4 N m/rad, m_el -86 ->
#: -359 N m, the torque limit).  The level before the move stays the reference of the moves back while the contacts
#: lie deeper than it by more than the departure threshold (a ringing twist's swings back, and its untwist when the
#: torque falls back, count their travel from there).  The share, not "any more torque": our simulator's traversal
#: (the slip lets the motor run through the zone with its own torque) ends in a contact with 4 % more m_el of the
#: same sign (test_flank's raw recordings).  Chosen on vector set 14 (s14-01) and our simulator; False:
#: deeper_travel_factor alone, as before
DEEPER_CONTACTS = True

#: Two windows whose entries (absolute rows) lie this close are one traversal's: the second is not given out.
DUPLICATE_ENTRY_SAMPLES = 2

#: A return traversal found by a window's edge scan (:meth:`FlankDetector._scan_returns`) opens no capture when one
#: exists with its entry this close (the contact rule found it already); one whose entry lies later, up to where the
#: traversal reached the other flank, is replaced
RETURN_MATCH_SAMPLES = 8
#: ... or when a capture's departure lies earlier in the same excursion (after the scan was last re-armed at the
#: re-contact edge, before the scan's start): the contact rule left a contact it had learnt while delta rested near the
#: re-contact edge, where the scan still saw delta resting, so the two captures of one traversal lay more than
#: RETURN_MATCH_SAMPLES apart and gave two windows (the vector drive's 2^14 variant: +56 and +1; docs/your_drive.md's
#: small drive at 30 dB: -2 and a false entry 24 samples before the gap; the ninth round).  False: the rule before
RETURN_SAME_EXCURSION = True
#: ... and scans only a window whose delta stays at (or beyond) its re-contact edge this many samples after the
#: re-contact (a contact there; our simulator's slip excursion with a skewed Imu read as a 'traversal' rang around
#: the edge and gave two false windows)
RETURN_REST_SAMPLES = 8

#: An entry inside a running window gets a window of its own only when its excursion, ending in a contact, travelled
#: at least this share of the zone the running windows crossed (the distance from the flank it left to their farthest
#: flank level): a soft coupling's swing after its re-contact leaves a contact on the flank it reached and settles
#: 5.6 mrad away, beyond min_travel_rad, as its torque falls back (the vector drive with k x 0.3, heavy load reversal:
#: 0.04 of its 133 mrad; a false entry, J1 outside the plausible band) -- chosen on that variant; the zoo's and the
#: variants' traversals back travel 0.99-1.03 of it, a turning point inside the zone read as a contact 0.17 (the fast
#: speed loop's light load reversal: a bounce window 59 samples late, now not given)
RETURN_MIN_SPAN_SHARE = 0.5

#: On a coarse encoder (2^13), a window's edge scan (:meth:`FlankDetector._scan_returns`) takes an excursion from the
#: re-contact edge that went into the zone, came back within this share of the zone's span of that edge and turns
#: away from it again for a bounce (the motor met the far flank, shorter than a contact), not for the start of a
#: traversal back: the second drive's 2^13 recordings bounce off the far flank (delta back to within 3 mrad of its
#: 197 mrad span, 20 samples at the flank) before they traverse back, and the scan gave the bounce's start as the
#: traversal's entry (125 samples early; the traversal itself then had no window) -- chosen on the second drive, tested
#: on the vector drive, ours, the variants and the DOL drive.  Not on a fine encoder: the second drive's wide backlash
#: (K2 9-10 mm, 2^16 CSV, detector_zoo) turns 2-6 mrad short of the far edge inside the zone and traverses back in one
#: gap; read as a bounce, 10 of its 84 traversals back went 154-167 samples late (a turn at the quantum's resolution
#: looks the same: the rule bets on a contact there)
RETURN_TURN_SHARE = 0.1
#: ... and the traversal back from that bounce's brief contact starts where delta has left its turning depth by this
#: many departure thresholds (a contact that carried the bounce's torque untwists before it is lost: the second drive's
#: 2^13 traversals back after a bounce were entered 4-6 samples early at one threshold, 2-5 at 1.5, 0..-3 at 2, -2..+3
#: at 2.5) -- chosen on the second drive (the only model whose traversals back start from such a bounce)
RETURN_REST_DEPARTURES = 2.0

#: ... a bounce's excursion must have gone this share of the span into the zone (was 2 x RETURN_TURN_SHARE: the
#: second drive's 2^13 reverse J1 1.073 K2 2.5 mm recording bounces twice, its second bounce 12.3 mrad into a 68 mrad
#: zone, and its traversal back had no window) -- chosen on the second drive, where the turns inside the zone that
#: are not bounces (J1 1.160 K2 2.5 mm, 11.5 and 14.6 mrad in) are told by RETURN_FREE_TURN_*
RETURN_SHALLOW_TURN_SHARE = 0.15
#: ... and a turn counts as a bounce only when the motor did not run free through it: the motor equation in angle
#: form fitted over RETURN_FREE_TURN_HALF rows each side of the turn leaves more than RETURN_FREE_TURN_RMS x delta's
#: quantum / sqrt 12 (second drive 2^13: its turn without contact (J1 1.160 K2 2.5 mm forward) 0.96, its shallow
#: bounces 2.15, its deep ones 4.8-7.4; with 15 or 25 rows each side a turn and a shallow bounce overlap) -- chosen on
#: the second drive, tested on the others
RETURN_FREE_TURN_HALF = 35
RETURN_FREE_TURN_RMS = 1.5
#: ... the rest depth (RETURN_REST_DEPARTURES) after a shallow bounce (its excursion not beyond 2 x RETURN_TURN_SHARE
#: of the span: a contact at a lower torque, less to untwist; the second drive's shallow bounce's traversal back +6 at
#: 2, -1 at 1) -- chosen on the second drive's one such recording (clean and 30 dB), so fitted to it
RETURN_SHALLOW_REST_DEPARTURES = 1.0

#: A window's own excursion (after its entry) that left its flank by at most this share of the zone delta then crosses
#: in the window (:meth:`FlankDetector._scan_rebound`: a slip's bounce, not a traversal; RETURN_TURN_SHARE's 0.1, not
#: tuned: the DOL draws' slip reversals' bounces 0.008-0.034 of their zones: d1-01, d1-06, d3-03, d4-02, d4-04; a soft
#: coupling's untwist counts in the excursion: d11-03's, k 3.0e4 N m/rad, 0.101, its crossing missed; 0.15 since stop 37,
#: chosen on DOL set 11) ...
REBOUND_MAX_SHARE = 0.15
#: ... came back toward it by at least this many quanta of delta (its smallest step, at least ANGLE_MODEL_FLOOR_RAD and
#: the white noise of the contact before the window's entry: the contact's dither on those drives' other events 1-4
#: quanta, the slip reversals' returns 1.1-2.5 mrad, 13-54 quanta: chosen on d4-02 and d4-04, DOL set 4) ...
REBOUND_MIN_QUANTA = 4.0
#: ... and by at least this share of min_departure_rad (vector set 1's s1-02, a light load reversal on 2^17 encoders:
#: delta drifts 0.29 mrad off its flank after the window's entry, turns back by 0.29 mrad at low speed inside the zone
#: and crosses; its quantum is 0.048 mrad, the quanta gate passed it (a false entry, 32 samples before the gap); the DOL
#: slip reversals' returns 1.1-2.5 mrad) -- chosen on vector set 1, a check set, after it showed that false entry
REBOUND_MIN_DEPARTURE_SHARE = 0.5
#: ... to within this share of its farthest move off the flank (a re-contact on the flank it left, at a lower torque:
#: d4-02's coupling carries 50 N m there against 123 before; the slip reversals' -0.11 ... 0.44 on d1-01, d1-06, d3-03,
#: d4-02, d4-04) -- chosen on DOL set 4 (d4-02, d4-04) and looked at on sets 1 and 3, tested on sets 5 and 6; 0.5 missed
#: the crossings of d5-12, d9-04, d10-07 and d11-03 (0.50-0.63: a soft coupling's untwist is most of the excursion, and
#: the re-contact twists it back only partly), 0.7 since stop 37, chosen on DOL sets 5, 9, 10, 11
REBOUND_BACK_SHARE = 0.7

#: On a coarse encoder (delta's smallest step / sqrt 12 beyond FREE_MAX_NOISE_RAD: 2^13), a window's own departure
#: counts from where delta left its flank by this many counts (:meth:`FlankDetector._coarse_departure`): a contact on
#: one count has sigma 0 and its threshold min_departure_rad (2 counts of 2^13), and the DOL drive's coupling untwists
#: 4.8 counts (3.7 mrad under 187 N m) before its contact is lost: its 2^13 slip drops and slip reversals departing
#: from such a contact were entered 4-5 samples early (those from a contact dithering over two counts, threshold 3.2
#: counts: -2 ... -1) -- chosen on the DOL drive, tested on the second drive, the vector drive, ours and the variants
COARSE_DEPARTURE_QUANTA = 3.5
#: ... searched this many samples from the departure (the untwist's counts come within 6 samples on the DOL drive)
COARSE_DEPARTURE_SEARCH = 8


#: single_mass_run fits m_el = J acc + c (True) or m_el = J acc (False).
SINGLE_MASS_OFFSET = True
#: ... with |c| at most this share of the run's median |m_el| or of the steady |m_el| before the departure, the
#: larger (friction and a torque estimate's offset; a light gap torque does not shrink the bound).
SINGLE_MASS_OFFSET_MAX = 0.15


def single_mass_run(m_el: np.ndarray, acc: np.ndarray, departure: int, inertia_seed_kgm2: float,
                    pre_samples: int = 48, max_shift: int = 16, rel_tol: float = 0.01, k_sigma: float = 4.0,
                    iterations: int = 4, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S):
    """(entry row, re-contact row, J1 fitted) of the backlash gap from the dynamics, or None.

    Inside the zone the load torque on the motor is zero: m_el = J1 dω1/dt, one J1 for every sample (the
    gap estimator's model).  Starting from ``inertia_seed_kgm2`` (J1_nom) with a wide tolerance (25 % of
    |m_el|), the gap is the first run of samples from the departure on (entry at most ``max_shift`` after
    it) whose residual |m_el - J acc| stays within the tolerance, ended by two samples outside it; J is
    refitted by least squares over the run and the run found again with the tolerance
    max(k_sigma * noise, rel_tol * |m_el|), noise from the steady samples before the departure (there
    dω1/dt = 0), ``iterations`` times.  The entry is the first sample whose load torque has vanished; the
    re-contact row the first with load again.
    """
    n = m_el.size
    lo = max(departure - pre_samples, 0)
    pre = slice(lo, max(departure - 1, lo + 2))
    lag = samples(1, sample_period_s)      # differences over 0.5 ms: the filtered acceleration's correlation as at 2 kHz
    sm, sa = _noise(m_el[pre], lag), _noise(acc[pre], lag)
    # the run's end (2 samples outside the tolerance) and least length (3) are durations at 2 kHz: the acceleration
    # from alpha1 is filtered over the same time at any rate, its excursions span as many ms (at 4 kHz two samples
    # outside ended the second drive's 2^13 runs 1.75 ms early, the re-contact row with them, and its traversals back
    # were scanned from a wrong edge: 60-70 ms late).  Its start stays 3 samples within the tolerance, the earliest
    # the run can be seen (3 samples at 8 kHz put the vector drive's heavy load reversal at +1, 12 at +19)
    n_ok, n_bad, n_min = 3, samples(2, sample_period_s, 2), samples(3, sample_period_s)
    pre_load = abs(float(np.median(m_el[pre])))      # the steady torque before the departure, N m
    j = float(inertia_seed_kgm2)
    c = 0.0
    tol_rel = 0.25
    entry = end = None
    stop = min(n, departure + samples(4000, sample_period_s))
    for it in range(iterations + 1):
        res = np.abs(m_el[departure:stop] - j * acc[departure:stop] - c)
        tol = np.maximum(k_sigma * math.hypot(sm, j * sa), tol_rel * np.abs(m_el[departure:stop]))
        ok = res <= tol
        run3 = np.lib.stride_tricks.sliding_window_view(ok, n_ok).all(axis=1) if ok.size >= n_ok else ok[:0]
        if not run3[:max_shift + 1].any():
            return None
        e = int(np.argmax(run3[:max_shift + 1]))
        bad2 = (np.lib.stride_tricks.sliding_window_view(~ok[e:], n_bad).all(axis=1) if ok.size - e >= n_bad
                else ok[:0])
        if not bad2.any():
            return None
        g = e + int(np.argmax(bad2))
        if g - e < n_min:
            return None
        a, b = departure + e, departure + g
        aa = acc[a:b]
        if SINGLE_MASS_OFFSET and b - a >= 6 and np.ptp(aa) > 0:
            # m_el = J acc + c: c takes the motor's friction and the torque estimate's offset (the vector drive:
            # 1.2 N m Coulomb + 2 N m viscous, torque estimate +1.7 %); without it a 1 % tolerance broke the run
            (j_new, c_new), *_ = np.linalg.lstsq(np.column_stack([aa, np.ones_like(aa)]), m_el[a:b], rcond=None)
            j_new, c_new = float(j_new), float(c_new)
            c_max = SINGLE_MASS_OFFSET_MAX * max(float(np.median(np.abs(m_el[a:b]))), pre_load)
            if abs(c_new) > c_max:          # more than friction: a contact torque left in the run, not an offset
                c_new = math.copysign(c_max, c_new)
                den = float(aa @ aa)
                j_new = float(aa @ (m_el[a:b] - c_new)) / den if den > 0 else -1.0
        else:
            den = float(aa @ aa)
            if not den > 0:
                return None
            j_new, c_new = float(aa @ m_el[a:b]) / den, 0.0
        if not j_new > 0:
            return None
        if (a, b) == (entry, end) and it > 1:
            break
        entry, end, j, c = a, b, j_new, c_new
        tol_rel = rel_tol
    return entry, end, j


#: The entry moves back over a sample while the BACK_BLOCK samples before it, on average, are explained by the motor
#: equation fitted to the first BACK_FIT samples of the gap (m_el = J dω1/dt + c: the friction and the torque
#: estimate's offset in c) within max(BACK_Z standard errors, BACK_REL_TOL |m_el|).
BACK_BLOCK = 3
BACK_FIT = 48
BACK_Z = 3.0
#: ... or this share of |m_el| (the fitted J's error drifts the residual by a few % of m_el over the fit; the load
#: torque before a contact loss is the whole m_el)
BACK_REL_TOL = 0.05
#: ... with a relative lag of m_el and dω1/dt as a regressor (dm_el/dt, per sample), kept when the fit puts it within
#: +-this many samples (the vector drive's torque estimate and its a1 are 0.1-0.2 samples apart: its fast torque
#: changes left a residual of 10 N m without it)
BACK_MAX_LAG_SAMPLES = 4.0
#: ... and J fitted only where the samples resolve it: its standard error within this share of the seed J1_nom, else
#: the seed with the offset fitted to it -- a gap whose dω1/dt barely varies lets J and the offset trade off (the vector
#: drive's speed reversal at 30 dB: J 0.93 with c 72 N m, the entry kept 3 samples late; its light load reversal at
#: 30 dB: 15 late; the second drive's return traversal at 30 dB: 76 late).  Chosen on the vector drive's zoo (0.05 and
#: 0.1 equal there); 0.05 put the J1 1.073 variant's speed reversal at 30 dB 16 samples early (the seed 8 % off the
#: drive's J1 walked back into the contact), 0.1 not: the seed's error bounds what this can give, see results.md
BACK_J_MAX_REL_SE = 0.1
#: ... and the fitted constant c (the gap's friction and the torque estimate's offset) within this share of the motor's
#: base torque M_b (FlankDetector's ``base_torque_nm``; friction and windage are 0.5-3 % of M_b, a torque estimate's
#: offset a few %): a larger one is J and c traded off over a gap whose dω1/dt barely varies, not friction, and J goes
#: back to the seed; where the seed's own c is beyond it too, the motor equation over the gap is not credible and the
#: entry is not moved.  At 30 dB with an Imu the vector drive's speed reversals fitted J 1.39 for 1.22 with c 56 N m
#: (s7-10: 26 % of M_b; s20-08: 23 %, and with the seed still 22 N m, 10.3 %), which explained the coupled rows and the
#: steady running before the speed command: the entry walked 26 rows back into it (false entries in steady running).
#: Chosen on vector draws set 7 (the bound) and set 20 (the seed's c beyond it too), tested on the other 38 sets and
#: the zoos (docs/results.md, stop 41)
BACK_CONSTANT_MAX_REL_BASE = 0.10
#: With a1, a window's own entry then moves forward (never back) to the end of the load torque's ramp: the residual
#: m_el - J1_nom dω1/dt is fitted by c + h (e - k)_+ (a contact torque falling linearly to zero at e, then the gap's
#: friction and offset) over the LOAD_HINGE_BEFORE samples before the entry and LOAD_HINGE_AFTER from it, e within
#: +-LOAD_HINGE_SEARCH of the entry, least squares (:func:`load_hinge`): single_mass_run's run starts where the
#: residual is within 4 noise sigmas, early at 30 dB (the vector drive's heavy load reversals: -4; the hinge -2, as
#: clean) -- chosen on the vector drive, tested on the second drive and ours (zoo report)
LOAD_HINGE_BEFORE = 8
LOAD_HINGE_AFTER = 16
LOAD_HINGE_SEARCH = 6
#: ... when the hinge explains the residual this much better than the entry itself (RSS at the entry / at the hinge:
#: the vector drive's heavy load reversals at 30 dB 3.8-4.9, the second drive's speed steps at 30 dB 1.9-2.6; a speed
#: reversal at 30 dB, whose torque falls in an S-curve, went 0 -> +3 at 1.14) -- chosen on the vector drive, tested on
#: the second drive and ours
LOAD_HINGE_MIN_GAIN = 1.5



def _resolved(X: np.ndarray, y: np.ndarray, j_seed: float) -> bool:
    """Whether the least-squares J of y on X (J the first column) is resolved: its standard error within
    BACK_J_MAX_REL_SE of the seed."""
    n, p = X.shape
    if n <= p + 1:
        return False
    try:
        cov = np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return False
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    s2 = float(np.sum((y - X @ coef) ** 2)) / (n - p)
    return math.sqrt(max(float(cov[0, 0]) * s2, 0.0)) <= BACK_J_MAX_REL_SE * abs(j_seed)


def back_to_load(m_el: np.ndarray, acc: np.ndarray, entry: int, first: int, inertia_seed_kgm2: float,
                 end: Optional[int] = None, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S,
                 constant_max_nm: Optional[float] = None) -> int:
    """The entry sample moved back from ``entry`` (a sample in the gap), not before ``first``, to where the motor
    equation stops explaining the samples (the load torque is back): a departure that delta shows late (a coupling
    that leaves its flank with no relative speed -- a light load reversal, a return traversal resting at the flank
    -- or a stiff coupling's unloading twist below the threshold).  The equation m_el = J dω1/dt + c - tau dm_el/dt
    is fitted to the BACK_FIT samples from ``entry`` (before ``end``, the re-contact, when known; without tau when
    it leaves +-BACK_MAX_LAG_SAMPLES, J kept at the seed when dω1/dt does not vary there or the fit leaves 0.5..2 x
    the seed; with ``constant_max_nm``, N m, J at the seed where the fitted constant is beyond it, and ``entry``
    unchanged where the seed's constant is too: BACK_CONSTANT_MAX_REL_BASE); the entry moves back while the BACK_BLOCK
    residuals before it average within max(BACK_Z standard errors, BACK_REL_TOL |m_el|).  Reaching ``first`` means no
    load was found: ``entry`` is returned unchanged (its ``rel_tol`` keyword, never passed, went in stop 41)."""
    fit, block = samples(BACK_FIT, sample_period_s), samples(BACK_BLOCK, sample_period_s)
    m = min(fit, m_el.size - entry, (end - entry) if end is not None else fit)
    if m < 4 or first >= entry:
        return entry
    y, x = m_el[entry:entry + m], acc[entry:entry + m]
    dm = np.gradient(m_el)          # a relative lag tau of m_el and dω1/dt: m_el(t) = m(t - tau) ~ m - tau dm/dt
    max_lag = samples_float(BACK_MAX_LAG_SAMPLES, sample_period_s)      # tau in samples, bounded as a duration
    j = float(inertia_seed_kgm2)
    c, lag = float(np.mean(y - j * x)), 0.0
    if np.ptp(x) > 0:
        X = np.column_stack([x, np.ones(m), dm[entry:entry + m]])
        (jf, cf, lf), *_ = np.linalg.lstsq(X, y, rcond=None)
        if 0.5 * j <= jf <= 2.0 * j and abs(lf) <= max_lag and _resolved(X, y, j):
            j, c, lag = float(jf), float(cf), float(lf)
        else:
            (jf, cf), *_ = np.linalg.lstsq(X[:, :2], y, rcond=None)
            if 0.5 * j <= jf <= 2.0 * j and _resolved(X[:, :2], y, j):
                j, c = float(jf), float(cf)
            else:
                c = float(np.mean(y - j * x))      # J not resolved: the seed, the offset fitted with it
    if constant_max_nm is not None and abs(c) > constant_max_nm:
        # no friction that large: J traded against the constant (BACK_CONSTANT_MAX_REL_BASE); the seed's, else no move
        j, lag = float(inertia_seed_kgm2), 0.0
        c = float(np.mean(y - j * x))
        if abs(c) > constant_max_nm:
            return entry
    res = m_el - j * acc - c - lag * dm
    sigma = float(np.std(res[entry:entry + m], ddof=3)) if m > 3 else 0.0

    k = entry
    first = max(int(first), block)
    # the block spans BACK_BLOCK samples at 2 kHz; its limit is a mean's over at most BACK_BLOCK samples: the
    # residual's model error (J at its seed, the offset fitted over the gap) does not average down with more samples
    # per block (the vector drive's light load reversal with a1 at 4 kHz stopped 34 samples late with sqrt(2 BACK_BLOCK)),
    # a block of fewer samples (1 kHz: 2) has the larger noise of its mean
    root = math.sqrt(min(block, BACK_BLOCK))
    while k > first:
        blk = slice(k - block, k)
        lim = max(BACK_Z * sigma / root, BACK_REL_TOL * float(np.mean(np.abs(m_el[blk]))))
        if abs(float(np.mean(res[blk]))) > lim:
            return k
        k -= 1
    return entry



def _lstsq_rss(X: np.ndarray, y: np.ndarray) -> tuple:
    """(residual sum of squares, coefficients) of the least-squares fit of y on X's columns."""
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    return float(r @ r), coef


def _profile(candidates, fit, default: int, ref: int | None = None) -> tuple:
    """A change point profiled over ``candidates``: ``fit(e)`` gives (the residual measure, anything else) of the
    model with its change at e.  Returns (the e of the least measure, the first of equal ones; ``default`` when none is
    finite, the measure there, its 'anything else', the measure at ``ref``): the load hinge's, the free hinge's, the
    coupling model's and the spring model's searches alike."""
    best, best_val, best_extra, at_ref = default, math.inf, None, math.nan
    for e in candidates:
        val, extra = fit(e)
        if e == ref:
            at_ref = val
        if val < best_val:
            best, best_val, best_extra = e, val, extra
    return best, best_val, best_extra, at_ref


def load_hinge(m_el: np.ndarray, acc: np.ndarray, entry: int, inertia_kgm2: float,
               sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> tuple:
    """(row, gain) of where the load torque's ramp ends near ``entry`` (LOAD_HINGE_* constants): r = m_el - J1 dω1/dt
    fitted by c + h (e - k)_+ over the fixed rows [entry - LOAD_HINGE_BEFORE, entry + LOAD_HINGE_AFTER), for e within
    +-LOAD_HINGE_SEARCH of ``entry``; the e of the least residual sum of squares (the first of equal ones) and the gain
    RSS(entry) / RSS(e).  (``entry``, 1.0) when the rows are not there."""
    lo, hi = entry - samples(LOAD_HINGE_BEFORE, sample_period_s), entry + samples(LOAD_HINGE_AFTER, sample_period_s)
    search = samples(LOAD_HINGE_SEARCH, sample_period_s)
    if lo < 0 or hi > m_el.size:
        return entry, 1.0
    k = np.arange(lo, hi, dtype=float)
    y = np.asarray(m_el[lo:hi], float) - float(inertia_kgm2) * np.asarray(acc[lo:hi], float)
    best, best_rss, _, rss_entry = _profile(
        range(max(entry - search, lo + 1), min(entry + search, hi - 2) + 1),
        lambda e: _lstsq_rss(np.column_stack([np.ones(k.size), np.clip(e - k, 0.0, None)]), y), entry, entry)
    return best, (rss_entry / best_rss if best_rss > 0 else 1.0)

#: Without a1, a return traversal's entry (delta resting near the flank it left with no relative speed, read as a
#: contact: the second drive's and the vector drive's traversals back were entered 26-138 samples late) moves back
#: while the motor equation in angle form still explains alpha1 (:func:`free_motion_start`): fitted over the
#: FREE_FIT_SAMPLES samples from the departure ...
FREE_FIT_SAMPLES = 48
#: ... walked back while the fit's rms over [s, departure + FREE_FIT_SAMPLES) stays within this factor of the rms
#: of the fit from the departure (the quantisation noise: alpha1 of a free motor is a + v t + Phi / J + c t^2 / 2
#: to the encoder's quantum; a contact's load torque bends it away) -- chosen on the vector drive's return
#: traversals (rms 2.5-2.7e-5 rad over the free samples; x 1.18 with 12 samples of contact in the fit, x 1.5 with
#: 15), checked on the second drive's (x 1.1 up to 4 samples before the true entry, x 1.5 at 6) and ours
FREE_RMS_FACTOR = 1.25
#: ... then placed where a torque ramping to zero meets the free motion: a hinge (e - t)_+^3 in alpha1 (a contact
#: torque falling linearly to zero at e, double-integrated) fitted over FREE_HINGE_PRE samples before each candidate
#: e and FREE_FIT_SAMPLES after it, e from FREE_HINGE_BACK before the walk's end to FREE_HINGE_FWD after it, least
#: squares (the walk ends where the contact's load becomes visible, 5-23 samples before the true entry)
FREE_HINGE_PRE = 24
FREE_HINGE_BACK = 8
FREE_HINGE_FWD = 24
#: The walk needs alpha1 resolved to this rms (rad) around the free fit: a 2^16 encoder gives 2.5-2.8e-5 (its
#: quantum / sqrt 12), a 2^13 one 2.1-2.3e-4, whose walk on the vector drive ran 51 samples back through a light
#: contact it could not see (a false entry) -- chosen on the vector drive, checked on the second drive
FREE_MAX_NOISE_RAD = 1.0e-4
#: ... the walk itself (free_motion_walk) refuses only above this rms: the geometric mean of a 2^14 encoder's
#: quantum / sqrt 12 (1.1e-4) and a 2^13 one's (2.2e-4, the false entry above).  FREE_MAX_NOISE_RAD (1.0e-4) lies within
#: the rms a 2^14 encoder's free fit scatters over (0.99-1.13e-4 on the same traversal back, captured at two
#: departures): the vector drive's 2^14 variant had its traversals back refused by one capture (+56/+58, the contact
#: rule's departure on a settling flank) and walked by the other (+1) -- chosen there (the ninth round), tested on the
#: zoo and the DOL zoo (their 2^13 walks stay refused, their 2^16 ones unchanged) and the other variants
FREE_WALK_MAX_NOISE_RAD = 1.56e-4
#: The angle models' own error (rad): the free motor (free_motion_walk) and delta's free curvature (free_departure)
#: hold the samples no better than this however fine the encoder, so their rms gates count from it at least.  Their
#: factors were chosen on 2^16 encoders, where the quantum / sqrt 12 (2.8e-5) stood for it; the free fits' rms there
#: is 2.5-2.8e-5 (above).  On 2^20 encoders (the vector drive's variant, 1.7e-6) the gates counted from the quantum
#: and failed on the models' own error: the light load reversal's line-then-parabola (rms 2.5e-5) was refused, +23,
#: and the traversal back's walk stopped 17 samples late (both 0 with the floor).  The value is the lower end of the
#: 2^16 rms, not tuned; on a 2^16 encoder whose quantum is configured it changes nothing
ANGLE_MODEL_FLOOR_RAD = 2.5e-5


def _double_integral(m_el: np.ndarray, sample_period_s: float) -> np.ndarray:
    """Phi(k) = sum_{j<k} sum_{i<=j} m_el(i) T_s^2 (rectangle rule; a free motor: alpha1 = a + v k + Phi / J)."""
    v = np.cumsum(np.asarray(m_el, float)) * sample_period_s
    phi = np.zeros(v.size)
    phi[1:] = np.cumsum(v[:-1]) * sample_period_s
    return phi


def _free_columns(k: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """The free motor's regressors (1, k, Phi, k^2), scaled to order 1."""
    ks = k / max(float(np.abs(k).max()), 1.0)
    return np.column_stack([np.ones_like(ks), ks, phi / max(float(np.abs(phi).max()), 1e-300), ks * ks])


def free_motion_start(alpha1: np.ndarray, m_el: np.ndarray, departure: int, first: int, sample_period_s: float,
                      quantum_rad: float = 0.0) -> int:
    """:func:`free_motion_walk`'s entry (its hinge's)."""
    return free_motion_walk(alpha1, m_el, departure, first, sample_period_s, quantum_rad)[1]


def free_motion_walk(alpha1: np.ndarray, m_el: np.ndarray, departure: int, first: int, sample_period_s: float,
                     quantum_rad: float = 0.0) -> tuple:
    """The entry row moved back from ``departure`` (not before ``first``) to where the motor started to run free,
    without a1 (module constants FREE_*): alpha1 = a + v k + Phi(k) / J + c k^2 / 2 (Phi the double integral of m_el;
    a, v, 1/J and c -- friction, the torque estimate's offset -- free) fitted over [s, departure + FREE_FIT_SAMPLES);
    s walks back while the rms stays within FREE_RMS_FACTOR x the rms from the departure (at least the quantum /
    sqrt 12; with the torque estimate's white noise through Phi / J, which grows with the fit's length, added); the
    entry is then refined by a hinge (a contact torque ramping to zero at e) around the walk's end.
    (walk's end, entry); (``departure``, ``departure``) when the walk does not move (the samples before it carry
    load)."""
    n = alpha1.size
    fit, pre = samples(FREE_FIT_SAMPLES, sample_period_s), samples(FREE_HINGE_PRE, sample_period_s)
    end = min(departure + fit, n)
    lo = max(int(first), pre)
    if end - departure < fit // 2 or lo >= departure:
        return departure, departure
    phi_all = _double_integral(m_el, sample_period_s)
    rows = np.arange(lo, end)
    k = (rows - departure).astype(float)
    X = _free_columns(k, phi_all[lo:end] - phi_all[departure])
    y = np.asarray(alpha1[lo:end], float)
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    y = y - X @ beta                     # a small residual: the normal equations below keep their precision
    # fits over [s, end) for every s in lo .. departure: reverse cumulative normal equations
    P = np.cumsum((X[:, :, None] * X[:, None, :])[::-1], axis=0)[::-1]
    q = np.cumsum((X * y[:, None])[::-1], axis=0)[::-1]
    yy = np.cumsum((y * y)[::-1])[::-1]
    m = departure - lo + 1                       # candidates s = lo + i, i < m
    try:
        b = np.linalg.solve(P[:m], q[:m, :, None])[..., 0]
    except np.linalg.LinAlgError:
        return departure, departure
    rss = np.maximum(yy[:m] - np.einsum("ki,ki->k", b, q[:m]), 0.0)
    dof = (end - rows[:m] - 4).astype(float)
    rms = np.sqrt(rss / np.maximum(dof, 1.0))
    noise = max(float(rms[-1]), quantum_rad / math.sqrt(12.0), ANGLE_MODEL_FLOOR_RAD)
    if not noise <= FREE_WALK_MAX_NOISE_RAD:
        return departure, departure        # a coarse encoder: a light contact's load is below its resolution
    # the torque estimate's white noise enters alpha1 through Phi / J, double-integrated: after the free fit's (1, k,
    # k^2) its residual's mean square grows as the fit's length L cubed (an integrated random walk detrended by a
    # quadratic: sigma^2 T_s^4 L^3 / 2520 / J^2), so the limit counts that growth beyond the departure's own fit (at
    # 30 dB a fit twice as long read 1.3 x the departure's rms with no contact in it: the walk stopped in the gap, and
    # the vector drive's traversals back went +17 ... +23)
    inv_j = abs(float(beta[2] + b[-1][2])) / max(float(np.abs(phi_all[lo:end] - phi_all[departure]).max()), 1e-300)
    torque_rad = _noise(np.asarray(m_el[departure:end], float)) * inv_j * sample_period_s ** 2
    length = (end - rows[:m]).astype(float)
    limit = FREE_RMS_FACTOR * np.sqrt(noise * noise + torque_rad ** 2 * np.maximum(length ** 3 - (end - departure) ** 3,
                                                                                      0.0) / 2520.0)
    bad = np.nonzero(rms > limit)[0]
    if bad.size == 0:
        return departure, departure        # no load seen before the departure within reach: nothing says where the gap began
    start = int(bad[-1]) + 1 + lo           # the earliest s of the unbroken run up to the departure
    if start >= departure:
        return departure, departure
    # the hinge: alpha1 = free motion - h (e - k)_+^3 (a contact torque falling linearly to zero at e, double-
    # integrated) over [e - FREE_HINGE_PRE, e + FREE_FIT_SAMPLES), e from FREE_HINGE_BACK before the walk's end to
    # FREE_HINGE_FWD after it (not past the departure); the e of the least mean square residual
    def hinge(e):
        a, z = e - pre, min(e + fit, n)
        kk = np.arange(a, z, dtype=float) - e
        Xh = np.column_stack([_free_columns(kk, phi_all[a:z] - phi_all[e]),
                              (np.clip(-kk, 0.0, None) / pre) ** 3])
        rss, _ = _lstsq_rss(Xh, np.asarray(alpha1[a:z], float) - float(alpha1[e]))
        return rss / max(z - a - 5, 1), None

    best = _profile(range(max(start - samples(FREE_HINGE_BACK, sample_period_s), lo),
                          min(start + samples(FREE_HINGE_FWD, sample_period_s), departure) + 1), hinge,
                    departure)[0]
    return start, best


#: With a1, a traversal back's entry moves on to the angle walk's (:meth:`FlankDetector._angle_walk_entry`, the no-a1
#: path: free_motion_walk, then the coupling model) when that lies this many samples or more before back_to_load's
#: (then the coupling model's): each walks back while its free-motor model explains the samples, and back_to_load's
#: J, fitted over a gap of nearly constant torque, absorbs the torque estimate's error -- on the vector drive's clean
#: speed steps (JointState+Imu, CSV) it stopped 11-24 samples after the contact loss, where the angle walk finds it
#: (0 / -1, as without a1).  Closer, the angle walk is no better: it leads by at most 2 on the second drive (there one
#: -2 -> -3 with any lead taken, 8 such windows) and by 5-6 on two variants' 30 dB traversals back (narrow backlash,
#: J1 1.073: both within +-2 -> -4 / -6 at a lead of 4, the first value tried).  Chosen on the vector drive (leads
#: 12-24), tested on the second drive, the DOL drive (no such traversal), ours and the 15 variants (docs/results.md,
#: "Entry placement, fifth round")
RETURN_ANGLE_WALK_MIN_LEAD = 8
#: A traversal back's walk (:meth:`FlankDetector._angle_walk_entry`) then moves forward to where the motor equation with
#: the nominal J1 holds (:func:`nominal_coupling_entry`): the walk's free fit takes J free, and a soft coupling that
#: untwists while the braking torque relaxes (the coupling still carries 230 -> 0 N m over 35 samples) is explained by
#: a J 2.5-3.3 times J1_nom, so the walk took the untwist for free motion ('several at once': the return traversal's
#: entry 37 samples before the zone, outside the zoo's 20-sample match: 3 false entries).  With J fixed the untwist
#: rows fail the coupling model clearly (a gain of 2.5-6.5 at the walk's end) and the search stops at the contact loss.
#: No threshold of its own: the first move needs COUPLING_MIN_GAIN (chosen on the vector drive), later moves a better
#: fit (COUPLING_MIN_GAIN_FORWARD's rule), the rms gate is the walk's FREE_WALK_MAX_NOISE_RAD (the 2^14 variant), the
#: reach the window's forward room.  Nothing was chosen on 'several at once' (a validation drive: tested there only).
#: With a1 the same search follows back_to_load's and the coupling model's entry when the walk does not lead by
#: RETURN_ANGLE_WALK_MIN_LEAD (the base drive's 30 dB traversal back -3 -> 0, with 'stamping jitter 50 µs', 'CiA 402
#: units', 'coarse torque', 'load encoder reversed'; no variant lower)
RETURN_NOMINAL_J = True
#: ... with the torque estimate's lag free in that fit: Phi(m_el(t - tau)) = Phi(m_el) - tau S(m_el) to first order (S
#: the single integral), a column with a free coefficient.  With J fixed and no lag term, a torque estimate a sample late
#: or smoothed by 2 ms misfits wherever m_el moves fast (the speed step's transient), and the search walked into the gap:
#: 'torque one sample late' -1 -> +22 (30 dB), 'smoothed torque 2 ms' -2 -> +34 -- chosen on those two variants
NOMINAL_J_FREE_LAG = True
#: ... then on with the lag left out (m_el as read), by this many samples at most: over a few samples a contact torque
#: ramping to zero and a torque estimate's lag look alike, and the lag's column took the base drive's last 3 samples of
#: contact (its 30 dB traversal back: -3; without the lag column 0, as on the 'stamping jitter 50 µs', 'CiA 402 units'
#: and 'coarse torque' variants), while a lag the variants declare move the lag-free search 6 samples or more ('torque
#: one sample late', 'smoothed torque 2 ms': clean traversals back -1 -> +6, 0 -> +6 at 6).  4 chosen on the base drive
#: (3) and those two (6); 5 also took 'narrow backlash''s 30 dB traversal back (-4 -> +1), a sample's margin: not taken
NOMINAL_J_UNLAGGED_MAX_MOVE = 4


#: Without a1, a window's own entry that delta left gradually (a coupling untwisting as its load falls, so delta
#: crosses the departure threshold before the contact is lost: the vector drive's heavy load reversals 8-9 samples
#: early) moves to the contact loss of a coupling model (:func:`coupling_entry`): alpha1 = a + v k + (Phi - K Psi -
#: D Psi') / J + c k^2 / 2, the contact torque K pen + D pen' of delta's penetration beyond the edge it leaves at
#: the candidate entry, fitted over COUPLING_FIT_BEFORE samples before the departure and COUPLING_FIT_AFTER from it
#: (before a short gap's re-contact: the second drive's 2.5 mm gaps last 30 samples), candidates within
#: +-COUPLING_SEARCH samples ...
COUPLING_FIT_BEFORE = 52
COUPLING_FIT_AFTER = 32
COUPLING_SEARCH = 12
#: ... taken only when it explains alpha1 this much better than the departure itself (residual sum of squares at the
#: departure / at the best candidate) -- chosen on the vector drive (heavy load reversals 1.8-2.3; its speed steps,
#: light load reversals and speed reversals 1.0-1.3, where the model's best lay up to 9 samples off), tested on the
#: second drive (1.0-1.15: unchanged)
COUPLING_MIN_GAIN = 1.5
#: A forward move (the contact still loaded after delta's departure: the second drive's speed steps, gains 1.0-1.15,
#: -3/-4 -> -2..-1) needs no more than a better fit; so does the coupling model's step after a traversal back's walk
#: (free_motion_start's hinge put the second drive's at +3, the vector drive's at -6; the coupling model at -2..+1),
#: with a1 after back_to_load too.  With a1 a window's own entry is not moved (its light load reversals went 5-11
#: samples late at gains 1.02-1.08, the heavy ones' gains 1.02-1.15 are no larger)
COUPLING_MIN_GAIN_FORWARD = 1.0
#: Without a1, a window's own entry whose best candidate lies on the search's forward edge searches again from there,
#: at most this many searches in all (COUPLING_SEARCH x this many samples forward): a soft coupling untwists far beyond
#: the departure threshold before the contact is lost (the vector drive with k x 0.3, heavy load reversal: 13 mrad
#: under 0.8 rated torque, the departure 22-23 samples early; two searches), when the edge explains alpha1
#: COUPLING_MIN_GAIN times better than the search's centre (that variant 1.89-1.98, the heavy load variant's heavy
#: load reversal 1.63: -13 -> 0; the fast speed loop's and the more friction variant's speed reversals, whose best
#: lay on the edge at gains 1.02-1.20, walked 11-21 samples late without it) -- chosen on the soft coupling variant,
#: tested on the zoo's three drives and the other variants (docs/results.md, "A soft coupling's contact loss")
COUPLING_FORWARD_ROUNDS = 3


def _coupling_fit(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, centre: int, side: float,
                  sample_period_s: float, inertia_kgm2: Optional[float] = None, free_lag: bool = True):
    """(best candidate, its RSS, the RSS at ``centre``, samples in the fit) of :func:`coupling_entry`'s search
    around ``centre``; None when the rows are not there.  ``inertia_kgm2``: J fixed there (Phi / J taken off alpha1,
    the Phi column dropped; the torque's lag free with ``free_lag`` and NOMINAL_J_FREE_LAG), else free."""
    ts = sample_period_s
    search = samples(COUPLING_SEARCH, ts)
    lo, hi = centre - samples(COUPLING_FIT_BEFORE, ts), centre + samples(COUPLING_FIT_AFTER, ts)
    if lo < 1 or hi > alpha1.size or centre - search < lo + 2:
        return None
    k = np.arange(lo, hi, dtype=float) - centre
    phi = _double_integral(m_el[lo:hi], ts)
    base = _free_columns(k, phi)
    y = np.asarray(alpha1[lo:hi], float)
    if inertia_kgm2 is not None:
        base, y = base[:, [0, 1, 3]], y - phi / inertia_kgm2
        if NOMINAL_J_FREE_LAG and free_lag:      # the torque estimate's lag, free (first order: its single integral)
            lag = np.cumsum(np.asarray(m_el[lo:hi], float)) * ts
            lag = lag - lag.mean()
            base = np.column_stack([base, lag / (float(np.abs(lag).max()) or 1.0)])
    y = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
    d = np.asarray(delta[lo:hi], float)
    rate = np.gradient(d) / ts
    def coupling(e):
        edge = 0.5 * (delta[e - 1] + delta[e])
        pen = np.clip(-side * (d - edge), 0.0, None)
        pen[e - lo:] = 0.0
        cols = [_double_integral(pen, ts), _double_integral(rate * (pen > 0), ts)]
        return _lstsq_rss(np.column_stack([base] + [c / (float(np.abs(c).max()) or 1.0) for c in cols]), y)

    best, best_rss, _, rss_centre = _profile(range(centre - search, centre + search + 1), coupling,
                                             centre, centre)
    return best, best_rss, rss_centre, y.size




#: Without a1, a window's own entry is placed by the motor-equation models (coupling, spring, damped spring, ramp),
#: which take the torque estimate's timing for the angles': their gates were chosen on drives whose m_el lags alpha1 by
#: about TORQUE_LAG_REF samples (where the coupling fit's RSS over a shift of m_el is least on the vector drive's speed
#: events: 0-0.5).  A drive that reports its torque a sample later moved the coupling model's entry forward and the
#: damped spring's back (the 'torque one sample late' variant's speed reversals +6/+7, speed steps -4/-5).  So, on a
#: fine encoder and not after a jump of delta, the coupling fit of :func:`coupling_entry` around the departure is made
#: with m_el shifted by TORQUE_LAG_REF and by TORQUE_LAG_REF + 1 sample (:func:`torque_late_gain`); when the second
#: explains alpha1 TORQUE_LATE_MIN_GAIN times better, m_el is advanced by one sample before the rules run ...
TORQUE_LAG_REF = 0.5
#: ... (gains on 'torque one sample late', where it was chosen: speed steps 1.11/1.13, speed reversals 1.13/1.38, load
#: reversals <= 1.02 (a load reversal's m_el hardly changes through the fit: nothing to time); elsewhere on fine
#: encoders at most 1.06 -- 1 kHz's 30 dB speed step, the reversed load encoder's speed reversal 1.05, the DOL drive's
#: slip drops <= 1.04 -- but the smoothed torques' speed events 1.06-1.82: a 2 ms filter lags by more than a sample;
#: advancing m_el by 2-3 samples put the 5 ms filter's speed reversals 0/+1 -> +20/+21, so one sample is all that is
#: advanced: docs/results.md, "Entry placement, eleventh round")
TORQUE_LATE_MIN_GAIN = 1.1


def shifted(x: np.ndarray, lag: float) -> np.ndarray:
    """x(k + lag) by linear interpolation (the last value held beyond the end)."""
    n = np.arange(np.size(x), dtype=float)
    return np.interp(n + float(lag), n, np.asarray(x, float))


def torque_late_gain(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, departure: int, side: float,
                     sample_period_s: float) -> float:
    """RSS of :func:`coupling_entry`'s fit around ``departure`` (its best candidate) with m_el shifted by
    TORQUE_LAG_REF (samples at 2 kHz) / the same with m_el one sample later still; 1.0 when the rows are not
    there."""
    ref = samples_float(TORQUE_LAG_REF, sample_period_s)
    rss = []
    for lag in (ref, ref + 1.0):
        got = _coupling_fit(alpha1, delta, shifted(m_el, lag), departure, side, sample_period_s)
        if got is None or not got[1] > 0:
            return 1.0
        rss.append(got[1])
    return rss[0] / rss[1]


#: An encoder's disc errors (a once- and a twice-per-revolution angle error: eccentricity and tilt, 0.2 / 0.1 mrad on
#: the 'encoder disc errors' variant, 4-7 times a 2^16 count's quantisation noise) bend alpha1 and delta over the
#: rules' fits, which take them for the motor's and the coupling's motion (that variant's light load reversal -11, heavy
#: -7, traversal back +24).  The error is a function of the encoder's own angle, the same every revolution: before the
#: rules, each angle (alpha1, alpha2) is fitted over the capture's last DISC_TAIL_SAMPLES rows (the contact after the
#: event, the drive running steadily again) by a polynomial of degree DISC_DEGREE in time plus sin/cos of the angle and
#: of twice the angle (:func:`disc_error`), when those rows turn DISC_MIN_REVOLUTIONS or more one way (the net turn at
#: least DISC_MIN_NET_SHARE of the path: a cubic cannot bend like three periods of a sine), and the harmonics are
#: subtracted over the whole capture where they explain those rows DISC_MIN_GAIN times better (rms without / with
#: them) and leave no more than DISC_MAX_RMS_FLOORS x the encoder's own noise (its quantum / sqrt 12, the quantum the
#: smallest step of the angle's second difference, at least ANGLE_MODEL_FLOOR_RAD): smooth motion plus the disc error,
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


def _disc_columns(angle: np.ndarray) -> np.ndarray:
    return np.column_stack([np.sin(angle), np.cos(angle), np.sin(2.0 * angle), np.cos(2.0 * angle)])


def disc_error(angle: np.ndarray, first: int, end: int) -> Optional[np.ndarray]:
    """The coefficients of sin/cos(angle), sin/cos(2 angle) of an encoder's disc error (DISC_* constants) fitted over
    rows ``first`` .. ``end`` of ``angle``; None when those rows do not qualify or the harmonics do not explain them."""
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
    steps = np.abs(np.diff(seg, 2))
    steps = steps[steps > 1e-9]
    floor = max(float(steps.min()) / math.sqrt(12.0) if steps.size else 0.0, ANGLE_MODEL_FLOOR_RAD)
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


def disc_corrected(angle: np.ndarray, sample_period_s: float) -> tuple:
    """(``angle`` with its encoder's disc error taken off, the coefficients (:func:`disc_error` over the last
    DISC_TAIL_SAMPLES rows at 2 kHz, converted to the recording's rows, else over the last DISC_SHORTER_TAILS rows)),
    or (``angle``, None) where it shows none: the gap stage's (jident_ros/identify/gap.py) and the detector's
    (FlankDetector._disc_corrected)."""
    x = np.asarray(angle, float)
    coef = None
    for tail in (DISC_TAIL_SAMPLES, *DISC_SHORTER_TAILS):
        coef = disc_error(x, x.size - samples(tail, sample_period_s), x.size)
        if coef is not None:
            break
    return (x, None) if coef is None else (x - _disc_columns(x) @ coef, coef)


def coupling_entry(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, departure: int, side: float,
                   sample_period_s: float, rounds: int = 1) -> tuple:
    """(entry row, gain, rms) of a coupling model's contact loss near ``departure`` (COUPLING_* constants): for each
    candidate e the contact torque acts while delta is beyond the edge delta had at e (on the side opposite to
    ``side``, the direction delta departs to) and not from e on; alpha1 = a + v k + b1 Phi + b2 Psi + b3 Psi_d +
    c k^2 (Phi, Psi, Psi_d the double integrals of m_el, the penetration and its rate) by least squares over one
    sample set; the e of the least residual and the gain RSS(departure) / RSS(e).  (departure, 1.0) when the rows are
    not there.  ``rounds`` > 1: a best candidate on the search's forward edge that explains alpha1 COUPLING_MIN_GAIN
    times better than the search's centre starts another search there (at most ``rounds`` searches, forward only: a
    soft coupling untwists beyond the search before its contact is lost, see COUPLING_FORWARD_ROUNDS); the gain is
    then the last search's."""
    got = _coupling_fit(alpha1, delta, m_el, departure, side, sample_period_s)
    if got is None:
        return departure, 1.0, math.inf
    rss_dep = got[2]
    centre, search = departure, samples(COUPLING_SEARCH, sample_period_s)
    for _ in range(int(rounds) - 1):
        if got[0] != centre + search or not got[2] >= COUPLING_MIN_GAIN * got[1]:
            break           # not on the forward edge, or not a clear gain there (the speed reversals: 1.02-1.2)
        nxt = _coupling_fit(alpha1, delta, m_el, got[0], side, sample_period_s)
        if nxt is None:
            break
        centre, got = got[0], nxt
    best, best_rss, rss_centre, n = got
    if not best_rss < rss_centre * (1.0 - 1e-9) or abs(best - centre) >= search:
        # no candidate explains alpha1 better, or the best lies on the search's edge (the minimum is beyond it: the
        # model locates nothing there; a traversal back 76 samples late went to +88)
        return departure, 1.0, math.sqrt(rss_dep / max(n - 6, 1))
    gain = rss_centre / best_rss if best_rss > 0 else 1.0
    return best, gain, math.sqrt(best_rss / max(n - 6, 1))


def nominal_coupling_entry(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, start: int, side: float,
                           fixed: tuple, sample_period_s: float, reach: int) -> tuple:
    """(entry row, rms): the coupling model's contact loss with the motor's J fixed, ``fixed`` = (J, whether the
    torque's lag is free) (:func:`_coupling_fit`), searched forward from ``start``: the first search must explain alpha1
    COUPLING_MIN_GAIN times better than ``start`` (the motor equation fails there), then the search moves on to its
    best while that lies later and explains alpha1 better, not beyond ``reach`` samples; (``start``, inf) when it does
    not move."""
    centre, search, rms = start, samples(COUPLING_SEARCH, sample_period_s), math.inf
    for i in range(int(reach) // max(search, 1) + 2):
        got = _coupling_fit(alpha1, delta, m_el, centre, side, sample_period_s, *fixed)
        if got is None:
            return (start, math.inf) if centre == start else (centre, rms)
        best, best_rss, rss_centre, n = got
        rms = math.sqrt(rss_centre / max(n - 6, 1))
        if best <= centre or best > start + reach or not best_rss * (COUPLING_MIN_GAIN if i == 0 else 1.0) < rss_centre:
            break
        centre = best
    return (start, math.inf) if centre == start else (centre, rms)


#: Without a1, a window's own entry that delta's departure threshold placed after the contact loss (a fast departure:
#: the vector drive's speed reversals, +3: the coupling untwists 0.8 mrad before the contact is lost, the threshold is
#: 1.5 mrad) moves to the contact loss of a spring whose stiffness the steady contact gives (:func:`spring_entry`):
#: in contact the coupling torque is T0 (1 - u / u_e), u delta's move off its flank level toward the zone, u_e that move
#: at the candidate entry e (so the coupling carries T0, the steady m_el before the departure, on the flank and nothing
#: at e), 0 from e on; alpha1 = a + v k + c k^2 + (Phi(m_el) - Phi(torque)) / J (Phi the double integral), least
#: squares over SPRING_FIT_BEFORE rows before the departure and SPRING_FIT_AFTER from it, e within +-SPRING_SEARCH;
#: T0 the median m_el over the rows SPRING_TORQUE_ROWS before the departure ...
SPRING_FIT_BEFORE = 52
SPRING_FIT_AFTER = 32
SPRING_SEARCH = 12
SPRING_TORQUE_ROWS = (80, 30)
#: ... taken when it explains alpha1 this much better than the departure (RSS at the departure / at e: the vector
#: drive's speed reversals 2.4-5.0, the second drive's speed steps 2.4-10; the vector drive's speed steps 1.3-1.7, whose
#: best lay 1-2 samples before the departure, early) ...
SPRING_MIN_GAIN = 2.0
#: ... with its J within this share of J1_nom (the vector drive's heavy load reversals, whose load torque reverses
#: during the contact, not a steady T0: J +20..+28 %, e 5 early; the speed reversals and the second drive's speed steps
#: -9..-1 %) -- chosen on the vector drive, tested on the second drive, ours (a jump: not applied) and the variants
SPRING_MAX_J_DEVIATION = 0.15
#: ... and only a move of at least this many samples: the model finds where the coupling torque vanishes, which comes
#: before the zone entry by the coupling's damping (c/k: 1.6 samples on the vector drive), so 1-2 samples are within
#: what it resolves (the vector drive's J1 1.073 speed step clean moved -1 -> -3, the second drive's speed steps
#: -1 -> -2 and -3 -> -2; the speed reversals move 4-5 samples back)
SPRING_MIN_MOVE = 3
#: A spring fit whose J lies within SPRING_TIGHT_J of J1_nom is taken at the lower gain SPRING_TIGHT_MIN_GAIN, when it
#: moves the entry SPRING_TIGHT_MIN_MOVE samples or more back and delta's measured quantum is fine (its smallest step
#: before the departure / sqrt 12 within FREE_MAX_NOISE_RAD, as :meth:`FlankDetector._ramp_move`).  A drive whose
#: motor is light against its load torque (docs/your_drive.md's small drive, J1 0.03 kg m^2 behind a 3:1 gear) leaves
#: its flank with no relative speed in a speed reversal: delta crosses the departure threshold (1.5 mrad) 6 samples
#: after the contact loss; the motor equation changes little there (the coupling torque ramps through zero), so the
#: spring fit explains alpha1 only 1.24 / 1.39 times better (clean / 30 dB), below SPRING_MIN_GAIN, but with J1
#: 0.0302 / 0.0300 (0.5 % / 0.0 % off J1_nom) at 2 / 1 samples from the contact loss.  Chosen on that variant; tested
#: on the others, the zoo and the DOL zoo (docs/results.md, "Entry placement, thirteenth round"): the soft coupling's
#: clean speed reversal (J 0.9 % off, gain 1.81) is a move of 3 to its separation, c/k before the zone (-2 -> -5),
#: hence the move of 4; the vector drive's 2^13 30 dB speed step lost one entry without the quantum gate (0 = off)
SPRING_TIGHT_J = 0.02
SPRING_TIGHT_MIN_GAIN = 1.2
SPRING_TIGHT_MIN_MOVE = 4


def spring_entry(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, departure: int, flank_rad: float,
                 sample_period_s: float) -> tuple:
    """(entry row, gain, J) of the spring model's contact loss near ``departure`` (SPRING_* constants); (departure, 1.0,
    nan) when the rows are not there or delta does not leave its flank."""
    fit_after, search = samples(SPRING_FIT_AFTER, sample_period_s), samples(SPRING_SEARCH, sample_period_s)
    torque_rows = samples(SPRING_TORQUE_ROWS, sample_period_s)
    lo, hi = departure - samples(SPRING_FIT_BEFORE, sample_period_s), departure + fit_after
    t_lo, t_hi = departure - torque_rows[0], departure - torque_rows[1]
    if min(lo, t_lo) < 0 or hi > alpha1.size or departure - search < lo + 2:
        return departure, 1.0, math.nan
    side = 1.0 if delta[departure] >= flank_rad else -1.0
    t0 = float(np.median(m_el[t_lo:t_hi]))
    rows = np.arange(lo, hi)
    k = (rows - departure) / float(fit_after)
    phi = _double_integral(m_el[lo:hi], sample_period_s)
    y = np.asarray(alpha1[lo:hi], float)
    y = y - y.mean()
    u = side * (np.asarray(delta[lo:hi], float) - flank_rad)
    base = np.column_stack([np.ones(k.size), k, k * k])
    def spring(e):
        ue = u[e - lo]
        frac = np.clip(1.0 - u / ue, 0.0, None) if ue > 0 else np.ones(k.size)
        torque = np.where(rows < e, t0 * frac, 0.0)
        rss, coef = _lstsq_rss(np.column_stack([base, phi - _double_integral(torque, sample_period_s)]), y)
        return rss, (1.0 / coef[3] if coef[3] != 0 else math.nan)

    best, best_rss, best_j, rss_dep = _profile(range(departure - search, departure + search + 1), spring,
                                               departure, departure)
    if not best_rss > 0:
        return departure, 1.0, math.nan
    return best, rss_dep / best_rss, math.nan if best_j is None else float(best_j)


#: Without a1, a window's own entry goes to the contact loss of a spring-damper coupling whose torque scale is fitted
#: (:func:`damped_spring_entry`): in contact the coupling torque is s (1 - u / u_e) - D du/dt (u delta's move off its
#: flank level toward the zone, u_e that move at the candidate entry e; s and D free), 0 in the zone, and again on the
#: flank it left once delta's excursion turns back below u_e (a re-contact on that flank within the fit: the DOL
#: drive's slip drop meets its flank 17 samples after the contact loss, inside the fit; left out, the coupling model
#: moved its entry from -3 to +7..+12); alpha1 = a + b k + c k^2 + (Phi(m_el) - Phi(torque)) / J1_nom (J1 the
#: drive's nominal, not fitted: with J free the spring model's J went 10-30 % off and its entry 3-5 samples early),
#: least squares over DAMPED_FIT_BEFORE rows before the departure and DAMPED_FIT_AFTER from it, e within
#: +-DAMPED_SEARCH of the departure.  The damping term matters: the contact torque vanishes c/k before the zone
#: entry (1.6 samples at the vector drive's and the DOL drive's 50 kN m/rad, 40 N m s/rad); without it the same fit
#: put every DOL slip drop and heavy load reversal 2-5 samples early
DAMPED_FIT_BEFORE = 52
DAMPED_FIT_AFTER = 32
DAMPED_SEARCH = 20
#: ... taken when it explains alpha1 this much better than the entry the other rules gave (RSS there / at e; against
#: the departure: the DOL drive's slip drops 5.2-8.3, its heavy load reversals 1.8-2.8 (entries -3..+1 where the
#: departure was -6); its slip reversals 1.0-1.4 and light load reversals 1.4-1.9, whose best lay -6..+7 off; against the
#: departure rather than that entry, a synthetic soft coupling whose coupling model had found the contact loss went 4
#: samples early) ...
DAMPED_MIN_GAIN = 2.0
#: ... and when the fitted torque scale s is within this share of T0, the steady m_el over the SPRING_TORQUE_ROWS
#: before the departure (a coupling that carried T0 until it untwisted: the DOL slip drops and heavy load reversals
#: 0.96-1.08, the vector drive's heavy load reversals 0.94-0.97; the light load reversals of both drives 0.3-0.7,
#: where friction and the load's ramp are a large share of the torque and the fit's e lay 3-8 samples late) -- both
#: chosen on the DOL drive (zoo_dol), tested on the vector drive, the second drive, ours and the variants
DAMPED_MAX_SCALE_DEVIATION = 0.2


def damped_spring_entry(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, departure: int, flank_rad: float,
                        inertia_kgm2: float, sample_period_s: float, ref: Optional[int] = None) -> tuple:
    """(entry row, gain, torque scale / T0) of the damped spring's contact loss near ``departure`` (DAMPED_*
    constants; the gain RSS(``ref``) / RSS(entry), ``ref`` the departure by default); (departure, 1.0, nan) when the
    rows are not there or delta does not leave its flank."""
    ref = departure if ref is None else int(ref)
    fit_after, torque_rows = samples(DAMPED_FIT_AFTER, sample_period_s), samples(SPRING_TORQUE_ROWS, sample_period_s)
    lo, hi = departure - samples(DAMPED_FIT_BEFORE, sample_period_s), departure + fit_after
    t_lo, t_hi = departure - torque_rows[0], departure - torque_rows[1]
    if min(lo, t_lo) < 0 or hi > alpha1.size or not inertia_kgm2 > 0:
        return departure, 1.0, math.nan
    ts = sample_period_s
    side = 1.0 if delta[departure] >= flank_rad else -1.0
    t0 = float(np.median(m_el[t_lo:t_hi]))
    rows = np.arange(lo, hi)
    k = (rows - departure) / float(fit_after)
    y = np.asarray(alpha1[lo:hi], float) - _double_integral(m_el[lo:hi], ts) / float(inertia_kgm2)
    y = y - y.mean()
    u = side * (np.asarray(delta[lo:hi], float) - flank_rad)
    du = np.gradient(u) / ts
    base = np.column_stack([np.ones(k.size), k, k * k])
    idx = np.arange(k.size)

    def damped(e):
        i = e - lo
        ue = u[i]
        if not ue > 0:
            return math.inf, math.nan
        turn = i + int(np.argmax(u[i:]))          # the excursion's extreme: a re-contact on this flank comes after it
        contact = (rows < e) | ((idx > turn) & (u < ue))
        frac = np.where(contact, np.clip(1.0 - u / ue, 0.0, None), 0.0)
        cols = np.column_stack([base, _double_integral(frac, ts) * 1e6, _double_integral(np.where(contact, du, 0.0), ts) * 1e3])
        rss, coef = _lstsq_rss(cols, y)
        return rss, -coef[3] * 1e6 * float(inertia_kgm2)      # the torque scale s, N m

    search = samples(DAMPED_SEARCH, ts)
    cand = range(max(departure - search, lo + 2), min(departure + search, hi - 4) + 1)
    best, best_rss, scale, rss_dep = _profile(cand, damped, departure, ref)
    if not best_rss > 0 or not math.isfinite(rss_dep) or t0 == 0:
        return departure, 1.0, math.nan
    return best, rss_dep / best_rss, float(scale) / t0


#: A damped coupling separates before the zone: its torque k x + c x' reaches zero while the twist x is still c/k x'
#: (docs/vector_drive.md), and from there both masses run free.  The motor-equation rules above find that separation;
#: the window's entry is the first sample in the zone (x = 0), about c/k later (the soft coupling variant's c/k is 5.3
#: samples: its speed steps -7/-8, its entries with a1 -5/-6; the base drive's 1.6: -2 on its speed steps).  So after
#: the rules a traversal's entry (a window's own, fine encoder, not after a jump of delta) moves forward to where delta
#: crosses the zone's edge (:func:`zone_edge_entry`): the steady contact's twist |T0| / k from the flank level F (both
#: means over the ZONE_STEADY_ROWS before the departure, as SPRING_TORQUE_ROWS), k and c/k from the motor equation over
#: the re-contact on the far flank, where the twist changes by more than the steady one (:func:`far_contact_model`:
#: alpha1 = a + v k + c k^2 + b0 Phi(m_el) - (K Psi(pen) + D Psi(pen') + B Psi(1)) / J over ZONE_FIT_BEFORE rows before
#: the re-contact row and ZONE_FIT_AFTER from it, the row itself within +-ZONE_RECONTACT_SEARCH by least squares; pen
#: delta's penetration beyond its value at that row, B the edge's rounding to the row; k = K/J x J1_nom) ...
ZONE_FIT_BEFORE = 16
ZONE_FIT_AFTER = 40
ZONE_RECONTACT_SEARCH = 3
ZONE_STEADY_ROWS = (80, 30)
#: ... when c/k is determined within this relative standard error -- chosen on the soft coupling variant (its fits
#: 0.008-0.098; on the base drive's, the heavy and the fast speed loop variants' clean speed steps, whose re-contact
#: rings, 1.0-1.3 with c/k 12-31 samples, and its light load reversals 0.3-0.7) ...
ZONE_MAX_CK_REL_SE = 0.1
#: ... and the crossing lies no further than c/k plus this many samples after the rules' entry (the soft coupling's
#: 30 dB speed step departs 3 samples before the separation: c/k + 3; forward only: a rule that found the zone entry
#: itself, the coupling model's, moves by a sample or not at all)
ZONE_MOVE_SLACK = 3
#: ... and delta crosses the edge by more per sample (over the 3 samples around the crossing) than the edge's
#: uncertainty: ZONE_K_SIGMAS standard errors of k on the twist plus delta's quantum (2, not tuned: the DOL drive's light
#: load reversals drift across a 0.58 mrad twist by one 2^16 count per sample, and a k 8 % low put them +3/+4)
ZONE_K_SIGMAS = 2.0


def far_contact_model(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, recontact: int,
                      sample_period_s: float) -> Optional[tuple]:
    """(K/J in 1/s^2 per rad of delta, c/k in s, the relative standard errors of c/k and of K) of the coupling over the
    re-contact on the far flank near row ``recontact`` (ZONE_* constants, see ZONE_FIT_BEFORE); None when the rows are
    not there."""
    ts = sample_period_s
    pre, post = samples(ZONE_FIT_BEFORE, ts), samples(ZONE_FIT_AFTER, ts)
    search = samples(ZONE_RECONTACT_SEARCH, ts)
    a1, d_all, m = (np.asarray(x, float) for x in (alpha1, delta, m_el))
    best = None
    for r in range(int(recontact) - search, int(recontact) + search + 1):
        lo, hi = r - pre, r + post
        if lo < 1 or hi > a1.size:
            continue
        k = np.arange(lo, hi, dtype=float) - r
        d = d_all[lo:hi]
        into = 1.0 if d_all[r + 1] >= d_all[r - 1] else -1.0       # the direction delta enters the far flank
        pen = np.clip(into * (d - 0.5 * (d_all[r - 1] + d_all[r])), 0.0, None)
        pen[:r - lo] = 0.0
        cols = [_double_integral(c, ts) for c in (pen, into * np.gradient(d) / ts * (pen > 0), (k >= 0).astype(float))]
        scale = [float(np.abs(c).max()) or 1.0 for c in cols]
        X = np.column_stack([_free_columns(k, _double_integral(m[lo:hi], ts))] + [c / s for c, s in zip(cols, scale)])
        rss, coef = _lstsq_rss(X, a1[lo:hi])
        if best is None or rss < best[0]:
            best = (rss, X, coef, scale, into)
    if best is None:
        return None
    rss, X, coef, scale, into = best
    if not coef[4] != 0:
        return None
    ratio = coef[5] / coef[4]
    cov = np.linalg.pinv(X.T @ X) * rss / max(X.shape[0] - X.shape[1], 1)
    g = np.zeros(X.shape[1])
    g[4], g[5] = -ratio / coef[4], 1.0 / coef[4]
    rse = math.sqrt(max(float(g @ cov @ g), 0.0)) / abs(ratio) if ratio != 0 else math.inf
    return -into * coef[4] / scale[0], ratio * scale[0] / scale[1], rse, math.sqrt(max(float(cov[4, 4]), 0.0)) / abs(coef[4])


#: With a1 (an Imu) the coupling's torque at the re-contact is read, not double-integrated: J1_nom a1 - m_el = -(k pen +
#: c pen') over the ZONE_FIT_AFTER rows from the re-contact row (searched within +-ZONE_RECONTACT_SEARCH by least
#: squares; pen as in :func:`far_contact_model`, a constant for the torque estimate's offset) --
#: :func:`far_contact_model_a1`.  On the soft coupling variant's 30 dB Imu recordings (where it was chosen) it gives k
#: 14400 / 15100 / 15000 N m/rad (true 15000) and c/k 5.0 / 5.1 / 5.4 samples (true 5.3) with relative standard errors
#: 0.01-0.02 on the light and heavy load reversals and the speed reversal, where the angle form gave k 19600 (c/k
#: undetermined, relative standard error 0.74) / 22800 / 15000; on the base drive's heavy load reversal 52100 and 1.50
#: samples (true 50000, 1.6).  The steady torque T0 is then m_el less J1_nom a1 (the coupling's share).  Over the 33
#: variants (detector replay) it moved the soft coupling's Imu heavy reversal -6 -> 0, the heavy load variant's -3 -> +1,
#: '4 kHz read at 2 kHz' +3 -> +1, 'smoothed torque 2 ms' -3 -> +1, and 'sampling jitter 50 us' Imu light reversal -1 ->
#: +3 (its edge from T0 included the motor's friction: ZONE_A1_FRICTION below);
#: docs/results.md, "Entry placement, thirteenth round".  False turns it off ...
ZONE_A1_FIT = True
#: ... and with a1 the motor's friction (and the torque estimate's offset) comes off T0 too: the mean of m_el - J1_nom
#: a1 over up to 40 rows of the gap (from c/k + 2 samples after the later of the entry and the departure, ending 2
#: before the re-contact), when alpha1 runs the same way there as over the steady rows (a Coulomb friction keeps its
#: sign).  Without it the light reversal of 'sampling jitter 50 us' with an Imu went -1 -> +3: T0 25.7 N m, the gap's
#: offset 3.3 N m, the true edge's torque 23.0 N m.  From the departure on instead, the soft coupling's heavy reversal
#: (departing 23 samples before its contact loss) read the contact as friction (33 N m) and went 0 -> -3.
ZONE_A1_FRICTION = True


def far_contact_model_a1(acc: np.ndarray, delta: np.ndarray, m_el: np.ndarray, recontact: int, inertia_kgm2: float,
                         sample_period_s: float) -> Optional[tuple]:
    """:func:`far_contact_model`'s (K/J, c/k in s, relative standard errors of c/k and of K) from the torque balance
    with the motor's acceleration ``acc`` in rad/s^2 (ZONE_A1_FIT); None when the rows are not there."""
    ts = sample_period_s
    post, search = samples(ZONE_FIT_AFTER, ts), samples(ZONE_RECONTACT_SEARCH, ts)
    acc, d_all, m = (np.asarray(x, float) for x in (acc, delta, m_el))
    best = None
    for r in range(int(recontact) - search, int(recontact) + search + 1):
        hi = r + post
        if r < 2 or hi + 1 > d_all.size:
            continue
        into = 1.0 if d_all[r + 1] >= d_all[r - 1] else -1.0       # the direction delta enters the far flank
        pen = np.clip(into * (d_all[r:hi] - 0.5 * (d_all[r - 1] + d_all[r])), 0.0, None)
        rate = into * np.gradient(d_all[r - 1:hi + 1])[1:-1] / ts * (pen > 0)
        X = np.column_stack([pen, rate, np.ones(hi - r)])
        rss, coef = _lstsq_rss(X, inertia_kgm2 * acc[r:hi] - m[r:hi])
        if best is None or rss < best[0]:
            best = (rss, X, coef, into)
    if best is None:
        return None
    rss, X, coef, into = best
    k = -into * coef[0]
    if not coef[0] != 0:
        return None
    ratio = coef[1] / coef[0]
    cov = np.linalg.pinv(X.T @ X) * rss / max(X.shape[0] - X.shape[1], 1)
    g = np.array([-ratio / coef[0], 1.0 / coef[0], 0.0])
    rse = math.sqrt(max(float(g @ cov @ g), 0.0)) / abs(ratio) if ratio != 0 else math.inf
    return k / inertia_kgm2, ratio, rse, math.sqrt(max(float(cov[0, 0]), 0.0)) / abs(coef[0])


def zone_edge_entry(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, rows: tuple, side: float,
                    inertia_kgm2: float, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S,
                    quantum_rad: float = 0.0) -> tuple:
    """(entry row, c/k in samples or NaN) of a traversal, ``rows`` = (the rules' entry, the departure, the re-contact
    row): the first row after the entry where delta is beyond the zone's edge (on ``side``, the direction it departs
    to), F + side |T0| / k, within c/k + ZONE_MOVE_SLACK samples, when :func:`far_contact_model` near the re-contact
    gives K > 0, c/k >= 0 within ZONE_MAX_CK_REL_SE and delta crosses the edge by more than its uncertainty per sample
    (ZONE_K_SIGMAS x K's relative standard error x the twist, plus delta's quantum ``quantum_rad``; ZONE_* constants);
    else the entry itself.  ``alpha1`` may be a pair (alpha1, the motor's acceleration from a1 in rad/s^2): then k and
    c/k come from :func:`far_contact_model_a1`, and J1_nom a1 and the gap's friction are taken off the steady torque
    (ZONE_A1_FIT, ZONE_A1_FRICTION)."""
    ts = sample_period_s
    alpha1, acc = alpha1 if isinstance(alpha1, tuple) else (alpha1, None)
    entry, departure, recontact = (int(r) for r in rows)
    if recontact <= entry:
        got = None
    elif acc is not None and ZONE_A1_FIT:
        got = far_contact_model_a1(acc, delta, m_el, recontact, inertia_kgm2, ts)
    else:
        got = far_contact_model(alpha1, delta, m_el, recontact, ts)
    if got is None:
        return entry, math.nan
    kj, ck, rse, rse_k = got
    ck_samples = ck / ts
    a, b = departure - samples(ZONE_STEADY_ROWS[0], ts), departure - samples(ZONE_STEADY_ROWS[1], ts)
    if not (kj > 0 and ck >= 0 and rse <= ZONE_MAX_CK_REL_SE) or a < 0:
        return entry, ck_samples
    d = np.asarray(delta, float)
    torque = np.asarray(m_el, float)[a:b]
    offset = 0.0
    if acc is not None and ZONE_A1_FIT:
        acc = np.asarray(acc, float)
        torque = torque - inertia_kgm2 * acc[a:b]     # the coupling's share: less J1 a1
        g0 = max(departure, entry) + int(math.ceil(ck_samples)) + 2
        g1 = min(g0 + 40, recontact - 2)
        x1 = np.asarray(alpha1, float)
        if ZONE_A1_FRICTION and g1 - g0 >= 8 and (x1[b] - x1[a]) * (x1[g1] - x1[g0]) > 0:
            offset = float(np.mean(np.asarray(m_el, float)[g0:g1] - inertia_kgm2 * acc[g0:g1]))
    twist = abs(float(np.mean(torque)) - offset) / (kj * inertia_kgm2)
    edge = float(np.mean(d[a:b])) + side * twist
    hi = entry + int(math.ceil(ck_samples + samples_float(ZONE_MOVE_SLACK, ts)))
    beyond = np.flatnonzero(side * (d[entry:hi + 1] - edge) > 0)
    z = entry + int(beyond[0]) if beyond.size else entry
    if z <= entry or z + 2 > d.size or abs(d[z + 1] - d[z - 2]) / 3.0 < ZONE_K_SIGMAS * rse_k * twist + quantum_rad:
        return entry, ck_samples        # no crossing, or one delta does not resolve (a light load reversal's drift)
    return z, ck_samples


#: On a coarse encoder (delta's quantum / sqrt 12 beyond FREE_MAX_NOISE_RAD: 2^13, where the coupling, spring and
#: damped spring models are off) a window's own entry without a1 goes to the end of the coupling's untwist
#: (:func:`untwist_entry`): delta = F + v (k - s)_+ + c (k - e)_+^2 -- at rest on its flank, then untwisting at a
#: constant rate while the coupling's torque ramps to zero (from s), then the free relative acceleration from the
#: contact loss (e) -- fitted over UNTWIST_FIT_BEFORE rows before the departure and UNTWIST_FIT_AFTER from it, s and e
#: by least squares (e up to UNTWIST_SEARCH_AFTER after the departure; 50 and 5 the first values tried, not tuned).
#: UNTWIST_FIT_AFTER 40 was chosen on the DOL drive's 2^13 heavy load reversals (with 32: -3 on each at 30 dB; with 40:
#: 0..+1, gains 1.9-2.3); the vector drive's were within +-2 alike with 32 and 40; with 24 the parabola had too few free
#: rows (gains 1.0-1.3, entries -32..+2) ...
UNTWIST_FIT_BEFORE = 50
UNTWIST_FIT_AFTER = 40
UNTWIST_SEARCH_AFTER = 5
#: ... taken when the untwist phase explains delta this much better than one kink (the least residual with e = s):
#: the vector drive's 2^13 speed reversals 1.14-1.43 (+6/+7 -> -1..+2: the departure threshold there is 2.9-3.1 mrad,
#: four quanta, for a 1-quantum untwist) and heavy load reversals 1.26-2.24 (-10..-1 -> -5..+2); its light load
#: reversals 1.06-1.09 (the model put them 5-16 late) and speed steps 1.00-1.03 (one kink: the untwist starts at the
#: contact loss's neighbour, e = s 5-11 samples early) stay -- chosen on the vector drive, tested on the DOL drive
#: (heavy load reversals 1.9-2.6: -4..-1 -> -1..+2; light ones 1.14-1.21: +16..+25 -> +5..+11; slip events <= 1.04)
#: and the second drive (speed steps 1.00)
UNTWIST_MIN_GAIN = 1.12


def untwist_entry(delta: np.ndarray, departure: int, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> tuple:
    """(e, gain) of :data:`UNTWIST_MIN_GAIN`'s model around ``departure``: the contact loss e of the best fit and
    the gain RSS(best with e = s) / RSS(best); (``departure``, 1.0) when the rows are not there."""
    lo = departure - samples(UNTWIST_FIT_BEFORE, sample_period_s)
    hi = departure + samples(UNTWIST_FIT_AFTER, sample_period_s)
    if lo < 0 or hi > delta.size:
        return departure, 1.0
    t = np.arange(lo, hi, dtype=float)
    y = np.asarray(delta[lo:hi], float)
    y = y - y.mean()
    first = lo + samples(5, sample_period_s)
    c = np.arange(first, departure + samples(UNTWIST_SEARCH_AFTER, sample_period_s) + 1, dtype=float)  # change points
    # (k - c)_+ in samples at 2 kHz (x T_s / 0.5 ms): the sums of its 4th power over 4 x the rows at 8 kHz left the
    # determinant test below failing on every one-kink fit (a gain of inf: the 2^13 entries went 1.5-2 ms late)
    scale = sample_period_s / REFERENCE_SAMPLE_PERIOD_S
    d = np.clip(t[None, :] - c[:, None], 0.0, None) * scale
    S = [np.sum(d ** p, axis=1) for p in range(5)]                             # sums of (k - c)_+^p
    dy, d2y = d @ y, (d * d) @ y
    pairs = np.array([(si, ei) for si in range(departure + 1 - first) for ei in range(si, c.size)])
    i, j = pairs[:, 0], pairs[:, 1]
    # the normal equations of (1, a, b), a = (k - s)_+, b = (k - e)_+^2, from the sums: sum a b over k >= e is
    # sum (k - e)^3 + (e - s) (k - e)^2
    ab = S[3][j] + (j - i) * scale * S[2][j]
    XtX = np.stack([np.stack([np.full(i.size, float(t.size)), S[1][i], S[2][j]], -1),
                    np.stack([S[1][i], S[2][i], ab], -1), np.stack([S[2][j], ab, S[4][j]], -1)], -2)
    Xty = np.stack([np.full(i.size, float(y.sum())), dy[i], d2y[j]], -1)
    coefs = np.linalg.lstsq(XtX[0], Xty[0], rcond=None)[0][None, :].repeat(pairs.shape[0], 0)
    ok = np.abs(np.linalg.det(XtX)) > 1e-12 * np.einsum("kii->k", XtX) ** 3
    coefs[ok] = np.linalg.solve(XtX[ok], Xty[ok][..., None])[..., 0]
    rss = np.where(ok, np.maximum(float(y @ y) - np.einsum("ki,ki->k", coefs, Xty), 0.0), np.inf)
    k = int(np.argmin(rss))
    one = rss[i == j]
    if not (np.isfinite(rss[k]) and rss[k] > 0 and one.size):
        return departure, 1.0
    return int(c[j[k]]), float(np.min(one) / rss[k])


#: Without a1, a window's own contact loss from the motor equation with the coupling torque ramping to zero
#: (:func:`ramp_entry`): in contact the coupling carries T0 (constant), from s it falls linearly to zero at the
#: contact loss e, and from e on the motor runs free: alpha1 = a + v k + c k^2 + (Phi(m_el) - T0 Phi(shape)) / J1_nom,
#: shape = 1 before s, (e - k) / (e - s) on [s, e), 0 from e (a, v, c -- friction, the torque estimate's offset -- and
#: T0 linear; s and e by least squares).  Unlike the spring models it does not read delta's untwist, which a stiff
#: coupling keeps below a count: a light load reversal's coupling lets go while the load torque still ramps and delta
#: creeps off its flank from rest, so its departure comes 12-38 samples late on the vector drive's variants (stiff
#: coupling, fast and slow speed loops, light load, 2^20 encoders).  Fitted over RAMP_FIT_BEFORE rows before the
#: earliest candidate e (RAMP_SEARCH before the departure) to RAMP_FIT_AFTER after the departure, ramps up to
#: RAMP_MAX_SAMPLES long (52 and 32 as the coupling model's; 48 and 60 cover the variants' late departures, +38, and
#: ramps, 13-29 samples: first values tried, not tuned) ...
RAMP_FIT_BEFORE = 52
RAMP_FIT_AFTER = 32
RAMP_SEARCH = 48
RAMP_MAX_SAMPLES = 60
#: ... taken, for a window's own entry on a fine encoder, when it lies SPRING_MIN_MOVE or more before the departure,
#: explains alpha1 RAMP_MIN_GAIN times better than the best fit with e at the departure and T0 lies within
#: RAMP_MAX_SCALE_DEVIATION of the steady m_el before the ramp (the values of the damped spring's gates, DAMPED_*,
#: not tuned again).  Gains on the vector drive (the base model, where it was checked): light load reversals 5.5-6.2
#: (0/-1 -> -1/+1), heavy ones 1.4-1.6, speed steps and reversals 1.0-1.1 (not taken: a fast departure's ramp is no
#: better than a kink there).  Also taken at a gain >= RAMP_TIED_MIN_GAIN when delta's untwist agrees: the joint RSS
#: of alpha1's and delta's models (RAMP_JOINT) falls RAMP_MIN_GAIN times or more from the departure to e (the DOL
#: drive's J1 1.16 light load reversals: alpha1 1.84-1.97, joint 5.6-5.8, 13-14 samples late before; the vector
#: drive's light load variant 1.76/1.82, joint 6.1/7.7; the DOL slip sweep's stiff coupling slip reversal at 30 dB
#: alpha1 1.77 but joint 1.30: not taken, it would go from +2 to -4; every other event of the zoo, the DOL zoo and the
#: variants on 2^16 <= 1.25 on alpha1) -- RAMP_TIED_MIN_GAIN chosen on the DOL zoo, checked on the others
RAMP_MIN_GAIN = 2.0
RAMP_TIED_MIN_GAIN = 1.5
RAMP_MAX_SCALE_DEVIATION = 0.2
#: alpha1 fixes the coupling torque's mean time of fall better than where it ends: along a valley of the RSS the ramp's
#: end e and its length trade off (the DOL drive's light load reversals, whose coupling torque falls faster towards the
#: contact loss than a line: -7 ... -1 within 2 % of RSS; J1_nom 8 % above the drive's J1 moved the best to -3/-4).
#: With RAMP_JOINT, among the candidates whose alpha1 RSS lies within RAMP_TIE_VARIANCES residual variances of the best
#: (RSS <= best (1 + RAMP_TIE_VARIANCES / (n - 5)), the 63 % profile-likelihood region of (s, e)), the one whose
#: untwist model of delta (:func:`untwist_entry`'s: at rest, a hinge at s, the free parabola from e) fits best is taken:
#: the DOL drive's light reversals on 2^16 -7 ... +14 -> -4 ... -1.  A joint sum of both RSS instead pulled the
#: vector drive's stiff coupling and slow speed loop 5-9 samples late (their relative acceleration grows from zero
#: after the contact loss, no parabola); a set of 6 variances (the 95 % region) put the fast speed loop's at -4 and
#: the DOL drive's all within 2, of 4 the fast loop's -3 and one DOL 30 dB -3: 2 was chosen on both
RAMP_JOINT = True
RAMP_TIE_VARIANCES = 2.0
#: On a coarse encoder (delta's quantum / sqrt 12 beyond FREE_MAX_NOISE_RAD: 2^13) alpha1 alone does not place the ramp
#: (the DOL drive's 2^13 light load reversals: gains 1.0-1.14, as every other event's); the joint RSS of alpha1's and
#: delta's models does: taken when it falls RAMP_COARSE_MIN_JOINT_GAIN times or more from the departure to e (the DOL
#: drive's 2^13 light reversals 1.23-1.42, +4 ... +19 -> -2 ... +3; its slip events and heavy reversals <= 1.05;
#: chosen there) -- tested on the zoo: the vector drive's 2^13 light reversals 1.35-1.63 (+2 ... +16 -> +1 ... +3), its
#: speed reversals 1.11-1.22, speed steps <= 1.12, heavy reversals 1.00, the second drive's speed steps <= 1.09, ours'
#: slips <= 1.04; 0 (off) is the rule before the eighth round
RAMP_COARSE_MIN_JOINT_GAIN = 1.25


def ramp_entry(alpha1: np.ndarray, m_el: np.ndarray, departure: int, inertia_kgm2: float,
               sample_period_s: float, delta: Optional[np.ndarray] = None, joint_gain: bool = False) -> tuple:
    """(e, gain, scale) of :data:`RAMP_MIN_GAIN`'s model around ``departure``: the contact loss e of the best fit, the
    gain RSS(best with e = departure) / RSS(best) and T0 / the median m_el over the first 20 fitted rows;
    (``departure``, 1.0, nan) when the rows are not there.  With ``delta`` the RSS is the joint one of alpha1's and
    delta's models with the same s and e (:data:`RAMP_JOINT`); ``joint_gain``: a fourth value, the gain of the sum of
    both RSS (at the departure's best / at e; 1.0 without ``delta``)."""
    ts = sample_period_s          # durations: samples at 2 kHz, converted to ts's (jident_ros.stream.rate)
    search, fit_after, max_ramp = samples(RAMP_SEARCH, ts), samples(RAMP_FIT_AFTER, ts), samples(RAMP_MAX_SAMPLES, ts)
    lo, hi = departure - search - samples(RAMP_FIT_BEFORE, ts), departure + fit_after
    if lo < 0 or hi > alpha1.size:
        return (departure, 1.0, math.nan) + ((1.0,) if joint_gain else ())
    k = np.arange(lo, hi, dtype=float)
    x = (k - departure) / fit_after
    Q, _ = np.linalg.qr(np.column_stack([np.ones_like(x), x, x * x]))
    y = np.asarray(alpha1[lo:hi], float) - _double_integral(m_el[lo:hi], sample_period_s) / inertia_kgm2
    y = y - Q @ (Q.T @ y)
    # shape = ((e - k)_+ - (s - k)_+) / (e - s), a step (k < e) for s = e: every candidate's double integral from
    # those of the hinges (c - k)_+ and the steps, projected off (1, k, k^2) once; then Gram sums
    c = np.arange(departure - search - max_ramp, departure + 1)
    cols = np.concatenate([np.clip(c[:, None] - k[None, :], 0.0, None), (k[None, :] < c[-search - 1:, None])])
    v = np.cumsum(cols, axis=1) * sample_period_s
    z = np.zeros_like(v)
    z[:, 1:] = np.cumsum(v[:, :-1], axis=1) * sample_period_s
    z = z - (z @ Q) @ Q.T
    G, zy_all = z @ z.T, z @ y
    es = np.arange(departure - search, departure + 1)
    rs = np.arange(0, max_ramp + 1)
    e, r = np.repeat(es, rs.size), np.tile(rs, es.size)
    ie, is_ = e - c[0], e - r - c[0]                                  # hinge columns of e and s
    istep = c.size + (e - es[0])                                      # step columns
    rr = np.maximum(r, 1).astype(float)
    zz = np.where(r == 0, G[istep, istep], (G[ie, ie] - 2.0 * G[ie, is_] + G[is_, is_]) / (rr * rr))
    zy = np.where(r == 0, zy_all[istep], (zy_all[ie] - zy_all[is_]) / rr)
    ok = zz > 1e-300
    gain_rss = np.where(ok, float(y @ y) - zy * zy / np.where(ok, zz, 1.0), np.inf)
    best = int(np.argmin(gain_rss))
    at_dep = float(np.min(gain_rss[e == departure]))
    if not (np.isfinite(gain_rss[best]) and gain_rss[best] > 0):
        return (departure, 1.0, math.nan) + ((1.0,) if joint_gain else ())
    if delta is not None:
        # among the candidates alpha1 cannot tell from its best (RSS within RAMP_TIE_VARIANCES residual variances of
        # it), the one whose untwist model explains delta best
        tie = gain_rss <= gain_rss[best] * (1.0 + RAMP_TIE_VARIANCES / max(y.size - 5, 1))
        rd = _untwist_rss(np.asarray(delta[lo:hi], float), k, c, es, ie, is_)
        if np.any(tie & np.isfinite(rd)):
            best = int(np.argmin(np.where(tie, rd, np.inf)))
    t0 = -float(zy[best] / zz[best]) * inertia_kgm2                 # alpha1 carries -T0 Phi(shape) / J
    steady = float(np.median(m_el[lo:lo + samples(20, ts)]))
    got = int(e[best]), at_dep / float(gain_rss[best]), (t0 / steady if steady != 0 else math.nan)
    if not joint_gain:
        return got
    both = gain_rss + rd if delta is not None else gain_rss
    return got + (float(np.min(both[e == departure]) / both[best]) if both[best] > 0 else 1.0,)


def _untwist_rss(d: np.ndarray, k: np.ndarray, c: np.ndarray, es: np.ndarray, i_e: np.ndarray,
                 i_s: np.ndarray) -> np.ndarray:
    """RSS of delta = F + v (k - s)_+ + a (k - e)_+^2 (:func:`untwist_entry`'s model) over the rows ``k`` for every
    candidate pair (s, e) = (c[i_s], c[i_e]), e in ``es``: from the Gram sums of the hinges (k - c)_+ and the
    parabolas (k - e)_+^2, centred (F free)."""
    scale = float(max(k[-1] - k[0], 1.0))
    h = np.clip(k[None, :] - c[:, None], 0.0, None) / scale
    p = np.clip(k[None, :] - es[:, None], 0.0, None) ** 2 / scale ** 2
    h -= h.mean(axis=1, keepdims=True)
    p -= p.mean(axis=1, keepdims=True)
    y = d - d.mean()
    j = i_e - (es[0] - c[0])                                        # parabola rows of e
    a11, a22 = np.einsum("ij,ij->i", h, h)[i_s], np.einsum("ij,ij->i", p, p)[j]
    a12 = (h @ p.T)[i_s, j]
    b1, b2 = (h @ y)[i_s], (p @ y)[j]
    det = a11 * a22 - a12 * a12
    ok = det > 1e-12 * a11 * a22
    fit = (a22 * b1 * b1 - 2.0 * a12 * b1 * b2 + a11 * b2 * b2) / np.where(ok, det, 1.0)
    return np.where(ok, float(y @ y) - fit, np.inf)


def _noise(x: np.ndarray, lag: int = 1) -> float:
    """White-noise standard deviation of a steady stretch, robust to a few samples of a starting transient
    (the drive may act just before the clutch leaves its flank): 1.4826 MAD of the differences over ``lag`` samples /
    sqrt 2.  (The acceleration from alpha1 is a Savitzky-Golay output over the same 3.5 ms at any rate: its samples
    1 apart at 4 kHz are more alike than at 2 kHz and their differences read less noise; ``lag`` = 0.5 ms in samples
    keeps the estimate, the tolerances built on it, as at 2 kHz.)"""
    if x.size < 5:
        return 0.0
    dx = x[lag:] - x[:-lag] if 0 < lag < x.size else np.diff(x)
    return float(1.4826 * np.median(np.abs(dx - np.median(dx))) / math.sqrt(2.0))


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


def _travel(d: np.ndarray, e: int, span: int = RECONTACT_SPAN) -> np.ndarray:
    """The travel of delta from the entry row on, positive in the direction it left in (``span`` rows decide:
    RECONTACT_SPAN at 2 kHz; when delta has not moved over them, its first move: a coarse encoder's delta creeps off
    its flank within a count for several samples after an entry placed at the contact loss, and the side taken from
    no move turned the travel negative, so the acceleration's re-contact row 5 samples after the entry stood: K2
    1.9e-5 m for 5 mm on the vector drive's 2^13 light load reversal)."""
    ref = d[min(e + span, d.size - 1)]
    if abs(ref - d[e]) <= 1e-9:                     # no move but a float rounding (as _delta_quantum's steps)
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
        return WidthResult(width, se, "same_flank", g)
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
    return WidthResult(width, se, "traversal", g)


class FlankDetector(BacklashDetector):
    """Streaming detector of backlash-zone entries that needs no K2 and no zone-centred angles
    (module docstring), and window capture.

    Parameters
    ----------
    wheel_radius_m : float         r (> 0): K2 = r theta_b
    sample_period_s : float        T_s (> 0)
    channels : names to capture, must include "t", "alpha1", "alpha2" (window column order)
    samples_before_entry, samples_from_entry, gap_tolerance : as BacklashDetector (48, 2000, 1.5)
    gear_ratio : float             N in delta = alpha1 - N alpha2 (motor turns per load-encoder turn), 1
    nominal_inertia_kgm2 : float   J1_nom for the load-torque refinement of the entry sample; None = off
    contact_samples : int          run length that makes a contact (default: 16 ms, 32 samples at 2 kHz)
    contact_tolerance_rad : float  largest spread of delta over such a run (2 mrad)
    k_sigma : float                departure threshold in contact-noise standard deviations (8)
    min_departure_rad : float      departure threshold floor (1.5 mrad: 16 counts of a 2^16 encoder;
                                   the grid's smallest half-zone is 25 mrad)
    flank_time_constant_s : float  drift tracking of the flank level (0.05 s)
    encoder_counts_per_rev : int   for the width uncertainty (quantisation), 0 = ideal angles
    refine_samples : int           the entry sample may move this far past the departure (default: 8 ms, 16 at
                                   2 kHz; the module's sample counts are durations at 2 kHz, converted to T_s's:
                                   :mod:`jident_ros.stream.rate`)
    load_drop_fraction : float     ... while T_L keeps more than this share of the steady load (0.5)
    unwrap_angles : bool           undo the wraps of positions reported in [-pi, pi) (BacklashDetector), True
    confirm_samples : int          a departure is an entry only when this many samples in a row (it and the next
                                   ones) are beyond the threshold on the same side (3): a spike of 1 or 2 samples
                                   of one encoder is not an entry (counted in ``spikes``); the detector hands
                                   samples on confirm_samples - 1 samples late
    min_travel_rad : float         an entry whose excursion ends in a new contact less than this far from the
                                   flank it left was a same-flank torque change (the coupling twisting more or
                                   less), not a backlash entry: its window is dropped and counted in
                                   ``flank_shifts`` (5 mrad; below the smallest half-zone K2/r you expect; 0: off)
                                   unless, with m_el, delta passed the coupling's zero-twist point (a slip drop's
                                   short gap, SHALLOW_*);
                                   the travel counts beyond the flank level before any same-flank move, in the
                                   direction delta left
    deeper_travel_factor : float   with m_el: delta moving *with* the torque the contact carries (sign of m_el
                                   over the contact, when significant) goes deeper into the flank (more torque,
                                   more twist): an entry only after this many min_travel_rad (4: 20 mrad), and
                                   not when its next contact carries at least twice that torque (DEEPER_CONTACTS)
    """

    #: The window header's ``detector`` field.
    detector_name = "flank"
    #: History kept beyond samples_before_entry (the entry sample may move this far before the departure).
    history_extra = 0
    #: Whether the history_extra rows are optional (the entry's back-walk is limited to the history there is; a
    #: stream that starts less than samples_before_entry + history_extra rows before an entry still gives its window)
    extra_optional = True
    #: An entry inside a running window gets a window of its own when its excursion ends on the other flank (a
    #: return traversal: the second drive's and the vector drive's speed steps re-cross the zone 130-270 samples
    #: after the first traversal, inside its window).  On since stop 20: the gap stage now carries a torque error
    #: drifting across the gap (gap_terms.drift_term), which refuses the return traversals' low-torque J1 that went out
    #: +12 % before (a fitted Coulomb term had absorbed the estimate's constant error, not its drift; docs/results.md
    #: "Zoo: return traversals on").  False: one window per excursion, as before.
    second_windows = True
    #: Entries at or before this time lie inside a window given out before this detector started (set by
    #: :class:`~jident_ros.stream.imu_skew.ImuSkewGuard` when it detects a window again without a1): traversals back
    inside_window_until_s = -math.inf

    def __init__(self, wheel_radius_m: float, sample_period_s: float,
                 channels: Sequence[str] = DEFAULT_CHANNELS, samples_before_entry: int = 48,
                 samples_from_entry: int = 2000, gap_tolerance: float = 1.5, gear_ratio: float = 1.0,
                 nominal_inertia_kgm2: Optional[float] = None, contact_samples: Optional[int] = None,
                 contact_tolerance_rad: float = 2e-3, k_sigma: float = 8.0, min_departure_rad: float = 1.5e-3,
                 flank_time_constant_s: float = 0.05, encoder_counts_per_rev: int = 0,
                 refine_samples: Optional[int] = None, load_drop_fraction: float = 0.5, unwrap_angles: bool = True,
                 confirm_samples: int = 3, min_travel_rad: float = 5e-3, deeper_travel_factor: float = 4.0,
                 base_torque_nm: Optional[float] = None):
        if isinstance(gear_ratio, bool) or not (math.isfinite(float(gear_ratio)) and gear_ratio != 0):
            raise ValueError(f"gear_ratio: must be a finite non-zero number (negative: the load encoder counts the "
                             f"other way), got {gear_ratio!r}")
        for name, v in (("contact_tolerance_rad", contact_tolerance_rad),
                        ("k_sigma", k_sigma), ("min_departure_rad", min_departure_rad),
                        ("flank_time_constant_s", flank_time_constant_s),
                        ("load_drop_fraction", load_drop_fraction)):
            if not _positive(v):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        if nominal_inertia_kgm2 is not None and not _positive(nominal_inertia_kgm2):
            raise ValueError(f"nominal_inertia_kgm2: must be a finite number > 0 or None, got {nominal_inertia_kgm2!r}")
        if base_torque_nm is not None and not _positive(base_torque_nm):
            raise ValueError(f"base_torque_nm: must be a finite number > 0 or None, got {base_torque_nm!r}")
        if contact_samples is None or refine_samples is None:       # durations at 2 kHz in T_s's samples
            if not _positive(sample_period_s):
                raise ValueError(f"sample_period_s: must be a finite number > 0, got {sample_period_s!r}")
            contact_samples = samples(32, sample_period_s, 4) if contact_samples is None else contact_samples
            refine_samples = samples(16, sample_period_s) if refine_samples is None else refine_samples
        if isinstance(min_travel_rad, bool) or not (math.isfinite(float(min_travel_rad)) and min_travel_rad >= 0):
            raise ValueError(f"min_travel_rad: must be a finite number >= 0, got {min_travel_rad!r}")
        for name, v, lo in (("contact_samples", contact_samples, 4), ("encoder_counts_per_rev", encoder_counts_per_rev, 0),
                            ("refine_samples", refine_samples, 0), ("confirm_samples", confirm_samples, 1)):
            if isinstance(v, bool) or int(v) != v or v < lo:
                raise ValueError(f"{name}: must be an integer >= {lo}, got {v!r}")
        # the base class validates the rest; its K2 is a placeholder the flank detector never uses
        super().__init__(1.0, wheel_radius_m, sample_period_s, channels, samples_before_entry,
                         samples_from_entry, gap_tolerance, unwrap_angles)
        self.gear_ratio = float(gear_ratio)
        self.nominal_inertia_kgm2 = None if nominal_inertia_kgm2 is None else float(nominal_inertia_kgm2)
        # the largest constant torque back_to_load's gap fit may take for friction and offset (None: no bound)
        self.back_constant_max_nm = None if base_torque_nm is None else BACK_CONSTANT_MAX_REL_BASE * float(base_torque_nm)
        self.contact_samples = int(contact_samples)
        self.contact_tolerance_rad = float(contact_tolerance_rad)
        self.k_sigma = float(k_sigma)
        self.min_departure_rad = float(min_departure_rad)
        self.flank_time_constant_s = float(flank_time_constant_s)
        self.encoder_counts_per_rev = int(encoder_counts_per_rev)
        self.refine_samples = int(refine_samples)
        self.load_drop_fraction = float(load_drop_fraction)
        self.confirm_samples = int(confirm_samples)
        self.deeper_travel_factor = float(deeper_travel_factor)
        self._i_m_el = self.channels.index("m_el") if "m_el" in self.channels and self.detector_name == "flank" else -1
        if self.nominal_inertia_kgm2 is not None and "m_el" in self.channels and "a1" in self.channels:
            # the entry sample may move back from the departure (back_to_load): the history holds it
            self.history_extra = self._history(REFINE_BACK_SAMPLES)
        elif self.detector_name == "flank" and "a1" not in self.channels and "m_el" in self.channels:
            self.history_extra = self._history(REFINE_BACK_SAMPLES)   # ... or to where the motor ran free (free_motion_start)
        elif self.detector_name == "flank" and "a1" not in self.channels:
            self.history_extra = self._history(DRIFT_BACK_SAMPLES)    # ... or to delta's free curvature (free_departure)
        self.min_travel_rad = float(min_travel_rad)
        #: departures back on their flank within confirm_samples (an encoder spike; not entries, counted)
        self.spikes = 0
        #: entries whose excursion found a new contact within min_travel_rad of the flank left (a same-flank
        #: torque change; their windows are dropped, counted; with m_el decided when the capture is complete, SHALLOW_*)
        self.flank_shifts = 0
        self._alpha = 1.0 - math.exp(-self.sample_period_s / self.flank_time_constant_s)
        self.backlash_width_m = math.nan
        self.last_width: Optional[WidthResult] = None
        self.second_entries = 0
        #: entries inside a running window that got a window of their own (a traversal back)
        self.return_windows = 0
        self.reset()

    def _n(self, n_ref):
        """A duration of ``n_ref`` samples at 2 kHz (a module constant) in this detector's samples
        (:func:`jident_ros.stream.rate.samples`; ``n_ref`` itself at 0.5 ms)."""
        return samples(n_ref, self.sample_period_s)

    def _history(self, n_ref: int) -> int:
        """Rows kept beyond samples_before_entry for a reach of ``n_ref`` samples at 2 kHz before the departure, with
        the window's samples_before_entry rows counted as the time they span at 2 kHz: at a higher rate those rows span
        less time and the difference is kept too (at 8 kHz the 48 rows are 6 ms, not 24: the second drive's traversal
        back walked back to 22 ms from the capture's start, short of the coupling model's 26 ms fit, +72 samples);
        ``n_ref`` itself at 0.5 ms."""
        return self._n(n_ref) + max(0, self._n(self.samples_before_entry) - self.samples_before_entry)

    # ------------------------------------------------------------- state
    @property
    def threshold_rad(self) -> float:
        """The departure threshold |delta - F| of the current contact (NaN while no flank is known)."""
        if self._flank is None:
            return math.nan
        return max(self.k_sigma * self._sigma, self.min_departure_rad)

    @property
    def flank_rad(self) -> Optional[float]:
        """The current flank level of delta (None: no contact learnt yet)."""
        return self._flank

    @property
    def capturing(self) -> bool:
        """True while a window is being captured (not counting an entry inside a window whose excursion is still
        undecided: a clock jump then restarts the detector, as outside a window)."""
        return any(not c.skip and not c.pending and not c.shallow for c in getattr(self, "_caps", ()))

    @property
    def _extra_needed(self) -> int:
        """History rows beyond samples_before_entry an entry needs for its window."""
        return 0 if self.extra_optional else self.history_extra

    @property
    def _forward_room(self) -> int:
        """Rows a window's entry may move forward from its departure: refine_samples (the dynamics), and without a1
        the coupling model's searches after them (a soft coupling's contact loss came 22 samples after its
        departure: its window lacked those rows, refused as short)."""
        if self.detector_name == "flank" and "a1" not in self.channels and "m_el" in self.channels:
            return self.refine_samples + self._n(COUPLING_SEARCH) * COUPLING_FORWARD_ROUNDS
        return self.refine_samples

    @property
    def angle_quantum_rad(self) -> float:
        if not self.encoder_counts_per_rev:
            return 0.0
        q = 2.0 * math.pi / self.encoder_counts_per_rev
        return math.hypot(q, self.gear_ratio * q) / math.sqrt(2.0)

    def reset(self) -> None:
        """Forget the history, the flank and the window in progress (continuity lost)."""
        if not hasattr(self, "gear_ratio"):     # called by the base __init__ before ours has run
            return
        self._wrap = {}
        self._tail = np.empty((0, len(self.channels)))
        self._last_t = None
        self._recent = np.empty(0)              # the last contact_samples - 1 delta values
        self._flank: Optional[float] = None
        self._sigma = 0.0
        self._caps: list = []                   # running captures, in the order of their entries
        self._last_cap: Optional[_FlankCapture] = None   # the capture the last entry opened (None: none)
        self._entry_id = 0                      # entries so far (ties second entries to their captures)
        self._entry_row = 0                     # stream row of the last entry
        self._new_caps: list = []               # captures opened by a window's edge scan, fed from its end on
        self._rows_in = 0                       # rows handed to the captures so far
        self._emitted_entry_rows: deque = deque(maxlen=8)    # stream rows of the last windows' entries
        if not hasattr(self, "_seen"):          # what the stream showed, for no_entry_reason (kept over resets)
            self._seen = {"contacts": 0, "spread_min": math.inf, "departure_max": 0.0, "threshold": math.nan}
        self._held_x = np.empty((0, len(self.channels)))     # rows waiting for their confirmation rows
        self._held_d = np.empty(0)
        self._skip = 0                          # samples of a spike still to skip
        self._tent: Optional[_Tent] = None      # the last entry's excursion (its travel's reference, side, need)
        self._travelled = False
        self._recent_aux = np.empty(0)          # m_el of the _recent rows (the contact's torque sign)
        self._torque_nm = 0.0                   # m_el over the current contact (0: not significant)
        self._ref_flank: Optional[float] = None  # the flank level before a same-flank move deeper into the flank
        self._last_entry_captured = False

    def set_backlash_width(self, backlash_width_m: float) -> None:
        """The flank detector needs no K2; a given width is ignored (kept for the node's interface)."""
        if getattr(self, "gear_ratio", None) is None:
            return

    # ------------------------------------------------------------- detection
    def _delta(self, x: np.ndarray) -> np.ndarray:
        return x[:, self._i_a1] - self.gear_ratio * x[:, self._i_a2]

    def _track(self, d: np.ndarray, look: np.ndarray, aux: Optional[np.ndarray] = None) -> list:
        """Run the contact tracker over the delta values ``d`` of the rows handed on (``look``: the next
        ``confirm_samples - 1`` values, to confirm a departure); returns in order ("entry", row, flank level it
        left, contact sigma) and ("cancel", row): the excursion of the last entry ended in a new contact at that row
        without ever reaching ``min_travel_rad`` from the flank it left (a same-flank torque change, not a backlash
        entry).  Vectorised per stretch."""
        events = []
        i, n, L = 0, d.size, self.contact_samples
        if self._skip:                              # the rest of a spike that began in the previous rows
            i = min(self._skip, n)
            self._skip -= i
        while i < n:
            if self._flank is None:                 # learning: the first run of L steady samples
                carried = self._recent.size
                seq = np.concatenate([self._recent, d[i:]])
                seq_aux = None if aux is None else np.concatenate([self._recent_aux, aux[i:]])
                if seq.size < L:
                    self._note_travel(seq)
                    self._recent = seq
                    if seq_aux is not None:
                        self._recent_aux = seq_aux
                    return events
                runs = np.lib.stride_tricks.sliding_window_view(seq, L)
                ok = self._contact_runs(runs)
                if not self._seen["contacts"]:
                    self._seen["spread_min"] = min(self._seen["spread_min"], float(np.ptp(runs, axis=1).min()))
                if not ok.any():
                    self._note_travel(seq)
                    self._recent = seq[-(L - 1):]
                    if seq_aux is not None:
                        self._recent_aux = seq_aux[-(L - 1):]
                    return events
                k = int(np.argmax(ok))
                level = float(runs[k].mean())
                torque = 0.0                        # m_el over the new contact (0: not significant or no m_el)
                if seq_aux is not None:
                    ra = seq_aux[k:k + L]
                    mu = float(ra.mean())
                    if abs(mu) > self.k_sigma * float(ra.std(ddof=1)) / math.sqrt(L):
                        torque = mu
                cancelled = False
                if self._tent is not None:
                    if not self._note_travel(seq[:k + L]) or self._deeper_contact(level, torque):
                        events.append(("cancel", i + k + L - carried - 1))
                        cancelled = True
                        if self._tent.side != self._torque_sign and (
                                not DEEPER_CONTACTS or self._ref_flank is None
                                or self._torque_sign * (level - self._ref_flank) <= self.threshold_rad):
                            self._ref_flank = None          # back from a deeper move: reference done
                    else:
                        self._ref_flank = None
                    self._tent = None
                if not cancelled:
                    events.append(("contact", i + k + L - carried - 1, level))
                self._torque_nm = torque
                self._recent_aux = np.empty(0)
                self._flank = level
                self._sigma = float(runs[k].std(ddof=1))
                self._seen["contacts"] += 1
                self._recent = np.empty(0)
                i += k + L - carried               # the first sample after the contact run
                continue
            # contact: first-order tracking of the flank; departure when |delta - F_prev| > threshold
            thr = self.threshold_rad
            seg = d[i:]
            f = first_order_lowpass(seg, self._alpha, self._flank)
            prev = np.concatenate([[self._flank], f[:-1]])
            out = self._departed(seg, prev, thr)
            if not self.windows_captured:
                self._seen["departure_max"] = max(self._seen["departure_max"], float(np.max(np.abs(seg - prev))))
                self._seen["threshold"] = thr
            if not out.any():
                self._flank = float(f[-1])
                return events
            k = int(np.argmax(out))
            # confirmed when the next confirm_samples - 1 values stay beyond the threshold on the same side
            side = 1.0 if seg[k] >= prev[k] else -1.0
            after = np.concatenate([seg[k + 1:], look])[:self.confirm_samples - 1]
            beyond = self._departed(after, np.full(after.size, prev[k]), thr) & (side * (after - prev[k]) > 0)
            if not beyond.all():                    # a spike: back on the flank within confirm_samples
                m = int(np.argmin(beyond))          # samples k .. k + m are the spike, skipped
                self.spikes += 1
                self._flank = float(prev[k])
                nxt = i + k + m + 1
                if nxt > n:
                    self._skip = nxt - n
                    return events
                i = nxt
                continue
            events.append(("entry", i + k, float(prev[k]), self._sigma))
            if self.min_travel_rad > 0:
                if side == self._torque_sign:
                    # deeper into the flank (delta moves with the torque it carries: more torque, the coupling
                    # twists more): an entry only after deeper_travel_factor x min_travel_rad; the level before
                    # it stays the reference of the move back
                    if self._ref_flank is None:
                        self._ref_flank = float(prev[k])
                    self._tent = _Tent(float(prev[k]), side, self.deeper_travel_factor * self.min_travel_rad,
                                       self._torque_nm)
                else:
                    ref = float(prev[k]) if self._ref_flank is None else self._ref_flank
                    self._tent = _Tent(ref, side, self.min_travel_rad)
            else:
                self._tent = None
            self._travelled = False
            self._flank = None
            self._recent = np.empty(0)
            i += k + 1      # the departure sample itself cannot be part of the next contact run
        return events

    @property
    def _torque_sign(self) -> float:
        """Sign of m_el over the current contact (0: not significant)."""
        return 0.0 if self._torque_nm == 0.0 else math.copysign(1.0, self._torque_nm)

    def _deeper_contact(self, level: float, torque: float) -> bool:
        """Whether the last entry's move deeper into the flank (with the torque its contact carried) ended in a
        contact deeper on that flank carrying m_el of the same sign, the contact it left at most
        UNTWIST_MAX_TORQUE_SHARE of it (DEEPER_CONTACTS): the coupling twisted more under more torque, a same-flank
        torque change, however far delta went."""
        t = self._tent
        if not DEEPER_CONTACTS or t is None or t.deeper_from_nm is None:
            return False
        before = t.deeper_from_nm
        return before * torque > 0.0 and abs(before) <= UNTWIST_MAX_TORQUE_SHARE * abs(torque) \
            and t.side * (level - t.ref_rad) > 0.0

    def _note_travel(self, seq: np.ndarray) -> bool:
        """Whether the excursion of the last entry has gone the travel it needs beyond its reference level, in
        the direction it left (so far)."""
        if self._tent is not None and not self._travelled and seq.size:
            t = self._tent
            self._travelled = bool(np.max(t.side * (seq - t.ref_rad)) >= t.need_rad)
        return self._travelled

    def _contact_runs(self, runs: np.ndarray) -> np.ndarray:
        """Which runs of contact_samples values are a contact: delta's spread within the tolerance."""
        return np.ptp(runs, axis=1) <= self.contact_tolerance_rad

    def _departed(self, seg: np.ndarray, prev: np.ndarray, thr: float) -> np.ndarray:
        """Which samples left the flank: |delta - F| above the threshold."""
        return np.abs(seg - prev) > thr

    def _consume(self, x: np.ndarray) -> list:
        """Hands the rows on to the tracker ``confirm_samples - 1`` rows late (a departure is confirmed by the
        rows after it)."""
        d = self._delta(x)
        h = self.confirm_samples - 1
        rows = np.concatenate([self._held_x, x]) if self._held_x.shape[0] else x
        dd = np.concatenate([self._held_d, d]) if self._held_d.size else d
        ready = rows.shape[0] - h
        events = []
        if ready > 0:
            events = self._consume_rows(rows[:ready], dd[:ready], dd[ready:])
            self._held_x, self._held_d = rows[ready:], dd[ready:]
        else:
            self._held_x, self._held_d = rows, dd
        self._last_t = float(x[-1, self._i_t])
        return events

    def _consume_rows(self, x: np.ndarray, d: np.ndarray, look: np.ndarray) -> list:
        events = []
        found = self._track(d, look, x[:, self._i_m_el] if self._i_m_el >= 0 else None)
        pos = 0                                   # rows of x before pos are fed to the running captures
        extra = self.history_extra
        for kind, k, *rest in found:
            if kind == "cancel":
                # the last entry was a same-flank torque change: its capture is dropped (counted) unless it was
                # complete before the change was known, or runs on as a shallow one (SHALLOW_*); in other windows it
                # is no longer a second entry
                events += self._feed(x[pos:k + 1])
                pos = max(pos, k + 1)
                self._cancel_last()
                continue
            if kind == "contact":
                # the last entry's excursion ended in a contact: an entry inside another window gets its own
                # window when that contact lies on the other flank (a traversal), else (a bounce back to the
                # flank it left) it stays a second entry of the window holding it
                last = self._last_cap
                travel = self._rows_in + k - self.contact_samples + 1 - self._entry_row
                if last is not None and last.pending and last in self._caps:
                    events += self._feed(x[pos:k + 1])
                    pos = max(pos, k + 1)
                if last is not None and last.pending and last in self._caps:
                    if abs(rest[0] - last.flank_rad) > max(self.min_travel_rad, self.threshold_for(last)) \
                            and travel >= self._n(MIN_TRAVERSAL_SAMPLES) and not self._came_back(last) \
                            and self._crossed_zone(last, rest[0]):
                        last.pending = False
                        self.return_windows += 1
                        for c in self._caps:
                            for e in c.second_entry_rows:
                                if e[1] == self._entry_id:
                                    e[2] = True
                    else:
                        self._caps.remove(last)
                self._last_cap = None
                continue
            flank, sigma = rest
            events += self._feed(x[pos:k])        # rows before k belong to the running captures
            pos = max(pos, k)
            for c in [c for c in self._caps if c.shallow]:
                self._caps.remove(c)               # a shallow excursion followed by an entry: dropped, as before
                self.flank_shifts += 1
            self._entry_id += 1
            self._entry_row = self._rows_in + k
            hist = np.concatenate([self._tail, x[:k]])[-(self.samples_before_entry + extra):]
            t_k = float(x[k, self._i_t])
            if self._caps:
                # an entry inside a running window: a second entry of each (information)
                for c in self._caps:
                    if not c.skip:
                        c.second_entry_rows.append([c.count, self._entry_id, False])
                self._last_cap = None
                if self.second_windows and not any(c.skip for c in self._caps) \
                        and hist.shape[0] >= self.samples_before_entry + self._extra_needed:
                    self._last_cap = _FlankCapture([hist], hist.shape[0], hist.shape[0], flank, sigma, pending=True,
                                                   returning=True,
                                                   start_row=self._entry_row - hist.shape[0])
                    self._caps.append(self._last_cap)
                continue
            # a new entry at row k (no capture running now)
            if hist.shape[0] < self.samples_before_entry + self._extra_needed:
                events.append(self._short_history(t_k, hist.shape[0], self.samples_before_entry + self._extra_needed))
                self._last_cap = _FlankCapture([], self.samples_before_entry + extra,
                                               self.samples_before_entry + extra, math.nan, math.nan, skip=True)
            else:
                # an entry inside a window given out before this detector started (ImuSkewGuard's second pass from
                # inside the window before the skewed one) is a traversal back, as one inside a running capture
                self._last_cap = _FlankCapture([hist], hist.shape[0], hist.shape[0], flank, sigma,
                                               start_row=self._entry_row - hist.shape[0],
                                               returning=t_k <= self.inside_window_until_s)
            self._caps.append(self._last_cap)
        events += self._feed(x[pos:])
        self._tail = np.concatenate([self._tail, x])[-(self.samples_before_entry + extra):]
        self._rows_in += x.shape[0]
        return events

    def _cancel_last(self) -> None:
        """The last entry's excursion ended in a contact short of min_travel_rad: a window's own capture runs on as a
        shallow one (SHALLOW_*, decided when it is complete), any other is dropped (a same-flank torque change,
        counted) and is no longer a second entry of the other windows."""
        last = self._last_cap
        self._last_cap = None
        if SHALLOW_GAPS and last is not None and last in self._caps and not (
                last.pending or last.returning or last.skip) and self._i_m_el >= 0:
            last.shallow = True
            return
        self.flank_shifts += 1
        if last is not None and last in self._caps:
            self._caps.remove(last)
        for c in self._caps:
            c.second_entry_rows = [e for e in c.second_entry_rows if e[1] != self._entry_id]

    def _crossed_zone(self, cap: _FlankCapture, level: float) -> bool:
        """Whether a pending entry's excursion, ending in a contact at ``level``, crossed the zone: it travelled at
        least RETURN_MIN_SPAN_SHARE of the way from the flank it left to the farthest flank level of the other
        running captures (the zone those windows crossed).  True when no other capture knows a flank."""
        spans = [abs(c.flank_rad - cap.flank_rad) for c in self._caps
                 if c is not cap and not c.skip and not c.pending and math.isfinite(c.flank_rad)]
        span = max(spans, default=0.0)
        if not span > max(self.min_travel_rad, self.threshold_for(cap)):
            return True
        return abs(level - cap.flank_rad) >= RETURN_MIN_SPAN_SHARE * span

    def _came_back(self, cap: _FlankCapture) -> bool:
        """Whether delta came back to the flank a capture's entry left (within its departure threshold) after the
        entry's confirmation: a bounce, whatever contact comes later (short contacts are not learnt)."""
        d = self._delta(np.concatenate(cap.rows)[cap.departure_row + self.confirm_samples:])
        return bool(np.any(np.abs(d - cap.flank_rad) <= self.threshold_for(cap)))

    def _feed(self, rows: np.ndarray) -> list:
        """Rows to every running capture (each up to its length); the windows completed by them, in order."""
        events = []
        for cap in list(self._caps):
            # a capture completed before it in this loop may have replaced it (_open_return: a traversal back
            # found late by the contact rule); a whole recording in one batch reaches that (it raised ValueError)
            if any(c is cap for c in self._caps):
                events += self._feed_one(cap, rows)
        return events

    def _feed_one(self, cap: _FlankCapture, rows: np.ndarray) -> list:
        """Rows to one capture; when it completes, its window (a pending one found no contact within its window: a
        long excursion, kept), then the rows after its end to the captures its edge scan opened.  A capture is
        complete with samples_from_entry + refine_samples rows from its departure on (the entry sample moves at
        most refine_samples forward; without a1, COUPLING_SEARCH x COUPLING_FORWARD_ROUNDS more: the coupling
        model's searches, :attr:`_forward_room`)."""
        need = cap.departure_row + self.samples_from_entry + self._forward_room
        take = max(min(need - cap.count, rows.shape[0]), 0)
        if take > 0:
            if not cap.skip:
                cap.rows.append(rows[:take])
            cap.count += take
        if cap.count < need:
            return []
        self._caps.remove(cap)
        if cap.skip:
            return []
        ev = self._finish_flank(cap)
        events = [] if ev is None else [ev]
        opened, self._new_caps = self._new_caps, []
        for new in opened:
            if any(c is new for c in self._caps):
                events += self._feed_one(new, rows[take:])
        return events

    def finish(self) -> list:
        """The data ended: a window in progress is reported as ``cut_off`` (a drop, counted); the event
        carries the partial window (FLAG_CUT_OFF set) for an offline report.  An entry inside another window
        whose excursion has not yet ended in a contact is not reported."""
        events = []
        if self._held_x.shape[0]:
            held_x, held_d = self._held_x, self._held_d
            self._held_x, self._held_d = held_x[:0], held_d[:0]
            events = self._consume_rows(held_x, held_d, held_d[:0])
        return events + self._finish_capture()

    def _finish_capture(self) -> list:
        caps, self._caps, self._last_cap = self._caps, [], None
        events = []
        for cap in caps:
            self.flank_shifts += int(cap.shallow)  # undecided: dropped as a same-flank torque change, as before
            if cap.skip or cap.pending or cap.shallow:
                continue
            data = np.concatenate(cap.rows)
            e = cap.departure_row
            events.append(self._cut_off(data, e, float(data[e, self._i_t]), math.nan, self.detector_name))
        return events

    def _finish_flank(self, cap: _FlankCapture) -> Event | None:
        """The window of a complete capture; None when a window with this entry went out already (counted)."""
        data = np.concatenate(cap.rows)
        dep = cap.departure_row
        shallow = self._shallow_gap(data, dep, cap.flank_rad) if cap.shallow else None
        if cap.shallow and shallow is None:
            self.flank_shifts += 1                 # a same-flank torque change after all (SHALLOW_*): no entry
            return None
        if not cap.returning and self._untwisted(data, dep, cap.flank_rad):
            self.flank_shifts += 1                 # a slip that left the coupling twisted (UNTWIST_*): no entry
            return None
        self._cap_sigma = cap.flank_sigma_rad      # the entry flank's contact noise (free_departure)
        self._cap_returning = cap.returning
        self._cap_flank = (cap.flank_rad, self.threshold_for(cap))
        self._prepared = None
        shift, recontact = self._refine(data, dep)
        shift = self._zone_move(self._prepared if self._prepared is not None else data, dep, dep + shift, cap,
                                recontact) - dep
        shallow_rc = shallow is not None and SHALLOW_AT_ZERO_TWIST
        if shallow_rc:
            shift = shallow[0] - dep               # the contact lost where the coupling's twist is zero (SHALLOW_*)
        entry_row = cap.start_row + dep + shift
        if cap.after_row < entry_row < cap.turn_row:
            # a crossing after a bounce walked back through its turn, not to the window's own entry (REBOUND_*)
            shift = cap.level_row - cap.start_row - dep
            entry_row = cap.level_row
        if self._repeated(entry_row, cap):
            return None
        self._emitted_entry_rows.append(entry_row)
        e0, win, rc, res = self._width(data, dep + shift, cap, recontact)
        back = None if not shallow_rc or shallow[1] is None else shallow[1] - e0
        if back is not None and back < self.window_length and not 0 <= res.recontact_index <= back:
            res.recontact_index = back             # met again by the time delta is back at the zero twist (SHALLOW_*)
        e = self.samples_before_entry
        self.last_width = res
        if self.second_windows and res.how == "traversal" and res.recontact_index > e:
            self._scan_returns(cap, data, self._delta(win), e0, e, res.recontact_index)
        if self.second_windows and REBOUND_MAX_SHARE and not cap.returning:
            self._scan_rebound(cap, data, dep + shift)
        flags = (FLAG_SHALLOW_GAP if cap.shallow else 0) | (FLAG_BOUNCE if res.how == BOUNCE_HOW else 0)
        inside = [se for se in cap.second_entry_rows if dep + shift < se[0] < e0 + self.window_length]
        swallowed = ""
        if inside:
            flags |= FLAG_SECOND_ENTRY
            self.second_entries += 1
            d = self._delta(win)
            back = np.abs(d[e:e + self.contact_samples // 2] - cap.flank_rad) <= self.threshold_for(cap)
            inside = [se for se in inside if not se[2]]     # the others have a window of their own
            if inside and (not math.isfinite(res.width_m) or back.any()):
                # the window's own entry shows no traversal, or delta was back on the flank it left within
                # contact_samples / 2 samples (a glitch longer than confirm_samples, not a gap: the shortest gap
                # on our models is 11 samples, and it never ends on the flank it left); the entry inside it gets
                # no window of its own: a loss, counted
                self.counts["swallowed_entry"] += len(inside)
                why = "delta back on its flank at once" if back.any() else f"no traversal: {res.how}"
                swallowed = (f"; its own entry looks false ({why}) and it holds {len(inside)} later "
                             f"entr{'y' if len(inside) == 1 else 'ies'} (swallowed, counted)")
        self.windows_captured += 1
        if math.isfinite(res.width_m):
            self.backlash_width_m = res.width_m
        w = Window(np.ascontiguousarray(win), self.channels, e, float(win[e, self._i_t]), res.width_m,
                   self.wheel_radius_m, self.sample_period_s, self.windows_captured,
                   backlash_width_estimate_m=res.width_m, backlash_width_se_m=res.se_m, detector=self.detector_name,
                   flags=flags,
                   recontact_index=res.recontact_index if res.recontact_index >= 0 or rc is None else rc)
        ev = Event("window", detail=f"window {w.window_id}: entry at t = {w.entry_time_s:.6f} s, K2 estimate "
                                    f"{res.width_m:.6g} m ({res.how}){swallowed}", window=w)
        self.last_event = ev
        return ev

    def _repeated(self, entry_row: int, cap: _FlankCapture) -> bool:
        """Whether a window entering at stream row ``entry_row`` repeats one given out (counted, ``duplicate_entry``):
        the same entry found by two rules, or a crossing after a bounce walked back to the bounce's own entry."""
        dup = self._n(DUPLICATE_ENTRY_SAMPLES)
        if any(abs(entry_row - r) <= dup for r in self._emitted_entry_rows) or entry_row <= cap.after_row:
            # the same traversal by two rules (a returning capture from a window's edge scan and the contact rule's:
            # docs/your_drive.md's small drive gave its traversal back twice, at the same sample), or a crossing after a
            # bounce (REBOUND_*) whose rules walked it back to the window's own entry
            self.counts["duplicate_entry"] += 1
            return True
        return False

    def _untwisted(self, data: np.ndarray, dep: int, flank_rad: float) -> bool:
        """Whether a capture's excursion only untwisted the coupling on the flank it left (UNTWIST_* constants): it
        settled there with the coupling carrying at most UNTWIST_MAX_TORQUE_SHARE of the steady torque of the same
        sign, and delta never passed the zero-twist point of the two contacts by UNTWIST_PAST_SHARE of it."""
        zt = self._zero_twist(data, dep, flank_rad)
        return zt is not None and zt[0] < (1.0 + UNTWIST_PAST_SHARE) * zt[1]

    def _shallow_gap(self, data: np.ndarray, dep: int, flank_rad: float) -> Optional[tuple]:
        """(the row where delta first reaches the zero-twist point z, the row where it comes back inside z or None) of
        a shallow excursion (SHALLOW_*: it ended short of min_travel_rad on the flank it left) that passed z of the two
        contacts by SHALLOW_PAST_SHARE of it and SHALLOW_PAST_QUANTA quanta of delta: the coupling let go (a gap), not
        only untwisted; None otherwise."""
        zt = self._zero_twist(data, dep, flank_rad)
        if zt is None:
            return None
        d = self._delta(data)
        q = max(_delta_quantum(d, dep, self.angle_quantum_rad, max(dep - self._n(UNTWIST_FIT_BEFORE), 0),
                               self.min_departure_rad), ANGLE_MODEL_FLOOR_RAD)
        if not zt[0] >= max((1.0 + SHALLOW_PAST_SHARE) * zt[1], zt[1] + SHALLOW_PAST_QUANTA * q):
            return None
        side = 1.0 if d[dep] >= flank_rad else -1.0
        entry = dep + int(np.nonzero(side * (d[dep:] - flank_rad) >= zt[1])[0][0])   # zt[0] >= z: delta reaches z
        back = np.nonzero(side * (d[entry:] - flank_rad) < zt[1])[0]
        return entry, (entry + int(back[0]) if back.size else None)

    def _zero_twist(self, data: np.ndarray, dep: int, flank_rad: float) -> Optional[tuple]:
        """(delta's farthest travel from the flank level after the departure, the zero-twist point z's distance) of
        an excursion that settled on the flank it left with the coupling carrying at most UNTWIST_MAX_TORQUE_SHARE of
        the steady torque of the same sign (UNTWIST_*); None otherwise (no m_el, too short, not settled, ...)."""
        if self._i_m_el < 0 or not math.isfinite(flank_rad):
            return None
        rows = samples(SPRING_TORQUE_ROWS, self.sample_period_s)
        tail = self._n(UNTWIST_TAIL_ROWS)
        if dep - rows[0] < 0 or data.shape[0] - tail <= dep:
            return None
        d = self._delta(data)
        m = data[:, self._i_m_el]
        t0 = float(np.median(m[dep - rows[0]:dep - rows[1]]))
        t1 = float(np.mean(m[-tail:]))
        if not (t0 != 0.0 and 0.0 <= t1 / t0 <= UNTWIST_MAX_TORQUE_SHARE):
            return None
        if np.ptp(d[-tail:]) > self.contact_tolerance_rad:
            return None                             # not settled in a contact
        side = 1.0 if d[dep] >= flank_rad else -1.0
        moved = side * (float(np.mean(d[-tail:])) - flank_rad)
        if not moved > 0:
            return None
        z = moved * t0 / (t0 - t1)                  # the zero-twist point's distance from the flank level
        return float(np.max(side * (d[dep:] - flank_rad))), z

    def _width(self, data: np.ndarray, entry: int, cap: _FlankCapture, recontact: Optional[int]) -> tuple:
        """(the window's first capture row, the window, its re-contact row from the rules or None, :func:`estimate_width`)
        of the window with its entry at capture row ``entry``."""
        e0 = entry - self.samples_before_entry
        win = data[e0:e0 + self.window_length]
        wd = {c: win[:, j] for j, c in enumerate(self.channels)}
        rc = None if recontact is None or recontact - e0 >= self.window_length else recontact - e0
        res = estimate_width(wd, self.samples_before_entry, self.wheel_radius_m, self.sample_period_s, self.gear_ratio,
                             flank_rad=cap.flank_rad, recontact=rc, angle_quantum_rad=self.angle_quantum_rad,
                             contact_samples=self.contact_samples, contact_tolerance_rad=self.contact_tolerance_rad)
        return e0, win, rc, res

    def _scan_returns(self, cap: _FlankCapture, data: np.ndarray, d: np.ndarray, e0: int, e: int, g: int) -> None:
        """Return traversals inside a traversal window that no contact announced (the contacts between them are
        shorter than contact_samples or ring: the second drive's impacts): the window's own traversal gives both
        flanks' edges (δ at its entry and at its re-contact); δ leaving the re-contact edge into the zone and
        reaching the entry edge before it comes back is a traversal back, entering at its first sample in the
        zone.  Each one that has no capture yet opens one (from this window's rows on, fed from its end)."""
        edge_in, edge_out = 0.5 * (d[e - 1] + d[e]), 0.5 * (d[g - 1] + d[g])
        span = edge_out - edge_in
        margin = self.threshold_for(cap)
        if not abs(span) > 4.0 * margin:
            return
        s = 1.0 if span > 0 else -1.0
        depth = s * (edge_out - d)                 # how far inside the zone from the re-contact edge (> 0: inside)
        to_in = s * (d - edge_in)                  # how far from the entry edge (<= margin: reached it)
        # the edge lies between the samples around the contact instant: beyond it by less than half that step is
        # no proof of a contact (the second drive's slow return traversal dips 0.8 mrad past the estimate)
        unsure = 0.5 * max(abs(d[g] - d[g - 1]), margin)
        rest_rows = self._n(RETURN_REST_SAMPLES)
        if g + rest_rows > d.size or np.any(depth[g:g + rest_rows] > unsure):
            return          # no contact on the re-contact edge after it (a misread excursion: edges not trusted)
        steady, quantum = self._scan_profile(d, margin)
        coarse, L = quantum > 0.0, self.contact_samples
        known = [c.start_row + c.departure_row for c in self._caps + self._new_caps]
        k, n, at_out, last_out, armed = g + 1, d.size, True, g, cap.start_row + e0 + g
        near = RETURN_TURN_SHARE * abs(span)
        rest = 0.0                                 # depth up to which delta rests at the re-contact edge
        deep, low, low_k = False, math.inf, -1     # this excursion: went beyond `near`; its least depth since then
        peak = 0.0                                 # ... and its greatest depth
        free_until = 0                             # a still run up to here was a turn the motor ran free through
        while k < n:
            if at_out:                             # resting at (or beyond) the re-contact edge
                if depth[k] <= rest:
                    last_out = k
                elif depth[k] > (margin if rest == 0.0 else rest) and to_in[k] > margin:
                    at_out, deep, low, peak = False, False, math.inf, 0.0     # left it into the zone
                k += 1
                continue
            if steady[k] and depth[k] >= -unsure and depth[k] < 0.5 * abs(span) and coarse and k >= free_until \
                    and self._turned_free(data, e0 + k - L // 2, quantum):
                # the motor ran free through delta's still run (RETURN_FREE_TURN_*): a turn inside the zone, no contact
                free_until = k + L
            if depth[k] < -unsure or (steady[k] and depth[k] < 0.5 * abs(span) and k >= free_until):
                # back beyond the re-contact edge, or a contact nearer to it than to the entry edge (the edge from
                # the window's re-contact row may be a few mrad off: 5 mrad on the vector drive's 2^13 JointState
                # recordings): a bounce
                at_out, last_out, rest = True, k, 0.0
                k += 1
                continue
            deep = deep or depth[k] > (RETURN_SHALLOW_TURN_SHARE if coarse else 2.0 * RETURN_TURN_SHARE) * abs(span)
            peak = max(peak, float(depth[k]))
            if deep and depth[k] < low:
                low, low_k = float(depth[k]), k
            if coarse and deep and low < near and depth[k] > low + margin:
                if self._turned_free(data, e0 + low_k, quantum):
                    # the motor ran free through the turn (the motor equation explains alpha1 across it): a turn
                    # inside the zone, no contact; this excursion goes on (RETURN_FREE_TURN_*)
                    deep, low, k = False, math.inf, k + 1
                    continue
                # back near the re-contact edge and leaving it again, shorter than a contact (RETURN_TURN_SHARE): a
                # bounce; delta rests there until it leaves its turning depth by RETURN_REST_DEPARTURES departure
                # thresholds, where a traversal back from it starts
                rests = RETURN_REST_DEPARTURES if peak > 2.0 * near else RETURN_SHALLOW_REST_DEPARTURES
                at_out, rest = True, low + rests * margin
                last_out = low_k + int(np.nonzero(depth[low_k:k + 1] <= rest)[0][-1])
                continue
            if to_in[k] > margin:
                k += 1
                continue
            # reached the entry edge: a traversal back, entering at the first sample past the re-contact edge
            reached = cap.start_row + e0 + k
            while k < n and depth[k] > 0:          # re-armed only once back at the re-contact edge
                k += 1
            at_out, start, rest, since, armed = True, last_out + 1, 0.0, armed, cap.start_row + e0 + k
            last_out = k
            row = e0 + start                            # capture row of the return traversal's entry
            abs_row = cap.start_row + row
            if any(abs(abs_row - r) <= self._n(RETURN_MATCH_SAMPLES) or RETURN_SAME_EXCURSION and since < r < abs_row for r in known):
                continue                                # the contact rule found it already (RETURN_SAME_EXCURSION)
            if self._open_return(cap, data, row, reached, float(edge_out)):
                known.append(abs_row)

    def _scan_rebound(self, cap: _FlankCapture, data: np.ndarray, entry: int) -> None:
        """A crossing of the zone that starts from a short re-contact on the flank a window's own excursion left
        (REBOUND_*): delta leaves its flank at the window's entry (a slip's bounce), comes back to it for fewer than
        contact_samples (the tracker learns no contact there and sees no departure), then crosses the zone.  The crossing
        gets a capture of its own, as a traversal back inside a running window does (:meth:`_open_return`), departing at
        delta's deepest return toward the flank; its traversal-back rules place its entry."""
        d = self._delta(data)
        lo, n = max(entry - self.samples_before_entry, 0), min(entry + self.samples_from_entry, d.size)
        base = float(np.median(d[lo:lo + self.contact_samples // 2]))   # the contact before the window's entry
        off = d[lo:n] - base
        far = int(np.argmax(np.abs(off)))
        u = (1.0 if off[far] > 0 else -1.0) * off[:far + 1]                # toward the far flank
        if not u[far] > 4.0 * self.threshold_for(cap):
            return                                  # no crossing of the zone in this window (as _scan_returns)
        peak = np.maximum.accumulate(u)
        t = int(np.argmax(peak - u))                # delta's deepest return toward the flank after leaving it
        quantum = max(_delta_quantum(d, entry, self.angle_quantum_rad, lo, self.min_departure_rad), ANGLE_MODEL_FLOOR_RAD,
                      _noise(d[lo:lo + self.contact_samples // 2]))
        back = max(REBOUND_MIN_QUANTA * quantum, REBOUND_MIN_DEPARTURE_SHARE * self.min_departure_rad)
        if not (peak[t] <= REBOUND_MAX_SHARE * u[far] and peak[t] - u[t] >= back
                and u[t] <= REBOUND_BACK_SHARE * peak[t]) or lo + t <= entry + self._n(RETURN_MATCH_SAMPLES):
            return                                  # no bounce, or the window's own entry lies at the crossing's start
        abs_row = cap.start_row + lo + t
        if any(abs(abs_row - c.start_row - c.departure_row) <= self._n(RETURN_MATCH_SAMPLES)
               for c in self._caps + self._new_caps):
            return                                  # the contact rule found it already
        if self._open_return(cap, data, lo + t, cap.start_row + lo + far, float(d[lo + t])):
            # its entry must come after the window's own: one its rules walk back to it is the window's excursion
            new = self._new_caps[-1]
            new.after_row = cap.start_row + entry + self._n(RETURN_MATCH_SAMPLES)
            # ... and not before the turn, where delta was back in contact: one the traversal-back walk puts there (a
            # soft coupling's re-contact twists it again, and the walk ran through the turn: d11-03 24 samples early)
            # lies where delta passes the level it left its flank at in the window's own entry (the zero twist of
            # the coupling, where the bounce let go: d11-03 +1; the rules' entries, kept otherwise, -2 ... +4)
            past = np.nonzero((1.0 if off[far] > 0 else -1.0) * (d[lo + t:lo + far + 1] - d[entry]) >= 0)[0]
            new.turn_row = cap.start_row + lo + t
            new.level_row = new.turn_row + int(past[0]) if past.size else new.turn_row

    def _scan_profile(self, d: np.ndarray, margin: float) -> tuple:
        """For :meth:`_scan_returns`: (whether a contact as the tracker takes it, contact_samples within
        contact_tolerance_rad, ends at each sample; delta's quantum on a coarse encoder, else 0: its smallest step, as
        _refine's, beyond FREE_MAX_NOISE_RAD sqrt 12 (2^13), where the traversal back's walk and coupling model are off
        and the scan's start is its entry, RETURN_TURN_SHARE)."""
        L = self.contact_samples
        steady = np.zeros(d.size, bool)
        if d.size >= L:
            steady[L - 1:] = np.ptp(np.lib.stride_tricks.sliding_window_view(d, L), axis=1) <= self.contact_tolerance_rad
        steps = np.abs(np.diff(d))
        steps = steps[(steps > 1e-9) & (steps < margin)]
        coarse = bool(steps.size) and float(steps.min()) / math.sqrt(12.0) > FREE_MAX_NOISE_RAD
        return steady, float(steps.min()) if coarse else 0.0

    def _turned_free(self, data: np.ndarray, row: int, quantum_rad: float) -> bool:
        """Whether the motor ran free through a turn of delta at capture row ``row``: the motor equation in angle form
        (alpha1 = a + v k + Phi / J + c k^2, :func:`_free_columns`) fitted over RETURN_FREE_TURN_HALF rows each side
        leaves an rms within RETURN_FREE_TURN_RMS x ``quantum_rad`` / sqrt 12 (delta's smallest step: the encoder's).
        False without m_el or rows enough (the turn is then taken for a bounce, as before)."""
        a, z = row - self._n(RETURN_FREE_TURN_HALF), row + self._n(RETURN_FREE_TURN_HALF)
        if "m_el" not in self.channels or a < 0 or z > data.shape[0]:
            return False
        alpha1 = np.asarray(data[a:z, self._i_a1], float)
        phi = _double_integral(data[a:z, self.channels.index("m_el")], self.sample_period_s)
        rss, _ = _lstsq_rss(_free_columns(np.arange(a, z, dtype=float) - row, phi), alpha1 - alpha1[0])
        rms = math.sqrt(rss / max(z - a - 4, 1))
        return rms <= RETURN_FREE_TURN_RMS * quantum_rad / math.sqrt(12.0)

    def _open_return(self, cap: _FlankCapture, data: np.ndarray, row: int, reached: int, edge_out: float) -> bool:
        """A capture for the traversal back entering at capture row ``row`` of ``cap`` (reaching the entry edge at
        stream row ``reached``), fed from ``data``'s rows on; False when the history before it is too short."""
        abs_row = cap.start_row + row
        lo = max(row - self.samples_before_entry - self.history_extra, 0)
        if row - lo < self.samples_before_entry + self._extra_needed:
            return False
        for c in [c for c in self._caps if abs_row < c.start_row + c.departure_row <= reached]:
            self._caps.remove(c)                    # found late by the contact rule (delta resting at the flank
            self.return_windows -= 1                # looked like a contact): the edge crossing replaces it
        rows = data[lo:]
        new = _FlankCapture([rows], rows.shape[0], row - lo, edge_out, cap.flank_sigma_rad, returning=True,
                            start_row=cap.start_row + lo)
        self._caps.append(new)
        self._new_caps.append(new)
        self.return_windows += 1
        for c in self._caps:
            if c is not new and not c.skip and c.start_row <= abs_row:
                c.second_entry_rows.append([abs_row - c.start_row, -1, True])
        return True

    def no_entry_reason(self) -> str:
        """Why no entry was found so far, and what to set (one line; '' when a window was captured)."""
        if self.windows_captured or not self.samples_seen:
            return ""
        seen = self._seen
        what = "delta = alpha1 - N alpha2" if self.detector_name == "flank" else "the load torque m_el - J1_nom dω1/dt"
        extra = ""
        if self.spikes or self.flank_shifts:
            extra = (f"; {self.spikes} encoder spike(s) and {self.flank_shifts} same-flank torque change(s) "
                     f"(excursion below min_travel_rad {self.min_travel_rad:g} rad) were not taken for entries")
        if not seen["contacts"]:
            if self.detector_name != "flank":
                return (f"{what} never showed a steady load over contact_samples {self.contact_samples} samples: a "
                        f"drive that carries no load has no contact to lose (nominal J1 {self.nominal_inertia_kgm2:g} "
                        f"kg m^2 wrong?){extra}")
            return (f"{what} (gear_ratio N = {self.gear_ratio:g}) never stayed within contact_tolerance_rad "
                    f"{self.contact_tolerance_rad:g} rad over contact_samples {self.contact_samples} samples (its "
                    f"smallest spread: {seen['spread_min']:.4g} rad): a wrong gear_ratio (motor turns per load-encoder "
                    f"turn; negative when the load encoder counts the other way), angles not in rad (--map SCALE), or "
                    f"a drive that never rests on a flank{extra}")
        return (f"{what} rested on a flank but never left it by more than the departure threshold "
                f"{seen['threshold']:.4g} (largest move {seen['departure_max']:.4g}): no backlash entry in these data "
                f"(k_sigma, min_departure_rad set the threshold){extra}")

    def threshold_for(self, cap: _FlankCapture) -> float:
        """The departure threshold of the contact a capture's entry left."""
        return max(self.k_sigma * cap.flank_sigma_rad, self.min_departure_rad)

    def _jumped(self, data: np.ndarray, dep: int) -> bool:
        """Whether delta left its flank by a jump at ``dep`` (a slip of the line or the load encoder, our simulator's
        scenario: the contact is lost at that sample, not while delta moves off gradually), as
        :func:`estimate_width` tells a slip: the step into the departure sample 4 x the steps around it, and beyond
        10 quanta and contact_tolerance_rad."""
        if not 2 <= dep < data.shape[0] - 1:
            return False
        d = self._delta(data[dep - 2:dep + 2])
        before, step, after = d[1] - d[0], d[2] - d[1], d[3] - d[2]
        return abs(step) > max(4.0 * max(abs(before), abs(after)), 10.0 * self.angle_quantum_rad,
                               self.contact_tolerance_rad)

    def _refine(self, data: np.ndarray, dep: int):
        """(samples from the departure to the entry sample, re-contact row or None): :meth:`_refine_from` the
        departure moved on to where delta left its flank by COARSE_DEPARTURE_QUANTA counts (:meth:`_coarse_departure`)."""
        moved = self._coarse_departure(data, dep)
        self._prepared = self._torque_aligned(self._disc_corrected(data), moved)
        shift, recontact = self._refine_from(self._prepared, moved)
        return shift + moved - dep, recontact

    def _disc_corrected(self, data: np.ndarray) -> np.ndarray:
        """``data`` with each encoder's disc error (:func:`disc_error`, fitted over the last DISC_TAIL_SAMPLES rows)
        subtracted from its angle; ``data`` itself when neither shows one."""
        if not DISC_MIN_GAIN or self.detector_name != "flank":
            return data
        out = data
        for j in (self._i_a1, self._i_a2):
            if j < 0:
                continue
            corrected, coef = disc_corrected(data[:, j], self.sample_period_s)
            if coef is not None:
                out = np.array(data, float, copy=True) if out is data else out
                out[:, j] = corrected
        return out

    def _torque_aligned(self, data: np.ndarray, dep: int) -> np.ndarray:
        """``data`` with m_el advanced by one sample when it reads a sample late (:func:`torque_late_gain` at least
        TORQUE_LATE_MIN_GAIN), for a window's own entry without a1, on a fine encoder (delta's quantum, the configured
        one else its smallest step before the departure, / sqrt 12 within FREE_MAX_NOISE_RAD, as :meth:`_ramp_move`)
        and not after a jump of delta (a slip: the rules do not run); else ``data`` itself."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not TORQUE_LATE_MIN_GAIN or self.detector_name != "flank" or "a1" in self.channels \
                or "m_el" not in self.channels or getattr(self, "_cap_returning", False) or not math.isfinite(flank) \
                or self._jumped(data, dep):
            return data
        delta = self._delta(data)
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(UNTWIST_FIT_BEFORE), 0),
                                 self.min_departure_rad)
        if not quantum / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD:
            return data
        after = delta[dep:dep + self._n(COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        i_m = self.channels.index("m_el")
        if not torque_late_gain(data[:, self._i_a1], delta, data[:, i_m], dep, side,
                                self.sample_period_s) >= TORQUE_LATE_MIN_GAIN:
            return data
        out = np.array(data, float, copy=True)
        out[:, i_m] = shifted(data[:, i_m], 1.0)
        return out

    def _coarse_departure(self, data: np.ndarray, dep: int) -> int:
        """On a coarse encoder (delta's quantum / sqrt 12 beyond FREE_MAX_NOISE_RAD: its smallest step in the
        UNTWIST_FIT_BEFORE rows before the departure, below the departure threshold, as :meth:`_untwist_move`), a
        window's own departure whose threshold was below COARSE_DEPARTURE_QUANTA counts moves on to the first sample
        beyond that many counts from the flank, within COARSE_DEPARTURE_SEARCH samples; else ``dep``."""
        flank, thr = getattr(self, "_cap_flank", (math.nan, math.nan))
        if getattr(self, "_cap_returning", False) or not math.isfinite(flank) or self.detector_name != "flank":
            return dep
        delta = self._delta(data)
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(UNTWIST_FIT_BEFORE), 0), thr)
        if not quantum / math.sqrt(12.0) > FREE_MAX_NOISE_RAD or thr >= COARSE_DEPARTURE_QUANTA * quantum:
            return dep
        beyond = np.nonzero(np.abs(delta[dep:dep + self._n(COARSE_DEPARTURE_SEARCH)] - flank)
                            > COARSE_DEPARTURE_QUANTA * quantum)[0]
        return dep + int(beyond[0]) if beyond.size else dep

    def _refine_from(self, data: np.ndarray, dep: int):
        """(samples from the departure to the entry sample, re-contact row or None) from the dynamics
        (:func:`single_mass_run`), (0, None) without m_el, a motor acceleration or J1_nom.  Without a1: first moved
        back to delta's free curvature when delta drifted off its flank before the departure (:func:`free_departure`;
        then the forward move is not tried); (0, None) when delta jumped off its flank (:meth:`_jumped`: a slip)."""
        jumped = self._jumped(data, dep)
        if self.detector_name == "flank" and "a1" not in self.channels and "m_el" in self.channels \
                and getattr(self, "_cap_returning", False):
            e = self._angle_walk_entry(data, dep)
            if e != dep:            # back, or forward past the departure (RETURN_NOMINAL_J)
                return e - dep, None
        # not in a traversal back (delta rings at the other flank after the impact before it leaves it again: on the
        # vector drive's 2^13 speed steps the move took return entries 10-40 samples back, one before its gap)
        if self.detector_name == "flank" and "a1" not in self.channels and not jumped \
                and not getattr(self, "_cap_returning", False):
            e = self._ramp_move(data, dep)
            if e is not None:
                # the motor equation's contact loss with the coupling torque ramping to zero (RAMP_*): before
                # free_departure, whose line-then-parabola fits delta of the base drive's light load reversal only
                return e - dep, None
            e = self._free_departure_entry(data, dep)
            if e < dep:
                return e - dep, None
        if self.nominal_inertia_kgm2 is None or "m_el" not in self.channels:
            return 0, None
        if "a1" not in self.channels and jumped:
            # delta jumped off its flank (a slip): the contact is lost at the jump.  Without a1 the dynamics' forward
            # move runs on the noisy second difference of alpha1 and put 21 of the raw scenario's 40 entries 1-12
            # samples late (its run's re-contact row with them: 8 of 40 windows refused); the gap stage finds both
            return 0, None
        # without a1 the rows kept for free_departure are left out here: the dynamics see the samples_before_entry
        # rows before the departure as before (single_mass_run's noise of the second difference of a 2^13 encoder's
        # alpha1 comes from them and the filter's edge; with 40 rows more the second drive's 2^13 K2 went from 6.4 %
        # to 39-86 % median error: the re-contact row is that fragile, the zoo report)
        off = 0 if "a1" in self.channels else max(dep - self.samples_before_entry, 0)
        wd = {c: data[off:, j] for j, c in enumerate(self.channels)}
        dep -= off
        acc, src = motor_acceleration(wd, self.wheel_radius_m, self.sample_period_s)
        if acc is None:
            return 0, None
        run = single_mass_run(wd["m_el"], acc, dep, self.nominal_inertia_kgm2, self.samples_before_entry,
                              self.refine_samples, sample_period_s=self.sample_period_s)
        entry, recontact = (dep, None) if run is None else run[:2]
        if src == "a1" and self.history_extra:
            first = max(entry - self.history_extra, self.samples_before_entry)     # the history there is
            entry = back_to_load(wd["m_el"], acc, entry, first, self.nominal_inertia_kgm2, end=recontact,
                                 sample_period_s=self.sample_period_s, constant_max_nm=self.back_constant_max_nm)
            if not getattr(self, "_cap_returning", False) and not jumped:
                # forward (never back) to the end of the load torque's ramp (LOAD_HINGE_*; not after a jump of delta,
                # our simulator's slip: its contact is lost at the jump, no ramp -- the hinge put it 1-4 samples late)
                hinge, gain = load_hinge(wd["m_el"], acc, entry, self.nominal_inertia_kgm2, self.sample_period_s)
                entry = hinge if hinge > entry and gain >= LOAD_HINGE_MIN_GAIN else entry
                if entry == dep:
                    # nothing moved the departure (a1 unresolved or noisy at a fast departure, as without it: the
                    # spring's contact loss, SPRING_*; the vector drive's 30 dB speed reversal +3 -> -1)
                    entry = self._spring_move(data, entry + off, dep + off) - off
            if getattr(self, "_cap_returning", False):
                # a traversal back: the coupling model's contact loss near back_to_load's entry
                entry = self._coupling_move(data, entry + off, dep + off, 1.0, 1.0) - off
                walk = self._angle_walk_entry(data, dep + off) - off     # if it leads clearly, else on to where
                entry = walk if walk <= entry - self._n(RETURN_ANGLE_WALK_MIN_LEAD) else \
                    self._nominal_j_move(data, entry + off, dep + off) - off    # J1_nom holds (RETURN_NOMINAL_J)
        elif src != "a1" and self.detector_name == "flank" and not getattr(self, "_cap_returning", False):
            untwist = self._untwist_move(data, dep + off)
            if untwist is not None:
                # a coarse encoder: the end of the coupling's untwist (UNTWIST_*; the models below are off there)
                return untwist - off - dep, None if recontact is None else recontact + off
            # without a1, a coupling that untwisted off its flank: the entry at the coupling model's contact loss
            entry = self._coupling_move(data, entry + off, dep + off, rounds=COUPLING_FORWARD_ROUNDS) - off
            if entry == dep:
                # nothing moved the departure (a coupling that untwisted off its flank moved forward, SPRING_*)
                entry = self._spring_move(data, entry + off, dep + off) - off
            damped = self._damped_move(data, dep + off, entry + off)
            if damped is not None and abs(damped - off - entry) >= self._n(SPRING_MIN_MOVE):
                # the damped spring's contact loss at a clear gain and a plausible torque scale (DAMPED_*), when it
                # lies SPRING_MIN_MOVE or more from the entry so far (it finds where the coupling torque vanishes,
                # before the zone entry by about the damping's c/k: the soft coupling variant's heavy load reversals
                # -1 -> -3 with any move taken; the DOL drive's slip drops moved 3-12 samples)
                entry = damped - off
        return entry - dep, None if recontact is None else recontact + off

    def _angle_walk_entry(self, data: np.ndarray, dep: int) -> int:
        """A traversal back's entry from the motor equation in angle form (``dep`` when it does not move): delta may
        rest near the flank it left with no relative speed (read as a contact); the walk finds where the motor started
        to run free (:func:`free_motion_walk`; through any excursion of delta into the zone: the second drive's
        traversal back turns inside the zone and rests 1 mrad off the flank it left before leaving it again, one gap;
        a guard that stopped the walk where delta was last inside the zone left 3 of them 88-92 samples late), then
        the coupling model's contact loss: forward from the walk's end (the walk stops where the contact's load
        becomes visible, before the contact loss), else near the hinge's entry; then forward to where the motor
        equation with J1_nom holds (:meth:`_nominal_j_move`, RETURN_NOMINAL_J: possibly past the departure)."""
        if "m_el" not in self.channels:
            return dep
        walk, e = free_motion_walk(data[:, self._i_a1], data[:, self.channels.index("m_el")], dep,
                                   self.samples_before_entry, self.sample_period_s, self.angle_quantum_rad)
        if e >= dep:
            return dep
        e2 = self._coupling_move(data, walk, dep, 1.0, 1.0)
        return self._nominal_j_move(data, min(e2 if e2 > walk else self._coupling_move(data, e, dep, 1.0, 1.0), dep),
                                    dep)

    def _nominal_j_move(self, data: np.ndarray, entry: int, dep: int) -> int:
        """A traversal back's ``entry`` (the walk's) moved forward to :func:`nominal_coupling_entry`'s contact loss, the
        coupling model with J1_nom (RETURN_NOMINAL_J), within the window's forward room from ``dep``, on an encoder the
        walk resolves (its fit's rms and the configured quantum / sqrt 12 within FREE_WALK_MAX_NOISE_RAD); else
        ``entry``."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not RETURN_NOMINAL_J or self.nominal_inertia_kgm2 is None or not math.isfinite(flank):
            return entry
        delta = self._delta(data)
        after = delta[dep:dep + self._n(COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        motor, m_el, floor = data[:, self._i_a1], data[:, self.channels.index("m_el")], self.angle_quantum_rad / math.sqrt(12)
        for free_lag, reach in ((True, dep - entry + self._forward_room), (False, self._n(NOMINAL_J_UNLAGGED_MAX_MOVE))):
            if not free_lag and not (NOMINAL_J_FREE_LAG and NOMINAL_J_UNLAGGED_MAX_MOVE):
                break
            # with the lag free, then (a few samples at most) without it
            e, rms = nominal_coupling_entry(motor, delta, m_el, entry, side, (self.nominal_inertia_kgm2, free_lag),
                                            self.sample_period_s, reach)
            entry = e if entry < e <= entry + reach and max(rms, floor) <= FREE_WALK_MAX_NOISE_RAD else entry
        return entry

    def _zone_move(self, data: np.ndarray, dep: int, entry: int, cap: _FlankCapture, recontact: Optional[int]) -> int:
        """``entry`` moved forward to the zone's edge (:func:`zone_edge_entry`, ZONE_*) for a window's own traversal
        (its re-contact the window's, :func:`estimate_width`'s, from the rules' ``recontact`` or delta) with m_el and
        J1_nom on a fine encoder (FREE_MAX_NOISE_RAD, as :meth:`_spring_move`), not after a jump of delta (a slip: the
        contact is lost at the jump); else ``entry``."""
        if not ZONE_MAX_CK_REL_SE or self.detector_name != "flank" or cap.returning or "m_el" not in self.channels \
                or self.nominal_inertia_kgm2 is None or not math.isfinite(cap.flank_rad) \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD or self._jumped(data, dep):
            return entry
        e0, _, _, res = self._width(data, entry, cap, recontact)
        if res.how != "traversal" or not res.recontact_index > self.samples_before_entry:
            return entry
        recontact = e0 + res.recontact_index
        delta = self._delta(data)
        after = delta[dep:dep + self._n(COUPLING_FIT_AFTER)] - cap.flank_rad
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(UNTWIST_FIT_BEFORE), 0),
                                 self.min_departure_rad)
        acc = data[:, self.channels.index("a1")] / self.wheel_radius_m if "a1" in self.channels else None
        motor = (data[:, self._i_a1], acc) if acc is not None else data[:, self._i_a1]
        z, _ = zone_edge_entry(motor, delta, data[:, self.channels.index("m_el")], (entry, dep, recontact),
                               side, self.nominal_inertia_kgm2, self.sample_period_s, quantum)
        return z

    def _untwist_move(self, data: np.ndarray, departure: int) -> Optional[int]:
        """:func:`untwist_entry`'s contact loss at a gain >= UNTWIST_MIN_GAIN on a coarse encoder (delta's quantum, the
        configured one else its smallest step before the departure, / sqrt 12 beyond FREE_MAX_NOISE_RAD); else None."""
        delta = self._delta(data)
        quantum = _delta_quantum(delta, departure, self.angle_quantum_rad, max(departure - self._n(UNTWIST_FIT_BEFORE), 0),
                                 self.min_departure_rad)
        if not quantum / math.sqrt(12.0) > FREE_MAX_NOISE_RAD:
            return None
        e, gain = untwist_entry(delta, departure, self.sample_period_s)
        return e if gain >= UNTWIST_MIN_GAIN else None

    def _ramp_move(self, data: np.ndarray, departure: int) -> Optional[int]:
        """:func:`ramp_entry`'s contact loss when it lies SPRING_MIN_MOVE or more before ``departure`` at a gain >=
        RAMP_MIN_GAIN with T0 within RAMP_MAX_SCALE_DEVIATION of the steady m_el, on a fine encoder (delta's quantum,
        the configured one else its smallest step before the departure, / sqrt 12 within FREE_MAX_NOISE_RAD, as
        :meth:`_untwist_move`'s gate the other way); else None."""
        if "m_el" not in self.channels or self.nominal_inertia_kgm2 is None:
            return None
        quantum = _delta_quantum(self._delta(data), departure, self.angle_quantum_rad,
                                 max(departure - self._n(UNTWIST_FIT_BEFORE), 0), self.min_departure_rad)
        coarse = not quantum / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD
        if coarse and not RAMP_COARSE_MIN_JOINT_GAIN:
            return None
        e, gain, scale, both = ramp_entry(data[:, self._i_a1], data[:, self.channels.index("m_el")], departure,
                                          self.nominal_inertia_kgm2, self.sample_period_s,
                                          self._delta(data) if RAMP_JOINT or coarse else None, joint_gain=True)
        clear = both >= RAMP_COARSE_MIN_JOINT_GAIN if coarse else \
            gain >= RAMP_MIN_GAIN or (gain >= RAMP_TIED_MIN_GAIN and both >= RAMP_MIN_GAIN)
        if e <= departure - self._n(SPRING_MIN_MOVE) and clear and abs(scale - 1.0) <= RAMP_MAX_SCALE_DEVIATION:
            return e
        return None

    def _free_departure_entry(self, data: np.ndarray, dep: int) -> int:
        """:func:`free_departure`'s entry for the capture ``data`` departing at ``dep``; its noise: the contact's sigma,
        at least the quantisation (the configured encoder's, else the smallest step delta makes before the departure,
        below the departure threshold)."""
        delta = self._delta(data)
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad,
                                 max(dep - self._n(DRIFT_BACK_SAMPLES) - self._n(DRIFT_PRE_SAMPLES), 0),
                                 self.min_departure_rad)
        sigma = float(getattr(self, "_cap_sigma", 0.0))
        noise = max(sigma if math.isfinite(sigma) else 0.0, quantum / math.sqrt(12.0), ANGLE_MODEL_FLOOR_RAD)
        return free_departure(delta, dep, self.samples_before_entry, noise, sample_period_s=self.sample_period_s)

    def _damped_move(self, data: np.ndarray, departure: int, entry: Optional[int] = None) -> Optional[int]:
        """:func:`damped_spring_entry`'s contact loss when it explains alpha1 DAMPED_MIN_GAIN times better than
        ``entry`` (the other rules' entry; default the departure) with a torque scale within DAMPED_MAX_SCALE_DEVIATION
        of the steady m_el, unless the configured encoder is coarse (FREE_MAX_NOISE_RAD, as :meth:`_spring_move`; with
        encoder_counts_per_rev 0 the gain decides: the zoos' 2^13 recordings stay below it); else None."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not math.isfinite(flank) or "m_el" not in self.channels or self.nominal_inertia_kgm2 is None \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD:
            return None
        e, gain, scale = damped_spring_entry(data[:, self._i_a1], self._delta(data),
                                             data[:, self.channels.index("m_el")], departure, flank,
                                             self.nominal_inertia_kgm2, self.sample_period_s, entry)
        if gain >= DAMPED_MIN_GAIN and abs(scale - 1.0) <= DAMPED_MAX_SCALE_DEVIATION:
            return e
        return None

    def _spring_move(self, data: np.ndarray, entry: int, departure: int) -> int:
        """``entry`` moved to :func:`spring_entry`'s contact loss at a clear gain with a plausible J, by SPRING_MIN_MOVE
        samples or more (SPRING_*), on a fine encoder (FREE_MAX_NOISE_RAD, as the coupling model); or at the lower gain
        with J close to J1_nom by SPRING_TIGHT_MIN_MOVE samples or more on a measured fine quantum (SPRING_TIGHT_*);
        else ``entry``."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not math.isfinite(flank) or "m_el" not in self.channels or self.nominal_inertia_kgm2 is None \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD:
            return entry
        e, gain, j = spring_entry(data[:, self._i_a1], self._delta(data), data[:, self.channels.index("m_el")],
                                  departure, flank, self.sample_period_s)
        dev = abs(j / self.nominal_inertia_kgm2 - 1.0)
        if gain >= SPRING_MIN_GAIN and dev <= SPRING_MAX_J_DEVIATION and e <= entry - self._n(SPRING_MIN_MOVE):
            return e
        if SPRING_TIGHT_MIN_GAIN and gain >= SPRING_TIGHT_MIN_GAIN and dev <= SPRING_TIGHT_J \
                and e <= entry - self._n(SPRING_TIGHT_MIN_MOVE):
            delta = self._delta(data)
            quantum = _delta_quantum(delta, departure, self.angle_quantum_rad,
                                     max(departure - self._n(UNTWIST_FIT_BEFORE), 0), self.min_departure_rad)
            if quantum / math.sqrt(12.0) <= FREE_MAX_NOISE_RAD:
                return e
        return entry

    def _coupling_move(self, data: np.ndarray, entry: int, departure: int,
                       forward_gain: float = COUPLING_MIN_GAIN_FORWARD, back_gain: float = COUPLING_MIN_GAIN,
                       rounds: int = 1) -> int:
        """``entry`` moved to the coupling model's contact loss (:func:`coupling_entry`, ``rounds`` searches forward;
        the side delta left its flank to: at ``departure``) when that explains alpha1 ``forward_gain`` (a later
        entry) or ``back_gain`` (an earlier one) times better; else ``entry``."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not math.isfinite(flank) or "m_el" not in self.channels:
            return entry
        delta = self._delta(data)
        # the side delta departs to: its farthest move off the flank over the fit's rows after the departure (a
        # traversal back's departure row lies on the re-contact edge its capture takes for the flank, where the sign of
        # delta - flank is rounding: a 5e-13 rad change of the angles turned the side and moved the vector drive's
        # traversal back with a1 from 0 to -6, test_flank's cut of it)
        after = delta[departure:departure + self._n(COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        e, gain, rms = coupling_entry(data[:, self._i_a1], delta, data[:, self.channels.index("m_el")], entry, side,
                                      self.sample_period_s, rounds)
        if not max(rms, self.angle_quantum_rad / math.sqrt(12.0)) <= FREE_MAX_NOISE_RAD:
            return entry        # a coarse encoder (2^13: its moves went 3-12 samples the wrong way)
        return e if gain >= (forward_gain if e > entry else back_gain) else entry
