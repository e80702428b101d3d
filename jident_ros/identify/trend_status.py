"""The pure pieces the diagnostic node needs for the trend (issue 14 part 2); no ROS.

* :func:`trend_inputs`: one window's diagnosis -> what the tracker takes of it (the published J1 of
  the gap estimate with its standard error, the backlash width estimate with its standard uncertainty:
  the flank detector's when the window has one, else the gap estimator's, and which).
* :func:`trend_status`: a :class:`~jident_ros.identify.trend.TrendUpdate` -> the content of the
  diagnostic node's periodic "jident_diagnostic: trend" DiagnosticStatus: (level, message,
  [(key, value), ...]) with the levels of diagnostic_msgs (OK 0, WARN 1, ERROR 2), the tracker's one-line
  message and the numbers as key/values
  (SI units in the key names; '' where a value is not known yet).
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple, Optional

from jident_ros.identify.trend import SECONDS_PER_DAY, TrendUpdate

#: Name of the DiagnosticStatus (the diagnostic node's periodic task "trend").
TREND_STATUS_NAME = "jident_diagnostic: trend"

#: z of the two-sided 95 % interval (a standard error from the interval when the fit gave none).
Z95 = 1.959963984540054


class TrendInputs(NamedTuple):
    """What :meth:`TrendTracker.update` takes of one window (None where a quantity is not known) and where
    the width came from: ``width_source`` 'flank' (the flank detector's flank-to-flank K2 of the window,
    window format 2's ``backlash_width_estimate_m``), 'gap' (the gap estimator's width at re-contact: the
    fallback when the window has no flank estimate) or None (no width)."""

    inertia_kgm2: Optional[float]
    inertia_se_kgm2: Optional[float]
    width_m: Optional[float]
    width_se_m: Optional[float]
    width_source: Optional[str]


#: the width sources of :class:`TrendInputs`
WIDTH_SOURCES = ("flank", "gap")


def _finite(*v) -> bool:
    return all(x is not None and math.isfinite(float(x)) for x in v)


def trend_inputs(diagnosis, width_se_floor_m: float = 0.0, window=None) -> TrendInputs:
    """The tracker's inputs from one window's :class:`~jident_ros.identify.diagnosis.WindowDiagnosis`
    (and the :class:`~jident_ros.stream.layout.Window` it was diagnosed from, when at hand).

    J1 only when the published J1 is the gap estimate (``source == 'gap'``: the policy accepted it; a
    refused or ambiguous gap estimate is not used): its standard error is the fit's, else
    (high - low) / (2 x 1.96) of its 95 % interval; a J1 of the image method alone has no standard error
    and is not used.  The width K2, in this order of preference (``width_source``):

    * 'flank': the flank detector's flank-to-flank estimate of the window (``window``'s
      ``backlash_width_estimate_m`` / ``backlash_width_se_m``, or the diagnosis' width when it came from
      the window: method 'flank'), whether or not the gap fit succeeded;
    * 'gap': the gap estimator's width at re-contact (paper-detector windows, zone-centred angles);

    its standard uncertainty at least ``width_se_floor_m`` (the tracker's floor)."""
    j = jse = w = wse = src = None
    g = getattr(diagnosis, "gap", None)
    if g is not None and getattr(diagnosis, "source", None) == "gap" and diagnosis.inertia_kgm2 is not None:
        j = float(g.inertia_kgm2)
        se = g.std_error_kgm2
        if se is None or not math.isfinite(float(se)):
            lo, hi = (float(v) for v in g.ci95_kgm2)
            se = (hi - lo) / (2 * Z95)
        jse = float(se)
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
    return TrendInputs(j, jse, w, wse, src)


def _v(x: Optional[float]) -> Any:
    return "" if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def trend_status(u: TrendUpdate) -> tuple[int, str, list]:
    """(level, message, key/values) of the trend status after update ``u``.

    The message is the tracker's one line (J1 drift from the baseline with its standard error, a
    recent change, width, wear rate, time to the limit; or why the window was skipped).  Key/values,
    in this order: window_index, time_s, skipped, skip_reason, commissioning, inertia_kgm2 (smoothed),
    inertia_se_kgm2, inertia_baseline_kgm2, inertia_reference_kgm2, inertia_drift_pct,
    inertia_drift_se_pct, inertia_drift_from_reference_pct, backlash_width_m (regression line),
    backlash_width_se_m, backlash_width_baseline_m, wear_rate_m_per_day, wear_rate_se_m_per_day,
    time_to_limit_days (+ _low, _high), changes_detected (at this window), and for the last change
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
    if u.changes:
        c = u.changes[-1]
        vals += [("last_change_quantity", c.quantity), ("last_change_time_s", c.time_s),
                 ("last_change_onset_time_s", c.onset_time_s), ("last_change_size", c.size),
                 ("last_change_size_pct", c.size_pct)]
    return int(u.level), u.message, vals


__all__ = ["TREND_STATUS_NAME", "TrendInputs", "WIDTH_SOURCES", "trend_inputs",
           "trend_status"]
