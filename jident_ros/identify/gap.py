"""J1 from the backlash gap itself: while the drive is inside the zone the load
moment is zero, so the motor side is a single mass,

    J1 dω1/dt = m_el − b1 ω1          (b1 = bearing friction, 0 in the paper's model)

and J1 follows from signals the window already holds, by least squares over the
gap samples.  Plain numpy/scipy; never imports rclpy.

Gap interval
------------
* ``"angles"``: when α1 and α2 are measured, the gap is the first run of
  samples from the entry sample on with |α1 − α2| < K2/r (inequality 1).
* ``"signature"``: with no angles, the gap ends at the first sample after the
  entry where the load moment reappears.  In the gap, m_el/a1 = J1/r is constant;
  the flank impact makes a1 drop sharply while m_el cannot (the flux is
  continuous), so the gap ends where a1 falls below ``drop`` (default 0.6) times
  a1 at the entry sample; the sample just before that drop is left out too (the
  impact happens between samples).  Drives without a1 use the same test on the
  smoothed second derivative of α1 (a motor encoder) or, failing that, on the
  smoothed derivative of ω1 (Savitzky-Golay, 7 samples, quadratic).

Fits
----
* ``"acceleration"`` (a1 and m_el measured; the default): one weighted least-squares
  fit of both channels together.  Before the entry the drive is in steady state, so
  m_el = m0 there; through the gap m_el is smooth and, because its slope is continuous
  at the entry (the fluxes and ω1 are), it starts with zero slope:
  m_el(t) = m0 + c2 τ^2 + c3 τ^3 (τ = time since the entry over the gap length), and
  a1(t) = (r/J1) m_el(t).  The pre-entry m_el samples, the gap m_el samples and the gap
  a1 samples are fitted together for (r/J1, m0, c2, c3), each channel weighted by its
  noise variance measured on the 48 pre-entry samples (a1 = 0 there).  The a1 samples,
  whose noise is small relative to their gap value, fix the torque's shape; the m_el
  samples before and inside the gap fix its level — so the level is no longer
  anchored on the 48 pre-entry samples alone (docs/method.md, "Gap estimator").
  Uncertainty: covariance of the least-squares solution with each channel's residual
  variance (robust to a wrong noise ratio), plus, in quadrature, the change of J1 when
  the torque model gets a linear term too (the model-form error).
* ``"gap_only"`` (a1 and m_el measured; no assumption about the drive before the entry):
  over the in-zone samples only, m_el − b1 ω1 = J1 a1/r sample by sample, the torque taken as
  measured (no torque model, no pre-entry anchoring).  Both sides are noisy, so J1 is the
  errors-in-variables (Deming) slope through the origin with the two noise levels measured on
  the window (robust scale of second differences).  The in-zone sample set comes from the
  dynamics: the interval's end samples whose load torque m_el − b1 ω1 − J1 a1/r is not zero
  within its noise (GAP_ONLY_TRIM_SIGMA) are dropped — an entry found a sample or two early, or a
  re-contact row one late, does not bias J1.  Uncertainty: the residual standard error, and in
  quadrature the model error, the change of J1 when one more sample is dropped at each end of the
  in-zone set.
* ``"auto"`` (``method=None`` with a1 in the window; the default): the **model choice**.  The joint
  fit's assumption, a steady torque before the entry, is tested on the pre-entry m_el samples
  (:func:`pre_entry_steady`: a quadratic in time against a constant, F test).  Steady: the joint
  fit (``"acceleration"``); not steady (e.g. a speed controller swinging the torque just before
  the entry): ``"gap_only"``.  The estimate's ``model_choice`` says which and why.
* ``"anchored"`` (the estimator of the first release, kept for comparison): m0 = the
  pre-entry mean (of m_el − b1 ω1, as in the gap), m_el ≈ m0 + b t + c t^2 fitted over the gap,
  then a1 = (r/J1) m_hat through the origin.  Uncertainty: the least-squares one of r/J1 (its
  relative variance is J1's), and in quadrature m_hat's error carried to J1 by the delta method.
* ``"angle"`` (α1 and m_el measured: a motor encoder and the drive's torque, no
  accelerometer): double-integral form, no differentiation.  Before the entry the
  motor turns at a constant speed, inside the gap J1 dω1/dt = m_el, so over the
  pre-entry and gap samples α1(t) = α0 + ω0 t + Z(t)/J1 with Z the double integral of
  m_el from the entry (0 before it).  m_el is first fitted with the joint fit's torque
  model (m0, then m0 + c2 τ² + c3 τ³ in the gap), Z is its exact double integral, and
  ordinary least squares give (α0, ω0, 1/J1); the torque fit's covariance and the
  model error go into the uncertainty.  An encoder's quantisation error on a steadily
  turning shaft is a deterministic sawtooth, not white noise: below ~2^18 counts/rev
  the interval is too narrow (docs/method.md).
* ``"speed"`` (ω1 and m_el measured, no accelerometer): integral form, no
  differentiation: ω1_k = ω1_0 + (1/J1) ∫_{t0}^{tk} m_el dt, ω1 regressed on the integral
  (:func:`speed_fit`: the noisy speed is the regressand; the residual's autocorrelation
  and the interval's end rows go into the uncertainty).
All report J1, its standard error, a 95 % confidence interval (Student t) and the
residual RMS.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from jident_ros.identify import lapack
from jident_ros.identify.distributions import t_quantile
from jident_ros.identify.gap_a1 import (  # noqa: F401  (re-exported)
    GAP_CUBIC_MIN,
    GAP_ONLY_MAX_TRIM,
    GAP_ONLY_REL_SE_FLOOR,
    GAP_ONLY_TRIM_REL,
    GAP_ONLY_TRIM_SIGMA,
    JOINT_FIT_MAX_ITER,
    JOINT_FIT_TOL,
    JOINT_NOISE_FLOOR_REL,
    TRIM_PERSIST,
    _a1_contact_rows,
    _constant_fit,
    _free_level,
    _gap_only_constant,
    _joint_constants,
    _joint_design,
    _joint_fit,
    _nonpositive_slope,
    _origin_slope,
    _robust_noise,
    _shape_terms,
    _std_ddof1,
    _torque_powers,
    gap_only_fit,
    gap_only_max_trim,
)
from jident_ros.identify.gap_cross import (  # noqa: F401  (re-exported)
    COMMON_TORQUE_TERMS,
    CROSS_CHECK_Z,
    DRIVE_CONSTANT_TERMS,
    _difference_se,
    _stat_se,
    _trend_choice,
    within_drive_se,
)
from jident_ros.identify.gap_free import (
    FREE_REL_SE_FLOOR,
    FreeFitError,
    GapModel,
    free_angle_fit,
)
from jident_ros.identify.gap_interval import _savgol_7_2, _savgol_for_gap, gap_interval  # noqa: F401  (re-exported)
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
from jident_ros.identify.gap_lag import LAG_MAX_FRACTION, LAG_MIN_SAMPLES, LAG_Z, torque_lag_estimate
from jident_ros.identify.gap_load import LOAD_ANGLE_KEY, load_free_bounds
from jident_ros.identify.gap_numerics import (  # noqa: F401  (fit_cache re-exported)
    FIT_MEMO,
    _ar1_inflation,
    _cumtrapz,
    _diff2,
    _median,
    _memoised,
    _quantum,
    fit_cache,
    window_memo,
)
from jident_ros.identify.gap_speed import SPEED_TRIM_SAMPLES, speed_fit  # noqa: F401  (re-exported)
from jident_ros.identify.gap_steady import STEADY_P_VALUE, STEADY_REL_TOL, SteadinessTest, _steady_design, pre_entry_steady  # noqa: F401  (re-exported)
from jident_ros.identify.gap_types import GapEstimate, NoGapError, _net_torque  # noqa: F401  (re-exported)
from jident_ros.identify.gap_width import (  # noqa: F401  (re-exported)
    CONTACT_FIT_PREFERENCE,
    CONTACT_FIT_REL_FLOOR,
    CONTACT_FIT_SAMPLES,
    WidthEstimate,
    estimate_backlash_width,
)
from jident_ros.stream.flank import disc_corrected
from jident_ros.stream.rate import samples as rate_samples

#: 'anchored' fit: gaps shorter than this fit m_el with a straight line (fewer free parameters).
GAP_QUADRATIC_MIN = 12

#: 'angle' fit: relative floor of the standard error.  The torque model's own error (noise-free,
#: grid: up to 0.03 % of J1) is not always seen by the model-error term; without the floor a
#: noise-free window could be flagged 'between classes' at 4e-5 off its class.
ANGLE_REL_SE_FLOOR = 2e-4

#: A gap fit whose standard error exceeds this fraction of J1 is refused (NoGapError): such a
#: window carries no free acceleration (e.g. a steady state mistaken for an entry).
MAX_RELATIVE_STD_ERROR = 0.25

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


#: Fits of :func:`estimate_inertia` (None = the model choice, 'auto').
FITS = ("acceleration", "gap_only", "anchored", "angle", "speed")


#: Why a shallow gap's window (stream.layout.FLAG_SHALLOW_GAP) gets no gap fit (identify.diagnosis).  The flank
#: detector keeps these windows for their entry and K2 (stop 34, round 18: the DOL draws' slip drops, 2-12 samples);
#: the gap fits' change-point search (25 rows at 2 kHz) is longer than such a gap, and where the slipping load moves
#: with the motor after the re-contact the fit ran on through 25 contact rows: DOL draws set 6's d6-12 (a 4-sample
#: gap) published J1 +19 % on three inputs outside their intervals.
SHALLOW_GAP_REASON = ("gap too short: a shallow gap (the motor ran only a few samples past the coupling's zero twist, a "
                      "slip drop's short gap): its entry and K2 are reported, no J1 (the gap fits cannot tell so few "
                      "free rows from the motor moving the slipping load)")

#: Why a short bounce's window that holds another entry (stream.layout.FLAG_BOUNCE and FLAG_SECOND_ENTRY: the
#: excursion came back toward the flank it left, no traversal, then went on to another entry inside the window) gets
#: no gap fit (identify.diagnosis), formatted with its rows and the change-point search's.  A traversal shows by its
#: geometry that the coupling let go (delta crossed the zone); a bounce shows it only by the motor's own fit, and over
#: fewer rows than the fit's change-point search that fit cannot tell a free motor from one still held by a swinging
#: coupling.  DOL draws set 8's d8-02 (a soft coupling, k 3.1e4 N m/rad, in a slip reversal) swung back 0.7 mrad
#: short of the zone, 40 samples before its gap; the detector saw a bounce of 9 rows (19 with an Imu), the crossing
#: after it a window of its own, and the gap stage published J1 +24 ... +34 % on three inputs, outside their
#: intervals.  Every short bounce without the second entry was tried: it also took the J1 of the DOL zoo's slip drops
#: (their only window, within 2.4 %) and 1-11 on each of DOL draws sets 1-5 (docs/results.md, "Stop 35").
SHORT_BOUNCE_REASON = ("gap too short: a bounce of {rows} rows that goes on to another entry in its window is shorter "
                       "than the gap fit's change-point search ({search} rows): the fit cannot tell free rows from the "
                       "coupling's swing before that crossing (which has a window of its own)")

#: How a NoGapError's message starts when the window's gap is there but cannot resolve J1 (too few samples in it,
#: a standard error above MAX_RELATIVE_STD_ERROR): a fact about this window, not about the monitor's configuration
#: or sensors (:func:`resolution_limited`).
RESOLUTION_REASONS = ("gap too short", "gap fit undetermined")


def resolution_limited(reason: str) -> bool:
    """Whether a gap failure (a NoGapError's message) says only that this window cannot resolve J1: every fit tried
    (the cross-check's "a1 fit: ...; angle fit: ...") failed for one of RESOLUTION_REASONS."""
    text = str(reason)
    if text.startswith("a1 fit: ") and "; angle fit: " in text:
        parts = text[len("a1 fit: "):].split("; angle fit: ", 1)
    else:
        parts = [text]
    return all(p.startswith(RESOLUTION_REASONS) for p in parts)


def estimate_inertia(window: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                     sample_period_s: float, method: str | None = None,
                     bearing_friction_nms_per_rad: float = 0.0, recontact_index: int | None = None,
                     entry_uncertainty_samples: int = 0, model: GapModel | None = None,
                     cross_check: bool = True) -> GapEstimate:
    """Least-squares J1 over the gap (:func:`_estimate_inertia`, whose arguments these are), with the torque's lag
    checked against the drive's declaration (:func:`_lag_beyond_declared`) on the free angle fit: where the motor angle
    shows the torque estimate lagging by more than the declared ``model.torque_lag_s``, the fits are made again
    with the lag the data show, and the model_choice says so.  Raises :class:`NoGapError` with a reason."""
    model = GapModel() if model is None else model
    if "m_el" not in window:
        raise NoGapError("no electromagnetic torque: the gap fit needs m_el")
    window = _delay_taken_off(window, model.torque_delay_s, model.torque_filter_s, sample_period_s)
    window, disc = _disc_taken_off(window, sample_period_s)
    try:
        with window_memo():       # the lag check and the cross-check fit the same rows again: decisions kept
            est = _lag_checked((window, entry_index, backlash_width_m, wheel_radius_m, sample_period_s, method,
                                bearing_friction_nms_per_rad, recontact_index, entry_uncertainty_samples), model,
                               cross_check)
    except NoGapError as exc:
        raise NoGapError(f"{exc}; {disc}" if disc else str(exc)) from None
    return replace(est, model_choice=f"{est.model_choice or est.method}; {disc}") if disc else est


def _delay_taken_off(window: dict, delay_s: float, filter_s: float, sample_period_s: float) -> dict:
    """The window with the drive's declared known delay and smoothing of m_el undone (GapModel.torque_delay_s: m_el(t +
    delay), by linear interpolation, its last value held; GapModel.torque_filter_s τ: m_el + τ·dm_el/dt, central
    differences, the first-order low-pass's inverse): ``window`` itself without them.  A torque reported late while it
    ramps through the gap reads as inertia: the DOL draws (set 7: the estimate a sample late and smoothed by up to
    0.5 ms) published J1 +3 … +6 % off with them only bounded (docs/results.md, stop 34)."""
    if not (delay_s or filter_s):
        return window
    m = np.asarray(window["m_el"], float)
    if delay_s:
        k = np.arange(m.size, dtype=float)
        m = np.interp(k + float(delay_s) / float(sample_period_s), k, m)
    if filter_s and m.size > 1:
        m = m + float(filter_s) * np.gradient(m, float(sample_period_s))
    return dict(window, m_el=m)


def _disc_taken_off(window: dict, sample_period_s: float) -> tuple:
    """(the window with the motor encoder's disc error taken off alpha1, a phrase saying so), or (window, '') where
    alpha1 shows none: jident_ros.stream.flank.disc_corrected, once and twice per revolution, fitted over the
    window's last rows where the drive turns steadily (the contact after the event: several revolutions).  A
    resolver-grade angle error (1 and 0.5 mrad) left undeclared bent the gap's angle: J1 5.9-6.5 % off with
    intervals that covered 2 of 4 (zoo_variants, stop 27); the declared encoder_accuracy_rad term stays."""
    if "alpha1" not in window:
        return window, ""
    alpha1, coef = disc_corrected(window["alpha1"], sample_period_s)
    if coef is None:
        return window, ""
    a1, a2 = float(np.hypot(coef[0], coef[1])), float(np.hypot(coef[2], coef[3]))
    return dict(window, alpha1=alpha1), (f"the motor encoder's disc error ({a1 * 1e6:.0f} and {a2 * 1e6:.0f} µrad "
                                         f"once and twice per revolution, fitted over the window's last rows) "
                                         f"taken off alpha1")


def _lag_checked(args: tuple, model: GapModel, cross_check: bool) -> GapEstimate:
    """:func:`_estimate_inertia` with the torque's lag checked against the declared one (:func:`estimate_inertia`);
    ``args``: its arguments up to ``entry_uncertainty_samples``."""
    window, method, bearing_friction_nms_per_rad, sample_period_s = args[0], args[5], args[6], args[4]
    if (method is None or method == "auto") and "a1" in window and "alpha1" in window and cross_check:
        return _cross_checked(args[:5], bearing_friction_nms_per_rad, args[7], args[8], model)
    est = _estimate_inertia(*args, model=model, cross_check=cross_check)
    lag = _lag_beyond_declared(window, bearing_friction_nms_per_rad, est, sample_period_s, model) \
        if est.method == "angle" else None
    if lag is None:
        return est
    try:
        again = _estimate_inertia(*args, model=replace(model, torque_lag_s=lag[0]), cross_check=cross_check)
    except NoGapError as exc:
        raise NoGapError(f"{exc}; {lag[1]}") from None
    return _lag_noted(again, lag[1])


def _lag_noted(est: GapEstimate, note: str) -> GapEstimate:
    """``est`` (fitted with the lag the data show) with ``note`` in its model_choice and its lag term named as the lag
    the angle shows ('torque_lag_seen': the data's, not the declaration's)."""
    terms = tuple(("torque_lag_seen" if k == "torque_lag" else k, v) for k, v in est.std_error_terms)
    return replace(est, model_choice=f"{est.model_choice or est.method}; {note}", std_error_terms=terms)


def _lag_beyond_declared(window: dict, b1: float, fit: GapEstimate, sample_period_s: float,
                         model: GapModel) -> tuple | None:
    """(the lag bound the data call for, s; the phrase saying so) when the motor angle over ``fit``'s rows shows the
    torque estimate lagging (or leading) by more than the declared ``model.torque_lag_s`` (:func:`torque_lag_estimate`:
    |τ̂| more than LAG_Z of its standard errors and LAG_MIN_SAMPLES sample periods above it, and at most
    LAG_MAX_FRACTION of the rows' duration: a drive's smoothed 'actual torque' its user did not declare); None
    otherwise.  The bound is |τ̂| + 1.96 se: the interval holds the lag the data show, not only the one declared."""
    tau, se_tau = torque_lag_estimate(window["alpha1"], _net_torque(window, b1), sample_period_s,
                                      fit.fit_start, fit.fit_end, 0.5 * float(model.coulomb_friction_max_nm))
    declared = float(model.torque_lag_s)
    duration = (fit.fit_end - fit.fit_start) * sample_period_s
    if not (np.isfinite(tau) and abs(tau) - declared > max(LAG_Z * se_tau, LAG_MIN_SAMPLES * sample_period_s)
            and abs(tau) <= LAG_MAX_FRACTION * duration):
        return None
    bound = abs(tau) + 1.96 * se_tau
    return bound, (f"the torque lags the motor angle by {tau * 1e3:.3g} ± {se_tau * 1e3:.2g} ms over rows "
                   f"{fit.fit_start}..{fit.fit_end}, beyond the declared {declared * 1e3:g} ms "
                   f"(torque_lag_max_s; docs/your_drive.md): the interval takes {bound * 1e3:.3g} ms")


def _trend_finished(j: float, se: float, terms: dict, model: GapModel) -> tuple:
    """A trend fit (GapEstimate.trend_fit) as the published fits end: the model's floor, then the torque accuracy."""
    terms = dict(terms)
    if float(se) < FREE_REL_SE_FLOOR * j:
        terms["model_floor"] = float(np.sqrt((FREE_REL_SE_FLOOR * j) ** 2 - float(se) ** 2))
        se = FREE_REL_SE_FLOOR * j
    if model.torque_accuracy:
        terms["torque_accuracy"] = j * model.torque_rel_se()
        se = float(np.hypot(se, terms["torque_accuracy"]))
    return float(j), float(se), tuple((k, float(v)) for k, v in terms.items())


def _estimate_inertia(window: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                      sample_period_s: float, method: str | None = None,
                      bearing_friction_nms_per_rad: float = 0.0, recontact_index: int | None = None,
                      entry_uncertainty_samples: int = 0, model: GapModel | None = None,
                      cross_check: bool = True) -> GapEstimate:
    """Least-squares J1 over the gap, the drive's declared lag taken as it is (:func:`estimate_inertia` checks it);
    raises :class:`NoGapError` with a reason.  ``recontact_index``: see :func:`gap_interval`.
    ``entry_uncertainty_samples`` k > 0: the entry row is known only to +-k samples
    (the dynamics detector without a1); J1 is refitted with the entry moved by -k and +k and the larger change
    is added to the standard error in quadrature (as a model error), so that a fit that depends on the entry
    row is refused or its interval widened, never published narrow.  ``method``: one of :data:`FITS`, or None /
    'auto' for the model choice (the module docstring): with a1, the joint fit when the pre-entry m_el is steady
    (:func:`pre_entry_steady`), else 'gap_only'; without a1, 'angle' (α1) or 'speed'.  ``model``: the
    drive's torque accuracy and friction band (:class:`~jident_ros.identify.gap_free.GapModel`; default: exact
    torque, no friction band): the torque-accuracy term J1 a/sqrt(3) goes into every fit's standard error.
    ``cross_check`` (the model choice with a1 and alpha1): the a1 fit and the free angle fit, cross-checked
    (:func:`_cross_checked`); False: the a1 fit's model choice alone."""
    model = GapModel() if model is None else model
    if "m_el" not in window:
        raise NoGapError("no electromagnetic torque: the gap fit needs m_el")
    if (method is None or method == "auto") and "a1" in window and "alpha1" in window and cross_check:
        return _cross_checked((window, entry_index, backlash_width_m, wheel_radius_m, sample_period_s),
                              bearing_friction_nms_per_rad, recontact_index, entry_uncertainty_samples, model)
    start, end, how = gap_interval(window, entry_index, backlash_width_m, wheel_radius_m,
                                   recontact_index=recontact_index)
    m = _net_torque(window, bearing_friction_nms_per_rad)[start:end]
    choice = ""
    fit_span = (start, end)
    free_extra: dict = {}
    gap_only = None                  # the 'gap_only' fit where the model choice has already made it
    if method is None or method == "auto":
        method = None
        if "a1" in window:
            test = pre_entry_steady(np.asarray(window["m_el"], float)[:start])
            method = "acceleration" if test.steady else "gap_only"
            choice = test.describe()
            if test.steady:
                contact, in_zone = _a1_contact_rows(window, start, end, wheel_radius_m, bearing_friction_nms_per_rad,
                                                    model, sample_period_s)
                if contact:          # its gap-only fit is the one the 'gap_only' branch below would make again
                    method, choice, gap_only = "gap_only", f"gap_only: {contact}", in_zone
        else:
            method = "angle" if "alpha1" in window else "speed"
            choice = f"{method}: no a1 in the window"
    n = end - start
    model_error = 0.0
    if method == "gap_only":
        if "a1" not in window:
            raise NoGapError("method 'gap_only' needs a1 (use 'speed' with omega1)")
        mf = _net_torque(window, bearing_friction_nms_per_rad)
        fit = gap_only if gap_only is not None else gap_only_fit(
            mf, np.asarray(window["a1"], float) / wheel_radius_m, start, end,
            max_trim=gap_only_max_trim(model, sample_period_s))
        j, se, res, dof, model_error = fit["j1"], fit["se"], fit["residual"], fit["dof"], fit["model_error"]
        fit_span = (fit["start"], fit["end"])
    elif method == "acceleration":
        if "a1" not in window:
            raise NoGapError("method 'acceleration' needs a1 (use 'speed' with omega1)")
        friction = None
        if bearing_friction_nms_per_rad and "omega1" in window:
            friction = bearing_friction_nms_per_rad * np.asarray(window["omega1"], float)[start:end]
        fit = _joint_fit(np.asarray(window["m_el"], float), np.asarray(window["a1"], float), start, end, friction)
        kappa = fit["kappa"]
        if not kappa > 0:
            raise NoGapError(f"gap fit gave a non-physical a1/m_el ratio {kappa:.4g}")
        j = wheel_radius_m / kappa
        alt = _joint_fit(np.asarray(window["m_el"], float), np.asarray(window["a1"], float), start, end, friction,
                         linear_term=True, warm=fit, kappa_only=True)
        model_error = abs(wheel_radius_m / alt["kappa"] - j) if alt["kappa"] > 0 else np.inf
        se = float(np.hypot(wheel_radius_m / kappa ** 2 * fit["kappa_se"], model_error))
        res = fit["a1_residual"] / kappa
        dof = fit["dof"]
    elif method == "anchored":
        # m_el is smooth through the gap (the fluxes are continuous) and constant before
        # the entry (steady state): anchor it with the pre-entry mean and a quadratic in
        # time over the gap, then fit a1 = (r/J1) m_el_hat through the origin.
        # b1 ω1 comes off the pre-entry samples too: m0 anchors m_el − b1 ω1, the torque that accelerates J1
        mf = _net_torque(window, bearing_friction_nms_per_rad)
        a = np.asarray(window["a1"], float)[start:end]
        t = np.arange(n) * sample_period_s
        pre = mf[:start]
        m0 = float(pre.mean()) if pre.size else float(m[0])
        T = t[:, None] if n < GAP_QUADRATIC_MIN else np.column_stack([t, t * t])
        coef, *_ = np.linalg.lstsq(T, m - m0, rcond=None)
        m_hat = m0 + T @ coef
        smm = float(m_hat @ m_hat)
        kappa = float(a @ m_hat) / smm
        if not kappa > 0:
            raise NoGapError(f"gap fit gave a non-physical a1/m_el ratio {kappa:.4g}")
        j = wheel_radius_m / kappa
        res = (a - kappa * m_hat) / kappa
        dof = n - 1
        var_k = (res @ res) / dof / smm if dof > 0 else np.inf
        # uncertainty of m_hat = m0 (1 - P 1) + P m (P: projection on T's columns): the pre-entry mean's
        # variance along u = 1 - P 1 and the gap m_el noise through P; its effect on J1 = r smm / (a . m_hat)
        # by the delta method, gradient dJ1/dm_hat = J1 (2 m_hat/smm - a/(a . m_hat))
        res_m = (m - m0) - T @ coef
        s2m = float(res_m @ res_m) / max(n - T.shape[1], 1)
        var_m0 = float(pre.var(ddof=1)) / pre.size if pre.size > 1 else s2m
        P = T @ np.linalg.pinv(T)
        u = 1.0 - P.sum(axis=1)
        grad = 2.0 * m_hat / smm - a / float(a @ m_hat)                 # relative: dJ1/dm_hat / J1
        rel_m2 = var_m0 * float(grad @ u) ** 2 + s2m * float(grad @ P @ grad)
        # var_k is the RELATIVE variance of kappa (res is a1's residual over kappa), and J1 = r/kappa has the same
        # relative variance (delta method): var(J1) = J1^2 var_k, plus m_hat's part in quadrature
        se = float(j * np.sqrt(var_k + rel_m2))
    elif method == "angle":
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
        entry_uncertainty_samples = 0        # the change-point search has taken the entry's uncertainty
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
    elif method == "speed":
        if "omega1" not in window:
            raise NoGapError("method 'speed' needs omega1")
        j, se, res, dof = speed_fit(np.asarray(window["omega1"], float)[start:end], m, sample_period_s, lag=True)
    else:
        raise ValueError(f"method: expected one of {', '.join(FITS)} (or None: the model choice), got {method!r}")
    if not np.isfinite(j) or j <= 0:
        raise NoGapError(f"gap fit gave a non-physical J1 = {j:.4g}")
    if "std_error_terms" in free_extra:
        # the angle fits: gap_free raises se to FREE_REL_SE_FLOOR J1 where the data would allow less; that floor
        # is a part too (the only way se exceeds its parts there)
        terms = dict(free_extra["std_error_terms"])
        total = float(np.sqrt(sum(float(v) ** 2 for v in terms.values())))
        if float(se) > total * (1.0 + 1e-9):
            terms["model_floor"] = float(np.sqrt(float(se) ** 2 - total ** 2))
            free_extra["std_error_terms"] = tuple(terms.items())
    else:
        # the a1, anchored and speed fits: their own standard error as parts too, so that the parts account for
        # se in quadrature on every path (verdict.widest_term names the largest; test_gap_bands checks the sum)
        own = {"statistical": float(np.sqrt(max(float(se) ** 2 - float(model_error) ** 2, 0.0)))}
        if model_error:
            own["change_points" if method == "gap_only" else "model_form"] = float(model_error)
        free_extra["std_error_terms"] = tuple(own.items())
    k = int(entry_uncertainty_samples)
    entry_error = 0.0
    if k > 0:
        moved = []
        for e in (entry_index - k, entry_index + k):
            try:
                moved.append(_estimate_inertia(window, e, backlash_width_m, wheel_radius_m, sample_period_s, method,
                                               bearing_friction_nms_per_rad, recontact_index).inertia_kgm2)
            except NoGapError:
                moved.append(np.inf)
        entry_error = max(abs(x - j) for x in moved)
        model_error = float(np.hypot(model_error, entry_error))
        se = float(np.hypot(se, entry_error))
        terms = dict(free_extra["std_error_terms"])
        terms["change_points"] = float(np.hypot(terms.get("change_points", 0.0), entry_error))
        free_extra["std_error_terms"] = tuple(terms.items())
    # the bounded constant torques the speed and a1 fits do not model: the Coulomb band (F in [0, F_max], a
    # uniform term of half-width F_max) and the torque offset (|T| <= torque_offset_nm, uniform)
    bounded = [(name, v) for name, v in (("coulomb_band", model.coulomb_friction_max_nm),
                                         ("torque_offset", model.torque_offset_nm)) if v]
    if method == "speed" and bounded:
        # a constant torque F is F t in ∫m_el dt, which moves J1 by J1 F (r_κ · t) (r_κ: the least-squares row
        # of 1/J1)
        tq = np.asarray(window["m_el"], float)[start:end]
        yint = np.concatenate([[0.0], np.cumsum(0.5 * (tq[1:] + tq[:-1])) * sample_period_s])
        A = np.column_stack([np.ones(n), yint, tq])
        row = np.linalg.pinv(A)[1]
        sens = j * abs(float(row @ (np.arange(n) * sample_period_s)))
        terms = dict(free_extra.get("std_error_terms", ()))
        for name, v in bounded:
            terms[name] = sens * v / np.sqrt(3.0)
            se = float(np.hypot(se, terms[name]))
        free_extra["std_error_terms"] = tuple(terms.items())
    if method in ("gap_only", "acceleration", "anchored") and (bounded or model.torque_lag_s) and "a1" in window:
        # the a1 fits: a constant torque F moves J1 (the slope of the torque on dω1/dt) by F Σx/Σx² over the
        # fitted samples
        x = np.asarray(window["a1"], float)[fit_span[0]:fit_span[1]] / wheel_radius_m
        terms = dict(free_extra.get("std_error_terms", ()))
        mt = (np.gradient(_net_torque(window, bearing_friction_nms_per_rad), sample_period_s)[fit_span[0]:fit_span[1]]
              if model.torque_lag_s else None)
        if method == "gap_only" and bounded:
            j, se, res, dof, terms, note, trend = _gap_only_constant(fit, mf, (x, mt), model, bounded, (j, se, res, dof),
                                                                     terms, entry_error)
            if note:
                free_extra["friction"] = note
                free_extra["trend_fit"] = _trend_finished(*trend, model)
                model_error = float(terms.get("change_points", 0.0))
        else:
            sens = abs(float(x.sum())) / max(float(x @ x), 1e-300)
            for name, v in bounded:
                terms[name] = sens * v / np.sqrt(3.0)
                se = float(np.hypot(se, terms[name]))
            for name, v in _shape_terms(x, mt, model).items():
                terms[name] = v
                se = float(np.hypot(se, v))
        free_extra["std_error_terms"] = tuple(terms.items())
    # every fit: the model's own error as a floor, then the drive's torque accuracy (a scale error of m_el
    # is one of J1: all fits of m_el share it)
    if float(se) < FREE_REL_SE_FLOOR * j:
        terms = dict(free_extra.get("std_error_terms", ()))
        terms["model_floor"] = float(np.sqrt((FREE_REL_SE_FLOOR * j) ** 2 - float(se) ** 2))
        free_extra["std_error_terms"] = tuple(terms.items())
        se = FREE_REL_SE_FLOOR * j
    if model.torque_accuracy:
        terms = dict(free_extra.get("std_error_terms", ()))
        terms["torque_accuracy"] = j * model.torque_rel_se()
        free_extra["std_error_terms"] = tuple(terms.items())
        se = float(np.hypot(se, j * model.torque_rel_se()))
    if not se <= MAX_RELATIVE_STD_ERROR * j:
        raise NoGapError(f"gap fit undetermined: J1 = {j:.4g} kg m^2 with standard error {se:.3g} kg m^2 "
                         f"(> {MAX_RELATIVE_STD_ERROR:.0%}); the window shows no free acceleration of the motor")
    half = _t975(max(int(dof), 1)) * se
    # the residual's RMS: np.mean's own reduction (np.add.reduce, divided by the count)
    rms = float(np.sqrt(np.add.reduce(res ** 2) / res.size))
    return GapEstimate(j, se, (j - half, j + half), rms, start, end, method, how,
                       float(model_error), choice, int(fit_span[0]), int(fit_span[1]), **free_extra)


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
    if z > CROSS_CHECK_Z:
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


def _cross_checked(args: tuple, b1: float, recontact_index, entry_uncertainty_samples: int,
                   model: GapModel, lag_check: bool = True) -> GapEstimate:
    """The model choice when the window has a1 and alpha1 (an Imu beside the encoder): the a1 fit (the joint
    or gap_only fit, :func:`pre_entry_steady`) and the free angle fit, cross-checked; the one with the smaller
    standard error is returned when they agree within CROSS_CHECK_Z combined standard errors, else NoGapError
    names both.  One that fails alone leaves the other, with the failure in its model_choice.  ``args``: the
    window, entry index, K2, r and T_s of :func:`estimate_inertia`.  ``lag_check``: both fits again with the lag the
    angle fit shows where it is beyond the declared one (:func:`_lag_beyond_declared`)."""
    kw = dict(bearing_friction_nms_per_rad=b1, recontact_index=recontact_index, model=model)
    fits, why = {}, {}
    for name, method in (("angle", "angle"), ("a1", None)):
        # each over its own interval (the a1 fit's from the detector, the angle fit's estimated): a shared
        # interval would make their errors common and the check weaker
        try:
            fits[name] = _estimate_inertia(*args, method=method, entry_uncertainty_samples=entry_uncertainty_samples,
                                           cross_check=False, **kw)
        except NoGapError as exc:
            why[name] = str(exc)
    # over either fit's rows (the a1 fit's may be the longer: a smoothed torque showed over them alone)
    lags = [x for x in (_lag_beyond_declared(args[0], b1, fits[k], args[4], model) for k in fits if lag_check) if x]
    lag = max(lags) if lags else None
    if lag is not None:
        # the fits again with the lag the angle shows (once: the check is not repeated on the refits)
        try:
            again = _cross_checked(args, b1, recontact_index, entry_uncertainty_samples,
                                   replace(model, torque_lag_s=lag[0]), lag_check=False)
        except NoGapError as exc:
            raise NoGapError(f"{exc}; {lag[1]}") from None
        return _lag_noted(again, lag[1])
    if "angle" in fits:
        contact = steady_entry_contact(args[0], fits["angle"], b1, args[3], model)
        if contact is not None:      # the angle fit's premise is false: it neither wins nor checks the a1 fit
            why["angle"] = contact
            del fits["angle"]
    a1_refit = ""
    if "angle" in fits and "a1" in fits:
        contact = a1_rows_contact(args[0], fits["a1"], fits["angle"], b1, args[3], model, args[4])
        if contact is not None:      # the a1 fit again from the angle fit's entry (its own trim goes on from there)
            moved = (args[0], int(fits["angle"].fit_start)) + tuple(args[2:])
            try:
                g = _estimate_inertia(*moved, method=None, entry_uncertainty_samples=0, cross_check=False, **kw)
                a1_refit = f"{contact}: fitted from row {fits['angle'].fit_start}"
                fits["a1"] = replace(g, model_choice=f"{g.model_choice or g.method}; {a1_refit}")
            except NoGapError as exc:
                why["a1"] = f"{contact}; from the angle fit's entry: {exc}"
                del fits["a1"]
    if not fits:
        raise NoGapError(f"a1 fit: {why['a1']}; angle fit: {why['angle']}")
    if len(fits) == 1:
        (name, g), = fits.items()
        other = "angle" if name == "a1" else "a1"
        return replace(g, model_choice=f"{g.model_choice or g.method}; no cross-check: the {other} fit failed "
                                       f"({why[other]})")
    a, b = fits["a1"], fits["angle"]
    z = abs(a.inertia_kgm2 - b.inertia_kgm2) / max(_difference_se(a, b, model), 1e-300)
    if z > CROSS_CHECK_Z:
        raise NoGapError(f"the a1 fit ({a.method}: J1 = {a.inertia_kgm2:.4g} ± {a.std_error_kgm2:.2g} kg m^2) and "
                         f"the angle fit (J1 = {b.inertia_kgm2:.4g} ± {b.std_error_kgm2:.2g} kg m^2) disagree by "
                         f"{z:.1f} standard errors (> {CROSS_CHECK_Z:g}): friction, a wrong gap interval or a "
                         f"lagging signal")
    best = a if a.std_error_kgm2 <= b.std_error_kgm2 else b
    other = b if best is a else a
    best = _trend_choice(best, other)
    # the a1 fit made again from the angle fit's entry says so where the angle fit is the one published, too
    refit = f": {a1_refit}" if a1_refit and best is b else ""
    return replace(best, model_choice=f"{best.model_choice or best.method}; cross-checked with the "
                                      f"{other.method} fit (J1 = {other.inertia_kgm2:.4g}, {z:.1f} standard errors"
                                      f"{refit})")


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


@lru_cache(maxsize=256)
def _t975(dof: int) -> float:
    """Student t 97.5 % quantile (cached: scipy's ppf costs ~0.3 ms a call)."""
    return t_quantile(0.975, dof)


def nearest_class(inertia_kgm2: float, classes_kgm2) -> int:
    """Index of the J1 class nearest to a continuous estimate."""
    return int(np.argmin(np.abs(np.asarray(classes_kgm2, float) - inertia_kgm2)))


