"""The flank detector's contact models at the zone's edge and of the coupling's untwist (pure numpy, never imports
rclpy):

* :func:`zone_edge_entry`: a window's own traversal moved forward from the damped coupling's separation to where delta
  crosses the zone's edge, k and c/k from the re-contact on the far flank (:func:`far_contact_model`, with a1
  :func:`far_contact_model_a1`; ZONE_*);
* :func:`untwist_entry`: the end of a coupling's untwist on a coarse encoder (UNTWIST_FIT_*, UNTWIST_*);
* :func:`ramp_entry`: the motor equation with the coupling torque ramping to zero (RAMP_*).

The gates the detector's rules apply to them are read by :mod:`jident_ros.stream.flank_refine`.  Moved from
:mod:`jident_ros.stream.flank` (which still finds every name here).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream.flank_free import _double_integral, _free_columns, _lstsq_rss
from jident_ros.stream.rate import REFERENCE_SAMPLE_PERIOD_S, samples, samples_float

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


#: The last :func:`far_contact_model` fit, (key, result): a window's forward and back zone moves (zone_edge_entry,
#: zone_edge_back) fit the same re-contact rows one after the other (0.5 ms each); the key holds every row the fit
#: reads, so a hit is the same fit.  Rebound whole (one assignment), never mutated.
_LAST_FAR_FIT: tuple = (None, None)


def far_contact_model(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, recontact: int,
                      sample_period_s: float) -> Optional[tuple]:
    """(K/J in 1/s^2 per rad of delta, c/k in s, the relative standard errors of c/k and of K) of the coupling over the
    re-contact on the far flank near row ``recontact`` (ZONE_* constants, see ZONE_FIT_BEFORE); None when the rows are
    not there."""
    global _LAST_FAR_FIT
    ts = sample_period_s
    pre, post = samples(ZONE_FIT_BEFORE, ts), samples(ZONE_FIT_AFTER, ts)
    search = samples(ZONE_RECONTACT_SEARCH, ts)
    a1, d_all, m = (np.asarray(x, float) for x in (alpha1, delta, m_el))
    rows = slice(max(int(recontact) - search - pre, 0), max(int(recontact) + search + post, 0))
    key = (int(recontact), float(ts), a1.size, d_all.size, m.size,
           a1[rows].tobytes(), d_all[rows].tobytes(), m[rows].tobytes())
    last = _LAST_FAR_FIT
    if last[0] == key:
        return last[1]
    got = _far_contact_fit(a1, d_all, m, int(recontact), (pre, post, search, ts))
    _LAST_FAR_FIT = (key, got)
    return got


def _far_contact_fit(a1: np.ndarray, d_all: np.ndarray, m: np.ndarray, recontact: int, spans: tuple) -> Optional[tuple]:
    """:func:`far_contact_model`'s fit (``spans`` = (ZONE_FIT_BEFORE, ZONE_FIT_AFTER, ZONE_RECONTACT_SEARCH) in rows,
    the sample period)."""
    pre, post, search, ts = spans
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


#: A fast departure crosses the departure threshold (1.5 mrad) well after the zone entry: the vector drives' speed
#: reversals, whose torque reverses within a few samples, leave a stiff coupling's 0.2-1 mrad twist in 1-2 samples and
#: run 3-12 samples on to the threshold, where no motor-equation rule moves them (the spring fit's gain there 1.1-1.2,
#: its J off J1_nom by the drawn class; vector set 1's s1-04: separation 1207, zone 1208, departure and entry 1214).  So
#: a window's own entry that the rules left at or after the departure and that lies beyond the zone's edge already
#: moves back to where delta last crossed that edge (:func:`zone_edge_back`): the edge as :func:`zone_edge_entry`'s, the
#: steady m_el over |k| from the re-contact on the far flank in angle form (with a1 too: the torque balance's edge takes
#: the gap's m_el - J1_nom a1 for friction, which a J1 off J1_nom by its class makes tens of N m in a speed reversal's
#: gap), the crossing searched within this many samples before the entry (0: off; samples at 2 kHz) -- 8 / 12 / 16 / 24
#: on vector sets 1-12 (the detector replayed on their captures; entries within +-2 of the zone over every event and
#: input, 1292 before; without the twist gate below): +113 / +139 / +147 / +151, 5 out of +-2 each; 24 also took light
#: load reversals 18-24 samples late to +2..+5: 16 kept, the speed reversals' lateness (docs/results.md, "A fast
#: departure's zone edge") ...
ZONE_BACK_MAX_MOVE = 16
#: ... when k is determined within this relative standard error (c/k need not be: the stiff couplings' c/k is below a
#: sample, its relative standard error 0.1-5 on most clean speed reversals: with the c/k gate (ZONE_MAX_CK_REL_SE) at
#: a reach of 12, vector sets 1-12's clean speed reversals 76 -> 89 of 144 within +-2 instead of 76 -> 106) -- 0.05 /
#: 0.1 / 0.2 tried there at a reach of 12: +135 / +139 / +142 within +-2 (4 / 5 / 5 out); 0.1, ZONE_MAX_CK_REL_SE's
#: value, kept.  The crossing must be resolved as the forward move's (ZONE_K_SIGMAS) ...
ZONE_BACK_MAX_K_REL_SE = 0.1
#: ... and the twist |T0| / k at most this share of the window's departure threshold (the rule's premise: the edge lies
#: well inside the threshold, so the departure came after the zone entry).  Where the twist reaches the threshold the
#: edge tells nothing the rules did not: the zoo's second drive (a Hertz contact, whose twist under T0 a linear k from
#: the re-contact puts at 1.4-1.5 mrad, the threshold 1.5) had its speed steps' entries, which the coupling model moved
#: 3-5 samples forward to 0/+1, taken back to the departure (-3/-4: test_detector_zoo, the golden second-drive files);
#: the DOL drive's slip reversals and heavy load reversals (twist 3-7 mrad, a J1 below J1_nom's class making k high
#: and the edge early) went -2/-1 -> -5/-4.  With no share: vector sets 1-12 +147 within +-2, 5 out; 0.67 (1 mrad at
#: the 1.5 mrad threshold): +111, 1 out; 0.5: +102, none out (the heavy load reversals, twist 1.3-8.6 mrad, no longer
#: move; the speed reversals 235 -> 329 of 432) -- 0.5 kept (chosen on vector sets 1-12 and the second drive; 0: no
#: move, as ZONE_BACK_MAX_MOVE 0)
ZONE_BACK_MAX_TWIST_SHARE = 0.5
#: A slow departure -- a light load reversal: the load torque ramps through zero, the coupling lets go while m_el is
#: still 10-15 N m, and the motor then runs free under a few N m -- crosses the 1.5 mrad departure threshold 10-50
#: samples after the zone entry (vector set 1's s1-12, 2^20 counts: zone 1219, departure and entry 1257).  Two things
#: kept :func:`zone_edge_back` from its crossing there: the steady rows before the departure (ZONE_STEADY_ROWS) overlap
#: the coupling's unloading, and T0 = the steady m_el holds the motor's friction (s1-12: 4 N m of 18), so the twist
#: |T0| / k came out 15-40 % high and the edge's crossing 3-7 samples late, beyond ZONE_BACK_MAX_MOVE.  So where the gap
#: after the rules' entry is slow -- its free torque |m_el - c| at most ZONE_BACK_SLOW_SHARE of the steady |T0 - c|, c
#: the constant torque of the motor equation with J1_nom over up to 40 gap rows (:func:`gap_constant_torque`: the
#: friction and the estimate's offset, alpha1 running the same way as over the steady rows) -- T0 less c makes the
#: twist, the crossing is searched within ZONE_BACK_SLOW_MAX_MOVE samples, and the steady rows move to end
#: ZONE_STEADY_ROWS[1] before the crossing found, up to ZONE_BACK_SLOW_ROUNDS times.  A speed reversal's or a speed
#: step's gap runs under tens of N m (c from a J1_nom 10-20 % off the drive's J1 would be off by as much): the gate
#: keeps them out.  Chosen on vector sets 1-12 (JointState light load reversals): the friction alone at a reach of 16
#: +0 within +-2, 48 without the gate +22 but the speed reversals -27 (329 -> 302) and the speed steps -8; with the gate
#: 0.5 / 0.25 +22 / +23, nothing else moved but 3 speed reversals (the steady rows moved for every traversal: now for
#: the slow ones only) -- 0.25 kept (a J1_nom 15 % off moves c by at most 4 % of T0), 48 and 3 not tuned.  A slow
#: departure's entry that a rule already moved back short of the crossing (before the departure) moves on to it too:
#: vector sets 1-12 +11 more within +-2, none out (the twist gate lifted for slow departures as well: +9 more on 11 of
#: them, a heavy load reversal taken for slow among them, 1 out: not done)
ZONE_BACK_SLOW_SHARE = 0.25
ZONE_BACK_SLOW_MAX_MOVE = 48
ZONE_BACK_SLOW_ROUNDS = 3


def gap_constant_torque(alpha1: np.ndarray, m_el: np.ndarray, inertia_kgm2: float, sample_period_s: float) -> float:
    """The constant torque c (N m, signed as m_el: the motor's friction and the torque estimate's offset) of a free
    motor over the rows given: alpha1 = a + v k + (Phi(m_el) - c Phi(1)) / J, a, v and c by least squares, J =
    ``inertia_kgm2`` (:func:`flank_free._double_integral`'s Phi)."""
    n = alpha1.size
    one = _double_integral(np.ones(n), sample_period_s) / inertia_kgm2
    scale = max(float(one.max()), 1e-300)
    y = np.asarray(alpha1, float) - _double_integral(m_el, sample_period_s) / inertia_kgm2
    X = np.column_stack([np.ones(n), np.arange(n, dtype=float) / max(n - 1, 1), -one / scale])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return float(coef[2] / scale)


def _slow_departure(alpha1: np.ndarray, m_el: np.ndarray, rows: tuple, steady: tuple, inertia_kgm2: float,
                    sample_period_s: float) -> Optional[float]:
    """:data:`ZONE_BACK_SLOW_SHARE`'s constant torque c of the gap after the rules' entry, ``rows`` = (the entry, the
    departure, the re-contact row), ``steady`` = the steady rows (first, end); None where the gap is not slow."""
    ts = sample_period_s
    entry, _, recontact = rows
    a, b = steady
    g0 = entry + samples(2, ts)
    g1 = min(g0 + samples(40, ts), recontact - samples(2, ts))
    x1, m = np.asarray(alpha1, float), np.asarray(m_el, float)
    if not ZONE_BACK_SLOW_MAX_MOVE or g1 - g0 < samples(8, ts) or g1 >= x1.size \
            or not (x1[b] - x1[a]) * (x1[g1] - x1[g0]) > 0:
        return None
    c = gap_constant_torque(x1[g0:g1], m[g0:g1], inertia_kgm2, ts)
    slow = abs(float(np.mean(m[g0:g1])) - c) <= ZONE_BACK_SLOW_SHARE * abs(float(np.mean(m[a:b])) - c)
    return c if slow else None


def zone_edge_back(alpha1: np.ndarray, delta: np.ndarray, m_el: np.ndarray, rows: tuple, side: float,
                   inertia_kgm2: float, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S,
                   levels: tuple = (0.0, math.inf)) -> int:
    """The entry row of a traversal, ``rows`` = (the rules' entry, the departure, the re-contact row), moved back to the
    first row of the run of rows up to the entry where delta lies beyond the zone's edge F + side |T0| / k (ZONE_BACK_*:
    k from :func:`far_contact_model` within ZONE_BACK_MAX_K_REL_SE, the twist |T0| / k within ZONE_BACK_MAX_TWIST_SHARE
    of the departure threshold, the crossing within ZONE_BACK_MAX_MOVE samples and resolved as :func:`zone_edge_entry`'s;
    ``levels`` = (delta's quantum, the departure threshold) in rad; a slow departure's twist less the gap's friction,
    its crossing searched further, its steady rows before the crossing: ZONE_BACK_SLOW_*); the entry itself when it
    lies before the departure (a rule moved it back) and the departure is not slow, is not beyond the edge, or the
    crossing is not found or not resolved."""
    ts = sample_period_s
    entry, departure, recontact = (int(r) for r in rows)
    quantum_rad, threshold_rad = levels
    reach = samples(ZONE_BACK_MAX_MOVE, ts)
    a, b = departure - samples(ZONE_STEADY_ROWS[0], ts), departure - samples(ZONE_STEADY_ROWS[1], ts)
    d = np.asarray(delta, float)
    if not reach or recontact <= entry or a < 0 or entry >= d.size:
        return entry
    slow = _slow_departure(alpha1, m_el, (entry, departure, recontact), (a, b), inertia_kgm2, ts)
    if entry < departure and slow is None:
        return entry        # a rule moved it back (a fast departure's entry lies at the departure or after it)
    got = far_contact_model(alpha1, delta, m_el, recontact, ts)
    if got is None or not (got[0] > 0 and got[3] <= ZONE_BACK_MAX_K_REL_SE):
        return entry
    offset, rounds = (0.0, 0) if slow is None else (slow, ZONE_BACK_SLOW_ROUNDS)
    reach = reach if slow is None else samples(ZONE_BACK_SLOW_MAX_MOVE, ts)
    anchor = departure
    for rnd in range(rounds + 1):
        twist = abs(float(np.mean(np.asarray(m_el, float)[a:b])) - offset) / (got[0] * inertia_kgm2)
        edge = float(np.mean(d[a:b])) + side * twist
        if not side * (d[entry] - edge) > 0 or not twist <= ZONE_BACK_MAX_TWIST_SHARE * threshold_rad:
            return entry
        i = entry
        while i - 1 >= max(entry - reach, 0) and side * (d[i - 1] - edge) > 0:
            i -= 1
        if i >= anchor or rnd == rounds:
            break
        anchor = i          # a slow departure: the steady rows end before the crossing (ZONE_BACK_SLOW_*)
        a, b = anchor - samples(ZONE_STEADY_ROWS[0], ts), anchor - samples(ZONE_STEADY_ROWS[1], ts)
        if a < 0:
            return entry
    if i == entry or i <= entry - reach or i < 2 or i + 1 >= d.size \
            or abs(d[i + 1] - d[i - 2]) / 3.0 < ZONE_K_SIGMAS * got[3] * twist + quantum_rad:
        return entry        # no crossing within the search, or one delta does not resolve
    return i


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
