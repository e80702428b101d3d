"""The flank detector's free-motion models (pure numpy, never imports rclpy): where a contact was lost, found
from the samples around delta's departure while the motor runs free of its load.

* :func:`free_departure`: delta's free curvature before a departure it drifted to (without a1; DRIFT_*);
* :func:`single_mass_run` (forward from the departure), :func:`back_to_load` (back to where the load torque is back)
  and :func:`load_hinge` (the end of the load torque's ramp): the motor equation m_el = J dω1/dt + c over the gap, with
  a motor acceleration (SINGLE_MASS_*, BACK_*, LOAD_HINGE_*);
* :func:`free_motion_walk` / :func:`free_motion_start`: the motor equation in angle form, alpha1 = a + v k + Phi / J +
  c k^2 / 2, walked back from a traversal back's departure (without a1; FREE_*, ANGLE_MODEL_FLOOR_RAD);
* the least-squares and noise helpers every flank model shares (:func:`_lstsq_rss`, :func:`_profile`,
  :func:`_double_integral`, :func:`_free_columns`, :func:`_noise`).

Moved from :mod:`jident_ros.stream.flank` (which still finds every name here).  Sample counts are durations at 2 kHz
(:mod:`jident_ros.stream.rate`).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream.rate import REFERENCE_SAMPLE_PERIOD_S, samples, samples_float

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
