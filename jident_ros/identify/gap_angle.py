"""The 'angle' fits (α1 and m_el measured: a motor encoder and the drive's torque, no accelerometer; issue 20 items 1-3)
as gap.py's ``_estimate_inertia`` takes them: the free angle fit (gap_free.free_angle_fit) and, for a drive steady
before the entry, the steady-entry fit (gap_kink) where the free fit supports it (:func:`_angle_fits`,
:func:`_anchored_angle`), the trend's refit at F_c = 0 (:func:`_angle_trend_refit`), the encoder's resolution
(:func:`encoder_resolved`), and the checks of the steady entry by a1 where an Imu is there too
(:func:`steady_entry_contact`, :func:`a1_rows_contact`: gap._cross_checked's).  Moved out of gap.py (its 600-line
limit, issue 20); the numbers are the same.

:func:`_angle_fit`, the first release's 'angle' fit (kept for comparison; docs/method.md, "Replaces"; its α1 and
m_el, no accelerometer): double-integral form, no differentiation.  Before the entry the
motor turns at a constant speed, inside the gap J1 dω1/dt = m_el, so over the
pre-entry and gap samples α1(t) = α0 + ω0 t + Z(t)/J1 with Z the double integral of
m_el from the entry (0 before it).  m_el is first fitted with the joint fit's torque
model (m0, then m0 + c2 τ² + c3 τ³ in the gap), Z is its exact double integral, and
ordinary least squares give (α0, ω0, 1/J1); the torque fit's covariance and the
model error go into the uncertainty.  An encoder's quantisation error on a steadily
turning shaft is a deterministic sawtooth, not white noise: below ~2^18 counts/rev
the interval is too narrow (docs/method.md).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import numpy as np

from jident_ros.identify import gap_cross, lapack
from jident_ros.identify.gap_a1 import _robust_noise, _torque_powers, gap_only_max_trim
from jident_ros.identify.gap_free import FREE_REL_SE_FLOOR, FreeFitError, GapModel, free_angle_fit
from jident_ros.identify.gap_kink import (
    KINK_LAG_ROWS,
    KINK_PRE_SAMPLES,
    KINK_SEARCH,
    KINK_UNLOAD_ROWS,
    kink_best_j1,
    kink_lag_variants,
    kink_locate,
    kink_terms,
)
from jident_ros.identify.gap_load import LOAD_ANGLE_KEY, load_free_bounds
from jident_ros.identify.gap_numerics import FIT_MEMO, _cumtrapz, _median, _quantum
from jident_ros.identify.gap_steady import pre_entry_steady
from jident_ros.identify.gap_types import FitState, GapEstimate, NoGapError, _net_torque
from jident_ros.stream.rate import samples as rate_samples

#: 'angle' fit: relative floor of the standard error.  The torque model's own error (noise-free,
#: grid: up to 0.03 % of J1) is not always seen by the model-error term; without the floor a
#: noise-free window could be flagged 'between classes' at 4e-5 off its class.
ANGLE_REL_SE_FLOOR = 2e-4


#: 'angle' fit: the gap's torque must move the motor by at least this many encoder counts from the free run its
#: initial angle and speed set (|∬ m_el dt²| / J1 over the fitted rows).  J1 is read from that curvature; a count's
#: rounding at either end of a displacement of D counts is up to 1/(2 D) of it: 10 % (the published interval's cap,
#: verdict.MAX_CI95_HALF_WIDTH_REL) at 5 counts, and a fit over fewer rows than the sawtooth's period does not average
#: it away.  A physical bound, not fitted: no published window of the zoo or the DOL zoo changes; it refuses,
#: naming the counts, 2^13 windows that were refused with a standard error above 25 % or infinite (ours, the second
#: drive).  It does not reach the DOL zoo's one 2^13 window whose interval misses (its
#: fit spans 32 rows, 26 counts, of which 8 before the entry and 7 after the re-contact: docs/results.md).
MIN_CURVATURE_COUNTS = 5.0


def encoder_resolved(alpha1: np.ndarray, torque: np.ndarray, span: tuple, j1: float, sample_period_s: float) -> None:
    """Raises NoGapError ('gap fit undetermined: ...') when the gap's torque moves the motor by fewer than
    :data:`MIN_CURVATURE_COUNTS` encoder counts over the fitted rows ``span`` (a quantised alpha1 only: a continuous
    or noisy angle has no count, its noise is the fit's)."""
    s, e = int(span[0]), int(span[1])
    if e - s < 2 or not j1 > 0:
        return
    q = _quantum(np.asarray(alpha1, float)[max(s - 20, 0):e])
    if q <= 0.0:
        return
    m = np.asarray(torque, float)[s:e]
    ts = float(sample_period_s)
    disp = float(_cumtrapz(_cumtrapz(m, ts), ts)[-1]) / j1                          # ∬ m dt² / J1, rad
    counts = abs(disp) / q
    if counts < MIN_CURVATURE_COUNTS:
        raise NoGapError(f"gap fit undetermined: the gap's torque moves the motor by {counts:.2g} encoder counts "
                         f"over its {e - s} rows (J1 = {j1:.4g} kg m^2), need >= {MIN_CURVATURE_COUNTS:g}: the "
                         f"encoder does not resolve J1 there")


def _angle_fits(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, start: int, end: int,
                model: GapModel, bounds: tuple | None = None) -> tuple:
    """(free angle fit, steady-entry fit) of the 'angle' method: :func:`free_angle_fit` (NoGapError when it
    fails; inside the load side's free ``bounds``, gap_load.py) and :func:`_anchored_angle` (a fresh dict: the
    caller pops from it); memoised under :func:`fit_cache`."""
    key = None
    if FIT_MEMO.memo is not None:
        key = ("angle_fits", alpha1.tobytes(), torque.tobytes(), float(sample_period_s), int(start), int(end), model,
               bounds)
        hit = FIT_MEMO.memo.get(key)
        if hit is not None:
            if isinstance(hit, str):
                raise NoGapError(hit)
            return hit[0], dict(hit[1])
    try:
        ff = free_angle_fit(alpha1, torque, sample_period_s, start, end, model, bounds=bounds)
    except FreeFitError as exc:
        if key is not None:
            FIT_MEMO.memo[key] = str(exc)
        raise NoGapError(str(exc)) from None
    anchored = _anchored_angle(alpha1, torque, ff, (start, end), sample_period_s, model)
    if key is not None:
        FIT_MEMO.memo[key] = (ff, anchored)
    return ff, dict(anchored)


def _angle_trend_refit(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, ff: dict) -> tuple:
    """The trend's J1 (GapEstimate.trend_fit) of a free angle fit ``ff`` under a Coulomb band: its rows [start, end)
    fitted with F_c = 0 (the design [1, t, Φ] of gap_free.free_angle_fit without the Coulomb column, the angle not
    moved by F_mid C: the same J1 to rounding as that function with a zero band and ``fixed``), as every other fit
    takes it (the a1 fits, the gap-only fit through the origin, the steady-entry fit: F_c = 0 with the band as a
    term).  The free angle fit takes F_c free or at the band's middle, whichever has the smaller standard error, and a
    free F_c's J1 scatters from window to window; at F_c = 0 the bias, F_c through the window's shape, is a constant of
    the drive and the same assumption as the fits a drive's other windows publish.  Its standard error and terms:
    ``ff``'s, scaled by the ratio of the two J1 (the rows and their regressors are the same; a full refit, its terms
    and change-point trims, cost 0.5 ms a window).  () where 1/J1 is not positive (the trend then reads ``ff``)."""
    s, e = int(ff["start"]), int(ff["end"])
    n = e - s
    phi = _cumtrapz(_cumtrapz(np.asarray(torque, float)[s:e], sample_period_s), sample_period_s)
    scale = max(float(np.abs(phi).max()), 1e-300)
    X = np.column_stack([np.ones(n), np.arange(n) / max(n - 1, 1), phi / scale])
    kappa = float(lapack.lstsq(X, np.asarray(alpha1, float)[s:e] - float(alpha1[s]))[2]) / scale
    if not (kappa > 0 and np.isfinite(kappa)):
        return ()
    ratio = (1.0 / kappa) / float(ff["j1"])
    return (1.0 / kappa, float(ff["se"]) * ratio,
            tuple((k, float(v) * ratio) for k, v in ff["terms"].items()))


def _anchored_angle(alpha1: np.ndarray, torque: np.ndarray, ff: dict, coarse: tuple, sample_period_s: float,
                    model: GapModel) -> dict:
    """The free angle fit's J1 with the pre-entry samples too, when the drive was steady before the entry.

    A drive on line (our simulator, the paper's) turns at constant speed under a steady torque before the entry;
    then the pre-entry samples pin ω0 and the torque level, and the first angle fit (:func:`_angle_fit`, over
    [0, e) of the detector's ``coarse`` interval (s, e)) is several times more precise than the free fit on a short
    gap (our simulator: 9-32 samples).  Used when the pre-entry m_el is steady (:func:`pre_entry_steady` on the
    samples before both entries), its J1 agrees with the free fit's within CROSS_CHECK_Z combined standard errors
    and its standard error (with a change-point term: the largest change of J1 with s or e moved in by 1 or 2) is the
    smaller: the free fit is its check.  Returns {} and a 'choice' phrase otherwise."""
    s, e = coarse
    lo, hi = min(s, ff["start"]), max(s, ff["start"])
    # durations counted at 2 kHz, in the recording's rows (stream/rate.py; unchanged at 0.5 ms)
    k_search, k_pre, k_agree = (rate_samples(k, sample_period_s) for k in (KINK_SEARCH, KINK_PRE_SAMPLES,
                                                                          KINK_FREE_AGREE_SAMPLES))
    # the coupling's unloading times searched: those within the declared bound (GapModel.coupling_release_s)
    unload = tuple(sorted({r for r in rate_samples(KINK_UNLOAD_ROWS, sample_period_s)
                           if r * sample_period_s <= float(model.coupling_release_s) * (1 + 1e-9)})) or (0,)
    test = pre_entry_steady(torque[:max(lo - k_search, 0)])
    if not test.steady:
        return {"choice": f"angle (free): {test.reason}"}
    end = min(e, ff["end"])
    try:
        # its standard error only once the checks below have kept it (most steady-entry fits are refused there)
        kf = kink_locate(alpha1, torque, sample_period_s, range(max(lo - k_search, 1), hi + k_search + 1),
                         end, unload)
    except (FreeFitError, np.linalg.LinAlgError) as exc:
        return {"choice": f"angle (free): the steady-entry fit failed ({exc})"}
    # a profile minimum on the edge of the searched rows has not located the entry: the change point may lie
    # beyond it (the vector drive's heavy load reversal at 30 dB: the edge row, 13 samples early, J1 +29 %)
    cand = range(max(lo - k_search, 1), hi + k_search + 1)
    if kf["start"] in (cand[0], cand[-1]) and cand[0] > 1:
        return {"choice": f"angle (free): the steady-entry fit's entry row {kf['start']} is on the edge of the rows "
                          f"searched ({cand[0]}..{cand[-1]}): not located"}
    # the steady-entry fit, the free fit and the detector must locate the same change point (a kink far from them is
    # the steady model taking contact samples for free motion: the vector drive's heavy load reversal at 30 dB, the
    # kink 10-15 samples early, J1 +26 … +27.5 % within ± 6 %); the kink row + R is where an unloading coupling lets go
    sep = kf["start"] + kf["unload_rows"]
    for what, row in (("the free fit's", ff["start"]), ("the detector's", s)):
        if abs(sep - row) > k_agree:
            return {"choice": f"angle (free): the steady-entry fit's entry row {sep} is "
                              f"{abs(sep - row)} samples from {what} ({row}): not the same change point"}
    unsteady = _unsteady_torque_at(torque, kf["start"], k_pre, k_search)
    if unsteady:
        return {"choice": f"angle (free): {unsteady}"}
    # fitted once the checks above have kept the steady-entry fit (a speed controller's entry is refused there)
    refits = _kink_refits(alpha1, torque, sample_period_s, kf, (cand[0], end), model.torque_lag_s)
    if isinstance(refits, str):
        return {"choice": f"angle (free): the steady-entry fit {refits}"}
    kf = kink_terms(kf, model.coulomb_friction_max_nm, model.torque_offset_nm, model.torque_lag_s,
                    model.encoder_error_rad)
    j, res, dof = kf["j1"], kf["residual"], kf["dof"]
    cp_end = max(abs(x - j) for x in refits[:2])
    terms = dict(kf["terms"])
    if model.torque_lag_s:
        # the lag's relocated spread, a uniform term like the linear one it bounds from below (kink_lag_spread)
        terms["torque_lag"] = max(terms.get("torque_lag", 0.0), max(abs(x - j) for x in refits[2:]) / np.sqrt(3.0))
    terms["change_points"] = float(np.hypot(terms["change_points"], cp_end))
    model_error = terms["change_points"]
    se = max(float(np.sqrt(sum(v * v for v in terms.values()))), FREE_REL_SE_FLOOR * j)
    z = abs(j - ff["j1"]) / max(float(np.hypot(se, ff["se_stat"])), 1e-300)
    if z > gap_cross.CROSS_CHECK_Z:
        return {"choice": f"angle (free): the steady-entry fit (J1 = {j:.4g}) disagrees by {z:.1f} standard errors"}
    if se >= ff["se_stat"]:
        return {"choice": f"angle (free): the steady-entry fit is no more precise (J1 = {j:.4g} ± {se:.2g})"}
    # Hausman's test of the steady-entry premise: where it holds, both fits estimate J1 and the steady-entry fit is
    # the more precise, so their difference has the variance se_free^2 - se^2 (smaller than the combined one above);
    # a standard error on its floor (FREE_REL_SE_FLOOR: noise-free windows) is no variance, and there is no test
    floors = (se <= FREE_REL_SE_FLOOR * j * (1 + 1e-9), ff["se_stat"] <= FREE_REL_SE_FLOOR * ff["j1"] * (1 + 1e-9))
    z_h = 0.0 if any(floors) else abs(j - ff["j1"]) / float(np.sqrt(ff["se_stat"] ** 2 - se ** 2))
    if z_h > KINK_PREMISE_Z:
        return {"choice": f"angle (free): the steady-entry fit (J1 = {j:.4g}) differs from the free fit by {z_h:.1f} "
                          f"standard errors of their difference (> {KINK_PREMISE_Z:g}): its steady entry is not the data's"}
    unloads = f" (the coupling unloading over {kf['unload_rows']} rows from it)" if kf["unload_rows"] else ""
    return {"choice": f"{STEADY_ENTRY_CHOICE}: the entry a change point of a steady drive at row {kf['start']}{unloads}, "
                      f"agrees with the free fit (J1 = {ff['j1']:.4g}, {z:.1f} standard errors)", "j1": j, "se": se,
            "res": res, "dof": dof, "model_error": model_error, "terms": terms, "span": (kf["start"], kf["end"])}


def _kink_refits(alpha1: np.ndarray, torque: np.ndarray, sample_period_s: float, kf: dict, rows: tuple,
                 torque_lag_s: float):
    """The steady-entry fit's refits (:func:`kink_best_j1`, one stacked solve) for its terms: J1 with the re-contact
    row moved in by 1 and 2 (contact after it is not modelled) and, under a declared lag (which moves the kink too),
    with the torque moved by ± the lag and the entry located again near the plausible pairs (kink_lag_variants; over
    ``rows`` = (the first candidate row, the end row)).  A list of J1 (the trims', then the lag's), or why not (str)."""
    first, end = rows
    variants = [(torque, kf["plausible"], end - k) for k in (1, 2)]
    if torque_lag_s:
        d_rows = rate_samples(KINK_LAG_ROWS, sample_period_s)
        near = sorted({(s_ + d, r_) for s_, r_ in kf["plausible"] for d in range(-d_rows, d_rows + 1) if s_ + d >= first})
        variants += kink_lag_variants(torque, sample_period_s, near, end, torque_lag_s)
    try:
        refits = kink_best_j1(alpha1, sample_period_s, variants)
    except np.linalg.LinAlgError as exc:
        return f"failed ({exc})"
    failed = [x for x in refits if isinstance(x, str)]
    if failed:
        lagged = not any(isinstance(x, str) for x in refits[:2])
        return f"{'fails with the torque moved by the declared lag' if lagged else 'failed'} ({failed[0]})"
    return refits


def _unsteady_torque_at(torque: np.ndarray, sb: int, k_pre: int, k_search: int) -> str:
    """Why m_el is not a steady drive's at the steady-entry fit's entry row ``sb`` ('' when it is): it must be steady
    right up to it (a speed controller acting just before it is not: its last ``k_search`` samples within 5 robust
    noise levels, or 1e-3 of the level, of the steady stretch's median) and stay near its level through the first
    samples after it (a machine on line: the flux is continuous; a speed controller reacting to an event moves it at
    once, and the kink is then the event)."""
    ref = torque[max(0, sb - k_pre):sb - k_search]
    last = torque[sb - k_search:sb]
    level = float(_median(np.asarray(ref, float)))
    tol = max(5.0 * _robust_noise(ref), 1e-3 * abs(level))
    if float(np.abs(last - level).max()) > tol:
        return (f"the torque changes in the {k_search} samples before the entry row {sb} "
                f"(by {float(np.max(np.abs(last - level))):.3g} N m): not a steady drive's entry")
    first = torque[sb:sb + k_search]
    if float(np.abs(first - level).max()) > max(tol, KINK_TORQUE_AFTER_REL * abs(level)):
        return (f"the torque moves by {float(np.max(np.abs(first - level))):.3g} N m in the {k_search} samples after "
                f"the entry row {sb}: not a steady drive's entry")
    return ""


#: Steady-entry fit: its entry row within this many samples (at 2 kHz; converted by stream/rate.py) of the free fit's
#: and of the detector's (chosen on our simulator's zoo windows with the detector's entry moved by -3..+3 samples:
#: |difference| <= 4 and <= 3; tested on the vector drive: its heavy load reversal's wrong kinks lie 13-15 and 10-16
#: samples off)
KINK_FREE_AGREE_SAMPLES = 6
#: The steady-entry fit is taken only where its difference from the free fit is within this many standard errors of
#: that difference (Hausman's test of its premise, :func:`_anchored_angle`): the two-sided 5 % point of the normal,
#: not tuned (the DOL drive with the detector's entry 6-12 samples early: the steady-entry fit +4 … +10 %, its
#: interval missing the truth, 2.0-2.8 such standard errors from the free fit).
KINK_PREMISE_Z = 1.96
#: Steady-entry fit: the torque may move by at most this fraction of its level in the first samples after the
#: entry (our simulator: 0.3 %; the stress bench's speed step: 100 % within 2 samples).
KINK_TORQUE_AFTER_REL = 0.02


#: The model choice's phrase of an angle fit that took the steady-entry fit (:func:`_anchored_angle`).
STEADY_ENTRY_CHOICE = "angle (steady entry)"
#: With a1 beside the encoder: the steady-entry fit's entry is checked by the motor equation over this many rows after
#: it -- their mean torque residual J1 a1/r - (m_el - b1 w1) within STEADY_ENTRY_A1_Z of its noise (_robust_noise of the
#: pre-entry rows) plus the declared torque offset and Coulomb bands and the torque accuracy.  A slowly
#: unloading contact, which m_el and the angle cannot show, leaves its torque there: the vector drive with a light
#: load (zoo_variants, J2 x 0.3), heavy load reversal at 30 dB: -86 N m in the first 4 rows (z = 32), the fit's entry 8
#: samples early and J1 +9.8 % published as another class.  No other window of the zoo or the variants took the
#: steady-entry fit with a1 (chosen on that one; the rule cannot change any other published window of either).  The
#: fit's own J1 uncertainty is part of the allowance (our simulator's noise-free entries: up to 2.2 of it).
STEADY_ENTRY_A1_ROWS = 4
STEADY_ENTRY_A1_Z = 5.0


def steady_entry_contact(window: dict, g: GapEstimate, b1: float, wheel_radius_m: float, model: GapModel):
    """None when a1 shows free motion right after a steady-entry fit's entry row (or there is nothing to check),
    else the reason (one line): the motor equation leaves a contact torque there."""
    if STEADY_ENTRY_CHOICE not in (g.model_choice or "") or "a1" not in window or g.fit_start < 2:
        return None
    s, k = int(g.fit_start), STEADY_ENTRY_A1_ROWS
    net = _net_torque(window, b1)
    res = g.inertia_kgm2 * np.asarray(window["a1"], float) / wheel_radius_m - net
    pre = res[max(0, s - 200):s]
    if pre.size < 8 or s + k > res.size:
        return None
    noise = _robust_noise(pre)
    mean = float(np.mean(res[s:s + k]))
    level = float(np.mean(np.abs(net[s:s + k])))
    # the fit's own J1 uncertainty moves the residual by (se/J1) |net|: our simulator's noise-free steady entries
    # leave up to 2.2 of those (jident evaluate's encoder sweep, 336 windows), a contact still loaded far more
    allowed = (STEADY_ENTRY_A1_Z * (noise / np.sqrt(k) + g.std_error_kgm2 / g.inertia_kgm2 * level)
               + model.torque_offset_nm + model.coulomb_friction_max_nm + model.torque_rel_se() * np.sqrt(3.0) * level)
    if abs(mean) <= allowed:
        return None
    return (f"a1 contradicts the angle fit's steady entry at row {s}: the motor equation leaves {mean:.3g} N m in its "
            f"first {k} rows (> {allowed:.3g} N m: noise and the declared torque bands), a contact still loaded")


#: With a1 beside the encoder: where the angle fit's change point puts the entry more than the a1 fit's own trim
#: (:func:`gap_only_max_trim`) after the a1 fit's first row, the rows between are tested by the motor equation: J1 and a
#: constant (the friction and offset both stretches share) fitted to a1 over the angle fit's rows, the rows' mean load
#: torque (m_el − b1 ω1 − J1 a1/r − the constant) beyond A1_ROWS_CONTACT_Z times its noise and that J1's error times the
#: acceleration's lever, plus the torque accuracy, is a contact still loaded, and the a1 fit is made again from the
#: angle fit's entry.  DOL d16-12 (a soft coupling's loaded rest before a slip reversal's traversal, the detector's entry
#: 49 early): the a1 fit over 44 loaded rows gave +8.2 % outside its interval, cross-checked at 2.7 standard errors; the
#: rows' load torque 15-25 N m against the gap's 5.  The z is the steady-entry a1 check's (STEADY_ENTRY_A1_Z, 5), not
#: tuned.
A1_ROWS_CONTACT_Z = STEADY_ENTRY_A1_Z
#: Set False to leave the a1 fit on the detector's rows whatever the angle fit's change point says.
A1_ROWS_FROM_ANGLE = True


def a1_rows_contact(window: dict, a1_fit: GapEstimate, angle_fit: GapEstimate, b1: float, wheel_radius_m: float,
                    model: GapModel, sample_period_s: float) -> str | None:
    """None when the a1 fit's rows before the angle fit's change-point entry are free (or there is nothing to
    check: the angle fit's entry within the a1 fit's own trim), else the reason (one line): the motor equation with
    the angle fit's J1 leaves a contact torque there."""
    s0, s1 = int(a1_fit.fit_start), int(angle_fit.fit_start)
    e1 = min(int(angle_fit.fit_end), int(a1_fit.fit_end))
    if not A1_ROWS_FROM_ANGLE or s1 - s0 <= gap_only_max_trim(model, sample_period_s)[0] or e1 - s1 < 8:
        return None
    net = _net_torque(window, b1)
    acc = np.asarray(window["a1"], float) / wheel_radius_m
    # J1 and a constant (friction and offset) from the a1 over the angle fit's rows, by least squares
    design = np.column_stack([acc[s1:e1], np.ones(e1 - s1)])
    coef, *_ = np.linalg.lstsq(design, net[s1:e1], rcond=None)
    if not coef[0] > 0:
        return None
    free = net[s1:e1] - design @ coef
    noise = float(np.sqrt(float(free @ free) / max(free.size - 2, 1)))
    j_se = noise * float(np.sqrt(np.linalg.pinv(design.T @ design)[0, 0]))
    diff = float(np.mean(net[s0:s1] - coef[0] * acc[s0:s1] - coef[1]))
    k = s1 - s0
    level = float(np.mean(np.abs(net[s0:s1])))
    lever = abs(float(np.mean(acc[s0:s1]) - np.mean(acc[s1:e1])))
    allowed = (A1_ROWS_CONTACT_Z * (noise * np.sqrt(1.0 / k + 1.0 / free.size) + j_se * lever)
               + model.torque_rel_se() * np.sqrt(3.0) * level)
    if abs(diff) <= allowed:
        return None
    return (f"the a1 fit's rows {s0}..{s1} before the angle fit's entry carry {diff:.3g} N m more load than the gap's "
            f"(> {allowed:.3g} N m: noise, the J1 of a1 over the angle fit's rows and the torque accuracy), a contact "
            f"still loaded")


def _angle_fit(alpha1: np.ndarray, m_el: np.ndarray, start: int, end: int, sample_period_s: float,
               linear_term: bool = False):
    """(J1, standard error, residual [rad], dof, model error) of the 'angle' fit (module docstring).

    ``m_el``: the torque over [0, end) (bearing friction already taken off).  Two linear
    least-squares steps:

    1. the torque model of the joint fit, m0 before the entry and m0 + c2 τ² + c3 τ³ in
       the gap (τ = time since the entry over the gap length; no c3 below GAP_CUBIC_MIN
       samples; a c1 τ term too with ``linear_term``), fitted to the pre-entry and gap
       m_el samples: the level m0 comes from all of them, and the noise of single
       samples does not reach the double integral;
    2. α1 against (1, t, Z) over the same samples, Z(t) the double integral of the
       fitted torque from the entry (exact for the polynomial, 0 before the entry),
       centred on the entry sample.

    Standard error of 1/J1: the least-squares one of step 2 (noise on α1) and the effect
    of the torque coefficients' covariance through Z, in quadrature; then the model error
    (|J1 with the linear torque term − J1|) in quadrature, as for the joint fit; at least
    ANGLE_REL_SE_FLOOR · J1.
    """
    ng = end - start
    duration = ng * sample_period_s
    tg = np.arange(ng) * sample_period_s
    powers = _torque_powers(ng, linear_term)
    G = np.zeros((end, 1 + len(powers)))      # torque model rows: [1, τ^p ...] (τ = 0 before the entry)
    H = np.zeros((end, 1 + len(powers)))      # their double integrals from the entry
    G[:, 0] = 1.0
    H[start:, 0] = tg ** 2 / 2.0
    for k, q in enumerate(powers, start=1):
        G[start:, k] = (tg / duration) ** q
        H[start:, k] = tg ** (q + 2) / ((q + 1) * (q + 2) * duration ** q)
    beta, *_ = np.linalg.lstsq(G, m_el[:end], rcond=None)
    r_m = m_el[:end] - G @ beta
    dof_m = end - G.shape[1]
    cov_beta = float(r_m @ r_m) / max(dof_m, 1) * np.linalg.pinv(G.T @ G)
    A = np.column_stack([np.ones(end), (np.arange(end) - start) * sample_period_s, H @ beta])
    y = alpha1[:end] - alpha1[start]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ coef
    dof = end - 3
    kappa = float(coef[2])     # 1/J1
    if not kappa > 0 or dof < 1:
        raise NoGapError(f"gap fit gave a non-physical 1/J1 = {kappa:.4g} from alpha1")
    row = np.linalg.pinv(A)[2]
    zrow = row @ H
    var_kappa = float(res @ res) / dof * float(row @ row) + kappa ** 2 * float(zrow @ cov_beta @ zrow)
    j = 1.0 / kappa
    model_error = 0.0
    if not linear_term:
        j_lin = _angle_fit(alpha1, m_el, start, end, sample_period_s, linear_term=True)[0] \
            if ng >= 4 else j
        model_error = abs(j_lin - j)
    se = float(np.hypot(np.sqrt(max(var_kappa, 0.0)) / kappa ** 2, model_error))
    return j, max(se, ANGLE_REL_SE_FLOOR * j), res, max(dof_m - 3, 1), model_error


def angle_over_rows(window: dict, rows: tuple, bearing_friction_nms_per_rad: float, sample_period_s: float,
                    model: GapModel):
    """(J1, its standard error (every term), its terms {name: kg m^2}), kg m^2, of the free angle fit over exactly
    ``rows`` (start, end exclusive; no change-point search, no steady-entry fit), or None where the rows cannot hold
    one (too few): gap._cross_checked's check of a disagreement over the a1 fit's own rows."""
    if "alpha1" not in window or rows[1] - rows[0] < 1:
        return None
    try:
        ff = free_angle_fit(np.asarray(window["alpha1"], float), _net_torque(window, bearing_friction_nms_per_rad),
                            sample_period_s, int(rows[0]), int(rows[1]), model, fixed=True)
    except (FreeFitError, np.linalg.LinAlgError):
        return None
    j = float(ff["j1"])
    return (j, float(ff["se"]), dict(ff["terms"])) if np.isfinite(j) and j > 0 else None


def _method_angle(window: dict, rows: tuple, drive: tuple, model: GapModel) -> FitState:
    """gap._estimate_inertia's 'angle' fit around ``rows`` (start, end: its change points are searched around them):
    the free angle fit, or the steady-entry fit where :func:`_anchored_angle` takes it, inside the load side's free
    bounds (gap_load.py); ``choice``: their phrases for the model choice.  ``drive``: (r, b1, T_s)."""
    (start, end), (_, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    choice = ""
    if "alpha1" not in window:
        raise NoGapError("method 'angle' needs alpha1 (use 'speed' with omega1)")
    torque = _net_torque(window, bearing_friction_nms_per_rad)
    search = model.search_rows(sample_period_s)
    bounds = load_free_bounds(window.get(LOAD_ANGLE_KEY, window.get("alpha2")), start, end, search)
    ff, anchored = _angle_fits(np.asarray(window["alpha1"], float), torque, sample_period_s, start, end, model,
                               bounds)
    if bounds is not None and (bounds[0] > start - search or bounds[1] < end + search):
        choice = "; ".join(x for x in (choice, f"the load angle free in rows {bounds[0]}..{bounds[1]}") if x)
    j, se, res, dof = ff["j1"], ff["se_stat"], ff["residual"], ff["dof"]
    model_error = ff["change_point_error"]
    fit_span = (ff["start"], ff["end"])
    free_extra = {"change_point_error_kgm2": ff["change_point_error"], "friction": ff["friction"],
                  "std_error_terms": tuple((k, float(v)) for k, v in ff["terms"].items())}
    choice = "; ".join(x for x in (choice, anchored.pop("choice")) if x)
    if not anchored and model.coulomb_friction_max_nm:
        free_extra["trend_fit"] = _angle_trend_refit(window["alpha1"], torque, sample_period_s, ff)
    if anchored:
        j, se, res, dof, model_error = (anchored[k] for k in ("j1", "se", "res", "dof", "model_error"))
        free_extra["std_error_terms"] = tuple(anchored["terms"].items())
        free_extra["change_point_error_kgm2"] = float(anchored["terms"]["change_points"])
        free_extra["friction"] = (f"bounded (F_c in [0, {model.coulomb_friction_max_nm:.3g}] N m, a term)"
                                  if model.coulomb_friction_max_nm else "none declared")
        fit_span = anchored["span"]
    encoder_resolved(window["alpha1"], torque, fit_span, j, sample_period_s)
    return FitState(j, se, res, dof, model_error, fit_span, free_extra, choice)
