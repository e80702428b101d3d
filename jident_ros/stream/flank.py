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
  :func:`far_contact_model_a1`, and T0 less J1_nom a1); one the rules left at or after the departure and beyond that
  edge moves back to where delta crossed it (:func:`zone_edge_back`, ZONE_BACK_*: a fast departure, a speed reversal's,
  crosses the departure threshold 3-12 samples after the zone entry).
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

The detector's models and rules live in sibling modules, grouped by what they model (each one's docstring says
what it holds): :mod:`~jident_ros.stream.flank_free` (free motion, walking back to the load),
:mod:`~jident_ros.stream.flank_coupling` (coupling, spring and damped spring models),
:mod:`~jident_ros.stream.flank_zone` (zone edge, untwist and ramp models), :mod:`~jident_ros.stream.flank_disc`
(the encoder's disc error), :mod:`~jident_ros.stream.flank_delta` (delta's travel, re-contact and the width), and
the detector's method groups :mod:`~jident_ros.stream.flank_window` (captures into windows),
:mod:`~jident_ros.stream.flank_scan` (traversals back found by a window's scans) and
:mod:`~jident_ros.stream.flank_refine` (the entry sample's rules).  This module keeps the state machine
(:class:`FlankDetector`: the contact tracker); a name those modules define is imported from its own module, not from
this one (stop 43 removed the PEP 562 lookup that found the moved names here).  Each constant is defined in one of
them and looked up there by every reader (``module.NAME`` elsewhere): a test patches it in that module (test_sizes.py
checks both).
"""
from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple, Optional, Sequence

import numpy as np

from jident_ros.stream import flank_coupling, flank_free, flank_window
from jident_ros.stream.detector import BacklashDetector, _positive
from jident_ros.stream.filters import first_order_lowpass
from jident_ros.stream.flank_capture import _FlankCapture
from jident_ros.stream.flank_delta import WidthResult
from jident_ros.stream.flank_refine import EntryRefineMixin
from jident_ros.stream.flank_scan import ReturnScanMixin
from jident_ros.stream.flank_window import CaptureMixin
from jident_ros.stream.layout import DEFAULT_CHANNELS
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


#: With m_el and a1 (an accelerometer), the entry sample may move back this many samples before the departure, to
#: where the motor equation starts to hold (:func:`back_to_load`; the vector drive's return traversal
#: rests at the flank for 54 samples after the contact loss).  Without a1 the second difference of alpha1 is too
#: noisy for it (2^16 counts at 2 kHz: ~20 N m of torque noise): the gap estimator's change points refine it.
REFINE_BACK_SAMPLES = 128

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


class FlankDetector(CaptureMixin, ReturnScanMixin, EntryRefineMixin, BacklashDetector):
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
        return before * torque > 0.0 and abs(before) <= flank_window.UNTWIST_MAX_TORQUE_SHARE * abs(torque) \
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
