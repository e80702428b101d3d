"""The steady-entry ("kink") fit: J1 with the samples before the entry, for a drive steady before it (issue 20).

A drive on line (our simulator, the paper's) turns at constant speed under a steady torque before the entry: the
pre-entry samples then pin ω0 and the torque level.  The entry row is a change point of the angle model (a profile
over candidate rows); the fit's standard error has the same terms as :func:`jident_ros.identify.gap_free.free_angle_fit`
(the statistical one, the torque noise, the change points, the declared friction, offset and lag bands).
``jident_ros.identify.gap._anchored_angle`` decides when it is used.  Moved out of gap_free.py (its size limit).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from jident_ros.identify import lapack
from jident_ros.identify.gap_free import FREE_REL_SE_FLOOR, FreeFitError
from jident_ros.identify.gap_numerics import (
    _ar1_inflation,
    _cumtrapz,
    _double_trapz_adjoint,
    _einsum,
    _quantum,
    _robust_noise,
)
from jident_ros.identify.gap_terms import drift_term, encoder_error_term
from jident_ros.stream.rate import samples as rate_samples

#: Kink fit: steady pre-entry samples used before the earliest candidate entry row, and the candidate rows
#: searched around the free fit's and the detector's entry rows (both durations, counted at 2 kHz and converted to
#: the recording's rows by jident_ros/stream/rate.py).
KINK_PRE_SAMPLES = 40
KINK_SEARCH = 4
#: Kink fit: fewest gap samples after a candidate entry (the steady samples before it carry ω0).
KINK_MIN_GAP_SAMPLES = 6
#: Kink fit: the pre-entry angle's t² term must not be significant beyond this t statistic.
KINK_STEADY_T = 3.0
#: Kink fit: entry rows whose profile residual is within this χ²₁ quantile (95 %) of the best one are plausible.
KINK_CHI2_1 = 3.841
#: Kink fit: the coupling's unloading times searched with the entry row, in rows at 2 kHz (converted by
#: jident_ros/stream/rate.py): a compliant coupling lets go over about a quarter period of the load on its spring, so
#: the torque it transmits falls from its steady level to zero over R rows after the kink, not at once (the DOL
#: drive's slip drop: the wheel of 0.12 kg m^2 on 50 000 N m/rad, 2.4 ms = 5 rows; our simulator's entry: at once).
#: Up to 4 ms; those within the drive's coupling_release_max_s are searched (0 alone: the model before stop 27).
KINK_UNLOAD_ROWS = (0, 1, 2, 3, 4, 5, 6, 8)
#: Kink fit under a declared torque lag: the entry is located again over the plausible (row, R) pairs with the row
#: moved by up to this many rows at 2 kHz (the DOL drive's slip reversals: half a sample of lag moved it by one).
KINK_LAG_ROWS = 2
#: Kink fit with an unloading coupling: its steady torque T0 is m_el's mean over this many rows before the kink row.
KINK_T0_ROWS = 4


def _kink_phi(m: np.ndarray, ts: float, s_arr: np.ndarray, P: int, end: int, unload=None) -> np.ndarray:
    """Φ_s of every candidate entry row ``s_arr`` (and unloading time ``unload``, rows per candidate; None: all 0) over
    rows [P, end), (candidate, row): the double trapezoid of the motor's free torque from its row (zeros before it).
    ``m``: the torque (N,), or one per candidate (candidates, N)."""
    n = end - P
    s_rel = s_arr - P
    mm = m[..., P:end]
    # the double trapezoid from each candidate's row, as rows of one cumulative sum (zeros before the row: a sum that
    # starts with zeros adds the same numbers in the same order as one started at the row).  Every candidate's
    # trapezoid terms are zero before column j0 (the earliest entry row's, less one: an unloading coupling's first
    # term), and so are its running sums there: the sums are formed from j0 on (the same numbers)
    j0 = max(int(s_rel.min()) - 1, 0)
    half = np.where(np.arange(j0, n - 1, dtype=float)[None, :] >= s_rel[:, None],
                    0.5 * (mm[..., j0 + 1:] + mm[..., j0:-1]), 0.0)
    if unload is not None:
        _unloading_terms(half, mm, s_rel, np.asarray(unload), j0)
    c1 = np.zeros((s_arr.size, n - j0))
    half.cumsum(axis=1, out=c1[:, 1:])
    c1 *= ts
    phi = np.zeros((s_arr.size, n))
    (0.5 * (c1[:, 1:] + c1[:, :-1])).cumsum(axis=1, out=phi[:, j0 + 1:])
    phi[:, j0 + 1:] *= ts
    return phi


def _kink_candidates(m: np.ndarray, ts: float, entries, P: int, end: int, y: np.ndarray, unload=None,
                     runs=None) -> tuple:
    """:func:`kink_fit`'s least-squares fit α1 = θ0 + ω0 t + κ Φ_s for every candidate entry row (and unloading time
    ``unload``, rows per candidate; None: all 0): arrays over the candidates of the residual sum of squares and κ =
    1/J1, and Φ (candidate, row) over rows [P, end) (:func:`_kink_phi`).  ``runs``: (rows, lo, hi) per run of
    consecutive candidates fitted over the same rows [lo, hi) (counted from P; :func:`kink_best_j1`'s variants, each
    over its own rows); None: all candidates over every row.

    The fit's (1, t) columns are common to the candidates of a run: they are projected out of α1 once and out of
    each Φ_s by its two sums (1 and t centred are orthogonal), so that κ = Φ_s·α1⊥ / |Φ_s⊥|² and the residual sum
    of squares |α1⊥|² − (Φ_s·α1⊥)²/|Φ_s⊥|² come from one product of Φ with (1, t, α1⊥) and the row sums of Φ²: the
    least squares of the per-candidate 3 x 3 normal equations (fe4eda0; the same fit: the span of (1, t) is that of
    (1, u)), to rounding (test_gap_kink_speed.py).  The chosen candidate's own fit: :func:`_kink_solution`.  Raises
    LinAlgError where a candidate's Φ_s lies in the span of (1, t) (a singular fit)."""
    s_arr = np.asarray(entries)
    phi = _kink_phi(m, ts, s_arr, P, end, unload)
    if runs is None:
        runs = [(s_arr.size, 0, end - P)]
    else:                                         # consecutive runs over the same rows as one
        merged = [list(runs[0])]
        for rows, lo, hi in runs[1:]:
            if (lo, hi) == tuple(merged[-1][1:]):
                merged[-1][0] += rows
            else:
                merged.append([rows, lo, hi])
        runs = merged
    S = np.empty((s_arr.size, 4))                 # per candidate: Φ·1, Φ·t, Φ·α1⊥ and Φ·Φ over its run's rows
    per_run = []
    c0 = 0
    for rows, lo, hi in runs:
        ph = phi[c0:c0 + rows, lo:hi]
        t, st = _centred_time(hi - lo)
        yr = y[lo:hi]
        yc = yr - float(yr.sum()) / (hi - lo)
        y_perp = yc - (float(yc @ t) / st) * t
        W = np.empty((hi - lo, 3))
        W[:, :2] = t[:, None] ** _POWERS
        W[:, 2] = y_perp
        np.matmul(ph, W, out=S[c0:c0 + rows, :3])
        _einsum("ij,ij->i", ph, ph, out=S[c0:c0 + rows, 3])
        per_run.append((hi - lo, st, float(y_perp @ y_perp)))
        c0 += rows
    k, st, yy = np.repeat(np.array(per_run), [r[0] for r in runs], axis=0).T
    a = S[:, 3] - S[:, 0] * S[:, 0] / k - S[:, 1] * S[:, 1] / st
    if not a.min() > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    b = S[:, 2]
    return yy - b * b / a, b / a, phi


_POWERS = np.array([0.0, 1.0])


@lru_cache(maxsize=64)
def _centred_time(k: int) -> tuple:
    """The rows 0..k-1 centred and over k (orthogonal to 1), read-only, and their sum of squares."""
    t = (np.arange(k) - 0.5 * (k - 1)) / k
    t.flags.writeable = False
    return t, float(t @ t)


_TERM_ROWS = np.array([0, 1])


def _unloading_terms(half: np.ndarray, mm: np.ndarray, s_rel: np.ndarray, r_arr: np.ndarray, j0: int) -> None:
    """:func:`_kink_phi`'s trapezoid terms (``half``, its columns from ``j0`` on) of the candidates whose
    coupling unloads over R = ``r_arr`` > 0 rows, written in place.  From the kink row on the coupling still carries
    T0 (1 − w), T0 its steady torque (m_el's mean over the KINK_T0_ROWS rows before the kink: the drive was balanced
    there) and w rising from 0 at the kink row to 1 R rows after it; the motor's free torque is m_el − T0 (1 − w), zero
    before the kink row.  Only the R + 1 terms from the one before the kink row differ from the rigid coupling's:
    from R rows after it on, m_el − T0 · 0 is m_el (test_gap_kink_speed.py: the full (candidate, row) computation)."""
    s_rel = np.asarray(s_rel, dtype=np.int64)
    r_arr = np.asarray(r_arr, dtype=np.int64)
    geo = _unloading_geometry(s_rel.tobytes(), r_arr.tobytes())
    if geo is None:
        return
    idx, s_u, k0, c_of, ci, j, jj, w, after = geo
    top = int(s_u.max())
    # T0 from the running sum of m_el from the window's first row (each candidate's row of it, when 2-D)
    if mm.ndim > 1:
        csum = np.zeros((idx.size, top + 1))
        np.cumsum(mm[idx, :top], axis=-1, out=csum[:, 1:])
        c_ix = np.arange(idx.size)
        t0 = (csum[c_ix, s_u] - csum[c_ix, s_u - k0]) / k0
        m2 = mm[ci[:, None], jj]
    else:
        csum = np.zeros(top + 1)
        np.cumsum(mm[:top], out=csum[1:])
        t0 = (csum[s_u] - csum[s_u - k0]) / k0
        m2 = mm[jj]
    free = np.where(after, m2 - t0[c_of][:, None] * (1.0 - w), 0.0)
    half[ci, j - j0] = 0.5 * (free[:, 1] + free[:, 0])


@lru_cache(maxsize=256)
def _unloading_geometry(s_bytes: bytes, r_bytes: bytes):
    """:func:`_unloading_terms`' index arrays, from the candidates' entry rows (counted from the first row fitted) and
    unloading rows (int64 bytes; the same for every window searched over the same rows: cached): the unloading
    candidates, their entry rows, T0's rows, each term's candidate (among them and among all), its rows j and (j, j + 1),
    w at those rows and whether they are at or after the kink row (read-only); None: no candidate unloads."""
    s_rel, r_arr = np.frombuffer(s_bytes, np.int64), np.frombuffer(r_bytes, np.int64)
    idx = np.flatnonzero(r_arr > 0)
    if not idx.size:
        return None
    s_u, r_u = s_rel[idx], r_arr[idx]
    k0 = np.minimum(KINK_T0_ROWS, s_u)
    # the terms j = s − 1 .. s + R − 1 of each (R + 1 of them), over the rows j and j + 1
    width = r_u + 1
    c_of = np.repeat(np.arange(idx.size), width)
    j = s_u[c_of] - 1 + (np.arange(int(width.sum())) - np.repeat(np.cumsum(width) - width, width))
    jj = j[:, None] + _TERM_ROWS                                        # (term, 2): its two rows
    dd = jj - s_u[c_of][:, None]                                        # the rows counted from the kink row
    w = np.clip(dd / np.maximum(r_u[c_of][:, None], 1), 0.0, 1.0)
    out = (idx, s_u, k0, c_of, idx[c_of], j, jj, w, dd >= 0)
    for x in out:
        x.flags.writeable = False
    return out


def _kink_solution(u: np.ndarray, f: np.ndarray, y: np.ndarray, scale: float) -> tuple:
    """One candidate's least-squares fit from its design (1, ``u``, ``f``) by (XᵀX)⁻¹Xᵀ (the solution whose row 2 the
    standard error needs): (1/J1, residual, row 2 of (XᵀX)⁻¹Xᵀ)."""
    X = np.empty((u.size, 3))                 # np.column_stack([np.ones(u.size), u, f]), written in place
    X[:, 0] = 1.0
    X[:, 1] = u
    X[:, 2] = f
    p = lapack.solve(X.T @ X, X.T)
    coef = p @ y
    return float(coef[2]) / scale, y - X @ coef, p[2]


@lru_cache(maxsize=64)
def _kink_pre_design(n_pre: int) -> tuple:
    """The kink fit's pre-entry steadiness test: the design (1, t, t²) over n_pre samples (t centred, over n_pre)
    and the (2, 2) element of (XᵀX)⁻¹ (read-only: shared)."""
    tt = (np.arange(n_pre) - n_pre / 2.0) / max(n_pre, 1)
    Xp = np.column_stack([np.ones(n_pre), tt, tt * tt])
    Xp.flags.writeable = False
    return Xp, float(lapack.inv(Xp.T @ Xp)[2, 2])


def kink_fit(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, entries, end: int,
             coulomb_max_nm: float = 0.0, torque_offset_nm: float = 0.0, torque_lag_s: float = 0.0) -> dict:
    """J1 with the entry row as a change point of a steady drive (profile likelihood).

    Before the entry the drive turns at constant speed (steady, in contact); from the entry row s on it is free:
    α1(t) = θ0 + ω0 (t − t_s) + [t ≥ t_s] Φ_s(t)/J1, Φ_s the double integral of the torque from t_s (zero value
    and slope at t_s: angle and speed are continuous).  (:func:`kink_locate` with ``unload_rows``: the coupling lets
    go over R rows from s, docs/method.md "A coupling that lets go over time".)  The same rows [P, end) for every candidate s in
    ``entries``, so the residual sums compare: s* minimises it; the plausible entries are those within
    KINK_CHI2_1 σ̂² of it, and the largest change of J1 over them is the change-point term.  Returns j1, se_stat
    (statistical, torque noise and change points in quadrature), terms, start (s*), end, residual, dof; raises
    FreeFitError.  :func:`kink_locate` and :func:`kink_terms`, its two halves, for a caller that may still refuse the
    fit or needs only J1."""
    return kink_terms(kink_locate(alpha1, torque, sample_period_s, entries, end), coulomb_max_nm, torque_offset_nm,
                      torque_lag_s)


def _kink_pairs(pairs, end: int, ts: float) -> tuple:
    """The (entry row, unloading rows) candidates that leave KINK_MIN_GAP_SAMPLES after the unloading, sorted; the
    first row fitted (KINK_PRE_SAMPLES before the earliest entry); why no fit can be made ('' when one can)."""
    last = end - KINK_MIN_GAP_SAMPLES
    pairs = sorted({p if type(p) is tuple and type(p[0]) is int is type(p[1]) else (int(p[0]), int(p[1]))
                    for p in pairs if p[0] + p[1] <= last})
    if not pairs:
        return pairs, 0, f"kink fit: fewer than {KINK_MIN_GAP_SAMPLES} samples after every candidate entry"
    P = max(0, pairs[0][0] - rate_samples(KINK_PRE_SAMPLES, ts))
    if pairs[0][0] - P < 10:
        return pairs, P, "kink fit: fewer than 10 steady samples before the entry"
    return pairs, P, ""


def kink_best_j1(alpha1: np.ndarray, sample_period_s: float, variants) -> list:
    """J1 of each variant's best candidate, the variants fitted together in one stacked solve: a variant is (torque,
    (entry row, unloading rows) pairs, end row), its J1 :func:`kink_locate`'s over those pairs without its checks
    (the refits of a fit that passed them: the change-point term's with the end moved in, the lag term's with the
    torque moved).  An item is the reason (str) where that variant gives no physical fit.  Each variant's rows are
    its own ([KINK_PRE_SAMPLES before its earliest entry, its end)): the others' weigh nothing in its sums."""
    a = np.asarray(alpha1, float)
    ts = float(sample_period_s)
    out: list = [None] * len(variants)
    groups = []
    for v, (torque, pairs, end) in enumerate(variants):
        pairs, P, problem = _kink_pairs(pairs, int(end), ts)
        if problem:
            out[v] = problem
        else:
            groups.append((v, np.asarray(torque, float), pairs, P, int(end)))
    if not groups:
        return out
    P0, E = min(g[3] for g in groups), max(g[4] for g in groups)
    # every candidate: (variant, entry row, unloading rows, first row, end row), its rows counted from P0
    # (each variant's candidates one after the other)
    cand = np.array([(s_, r_, g[3], g[4]) for g in groups for s_, r_ in g[2]])
    sizes = [len(g[2]) for g in groups]
    first = groups[0][1]
    # one torque for all (the trims'), or each candidate its variant's (the lag's moved ones)
    if all(g[1] is first for g in groups):
        m = first[P0:E]
    else:
        m = np.empty((len(groups), E - P0))
        for gi, g in enumerate(groups):
            m[gi] = g[1][P0:E]
        m = m[np.repeat(np.arange(len(groups)), sizes)]
    rss, kappa_all, _ = _kink_candidates(m, ts, cand[:, 0] - P0, 0, E - P0, a[P0:E] - a[P0],
                                         cand[:, 1] if cand[:, 1].any() else None,
                                         [(size, g[3] - P0, g[4] - P0) for g, size in zip(groups, sizes)])
    lo = 0
    for (v, *_), size in zip(groups, sizes):
        kappa = float(kappa_all[lo + int(np.argmin(rss[lo:lo + size]))])
        lo += size
        out[v] = 1.0 / kappa if kappa > 0 else f"kink fit: non-physical 1/J1 = {kappa:.4g}"
    return out


def kink_locate(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, entries, end: int,
                unload_rows=(0,), pairs=None) -> dict:
    """:func:`kink_fit` without its standard error: the entry row, J1 and the fit's checks (FreeFitError) — j1,
    start, end, residual, dof, plausible_entries, unload_rows (the best candidate's unloading time, rows) and
    plausible (the plausible (entry row, unloading rows) pairs; :func:`kink_terms` adds se_stat and terms).
    ``unload_rows``: the coupling's unloading times to search with every entry row (rows; KINK_UNLOAD_ROWS);
    ``pairs``: the (entry row, unloading rows) candidates themselves instead (``entries`` and ``unload_rows`` unused).
    The refits of a fit that passed its checks (the change-point and lag terms'): :func:`kink_best_j1`."""
    a = np.asarray(alpha1, float)
    m = np.asarray(torque, float)
    ts = float(sample_period_s)
    if pairs is None:
        pairs = [(x, r) for x in entries for r in set(unload_rows)]
    pairs, P, problem = _kink_pairs(pairs, end, ts)
    if problem:
        raise FreeFitError(problem)
    entries = [p_[0] for p_ in pairs]
    y = a[P:end] - a[entries[0]]
    unload = [p_[1] for p_ in pairs]
    rss_all, kappa_all, phi = _kink_candidates(m, ts, entries, P, end, y, unload if any(unload) else None)
    k = int(np.argmin(rss_all))
    # the chosen candidate's fit by (XᵀX)⁻¹Xᵀ on its design (1, u, Φ/max|Φ|), u the time from its entry row over the
    # rows after it: its 1/J1, residual and the solution's row 2 (the standard error's)
    scale_k = np.maximum(np.abs(phi[k]).max(), 1e-300)
    u_k = (np.arange(P, end, dtype=float) - entries[k]) * ts / max((end - entries[k]) * ts, ts)
    kappa, res_k, row_k = _kink_solution(u_k, phi[k] / scale_k, y, scale_k)
    rss_all[k] = rss_min = float(res_k @ res_k)
    kappa_all[k] = kappa
    s_best = entries[k]
    if not kappa > 0:
        raise FreeFitError(f"kink fit: non-physical 1/J1 = {kappa:.4g}")
    dof = end - P - 3
    q = _quantum(a[P:end])
    s2 = max(rss_min / max(dof, 1), q * q / 12.0, 1e-30)
    # the model's premise: constant speed before the entry (a speed controller's drive is not): the pre-entry
    # angle gets a t² term, refused when it is significant (t statistic > KINK_STEADY_T)
    n_pre = s_best - P
    Xp, xtx_inv_22 = _kink_pre_design(n_pre)
    cp_ = lapack.lstsq(Xp, a[P:s_best])
    rp = a[P:s_best] - Xp @ cp_
    s2p = max(float(rp @ rp) / max(n_pre - 3, 1), q * q / 12.0, 1e-30)
    t_quad = abs(float(cp_[2])) / float(np.sqrt(s2p * xtx_inv_22))
    if t_quad > KINK_STEADY_T:
        raise FreeFitError(f"kink fit: the speed before the entry is not constant (t = {t_quad:.3g} for a t² term "
                           f"over {n_pre} samples)")
    j1 = 1.0 / kappa
    plausible = np.flatnonzero((rss_all - rss_min <= KINK_CHI2_1 * s2) & (kappa_all > 0)).tolist()
    kappa_list = kappa_all[plausible].tolist()
    if k in plausible:                              # the chosen candidate's own κ (its type: np.float64) as before
        kappa_list[plausible.index(k)] = kappa
    fit = {"j1": j1, "start": int(s_best), "end": int(end), "residual": res_k, "dof": dof,
           "plausible_entries": sorted({entries[q_] for q_ in plausible}), "unload_rows": int(unload[k]),
           "plausible": [pairs[q_] for q_ in plausible],
           "_state": (m, ts, P, kappa, row_k / scale_k, s2, kappa_list, a[P:end])}
    return fit


def kink_terms(fit: dict, coulomb_max_nm: float = 0.0, torque_offset_nm: float = 0.0,
               torque_lag_s: float = 0.0, encoder_error_rad: float = 0.0) -> dict:
    """:func:`kink_fit`'s result with its standard error (se_stat, terms), from :func:`kink_locate`'s."""
    m, ts, P, kappa, row, s2, plausible_kappa, angles = fit["_state"]
    j1, res, s_best, end = fit["j1"], fit["residual"], fit["start"], fit["end"]
    cp = max(abs(1.0 / k - j1) for k in plausible_kappa)
    var_stat = s2 * float(row @ row) * _ar1_inflation(res)
    i = s_best - P
    g = _double_trapz_adjoint(row[i:], ts)
    sm = _robust_noise(m[s_best:end])
    terms = {"statistical": j1 * j1 * float(np.sqrt(var_stat)),
             "torque_noise": j1 * j1 * kappa * sm * float(np.sqrt(g @ g)), "change_points": float(cp)}
    if coulomb_max_nm:
        # an unmodelled Coulomb friction F in [0, F_max] is a torque offset in the gap: C = (t − t_s)²/2 after
        # the entry; J1 moves by J1 F (r_κ · C); a uniform term of half-width F_max (not centred: a drive without
        # friction is not biased)
        c_col = np.zeros(end - P)
        c_col[i:] = 0.5 * ((np.arange(end - s_best)) * ts) ** 2
        terms["coulomb_band"] = j1 * abs(float(row @ c_col)) * float(coulomb_max_nm) / np.sqrt(3.0)
    if torque_offset_nm:
        # an unknown constant torque T in [-torque_offset_nm, +torque_offset_nm] in the gap: the same column, symmetric
        c_col = np.zeros(end - P)
        c_col[i:] = 0.5 * ((np.arange(end - s_best)) * ts) ** 2
        terms["torque_offset"] = j1 * abs(float(row @ c_col)) * float(torque_offset_nm) / np.sqrt(3.0)
        # ... and one that drifts across the gap (drift_term), zero before the entry
        terms["torque_drift"] = drift_term(row[i:], np.arange(end - s_best) * ts, j1, float(torque_offset_nm))
    if torque_lag_s:
        # the torque estimate's bounded lag: m_el(t + τ) ≈ m_el + τ dm_el/dt adds τ ∫(m_el − m_el(t_s)) dt from the
        # entry (free_angle_fit's τ ∫m_el dt, whose m_el(t_s) (t − t_s) part the free fit's speed absorbs: here the
        # speed at the entry is pinned by the steady samples before it: with ∫m_el, a decaying torque one sample late
        # moved J1 by +5.7 % and the term said 1.4 %; with this column, 5.0 % at 1.5 samples declared)
        l_col = np.zeros(end - P)
        l_col[i:] = _cumtrapz(m[s_best:end] - m[s_best], ts)
        terms["torque_lag"] = j1 * abs(float(row @ l_col)) * float(torque_lag_s) / np.sqrt(3.0)
    if encoder_error_rad:
        # the motor encoder's angle error over every fitted row (before the entry too: free_angle_fit's term)
        terms["encoder_error"] = encoder_error_term(row, angles, j1, float(encoder_error_rad))
    se = float(np.sqrt(sum(v * v for v in terms.values())))
    return {"j1": j1, "se_stat": max(se, FREE_REL_SE_FLOOR * j1), "terms": terms, "start": int(s_best),
            "end": int(end), "residual": res, "dof": fit["dof"], "plausible_entries": fit["plausible_entries"],
            "unload_rows": fit.get("unload_rows", 0), "plausible": fit.get("plausible", [])}


def kink_lag_variants(torque: np.ndarray, sample_period_s: float, pairs, end: int, torque_lag_s: float) -> list:
    """:func:`kink_best_j1`'s variants of :func:`kink_lag_spread`: the torque moved by − and + ``torque_lag_s``
    (linear interpolation between samples), each over ``pairs`` to ``end``.  Only the rows a fit over those pairs
    reads are moved (from KINK_PRE_SAMPLES before the earliest pair's entry row to ``end``: np.interp's value at a row
    is its own, the same numbers as the whole array's); the rows outside them are NaN."""
    m = np.asarray(torque, float)
    t = np.arange(m.size, dtype=float)
    k = float(torque_lag_s) / float(sample_period_s)
    lo = max(0, min((int(x) for x, _ in pairs), default=0) - rate_samples(KINK_PRE_SAMPLES, float(sample_period_s)))
    hi = max(lo, min(int(end), m.size))
    out = []
    for shift in (-k, k):
        moved = np.full(m.size, np.nan)
        moved[lo:hi] = np.interp(t[lo:hi] + shift, t, m)
        out.append((moved, pairs, end))
    return out


def kink_lag_spread(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, pairs, end: int, j1: float,
                    torque_lag_s: float) -> float:
    """The largest change of the steady-entry fit's J1 when the torque is moved by ± ``torque_lag_s`` (linear
    interpolation between samples) and the entry row located again (:func:`kink_locate` over the (entry row,
    unloading rows) ``pairs``: the plausible ones and their rows moved by up to KINK_LAG_ROWS).

    A torque estimate that lags the angles moves the kink the profile finds, not only Φ at a fixed entry row
    (:func:`kink_terms`' linear τ∫m term): on the DOL drive's slip reversals at 2^13 counts, half a sample of lag
    moved the located entry by one row and J1 by 2.5-4 %, the linear term by under 1 %.  Raises FreeFitError when a
    moved torque gives no physical fit.  (gap._anchored_angle fits these with its other refits at once.)"""
    fits = kink_best_j1(alpha1, sample_period_s, kink_lag_variants(torque, sample_period_s, pairs, end, torque_lag_s))
    for x in fits:
        if isinstance(x, str):
            raise FreeFitError(x)
    return max(abs(x - j1) for x in fits)
