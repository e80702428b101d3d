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

**Width estimate** and **re-contact row** (per window): :func:`~jident_ros.stream.flank_delta.estimate_width`, its
module's docstring.

Same batch API, events and drop reasons as :class:`~jident_ros.stream.detector.BacklashDetector` (which it
extends), so the windowing node and ``jident diagnose`` take either.  The result does not depend on how a
stream is cut into batches (tested).

Every sample count below that is a duration (the module constants, ``contact_samples``, ``refine_samples``) is
given in samples at 2 kHz, where it was chosen, and converted to the detector's ``sample_period_s``
(:mod:`jident_ros.stream.rate`: identical at 0.5 ms); noise quanta, shares, factors and counts of rounds stay as they
are.

The detector's models live in sibling modules, grouped by what they model (each one's docstring says what it
holds): :mod:`~jident_ros.stream.flank_free` (free motion, walking back to the load),
:mod:`~jident_ros.stream.flank_coupling` (coupling, spring and damped spring models),
:mod:`~jident_ros.stream.flank_zone` (zone edge, untwist and ramp models), :mod:`~jident_ros.stream.flank_disc`
(the encoder's disc error) and :mod:`~jident_ros.stream.flank_delta` (delta's travel, re-contact and the width).
This module keeps the detector (:class:`FlankDetector`) and finds every name those modules define (``flank.X``,
``from jident_ros.stream.flank import X``).  Each constant is defined in one module and looked up there by every
reader (``module.NAME`` elsewhere): a test patches it in that module.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Sequence

import numpy as np

from jident_ros.stream import flank_coupling, flank_delta, flank_disc, flank_free, flank_zone
from jident_ros.stream.detector import BacklashDetector, Event, _positive
from jident_ros.stream.filters import first_order_lowpass
from jident_ros.stream.flank_coupling import (
    coupling_entry,
    damped_spring_entry,
    nominal_coupling_entry,
    shifted,
    spring_entry,
    torque_late_gain,
)
from jident_ros.stream.flank_delta import WidthResult, _delta_quantum, estimate_width, motor_acceleration
from jident_ros.stream.flank_disc import disc_corrected
from jident_ros.stream.flank_free import (
    _double_integral,
    _free_columns,
    _lstsq_rss,
    back_to_load,
    free_departure,
    free_motion_walk,
    load_hinge,
    single_mass_run,
)
from jident_ros.stream.flank_zone import ramp_entry, untwist_entry, zone_edge_entry
from jident_ros.stream.layout import DEFAULT_CHANNELS, FLAG_BOUNCE, FLAG_SECOND_ENTRY, FLAG_SHALLOW_GAP, Window
from jident_ros.stream.rate import samples

#: Detector names of the ``detector`` parameter.
DETECTORS = ("flank", "paper", "dynamics")


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


#: An entry inside a running window gets its own window only when its excursion took at least this many samples
#: to the contact on the other flank (a traversal takes time; a jump of delta -- the line's slip, an encoder glitch
#: -- is at its new level at once).
MIN_TRAVERSAL_SAMPLES = 4

#: With m_el and a1 (an accelerometer), the entry sample may move back this many samples before the departure, to
#: where the motor equation starts to hold (:func:`back_to_load`; the vector drive's return traversal
#: rests at the flank for 54 samples after the contact loss).  Without a1 the second difference of alpha1 is too
#: noisy for it (2^16 counts at 2 kHz: ~20 N m of torque noise): the gap estimator's change points refine it.
REFINE_BACK_SAMPLES = 128

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
        self.back_constant_max_nm = None if base_torque_nm is None else flank_free.BACK_CONSTANT_MAX_REL_BASE * float(base_torque_nm)
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
            self.history_extra = self._history(flank_free.DRIFT_BACK_SAMPLES)    # ... or to delta's free curvature (free_departure)
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
            return self.refine_samples + self._n(flank_coupling.COUPLING_SEARCH) * flank_coupling.COUPLING_FORWARD_ROUNDS
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
        flags = (FLAG_SHALLOW_GAP if cap.shallow else 0) | (FLAG_BOUNCE if res.how == flank_delta.BOUNCE_HOW else 0)
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
        q = max(_delta_quantum(d, dep, self.angle_quantum_rad, max(dep - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0),
                               self.min_departure_rad), flank_free.ANGLE_MODEL_FLOOR_RAD)
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
        rows = samples(flank_coupling.SPRING_TORQUE_ROWS, self.sample_period_s)
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
        quantum = max(_delta_quantum(d, entry, self.angle_quantum_rad, lo, self.min_departure_rad), flank_free.ANGLE_MODEL_FLOOR_RAD,
                      flank_free._noise(d[lo:lo + self.contact_samples // 2]))
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
        coarse = bool(steps.size) and float(steps.min()) / math.sqrt(12.0) > flank_free.FREE_MAX_NOISE_RAD
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
        if not flank_disc.DISC_MIN_GAIN or self.detector_name != "flank":
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
        if not flank_coupling.TORQUE_LATE_MIN_GAIN or self.detector_name != "flank" or "a1" in self.channels \
                or "m_el" not in self.channels or getattr(self, "_cap_returning", False) or not math.isfinite(flank) \
                or self._jumped(data, dep):
            return data
        delta = self._delta(data)
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0),
                                 self.min_departure_rad)
        if not quantum / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD:
            return data
        after = delta[dep:dep + self._n(flank_coupling.COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        i_m = self.channels.index("m_el")
        if not torque_late_gain(data[:, self._i_a1], delta, data[:, i_m], dep, side,
                                self.sample_period_s) >= flank_coupling.TORQUE_LATE_MIN_GAIN:
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
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0), thr)
        if not quantum / math.sqrt(12.0) > flank_free.FREE_MAX_NOISE_RAD or thr >= COARSE_DEPARTURE_QUANTA * quantum:
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
                entry = hinge if hinge > entry and gain >= flank_free.LOAD_HINGE_MIN_GAIN else entry
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
            entry = self._coupling_move(data, entry + off, dep + off, rounds=flank_coupling.COUPLING_FORWARD_ROUNDS) - off
            if entry == dep:
                # nothing moved the departure (a coupling that untwisted off its flank moved forward, SPRING_*)
                entry = self._spring_move(data, entry + off, dep + off) - off
            damped = self._damped_move(data, dep + off, entry + off)
            if damped is not None and abs(damped - off - entry) >= self._n(flank_coupling.SPRING_MIN_MOVE):
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
        if not flank_coupling.RETURN_NOMINAL_J or self.nominal_inertia_kgm2 is None or not math.isfinite(flank):
            return entry
        delta = self._delta(data)
        after = delta[dep:dep + self._n(flank_coupling.COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        motor, m_el, floor = data[:, self._i_a1], data[:, self.channels.index("m_el")], self.angle_quantum_rad / math.sqrt(12)
        for free_lag, reach in ((True, dep - entry + self._forward_room), (False, self._n(flank_coupling.NOMINAL_J_UNLAGGED_MAX_MOVE))):
            if not free_lag and not (flank_coupling.NOMINAL_J_FREE_LAG and flank_coupling.NOMINAL_J_UNLAGGED_MAX_MOVE):
                break
            # with the lag free, then (a few samples at most) without it
            e, rms = nominal_coupling_entry(motor, delta, m_el, entry, side, (self.nominal_inertia_kgm2, free_lag),
                                            self.sample_period_s, reach)
            entry = e if entry < e <= entry + reach and max(rms, floor) <= flank_free.FREE_WALK_MAX_NOISE_RAD else entry
        return entry

    def _zone_move(self, data: np.ndarray, dep: int, entry: int, cap: _FlankCapture, recontact: Optional[int]) -> int:
        """``entry`` moved forward to the zone's edge (:func:`zone_edge_entry`, ZONE_*) for a window's own traversal
        (its re-contact the window's, :func:`estimate_width`'s, from the rules' ``recontact`` or delta) with m_el and
        J1_nom on a fine encoder (FREE_MAX_NOISE_RAD, as :meth:`_spring_move`), not after a jump of delta (a slip: the
        contact is lost at the jump); else ``entry``."""
        if not flank_zone.ZONE_MAX_CK_REL_SE or self.detector_name != "flank" or cap.returning or "m_el" not in self.channels \
                or self.nominal_inertia_kgm2 is None or not math.isfinite(cap.flank_rad) \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD or self._jumped(data, dep):
            return entry
        e0, _, _, res = self._width(data, entry, cap, recontact)
        if res.how != "traversal" or not res.recontact_index > self.samples_before_entry:
            return entry
        recontact = e0 + res.recontact_index
        delta = self._delta(data)
        after = delta[dep:dep + self._n(flank_coupling.COUPLING_FIT_AFTER)] - cap.flank_rad
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad, max(dep - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0),
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
        quantum = _delta_quantum(delta, departure, self.angle_quantum_rad, max(departure - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0),
                                 self.min_departure_rad)
        if not quantum / math.sqrt(12.0) > flank_free.FREE_MAX_NOISE_RAD:
            return None
        e, gain = untwist_entry(delta, departure, self.sample_period_s)
        return e if gain >= flank_zone.UNTWIST_MIN_GAIN else None

    def _ramp_move(self, data: np.ndarray, departure: int) -> Optional[int]:
        """:func:`ramp_entry`'s contact loss when it lies SPRING_MIN_MOVE or more before ``departure`` at a gain >=
        RAMP_MIN_GAIN with T0 within RAMP_MAX_SCALE_DEVIATION of the steady m_el, on a fine encoder (delta's quantum,
        the configured one else its smallest step before the departure, / sqrt 12 within FREE_MAX_NOISE_RAD, as
        :meth:`_untwist_move`'s gate the other way); else None."""
        if "m_el" not in self.channels or self.nominal_inertia_kgm2 is None:
            return None
        quantum = _delta_quantum(self._delta(data), departure, self.angle_quantum_rad,
                                 max(departure - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0), self.min_departure_rad)
        coarse = not quantum / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD
        if coarse and not flank_zone.RAMP_COARSE_MIN_JOINT_GAIN:
            return None
        e, gain, scale, both = ramp_entry(data[:, self._i_a1], data[:, self.channels.index("m_el")], departure,
                                          self.nominal_inertia_kgm2, self.sample_period_s,
                                          self._delta(data) if flank_zone.RAMP_JOINT or coarse else None, joint_gain=True)
        clear = both >= flank_zone.RAMP_COARSE_MIN_JOINT_GAIN if coarse else \
            gain >= flank_zone.RAMP_MIN_GAIN or (gain >= flank_zone.RAMP_TIED_MIN_GAIN and both >= flank_zone.RAMP_MIN_GAIN)
        if e <= departure - self._n(flank_coupling.SPRING_MIN_MOVE) and clear and abs(scale - 1.0) <= flank_zone.RAMP_MAX_SCALE_DEVIATION:
            return e
        return None

    def _free_departure_entry(self, data: np.ndarray, dep: int) -> int:
        """:func:`free_departure`'s entry for the capture ``data`` departing at ``dep``; its noise: the contact's sigma,
        at least the quantisation (the configured encoder's, else the smallest step delta makes before the departure,
        below the departure threshold)."""
        delta = self._delta(data)
        quantum = _delta_quantum(delta, dep, self.angle_quantum_rad,
                                 max(dep - self._n(flank_free.DRIFT_BACK_SAMPLES) - self._n(flank_free.DRIFT_PRE_SAMPLES), 0),
                                 self.min_departure_rad)
        sigma = float(getattr(self, "_cap_sigma", 0.0))
        noise = max(sigma if math.isfinite(sigma) else 0.0, quantum / math.sqrt(12.0), flank_free.ANGLE_MODEL_FLOOR_RAD)
        return free_departure(delta, dep, self.samples_before_entry, noise, sample_period_s=self.sample_period_s)

    def _damped_move(self, data: np.ndarray, departure: int, entry: Optional[int] = None) -> Optional[int]:
        """:func:`damped_spring_entry`'s contact loss when it explains alpha1 DAMPED_MIN_GAIN times better than
        ``entry`` (the other rules' entry; default the departure) with a torque scale within DAMPED_MAX_SCALE_DEVIATION
        of the steady m_el, unless the configured encoder is coarse (FREE_MAX_NOISE_RAD, as :meth:`_spring_move`; with
        encoder_counts_per_rev 0 the gain decides: the zoos' 2^13 recordings stay below it); else None."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not math.isfinite(flank) or "m_el" not in self.channels or self.nominal_inertia_kgm2 is None \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD:
            return None
        e, gain, scale = damped_spring_entry(data[:, self._i_a1], self._delta(data),
                                             data[:, self.channels.index("m_el")], departure, flank,
                                             self.nominal_inertia_kgm2, self.sample_period_s, entry)
        if gain >= flank_coupling.DAMPED_MIN_GAIN and abs(scale - 1.0) <= flank_coupling.DAMPED_MAX_SCALE_DEVIATION:
            return e
        return None

    def _spring_move(self, data: np.ndarray, entry: int, departure: int) -> int:
        """``entry`` moved to :func:`spring_entry`'s contact loss at a clear gain with a plausible J, by SPRING_MIN_MOVE
        samples or more (SPRING_*), on a fine encoder (FREE_MAX_NOISE_RAD, as the coupling model); or at the lower gain
        with J close to J1_nom by SPRING_TIGHT_MIN_MOVE samples or more on a measured fine quantum (SPRING_TIGHT_*);
        else ``entry``."""
        flank = getattr(self, "_cap_flank", (math.nan, math.nan))[0]
        if not math.isfinite(flank) or "m_el" not in self.channels or self.nominal_inertia_kgm2 is None \
                or not self.angle_quantum_rad / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD:
            return entry
        e, gain, j = spring_entry(data[:, self._i_a1], self._delta(data), data[:, self.channels.index("m_el")],
                                  departure, flank, self.sample_period_s)
        dev = abs(j / self.nominal_inertia_kgm2 - 1.0)
        if gain >= flank_coupling.SPRING_MIN_GAIN and dev <= flank_coupling.SPRING_MAX_J_DEVIATION \
                and e <= entry - self._n(flank_coupling.SPRING_MIN_MOVE):
            return e
        if flank_coupling.SPRING_TIGHT_MIN_GAIN and gain >= flank_coupling.SPRING_TIGHT_MIN_GAIN \
                and dev <= flank_coupling.SPRING_TIGHT_J \
                and e <= entry - self._n(flank_coupling.SPRING_TIGHT_MIN_MOVE):
            delta = self._delta(data)
            quantum = _delta_quantum(delta, departure, self.angle_quantum_rad,
                                     max(departure - self._n(flank_zone.UNTWIST_FIT_BEFORE), 0), self.min_departure_rad)
            if quantum / math.sqrt(12.0) <= flank_free.FREE_MAX_NOISE_RAD:
                return e
        return entry

    def _coupling_move(self, data: np.ndarray, entry: int, departure: int,
                       forward_gain: float = flank_coupling.COUPLING_MIN_GAIN_FORWARD,
                       back_gain: float = flank_coupling.COUPLING_MIN_GAIN,
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
        after = delta[departure:departure + self._n(flank_coupling.COUPLING_FIT_AFTER)] - flank
        side = 1.0 if after.size and after[int(np.argmax(np.abs(after)))] >= 0 else -1.0
        e, gain, rms = coupling_entry(data[:, self._i_a1], delta, data[:, self.channels.index("m_el")], entry, side,
                                      self.sample_period_s, rounds)
        if not max(rms, self.angle_quantum_rad / math.sqrt(12.0)) <= flank_free.FREE_MAX_NOISE_RAD:
            return entry        # a coarse encoder (2^13: its moves went 3-12 samples the wrong way)
        return e if gain >= (forward_gain if e > entry else back_gain) else entry


#: The modules the detector's models and rules moved to: ``flank.X`` and ``from jident_ros.stream.flank import X`` find
#: every name they define (PEP 562).  A patch must go to the module that defines the name: every reader looks it up
#: there, not here (test_sizes.py checks the tests' patches).
_HOMES = (flank_free, flank_delta, flank_disc, flank_coupling, flank_zone)


def __getattr__(name: str):
    for module in _HOMES:
        if not name.startswith("__") and name in vars(module):
            return vars(module)[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
