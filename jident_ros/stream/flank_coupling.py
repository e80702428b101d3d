"""The flank detector's coupling models of a contact loss (pure numpy, never imports rclpy), each fitting alpha1 by
the motor equation with a contact torque that ends at a candidate entry:

* :func:`coupling_entry`: a spring-damper torque while delta is beyond the edge it leaves (COUPLING_*), and
  :func:`nominal_coupling_entry`, the same with J1_nom (a traversal back's forward move: RETURN_NOMINAL_J,
  NOMINAL_J_*);
* :func:`torque_late_gain`: whether the torque estimate reads a sample late (TORQUE_*; :func:`shifted`);
* :func:`spring_entry`: a spring carrying the steady m_el (SPRING_*);
* :func:`damped_spring_entry`: a damped spring with a fitted torque scale (DAMPED_*).

The gates the detector's rules apply to them (the gains, moves and J deviations of these blocks) are read by
:mod:`jident_ros.stream.flank_refine`.  Moved from :mod:`jident_ros.stream.flank` (which still finds every name here).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream.flank_free import _double_integral, _free_columns, _lstsq_rss, _profile
from jident_ros.stream.rate import samples, samples_float

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
