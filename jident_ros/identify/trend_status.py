"""The pure pieces the diagnostic node needs for the trend (issue 14 part 2); no ROS.

* :func:`trend_inputs`: one window's diagnosis -> what the tracker takes of it (the gap estimate's J1
  with its standard error whenever physics allows it, published or not; the backlash width estimate with its
  standard uncertainty: the flank detector's when the window has one, else the gap estimator's, and which;
  and why there is no J1).
* :func:`trend_status`: a :class:`~jident_ros.identify.trend.TrendUpdate` -> the content of the
  diagnostic node's periodic "jident_diagnostic: trend" DiagnosticStatus: (level, message,
  [(key, value), ...]) with the levels of diagnostic_msgs (OK 0, WARN 1, ERROR 2), the tracker's one-line
  message and the numbers as key/values
  (SI units in the key names; '' where a value is not known yet).
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple, Optional

from jident_ros.identify.gap import DRIVE_CONSTANT_TERMS, within_drive_se
from jident_ros.identify.trend import SECONDS_PER_DAY, Z95, TrendUpdate

#: Name of the DiagnosticStatus (the diagnostic node's periodic task "trend").
TREND_STATUS_NAME = "jident_diagnostic: trend"


class TrendInputs(NamedTuple):
    """What :meth:`TrendTracker.update` takes of one window (None where a quantity is not known), where the
    width came from, and why the window has no J1: ``width_source`` 'flank' (the flank detector's
    flank-to-flank K2 of the window, window format 2's ``backlash_width_estimate_m``), 'gap' (the gap
    estimator's width at re-contact: the fallback when the window has no flank estimate) or None (no width);
    ``inertia_refused`` one of :data:`REFUSAL_KINDS` when the window has no J1 for the trend, else None."""

    inertia_kgm2: Optional[float]
    inertia_se_kgm2: Optional[float]
    width_m: Optional[float]
    width_se_m: Optional[float]
    width_source: Optional[str]
    inertia_refused: Optional[str] = None


#: the width sources of :class:`TrendInputs`
WIDTH_SOURCES = ("flank", "gap")

#: Why a window gives the trend no J1 (issue 21: only physics refuses an estimate; the class verdict does not):
#: the key counted by the tracker -> what it means.
REFUSAL_KINDS = {
    "outside_band": "the gap J1 is outside the plausible band (a false entry, a wrong K2, radius or torque scale)",
    "inconsistent": "the gap fit is inconsistent with the window (the K2 disagrees with the re-contact)",
    "no_gap": "no gap estimate (undetermined, too short, no usable fit)",
    "input": "the window's input was refused",
    "no_std_error": "a J1 without a standard error (the image method's class alone)",
    "same_traversal": "the gap fit read the rows the window before's did (one traversal, given to the trend once)",
}
#: The REFUSAL_KINDS key of a second window of one traversal (identify.monitor.DriveMonitor).
SAME_TRAVERSAL = "same_traversal"


def _finite(*v) -> bool:
    return all(x is not None and math.isfinite(float(x)) for x in v)


def _trend_fit(g) -> tuple:
    """(J1, se) the trend reads of gap estimate ``g``: its ``trend_fit`` where it has one (a J1 whose bias is a
    constant of the drive: the fit with the motor's Coulomb friction at 0, the band a term, where ``g`` is the free
    angle fit under a band or the gap-only fit with its constant free, or the cross-check's other fit where that one
    scatters less from window to window; GapEstimate.trend_fit), else its own J1; the standard error without the
    drive's constant terms (gap.within_drive_se, :func:`_gap_se`)."""
    tf = getattr(g, "trend_fit", ()) or ()
    if len(tf) == 3:
        return float(tf[0]), within_drive_se(float(tf[1]), tf[2])
    return float(g.inertia_kgm2), _gap_se(g)


def _gap_se(g) -> float:
    """The gap J1's standard error for the trend: the fit's (else from its 95 % interval) WITHOUT the terms that are
    constants of the drive (:data:`DRIVE_CONSTANT_TERMS`, gap.within_drive_se): they move every J1 of the drive alike
    and cancel in J1 relative to its own baseline, which is what the trend tests; the absolute J1 gets the torque
    accuracy back (TrendConfig.torque_accuracy_pct).  If they do not cancel on a drive (windows of very different
    shapes), its windows scatter more than this se says, and the tracker's error scale, learnt from the drive's own
    windows, widens the band (docs/trend.md, "The drive's error scale")."""
    se = g.std_error_kgm2
    if se is None or not math.isfinite(float(se)):
        lo, hi = (float(v) for v in g.ci95_kgm2)
        se = (hi - lo) / (2 * Z95)
    return within_drive_se(float(se), getattr(g, "std_error_terms", ()))


def refusal_kind(diagnosis) -> Optional[str]:
    """None when the window's gap estimate goes to the trend, else the :data:`REFUSAL_KINDS` key.  A gap
    estimate goes to the trend whatever its class verdict ('ambiguous': an interval over two classes, or
    'between classes'), unless the publishing policy refused it for a physical reason ('refused': outside the
    plausible band, K2 inconsistent with the re-contact), or it is not finite."""
    g = getattr(diagnosis, "gap", None)
    status = getattr(diagnosis, "status", None)
    if g is None:
        if getattr(diagnosis, "inertia_kgm2", None) is not None:
            return "no_std_error"
        return "input" if status == "refused" else "no_gap"
    if status == "refused":
        return "outside_band" if "plausible band" in (getattr(diagnosis, "refused_reason", "") or "") \
            else "inconsistent"
    if not _finite(g.inertia_kgm2):
        return "no_gap"
    j, se = _trend_fit(g)
    if not _finite(j, se) or not se > 0.0:
        return "no_gap"
    return None


def trend_inputs(diagnosis, width_se_floor_m: float = 0.0, window=None) -> TrendInputs:
    """The tracker's inputs from one window's :class:`~jident_ros.identify.diagnosis.WindowDiagnosis`
    (and the :class:`~jident_ros.stream.layout.Window` it was diagnosed from, when at hand).

    J1: the gap estimate whenever physics allows it (:func:`refusal_kind`), published or not (an 'ambiguous'
    window, whose interval holds two classes, still carries its J1 and standard error: twenty such windows
    can name a change that one cannot): its ``trend_fit`` where it has one (a J1 whose bias is a constant of the
    drive, :func:`_trend_fit`), else its own; its standard error is the fit's, else (high - low) / (2 x 1.96) of
    its 95 % interval, without the drive's constant terms; a J1 of the image method alone has no standard error
    and is not used.  The width K2, in
    this order of preference (``width_source``):

    * 'flank': the flank detector's flank-to-flank estimate of the window (``window``'s
      ``backlash_width_estimate_m`` / ``backlash_width_se_m``, or the diagnosis' width when it came from
      the window: method 'flank'), whether or not the gap fit succeeded;
    * 'gap': the gap estimator's width at re-contact (paper-detector windows, zone-centred angles);

    none when the gap estimate was refused as physically implausible or inconsistent (the window is then
    likely a false entry: its width is not trusted either); its standard uncertainty at least
    ``width_se_floor_m`` (the tracker's floor)."""
    j = jse = w = wse = src = None
    kind = refusal_kind(diagnosis)
    g = getattr(diagnosis, "gap", None)
    if kind is None:
        j, jse = _trend_fit(g)
    if kind in ("outside_band", "inconsistent"):
        return TrendInputs(None, None, None, None, None, kind)
    est = getattr(window, "backlash_width_estimate_m", None)
    est_se = getattr(window, "backlash_width_se_m", None)
    width = getattr(diagnosis, "width", None)
    if getattr(window, "detector", None) == "flank" and _finite(est, est_se):
        w, wse, src = float(est), float(est_se), "flank"
    elif width is not None and _finite(width.width_m, width.std_m):
        w, wse = float(width.width_m), float(width.std_m)
        src = "flank" if getattr(width, "method", "") == "flank" else "gap"
    if w is not None:
        wse = max(wse, float(width_se_floor_m))
    return TrendInputs(j, jse, w, wse, src, kind)


def _v(x: Optional[float]) -> Any:
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def _counts(d: dict) -> str:
    """{reason: n} -> 'reason n, reason n' (largest first); '' when empty."""
    return ", ".join(f"{k} {n}" for k, n in sorted(d.items(), key=lambda kv: -kv[1]))


def trend_status(u: TrendUpdate) -> tuple[int, str, list]:
    """(level, message, key/values) of the trend status after update ``u``.

    The message is the tracker's one line (J1 drift from the baseline with its standard error, a
    recent change, width, wear rate, time to the limit; or why the window was skipped).  Key/values,
    in this order: window_index, time_s, skipped, skip_reason, commissioning, inertia_kgm2 (smoothed),
    inertia_se_kgm2, inertia_baseline_kgm2, inertia_reference_kgm2, inertia_drift_pct,
    inertia_drift_se_pct, inertia_drift_from_reference_pct, backlash_width_m (regression line),
    backlash_width_se_m, backlash_width_baseline_m, wear_rate_m_per_day, wear_rate_se_m_per_day,
    time_to_limit_days (+ _low, _high), changes_detected (at this window), inertia_drift_ci95_low_pct /
    _high_pct, inertia_abs_se_kgm2 (with the torque-accuracy term), inertia_baseline_windows_refining (0: refined),
    inertia_windows_fed, inertia_windows_refused and windows_skipped (by reason, 'reason n, ...'), time_segment,
    inertia_error_scale and inertia_error_scale_dof (the drive's learnt J1 error scale and its dof), and for the last
    change
    of this window: last_change_quantity, last_change_time_s, last_change_onset_time_s,
    last_change_size, last_change_size_pct."""
    def days(s):
        return None if s is None else s / SECONDS_PER_DAY
    vals = [("window_index", int(u.window_index)), ("time_s", _v(u.time_s)), ("skipped", bool(u.skipped)),
            ("skip_reason", u.reason or ""), ("commissioning", bool(u.commissioning)),
            ("inertia_kgm2", _v(u.inertia_kgm2)), ("inertia_se_kgm2", _v(u.inertia_se_kgm2)),
            ("inertia_baseline_kgm2", _v(u.inertia_baseline_kgm2)),
            ("inertia_reference_kgm2", _v(u.inertia_reference_kgm2)),
            ("inertia_drift_pct", _v(u.inertia_drift_pct)), ("inertia_drift_se_pct", _v(u.inertia_drift_se_pct)),
            ("inertia_drift_from_reference_pct", _v(u.inertia_drift_from_reference_pct)),
            ("backlash_width_m", _v(u.width_m)), ("backlash_width_se_m", _v(u.width_se_m)),
            ("backlash_width_baseline_m", _v(u.width_baseline_m)),
            ("wear_rate_m_per_day", _v(u.wear_rate_m_per_day)),
            ("wear_rate_se_m_per_day", _v(u.wear_rate_se_m_per_day)),
            ("time_to_limit_days", _v(days(u.time_to_limit_s))),
            ("time_to_limit_low_days", _v(days(u.time_to_limit_low_s))),
            ("time_to_limit_high_days", _v(days(u.time_to_limit_high_s))),
            ("changes_detected", len(u.changes))]
    lo_hi = u.inertia_drift_ci95_pct or (None, None)
    vals += [("inertia_drift_ci95_low_pct", _v(lo_hi[0])), ("inertia_drift_ci95_high_pct", _v(lo_hi[1])),
             ("inertia_abs_se_kgm2", _v(u.inertia_abs_se_kgm2)),
             ("inertia_baseline_windows_refining", int(u.inertia_baseline_windows)),
             ("inertia_windows_fed", int(u.inertia_windows_fed)),
             ("inertia_windows_refused", _counts(u.inertia_windows_refused)),
             ("windows_skipped", _counts(u.windows_skipped)), ("time_segment", int(u.time_segment)),
             ("inertia_error_scale", _v(u.inertia_error_scale)),
             ("inertia_error_scale_dof", _v(u.inertia_error_scale_dof))]
    if u.changes:
        c = u.changes[-1]
        vals += [("last_change_quantity", c.quantity), ("last_change_time_s", c.time_s),
                 ("last_change_onset_time_s", c.onset_time_s), ("last_change_size", c.size),
                 ("last_change_size_pct", c.size_pct)]
    return int(u.level), u.message, vals


__all__ = ["DRIVE_CONSTANT_TERMS", "REFUSAL_KINDS", "SAME_TRAVERSAL", "TREND_STATUS_NAME", "TrendInputs", "WIDTH_SOURCES", "refusal_kind",
           "trend_inputs", "trend_status"]
