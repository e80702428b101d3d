"""The flank detector's rules that place a window's entry sample (pure numpy, never imports rclpy):
:class:`EntryRefineMixin`, the methods of :class:`~jident_ros.stream.flank.FlankDetector` that move the entry from
delta's departure (:meth:`~EntryRefineMixin._refine`: the disc error taken off, a late torque advanced, then
:meth:`~EntryRefineMixin._refine_from` and the ``_*_move`` rules) by the models of
:mod:`jident_ros.stream.flank_free`, :mod:`jident_ros.stream.flank_coupling` and :mod:`jident_ros.stream.flank_zone`
(whose gates they read there); COARSE_DEPARTURE_* and RETURN_ANGLE_WALK_MIN_LEAD are read here.  The module docstring
of :mod:`jident_ros.stream.flank` ("Entry sample") describes the rules.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream import flank_coupling, flank_disc, flank_free, flank_zone
from jident_ros.stream.flank_capture import _FlankCapture
from jident_ros.stream.flank_coupling import (
    coupling_entry,
    damped_spring_entry,
    nominal_coupling_entry,
    shifted,
    spring_entry,
    torque_late_gain,
)
from jident_ros.stream.flank_delta import _delta_quantum, motor_acceleration
from jident_ros.stream.flank_disc import disc_corrected
from jident_ros.stream.flank_free import back_to_load, free_departure, free_motion_walk, load_hinge, single_mass_run
from jident_ros.stream.flank_zone import ramp_entry, untwist_entry, zone_edge_back, zone_edge_entry

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


class EntryRefineMixin:
    """The entry sample's rules of :class:`~jident_ros.stream.flank.FlankDetector` (module docstring)."""

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
            corrected, coef = disc_corrected(data[:, j], self.sample_period_s, flank_disc.DISC_DETECTOR_OFF_GRID)
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
        """``entry`` moved forward to the zone's edge (:func:`zone_edge_entry`, ZONE_*), else back to it
        (:func:`zone_edge_back`, ZONE_BACK_*), for a window's own traversal
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
        if z == entry:
            # not moved forward: back to the edge's crossing when the rules' entry lies beyond it (ZONE_BACK_*: a fast
            # departure crosses the threshold after the zone entry)
            z = zone_edge_back(data[:, self._i_a1], delta, data[:, self.channels.index("m_el")], (entry, dep, recontact),
                               side, self.nominal_inertia_kgm2, self.sample_period_s, (quantum, self.threshold_for(cap)))
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
