"""J1 from the backlash gap itself: while the drive is inside the zone the load
moment is zero, so the motor side is a single mass,

    J1 dω1/dt = m_el − b1 ω1          (b1 = bearing friction, 0 in the paper's model)

and J1 follows from signals the window already holds, by least squares over the
gap samples.  Plain numpy/scipy; never imports rclpy.

This module is the entry (:func:`estimate_inertia`) and the choice between the fits; split by fit (issue 20), the fits
are its sibling modules, which never import it: the gap interval (gap_interval.py: from the detector's re-contact, the
angles or the a1 signature), the a1 fits (gap_a1.py), the angle fits (gap_angle.py, over gap_free.py's free angle fit
and gap_kink.py's steady-entry fit), the speed fit (gap_speed.py), the steadiness test (gap_steady.py), the
cross-check's statistics (gap_cross.py), the backlash width (gap_width.py) and what they share (gap_types.py:
GapEstimate, NoGapError, FitState).  Each fit is one function of its module (``_method_*`` of gap_a1.py, gap_angle.py
and gap_speed.py), which :func:`_estimate_inertia` calls and finishes.  The names other modules and the tests import
from here are re-exported.

Fits
----
* ``"acceleration"`` (a1 and m_el measured; the default): one weighted least-squares fit of both channels together,
  the torque steady before the entry (gap_a1.py, ``_joint_fit``; its module docstring).
* ``"gap_only"`` (a1 and m_el measured; no assumption about the drive before the entry): over the in-zone samples
  only, the errors-in-variables slope of m_el − b1 ω1 on a1/r (gap_a1.py, :func:`gap_only_fit`).
* ``"auto"`` (``method=None`` with a1 in the window; the default): the **model choice**.  The joint
  fit's assumption, a steady torque before the entry, is tested on the pre-entry m_el samples
  (:func:`pre_entry_steady`: a quadratic in time against a constant, F test).  Steady: the joint
  fit (``"acceleration"``); not steady (e.g. a speed controller swinging the torque just before
  the entry): ``"gap_only"``.  The estimate's ``model_choice`` says which and why.
* ``"anchored"`` (the estimator of the first release, kept for comparison; gap_a1.py): m0 = the
  pre-entry mean (of m_el − b1 ω1, as in the gap), m_el ≈ m0 + b t + c t^2 fitted over the gap,
  then a1 = (r/J1) m_hat through the origin.  Uncertainty: the least-squares one of r/J1 (its
  relative variance is J1's), and in quadrature m_hat's error carried to J1 by the delta method.
* ``"angle"`` (α1 and m_el measured: a motor encoder and the drive's torque, no accelerometer): double-integral form,
  no differentiation: the free angle fit, or the steady-entry fit where the drive was steady before the entry and the
  free fit supports it (gap_angle.py; the first release's angle fit, ``_angle_fit``, is described there).
* ``"speed"`` (ω1 and m_el measured, no accelerometer): integral form, no
  differentiation: ω1_k = ω1_0 + (1/J1) ∫_{t0}^{tk} m_el dt, ω1 regressed on the integral
  (:func:`speed_fit`, gap_speed.py: the noisy speed is the regressand; the residual's autocorrelation
  and the interval's end rows go into the uncertainty).
All report J1, its standard error, a 95 % confidence interval (Student t) and the
residual RMS.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from jident_ros.identify import gap_cross, gap_terms
from jident_ros.identify.distributions import t_quantile
from jident_ros.identify.gap_a1 import (  # noqa: F401  (re-exported: the a1 fits' names the tests and research import)
    GAP_ONLY_MAX_TRIM,
    GAP_ONLY_REL_SE_FLOOR,
    GAP_ONLY_TRIM_REL,
    GAP_ONLY_TRIM_SIGMA,
    GAP_QUADRATIC_MIN,
    _a1_bounded,
    _a1_contact_rows,
    _joint_fit,
    _method_acceleration,
    _method_anchored,
    _method_gap_only,
    _origin_slope,
    _robust_noise,
    _std_ddof1,
    _torque_powers,
    gap_only_fit,
    gap_only_max_trim,
)
from jident_ros.identify.gap_angle import (  # noqa: F401  (re-exported: the angle fits' names the tests import)
    ANGLE_REL_SE_FLOOR,
    KINK_PREMISE_Z,
    MIN_CURVATURE_COUNTS,
    STEADY_ENTRY_CHOICE,
    _anchored_angle,
    _method_angle,
    a1_rows_contact,
    angle_over_rows,
    encoder_resolved,
    steady_entry_contact,
)
from jident_ros.identify.gap_cross import (  # noqa: F401  (re-exported: trend_status and the tests)
    COMMON_TORQUE_TERMS,
    DRIVE_CONSTANT_TERMS,
    _difference_se,
    _trend_choice,
    within_drive_se,
)
from jident_ros.identify.gap_free import FREE_REL_SE_FLOOR, GapModel
from jident_ros.identify.gap_interval import _savgol_for_gap, gap_interval  # noqa: F401  (re-exported)
from jident_ros.identify.gap_lag import LAG_MAX_FRACTION, LAG_MIN_SAMPLES, LAG_Z, torque_lag_estimate
from jident_ros.identify.gap_numerics import fit_cache, window_memo  # noqa: F401  (fit_cache re-exported)
from jident_ros.identify.gap_speed import _method_speed, _speed_bounded, speed_fit  # noqa: F401  (speed_fit re-exported)
from jident_ros.identify.gap_steady import STEADY_P_VALUE, pre_entry_steady  # noqa: F401  (STEADY_P_VALUE re-exported)
from jident_ros.identify.gap_types import FitState, GapEstimate, NoGapError, _net_torque
from jident_ros.identify.gap_width import WidthEstimate, estimate_backlash_width  # noqa: F401  (re-exported)
from jident_ros.stream.flank_disc import disc_corrected

#: A gap fit whose standard error exceeds this fraction of J1 is refused (NoGapError): such a
#: window carries no free acceleration (e.g. a steady state mistaken for an entry).
MAX_RELATIVE_STD_ERROR = 0.25


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
    alpha1 shows none: jident_ros.stream.flank_disc.disc_corrected, once and twice per revolution, fitted over the
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
    (:func:`_cross_checked`); False: the a1 fit's model choice alone.  One function per fit (gap_a1's, gap_angle's and
    gap_speed's ``_method_*``), then the steps every fit takes (the entry's uncertainty, the bounded torques, the
    floor and the torque accuracy)."""
    model = GapModel() if model is None else model
    if "m_el" not in window:
        raise NoGapError("no electromagnetic torque: the gap fit needs m_el")
    if (method is None or method == "auto") and "a1" in window and "alpha1" in window and cross_check:
        return _cross_checked((window, entry_index, backlash_width_m, wheel_radius_m, sample_period_s),
                              bearing_friction_nms_per_rad, recontact_index, entry_uncertainty_samples, model)
    start, end, how = gap_interval(window, entry_index, backlash_width_m, wheel_radius_m,
                                   recontact_index=recontact_index)
    drive = (wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s)
    method, choice, gap_only = _model_choice(window, method, (start, end), drive, model)
    f = _method_fit(window, method, (start, end), drive, model, gap_only)
    if method == "angle":
        choice = "; ".join(x for x in (choice, f.choice) if x)
        entry_uncertainty_samples = 0        # the change-point search has taken the entry's uncertainty
    if not np.isfinite(f.j) or f.j <= 0:
        raise NoGapError(f"gap fit gave a non-physical J1 = {f.j:.4g}")
    _own_terms(f, method)
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
        entry_error = max(abs(x - f.j) for x in moved)
        f.model_error = float(np.hypot(f.model_error, entry_error))
        f.se = float(np.hypot(f.se, entry_error))
        terms = dict(f.extra["std_error_terms"])
        terms["change_points"] = float(np.hypot(terms.get("change_points", 0.0), entry_error))
        f.extra["std_error_terms"] = tuple(terms.items())
    # the bounded constant torques the speed and a1 fits do not model: the Coulomb band (F in [0, F_max], a
    # uniform term of half-width F_max) and the torque offset (|T| <= torque_offset_nm, uniform)
    bounded = [(name, v) for name, v in (("coulomb_band", model.coulomb_friction_max_nm),
                                         ("torque_offset", model.torque_offset_nm)) if v]
    if method == "speed" and bounded:
        _speed_bounded(f, window["m_el"], (start, end), sample_period_s, bounded)
    if method in ("gap_only", "acceleration", "anchored") and (bounded or model.torque_lag_s) and "a1" in window:
        _a1_bounded(f, window, method, drive, model, bounded, entry_error)
    _floored(f, model)
    j, se = f.j, f.se
    if not se <= MAX_RELATIVE_STD_ERROR * j:
        raise NoGapError(f"gap fit undetermined: J1 = {j:.4g} kg m^2 with standard error {se:.3g} kg m^2 "
                         f"(> {MAX_RELATIVE_STD_ERROR:.0%}); the window shows no free acceleration of the motor")
    half = _t975(max(int(f.dof), 1)) * se
    # the residual's RMS: np.mean's own reduction (np.add.reduce, divided by the count)
    rms = float(np.sqrt(np.add.reduce(f.res ** 2) / f.res.size))
    return GapEstimate(j, se, (j - half, j + half), rms, start, end, method, how,
                       float(f.model_error), choice, int(f.span[0]), int(f.span[1]), **f.extra)


def _model_choice(window: dict, method: str | None, rows: tuple, drive: tuple, model: GapModel) -> tuple:
    """(the fit, the model choice's phrase, the 'gap_only' fit where the choice has already made it, or None) of
    :func:`_estimate_inertia` over ``rows`` (start, end): ``method`` as named, or with None / 'auto' the model choice
    (the module docstring).  ``drive``: (r, b1, T_s)."""
    (start, end), (wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    choice = ""
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
                if contact:          # its gap-only fit is the one the 'gap_only' fit would make again
                    method, choice, gap_only = "gap_only", f"gap_only: {contact}", in_zone
        else:
            method = "angle" if "alpha1" in window else "speed"
            choice = f"{method}: no a1 in the window"
    return method, choice, gap_only


def _method_fit(window: dict, method: str, rows: tuple, drive: tuple, model: GapModel, gap_only: dict | None):
    """The fit ``method`` over ``rows`` (start, end), a :class:`~jident_ros.identify.gap_types.FitState`: one function
    per fit (gap_a1's, gap_angle's and gap_speed's ``_method_*``).  ``drive``: (r, b1, T_s)."""
    if method == "gap_only":
        return _method_gap_only(window, rows, drive, model, gap_only)
    if method == "acceleration":
        return _method_acceleration(window, rows, drive, model)
    if method == "anchored":
        return _method_anchored(window, rows, drive)
    if method == "angle":
        return _method_angle(window, rows, drive, model)
    if method == "speed":
        return _method_speed(window, rows, drive)
    raise ValueError(f"method: expected one of {', '.join(FITS)} (or None: the model choice), got {method!r}")


def _own_terms(f: FitState, method: str) -> None:
    """``f``'s std_error_terms made to account for its standard error in quadrature (``f`` changed in place)."""
    free_extra, se, model_error = f.extra, f.se, f.model_error
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
        ratio = float((f.made or {}).get("noise_ratio", 0.0)) if method == "gap_only" else 0.0
        own = {"statistical": float(np.sqrt(max(float(se) ** 2 - float(model_error) ** 2 - ratio ** 2, 0.0)))}
        if ratio:
            own["noise_ratio"] = ratio
        if model_error:
            own["change_points" if method == "gap_only" else "model_form"] = float(model_error)
        free_extra["std_error_terms"] = tuple(own.items())


def _floored(f: FitState, model: GapModel) -> None:
    """Every fit: the model's own error as a floor, then the drive's torque accuracy (a scale error of m_el is one of
    J1: all fits of m_el share it); ``f`` changed in place."""
    j, se, free_extra = f.j, f.se, f.extra
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
    f.se = se


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
    best = a if a.std_error_kgm2 <= b.std_error_kgm2 else b       # the one published when they agree
    if z > gap_cross.CROSS_CHECK_Z:
        text = (f"the a1 fit ({a.method}: J1 = {a.inertia_kgm2:.4g} ± {a.std_error_kgm2:.2g} kg m^2) and the angle fit "
                f"(J1 = {b.inertia_kgm2:.4g} ± {b.std_error_kgm2:.2g} kg m^2) disagree by {z:.1f} standard errors (> "
                f"{gap_cross.CROSS_CHECK_Z:g})")
        half = 0.5 * (best.ci95_kgm2[1] - best.ci95_kgm2[0]) / best.inertia_kgm2
        if not half <= gap_terms.MAX_CI95_HALF_WIDTH_REL:
            # the fit that would go out had they agreed is wider than a published interval may be: nothing would be
            # published either way, so the disagreement is this window's resolution, not a configuration to check
            raise NoGapError(f"gap fit undetermined: {text}, and the better of them (± {100 * half:.3g} %) could not "
                             f"be published either (± {100 * gap_terms.MAX_CI95_HALF_WIDTH_REL:g} % at most)")
        same = _same_rows(args, b1, a, b, model)
        if same:
            # over the same rows the signals do not disagree: the fits' gap intervals do (a short gap the angle fit's
            # change points grew into contact), this window's resolution, not a configuration to check
            raise NoGapError(f"gap fit undetermined: {text}; {same}")
        raise NoGapError(f"{text}: friction, a wrong gap interval or a lagging signal")
    other = b if best is a else a
    best = _trend_choice(best, other)
    # the a1 fit made again from the angle fit's entry says so where the angle fit is the one published, too
    refit = f": {a1_refit}" if a1_refit and best is b else ""
    return replace(best, model_choice=f"{best.model_choice or best.method}; cross-checked with the "
                                      f"{other.method} fit (J1 = {other.inertia_kgm2:.4g}, {z:.1f} standard errors"
                                      f"{refit})")


def _same_rows(args: tuple, b1: float, a: GapEstimate, b: GapEstimate, model: GapModel) -> str:
    """Why a disagreement of the a1 fit ``a`` and the angle fit ``b`` lies in their gap intervals, not their signals:
    the angle fit over the a1 fit's own rows (:func:`angle_over_rows`) agrees with it within CROSS_CHECK_Z combined
    standard errors, or those rows cannot hold an angle fit (the angle fit's disagreement then came from rows the a1
    fit does not hold); '' where the angle fit used the same rows, or disagrees over them too (friction, a lagging
    signal, a wrong radius: the refusal names them)."""
    rows = a.fitted_rows
    if rows == b.fitted_rows:
        return ""
    got = angle_over_rows(args[0], rows, b1, args[4], model)
    if got is None:
        return (f"the a1 fit's rows {rows[0]}..{rows[1]} are too few for the angle fit, whose rows "
                f"{b.fit_start}..{b.fit_end} are others")
    # the refit as the angle fit's estimate over those rows: the difference's standard error as the check's own
    # (_difference_se: the torque terms both fits share as their difference; in quadrature the second drive's a1
    # fit 25 % off under a wrong radius passed at 2.9, scripts/golden.py's second_drive_signals)
    refit = replace(b, inertia_kgm2=got[0], std_error_kgm2=got[1], std_error_terms=tuple(got[2].items()),
                    fit_start=rows[0], fit_end=rows[1])
    z = abs(got[0] - a.inertia_kgm2) / max(_difference_se(a, refit, model), 1e-300)
    if z > gap_cross.CROSS_CHECK_Z:
        return ""
    return (f"over the a1 fit's rows {rows[0]}..{rows[1]} the angle fit gives J1 = {got[0]:.4g} ± {got[1]:.2g} kg m^2, "
            f"within {z:.1f} standard errors of it: the fits' gap intervals differ, not their signals")


@lru_cache(maxsize=256)
def _t975(dof: int) -> float:
    """Student t 97.5 % quantile (cached: scipy's ppf costs ~0.3 ms a call)."""
    return t_quantile(0.975, dof)


def nearest_class(inertia_kgm2: float, classes_kgm2) -> int:
    """Index of the J1 class nearest to a continuous estimate."""
    return int(np.argmin(np.abs(np.asarray(classes_kgm2, float) - inertia_kgm2)))
