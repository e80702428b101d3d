"""The flank detector's captures (pure numpy, never imports rclpy): :class:`CaptureMixin`, the methods of
:class:`~jident_ros.stream.flank.FlankDetector` that open captures at the tracker's entries, feed them rows and turn a
complete one into its window -- the entry inside another window that becomes a traversal back (RETURN_MIN_SPAN_SHARE,
MIN_TRAVERSAL_SAMPLES), the same-flank excursions dropped or kept (UNTWIST_*, SHALLOW_*), a repeated entry
(DUPLICATE_ENTRY_SAMPLES), the window's width (:func:`~jident_ros.stream.flank_delta.estimate_width`).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream import flank_coupling, flank_delta, flank_free, flank_scan, flank_zone
from jident_ros.stream.detector import Event
from jident_ros.stream.flank_capture import _FlankCapture
from jident_ros.stream.flank_delta import _delta_quantum, estimate_width
from jident_ros.stream.layout import FLAG_BOUNCE, FLAG_SECOND_ENTRY, FLAG_SHALLOW_GAP, Window
from jident_ros.stream.rate import samples

#: An entry inside a running window gets its own window only when its excursion took at least this many samples
#: to the contact on the other flank (a traversal takes time; a jump of delta -- the line's slip, an encoder glitch
#: -- is at its new level at once).
MIN_TRAVERSAL_SAMPLES = 4

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

#: Two windows whose entries (absolute rows) lie this close are one traversal's: the second is not given out.
DUPLICATE_ENTRY_SAMPLES = 2

#: An entry inside a running window gets a window of its own only when its excursion, ending in a contact, travelled
#: at least this share of the zone the running windows crossed (the distance from the flank it left to their farthest
#: flank level): a soft coupling's swing after its re-contact leaves a contact on the flank it reached and settles
#: 5.6 mrad away, beyond min_travel_rad, as its torque falls back (the vector drive with k x 0.3, heavy load reversal:
#: 0.04 of its 133 mrad; a false entry, J1 outside the plausible band) -- chosen on that variant; the zoo's and the
#: variants' traversals back travel 0.99-1.03 of it, a turning point inside the zone read as a contact 0.17 (the fast
#: speed loop's light load reversal: a bounce window 59 samples late, now not given)
RETURN_MIN_SPAN_SHARE = 0.5


#: A window's entry moved forward by the rules and the zone model (ZONE_*, whose move after the rules' entry is up to
#: the coupling's c/k plus ZONE_MOVE_SLACK, beyond the capture's forward room) stays where the capture still holds
#: its whole window: the vector draws' load reversals with an Imu had windows 3 rows short (19 drives over sets 1-21,
#: each refused, ERROR "samples: 2045 in the window, need >= 2048") -- not a tuned value.  False: as before
WINDOW_FITS_CAPTURE = True


class CaptureMixin:
    """Captures of :class:`~jident_ros.stream.flank.FlankDetector`: opened at the tracker's entries, fed rows,
    completed into windows (module docstring)."""

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
        held = None
        if WINDOW_FITS_CAPTURE:
            # no entry moved forward beyond the rows captured for its window (the zone model's move adds up to c/k
            # + ZONE_MOVE_SLACK to the rules' forward room: a window 3 rows short was refused, ERROR); counted
            # (entry_held) when the window goes out with the entry held there
            room = data.shape[0] - self.window_length + self.samples_before_entry - dep
            held = room if shift > room else None
            shift = min(shift, room)
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
        if held is not None and shift == held:
            self.counts["entry_held"] += 1
        self._emitted_entry_rows.append(entry_row)
        e0, win, rc, res = self._width(data, dep + shift, cap, recontact)
        back = None if not shallow_rc or shallow[1] is None else shallow[1] - e0
        if back is not None and back < self.window_length and not 0 <= res.recontact_index <= back:
            res.recontact_index = back             # met again by the time delta is back at the zero twist (SHALLOW_*)
        e = self.samples_before_entry
        self.last_width = res
        if self.second_windows and res.how == "traversal" and res.recontact_index > e:
            self._scan_returns(cap, data, self._delta(win), e0, e, res.recontact_index)
        if self.second_windows and flank_scan.REBOUND_MAX_SHARE and not cap.returning:
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
