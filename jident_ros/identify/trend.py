"""Condition monitoring over time (issue 14): trend of J1 and of the backlash width K2 per drive.

Pure numpy/scipy, no ROS.  Input: the estimates of every backlash-zone entry ("window") with their
standard errors; either quantity may be missing for a window (it is then not updated).  Method
(details, equations and the false-alarm rate: ``docs/trend.md``):

* **Baseline**: a robust (Huber) inverse-variance weighted mean over a commissioning period (a number
  of windows, or a duration), or given in the configuration.  Optionally
  (``se_scale_from_commissioning``) the commissioning scatter scales the reported standard errors
  when it is significantly above what they say.
* **J1 smoothing**: a Kalman local-level filter (random walk of ``inertia_process_sd_pct_per_window``
  per window), measurement variance = (s * se)^2, innovations clipped at ``innovation_clip_sd``.
* **Width smoothing / wear rate**: inverse-variance weighted linear regression over the last
  ``width_regression_windows`` windows of the current segment (time in seconds); the slope is the
  wear rate (m/s, m/day), its standard error is inflated by ``sqrt(chi^2/dof)`` when the residuals
  scatter more than the reported errors say.  Projected time to ``width_limit_m`` (with an interval
  from the slope's interval) when the slope is significantly positive, otherwise None.
* **Change detection**: a two-sided CUSUM on the standardised innovations, clipped at
  ``innovation_clip_sd``: for J1 against the baseline, z = (y - b) / sqrt((s se)^2 + var b); for the
  width against the one-step prediction of the regression line (so a steady wear does not fire).
  Reference value k = ``cusum_reference_sd``; threshold h from ``cusum_threshold_sd`` or, by default,
  for a target in-control average run length ``target_arl_windows`` from the CUSUM's ARL integral
  equation (:func:`cusum_arl`, :func:`cusum_threshold_for_arl`; Siegmund's approximation is available
  too, :func:`siegmund_arl`).  With ``innovation_clip_sd - k < h`` a single outlier cannot
  fire.  After a change: the change is reported (time, window index, estimated onset, size, sign),
  the smoother restarts from the windows since the onset, and after ``relearn_windows`` windows
  their weighted mean becomes the new baseline; the commissioned reference is kept, and drift is
  reported against both.
* **Health**: OK / WARN / ERROR with a one-line message (:meth:`TrendTracker.update`).
* **State**: :meth:`TrendTracker.to_dict` / :meth:`TrendTracker.from_dict` (JSON, versioned),
  :meth:`TrendTracker.save` (atomic) / :meth:`TrendTracker.load` (refuses corrupt or wrong-version
  files with :class:`TrendStateError`).

Where each piece lives: the CUSUM design and the robust means in :mod:`jident_ros.identify.trend_maths`, the
configuration and the ``trend_*`` parameter mapping in :mod:`jident_ros.identify.trend_config`, the J1 and width
channels in :mod:`jident_ros.identify.trend_channels`; this module holds the tracker, its update/status and its
state file (the names of the others are re-exported here).  The simulation harness (:func:`simulate_series`,
:func:`measure_targets`) is research, in :mod:`jident_ros.research.evaluation.trend_simulation`.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

import numpy as np

from jident_ros.identify.trend_channels import (  # noqa: F401  (re-exported: the tracker's public API)
    COMMISSIONING,
    MONITORING,
    RELEARNING,
    ChangeEvent,
    Channel,
    InertiaChannel,
    TrendStateError,
    WidthChannel,
)
from jident_ros.identify.trend_config import (  # noqa: F401  (re-exported)
    NODE_ONLY,
    PARAMETER_FIELDS,
    SECONDS_PER_DAY,
    ZERO_IS_NONE,
    TrendConfig,
)
from jident_ros.identify.trend_maths import (  # noqa: F401  (re-exported)
    coverage_to_se_scale,
    cusum_arl,
    cusum_threshold_for_arl,
    siegmund_arl,
    two_sided_arl,
)
from jident_ros.identify.trend_state import (  # noqa: F401  (re-exported)
    STATE_KIND,
    STATE_VERSION,
    load_state,
    save_state,
    state_from_dict,
    state_to_dict,
)

#: z of the two-sided 95 % interval.
Z95 = 1.959963984540054
#: The end of the skip reason of a window at the previous window's time (a duplicate: counted, no WARN).
SAME_WINDOW = "(the same window again)"
#: The skip reason of a window without any estimate (counted as refused, not as skipped).
NO_ESTIMATE = "no estimate in this window"

#: Levels, same values as diagnostic_msgs/DiagnosticStatus (and jident_ros.ros_io).
OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}



@dataclass(frozen=True)
class TrendUpdate:
    """The tracker's state after one window.  None where a quantity has no value yet."""

    window_index: int
    time_s: float
    skipped: bool
    reason: str | None          # why the window was refused (skipped) else None
    commissioning: bool         # J1 (or the width, when J1 has no data) is still learning its baseline
    # J1
    inertia_kgm2: float | None                  # smoothed
    inertia_se_kgm2: float | None
    inertia_baseline_kgm2: float | None
    inertia_baseline_se_kgm2: float | None
    inertia_reference_kgm2: float | None        # commissioned (or given) baseline, kept over re-baselines
    inertia_drift_pct: float | None             # 100 (smoothed - baseline) / baseline
    inertia_drift_se_pct: float | None
    inertia_drift_from_reference_pct: float | None
    inertia_cusum_sd: float                     # max of the two CUSUM statistics (fires above the threshold)
    # width
    width_m: float | None                       # regression line at this window's time
    width_se_m: float | None
    width_baseline_m: float | None
    width_baseline_se_m: float | None
    width_drift_pct: float | None
    width_drift_se_pct: float | None
    width_cusum_sd: float
    wear_rate_m_per_s: float | None
    wear_rate_se_m_per_s: float | None
    wear_rate_m_per_day: float | None
    wear_rate_se_m_per_day: float | None
    time_to_limit_s: float | None               # None unless the wear rate is significantly positive
    time_to_limit_low_s: float | None
    time_to_limit_high_s: float | None
    # changes and health
    change: bool                                # a change was detected at this window
    changes: tuple                              # the ChangeEvents detected at this window
    level: int                                  # OK 0 / WARN 1 / ERROR 2
    message: str
    # J1 relative to the drive's own baseline (the monitored quantity) and the absolute J1 beside it (issue 21)
    inertia_drift_ci95_pct: tuple | None = None     # 95 % interval of inertia_drift_pct (the baseline's included)
    inertia_abs_se_kgm2: float | None = None        # smoothed J1's se with the torque-accuracy term
    inertia_baseline_windows: int = 0               # windows the baseline rests on while still refined (0: done)
    # what went in, what did not (issues 21, 24)
    inertia_windows_fed: int = 0                    # windows whose J1 went into the tracker, so far
    inertia_windows_refused: dict = field(default_factory=dict)   # windows without a J1, by reason, so far
    windows_skipped: dict = field(default_factory=dict)           # windows refused whole, by field, so far
    time_segment: int = 0                           # time discontinuities so far (clock back / far ahead)
    inertia_error_scale: float | None = None        # the drive's learnt J1 error scale sigma_hat (None: not learnt)
    inertia_error_scale_dof: float | None = None    # its degrees of freedom (prior's included)

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES[self.level]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["changes"] = [asdict(c) for c in self.changes]
        d["level_name"] = self.level_name
        return d



def _parse_float(name: str, v) -> tuple[float | None, str | None]:
    """(finite float, None) or (None, the reason naming ``name``); None stays (None, None)."""
    if v is None:
        return None, None
    if isinstance(v, bool):
        return None, f"{name}: not a number ({v!r})"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None, f"{name}: not a number ({v!r})"
    if not math.isfinite(f):
        return None, f"{name}: not finite ({f!r})"
    return f, None


def _check_value(name: str, v) -> tuple[float | None, str | None]:
    f, reason = _parse_float(name, v)
    if f is not None and f <= 0.0:
        return None, f"{name}: must be > 0, got {f!r}"
    return f, reason


def _check_time(v) -> tuple[float | None, str | None]:
    if v is None:
        return None, "time_s: missing"
    return _parse_float("time_s", v)


def _beyond(value: float, warn: float, alarm: float) -> int:
    """OK, WARN (value above ``warn``) or ERROR (above ``alarm``)."""
    return ERROR if value > alarm else (WARN if value > warn else OK)


def _beyond_text(level: int, warn: str, alarm: str) -> str:
    """The status phrase of a :func:`_beyond` level: nothing, "beyond the <warn>" or "beyond the <alarm>"."""
    return ("", f" beyond the {warn}", f" beyond the {alarm}")[level]


def _fmt_pm(v: float, se: float, digits: int = 2) -> str:
    return f"{v:+.{digits}f} ± {se:.{digits}f}"


class TrendTracker:
    """Trend of J1 and the backlash width of one drive.  ``update`` once per window."""

    def __init__(self, config: TrendConfig | None = None):
        self.config = config if config is not None else TrendConfig()
        self._k = self.config.cusum_reference_sd
        self._h = self.config.threshold_sd
        self._inertia = InertiaChannel(self.config)
        self._width = WidthChannel(self.config)
        self.n_windows = 0
        self.last_time_s: float | None = None
        self.changes: list[ChangeEvent] = []
        self.inertia_fed = 0                         # windows whose J1 went into the tracker
        self.inertia_refused: dict[str, int] = {}    # windows without a J1, by reason
        self.windows_skipped: dict[str, int] = {}    # windows refused whole (bad input or time), by field
        self.last_skip: tuple | None = None          # (window index, reason) of the last skipped window
        self.time_segment = 0                        # time discontinuities so far
        self.last_discontinuity: tuple | None = None   # (window index, what)
        # offline (jident trend): where the windows fed so far end: (the last recording's start, ns, or None when
        # it has none; its last window's drive time, s); resuming from a state leaves out what it covers
        self.recording_cursor: tuple | None = None

    # -- public API ---------------------------------------------------------------------------------
    @property
    def threshold_sd(self) -> float:
        return self._h

    def reconfigure(self, config: TrendConfig) -> "TrendTracker":
        """The same state under another configuration (a parameter changed at run time): thresholds,
        limits, the CUSUM design, the smoothing and the commissioning length take effect with the next
        window.  A given baseline (``*_baseline_*``) acts only on a fresh tracker and is kept as it was;
        ``width_regression_windows`` cannot change (the regression buffer): TrendStateError."""
        return TrendTracker.from_dict(self.to_dict(), config)

    def recommission(self):
        """Forget the baselines and learn them again (e.g. after maintenance); keeps the window count."""
        self._inertia = InertiaChannel(self.config)
        self._width = WidthChannel(self.config)

    def update(self, time_s: float, inertia_kgm2: float | None = None, inertia_se_kgm2: float | None = None,
               width_m: float | None = None, width_se_m: float | None = None, *,
               inertia_refused: str | None = None) -> TrendUpdate:
        """One window.  A quantity whose value and standard error are both None is not updated
        (``inertia_refused``: why the window has no J1, counted per reason, :data:`~jident_ros.identify.
        trend_status.REFUSAL_KINDS`); a non-finite or non-positive input (or a value without its standard error,
        or the previous window's time again) refuses the whole window: the returned update has ``skipped=True``
        and the reason, the state is unchanged (the window is still counted, and the skip by its reason; the
        status is WARN).  A time before the previous window's (the drive's clock went back: a restart) or more
        than ``time_discontinuity_s`` after it starts a new time segment: reported, the wear line restarts,
        the window is used."""
        idx = self.n_windows
        self.n_windows += 1
        t, vals, reason = self._check_window(time_s, inertia_kgm2, inertia_se_kgm2, width_m, width_se_m)
        if vals and vals["inertia_kgm2"][0] is None and inertia_refused:
            self.count_refused(inertia_refused)
        if reason is not None:
            if reason.endswith(SAME_WINDOW):
                self.windows_skipped["duplicate"] = self.windows_skipped.get("duplicate", 0) + 1
            elif reason != NO_ESTIMATE:
                kind = reason.split(":", 1)[0]
                self.windows_skipped[kind] = self.windows_skipped.get(kind, 0) + 1
                self.last_skip = (idx, reason)
            return self._snapshot(idx, t if t is not None else float("nan"), True, reason, ())
        if self.last_time_s is not None and (t < self.last_time_s
                                             or t - self.last_time_s > self.config.time_discontinuity_s):
            self._discontinuity(idx, t)
        self.last_time_s = t
        events = []
        y, se = vals["inertia_kgm2"]
        if y is not None:
            self.inertia_fed += 1
            ev = self._inertia.update(idx, t, y, se, self._k, self._h)
            if ev is not None:
                events.append(self._classed(ev))
        y, se = vals["width_m"]
        if y is not None:
            ev = self._width.update(idx, t, y, se, self._k, self._h)
            if ev is not None:
                events.append(ev)
        if events:
            self.changes.extend(events)
            del self.changes[:-self.config.max_changes_kept]
        return self._snapshot(idx, t, False, None, tuple(events))

    def count_refused(self, kind: str):
        """Count a window without a J1 for the trend, by reason (a window not given to :meth:`update` at all,
        e.g. without any estimate); the status says how many and why."""
        self.inertia_refused[str(kind)] = self.inertia_refused.get(str(kind), 0) + 1

    def _check_window(self, time_s, inertia_kgm2, inertia_se_kgm2, width_m, width_se_m):
        """(time, {quantity: (value, se)}, None) or (time or None, the values so far, the reason to skip)."""
        t, reason = _check_time(time_s)
        if reason is None and self.last_time_s is not None and t == self.last_time_s:
            # the same window again (e.g. re-delivered by a latched drive/window after a restart)
            reason = f"time_s: {t!r} is the previous window's {SAME_WINDOW}"
        vals = {}
        if reason is None:
            for name, v, sename, se in (("inertia_kgm2", inertia_kgm2, "inertia_se_kgm2", inertia_se_kgm2),
                                        ("width_m", width_m, "width_se_m", width_se_m)):
                fv, r = _check_value(name, v)
                fse, rse = _check_value(sename, se)
                reason = r or rse
                if reason is None and (fv is None) != (fse is None):
                    reason = (f"{sename}: missing while {name} is given" if fse is None
                              else f"{name}: missing while {sename} is given")
                if reason is not None:
                    break
                vals[name] = (fv, fse)
            if reason is None and vals["inertia_kgm2"][0] is None and vals["width_m"][0] is None:
                reason = NO_ESTIMATE
        return t, vals, reason

    def _discontinuity(self, idx: int, t: float):
        """The drive clock went back, or jumped ahead by more than time_discontinuity_s: a new time segment.
        The wear line restarts on it (its slope never spans the jump); J1 and the baselines carry on."""
        dt = t - self.last_time_s
        what = (f"the drive clock went back by {-dt:.6g} s (a restart?)" if dt < 0 else
                f"the drive clock jumped ahead by {dt:.6g} s (> time_discontinuity_s {self.config.time_discontinuity_s:g})")
        self.time_segment += 1
        self.last_discontinuity = (idx, f"time segment {self.time_segment} from window {idx}: {what}")
        for ch in (self._inertia, self._width):
            if ch.first_time is not None:
                ch.first_time += dt          # the commissioning duration counts drive time within segments
        self._width.new_segment(idx)

    def _classed(self, ev: ChangeEvent) -> ChangeEvent:
        """A J1 change with the nearest of the paper's relative classes (change_classes_pct)."""
        cls = min(self.config.change_classes_pct, key=lambda c: abs(c - ev.size_pct))
        return dataclasses.replace(ev, class_pct=float(cls))

    def batch(self, time_s: Sequence[float], inertia_kgm2: Sequence | None = None,
              inertia_se_kgm2: Sequence | None = None, width_m: Sequence | None = None,
              width_se_m: Sequence | None = None, nan_is_missing: bool = False) -> list[TrendUpdate]:
        """``update`` over arrays (offline use).  A whole quantity may be None (absent); single
        entries may be None (missing); with ``nan_is_missing`` a NaN value/se pair counts as missing
        instead of refusing the window."""
        n = len(time_s)

        def col(a, name):
            if a is None:
                return [None] * n
            if len(a) != n:
                raise ValueError(f"{name}: {len(a)} entries, time_s has {n}")
            return list(a)

        cols = [col(inertia_kgm2, "inertia_kgm2"), col(inertia_se_kgm2, "inertia_se_kgm2"),
                col(width_m, "width_m"), col(width_se_m, "width_se_m")]
        out = []
        for i in range(n):
            v = [c[i] for c in cols]
            if nan_is_missing:
                for j in (0, 2):
                    if _isnan(v[j]) or (v[j] is not None and _isnan(v[j + 1])):
                        v[j] = v[j + 1] = None
                    elif v[j] is None and _isnan(v[j + 1]):
                        v[j + 1] = None
            out.append(self.update(time_s[i], *v))
        return out

    # -- snapshot and health ------------------------------------------------------------------------
    def _snapshot(self, idx: int, t: float, skipped: bool, reason: str | None, events: tuple) -> TrendUpdate:
        cfg = self.config
        J, Wd = self._inertia, self._width
        # J1
        jx = J.x
        jse = math.sqrt(J.P) if J.P is not None else None
        jb = J.baseline
        jbse = math.sqrt(J.baseline_var) if J.baseline_var is not None else None
        jd = jdse = jdr = None
        if jx is not None and jb is not None:
            jd = 100.0 * (jx - jb) / jb
            jdse = 100.0 * math.sqrt(J.P + J.baseline_var) / jb
            jdr = 100.0 * (jx - J.reference) / J.reference
        # width
        wx = wse = wd = wdse = None
        rate = rate_se = ttl = ttl_lo = ttl_hi = None
        tw = self.last_time_s if skipped else t   # the line at this window's time (skipped: the last accepted)
        if Wd.fit is not None and tw is not None:
            wx, wvar = Wd.predict(tw)
            wse = math.sqrt(wvar)
            if Wd.baseline is not None:
                wd = 100.0 * (wx - Wd.baseline) / Wd.baseline
                wdse = 100.0 * math.sqrt(wvar + Wd.baseline_var) / Wd.baseline
            sl = Wd.slope()
            if sl is not None:
                rate, rate_se = sl[0], math.sqrt(sl[1])
                zz = cfg.wear_significance_sd
                if rate > zz * rate_se:
                    remaining = cfg.width_limit_m - wx
                    if remaining <= 0.0:
                        ttl = ttl_lo = ttl_hi = 0.0
                    else:
                        ttl = remaining / rate
                        ttl_lo = remaining / (rate + zz * rate_se)
                        ttl_hi = remaining / (rate - zz * rate_se)
        commissioning = (J.phase == COMMISSIONING and (J.n > 0 or Wd.n == 0)) or \
                        (J.n == 0 and Wd.phase == COMMISSIONING)
        u = TrendUpdate(
            idx, t, skipped, reason, commissioning,
            jx, jse, jb, jbse, J.reference, jd, jdse, jdr, J.cusum.stat,
            wx, wse, Wd.baseline, math.sqrt(Wd.baseline_var) if Wd.baseline_var is not None else None, wd, wdse,
            Wd.cusum.stat, rate, rate_se,
            None if rate is None else rate * SECONDS_PER_DAY, None if rate_se is None else rate_se * SECONDS_PER_DAY,
            ttl, ttl_lo, ttl_hi, bool(events), events, OK, "",
            None if jd is None else (jd - Z95 * jdse, jd + Z95 * jdse),
            None if jx is None else math.sqrt(J.P + (0.01 * cfg.torque_accuracy_pct * jx) ** 2),
            J.baseline_windows if J.phase != COMMISSIONING else len(J.comm), self.inertia_fed,
            dict(self.inertia_refused), dict(self.windows_skipped), self.time_segment,
            *(J.error_scale() or (None, None)))
        level, message = self._health(u)
        if skipped:
            message = f"window skipped ({reason}); {message}"
            if reason != NO_ESTIMATE and not reason.endswith(SAME_WINDOW):
                level = max(level, WARN)
        return dataclasses.replace(u, level=level, message=message)

    def _health(self, u: TrendUpdate) -> tuple[int, str]:
        """(level, one-line message) of the tracker after the window of update ``u`` (its level/message unset)."""
        J, Wd = self._inertia, self._width
        if J.n == 0 and Wd.n == 0:
            level, text = OK, f"learning the baseline: 0 of {self.config.commissioning_windows} windows (no estimate yet)"
            lv, extra = self._inputs_text(u)
            return max(level, lv), text + extra
        level, parts = OK, []
        for lv, txt in (self._inertia_text(u), self._width_text(u)):
            level = max(level, lv)
            if txt:
                parts.append(txt)
        lv, extra = self._inputs_text(u)
        return max(level, lv), "; ".join(parts) + extra

    def _inertia_text(self, u: TrendUpdate) -> tuple[int, str]:
        """J1 relative to the drive's own baseline (drift with its 95 % interval; alarms and the class of a
        change from it), the absolute J1 beside it (with the torque-accuracy term)."""
        cfg, J = self.config, self._inertia
        jx, jb, jd, jdr = u.inertia_kgm2, u.inertia_baseline_kgm2, u.inertia_drift_pct, u.inertia_drift_from_reference_pct
        if J.phase == COMMISSIONING:
            if J.n > 0 or J.baseline is None:
                return OK, (f"J1 learning the baseline: {J.progress()}"
                            + (f" (J1 {jx:.5g} kg m^2)" if jx is not None else ""))
            return OK, ""
        lo, hi = u.inertia_drift_ci95_pct
        txt = f"J1 {jx:.5g} kg m^2 ({_fmt_pm(jd, u.inertia_drift_se_pct)} % of baseline {jb:.5g}"
        if J.reference != jb:
            txt += f"; {jdr:+.2f} % of commissioned {J.reference:.5g}"
        txt += f"; 95 % [{lo:+.2f}, {hi:+.2f}] %"
        if u.inertia_baseline_windows:
            txt += f"; baseline on {u.inertia_baseline_windows} of {cfg.baseline_refine_windows} windows, refining"
        txt += ")"
        if cfg.torque_accuracy_pct > 0:
            txt += f", absolute ± {Z95 * u.inertia_abs_se_kgm2:.2g} kg m^2 with the {cfg.torque_accuracy_pct:g} % torque accuracy"
        level = _beyond(max(abs(jd), abs(jdr)), cfg.drift_warn_pct, cfg.drift_alarm_pct)
        txt += _beyond_text(level, f"{cfg.drift_warn_pct:g} % warning", f"{cfg.drift_alarm_pct:g} % alarm")
        if J.phase == RELEARNING:
            txt += f", re-learning the baseline ({len(J.relearn)} of {cfg.relearn_windows})"

        def what(ev):
            cls = "" if ev.class_pct is None else f", nearest class {ev.class_pct:+g} %"
            return f"; change {ev.size_pct:+.2f} % ({ev.size:+.4g} kg m^2{cls})"
        return self._with_change(level, txt, J, u.window_index, what)

    def _width_text(self, u: TrendUpdate) -> tuple[int, str]:
        cfg, Wd = self.config, self._width
        wx, rate, rate_se = u.width_m, u.wear_rate_m_per_s, u.wear_rate_se_m_per_s
        ttl, ttl_lo, ttl_hi = u.time_to_limit_s, u.time_to_limit_low_s, u.time_to_limit_high_s
        if Wd.n == 0:
            return OK, ""
        if wx is None:
            return OK, (f"width learning the baseline: {Wd.progress()}" if Wd.phase == COMMISSIONING
                        else "width: a new time segment, no line yet")
        txt = f"width {wx * 1e3:.4g} mm"
        if rate is not None:
            txt += f", wear {rate * SECONDS_PER_DAY * 1e3:.3g} ± {rate_se * SECONDS_PER_DAY * 1e3:.2g} mm/day"
        if ttl is not None:
            txt += (f", limit {cfg.width_limit_m * 1e3:.4g} mm in {ttl / SECONDS_PER_DAY:.3g} d "
                    f"[{ttl_lo / SECONDS_PER_DAY:.3g}, {ttl_hi / SECONDS_PER_DAY:.3g}]")
        lv = _beyond(wx, cfg.width_warn_limit_m, cfg.width_limit_m)
        txt += _beyond_text(lv, f"{cfg.width_warn_limit_m * 1e3:.4g} mm warning", f"{cfg.width_limit_m * 1e3:.4g} mm limit")
        if lv == OK and ttl is not None and cfg.time_to_limit_warn_s is not None and ttl < cfg.time_to_limit_warn_s:
            lv = WARN
            txt += f" (< {cfg.time_to_limit_warn_s / SECONDS_PER_DAY:.3g} d)"
        if Wd.phase == COMMISSIONING:
            txt += f" (learning the baseline: {Wd.progress()})"
        return self._with_change(lv, txt, Wd, u.window_index, lambda ev: f"; width change {ev.size * 1e3:+.3g} mm")

    def _inputs_text(self, u: TrendUpdate) -> tuple[int, str]:
        """What went in and what did not: J1 windows fed / refused by reason; WARN for change_hold_windows after
        a skipped window or a time discontinuity, with the reason."""
        hold = self.config.change_hold_windows
        text, level = "", OK
        if self.inertia_refused or self.windows_skipped:
            text = f"; J1 fed {self.inertia_fed} of {self.n_windows} windows"
            refused = sum(self.inertia_refused.values())
            if refused:
                text += f", {refused} without J1 (" + ", ".join(
                    f"{n} {k}" for k, n in sorted(self.inertia_refused.items(), key=lambda kv: -kv[1])) + ")"
            skipped = sum(self.windows_skipped.values())
            if skipped:
                text += f", {skipped} skipped (" + ", ".join(
                    f"{n} {k}" for k, n in sorted(self.windows_skipped.items(), key=lambda kv: -kv[1])) + ")"
        if self.last_skip is not None and u.window_index - self.last_skip[0] < hold and not u.skipped:
            level, text = WARN, text + f"; window {self.last_skip[0]} skipped: {self.last_skip[1]}"
        if self.last_discontinuity is not None and u.window_index - self.last_discontinuity[0] < hold:
            level, text = WARN, text + f"; {self.last_discontinuity[1]}"
        return level, text

    def _with_change(self, level: int, txt: str, ch: Channel, idx: int, what) -> tuple[int, str]:
        """(level, txt) with the channel's held change (:meth:`_held_change`) appended and WARN raised."""
        phrase = self._held_change(ch, idx, what)
        return (level, txt) if phrase is None else (max(level, WARN), txt + phrase)

    def _held_change(self, ch: Channel, idx: int, what) -> str | None:
        """None unless the channel's last change is within change_hold_windows of window ``idx`` (WARN);
        then its phrase: ``what(event)`` + where it was detected ('' when the event was dropped)."""
        if ch.last_change_index is None or idx - ch.last_change_index >= self.config.change_hold_windows:
            return None
        ev = next((e for e in reversed(self.changes) if e.quantity == ch.name), None)
        return "" if ev is None else f"{what(ev)} detected at window {ev.window_index} (t = {ev.time_s:.0f} s)"

    # -- state (jident_ros.identify.trend_state) ------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-serialisable state (with the configuration), versioned."""
        return state_to_dict(self)

    @classmethod
    def from_dict(cls, d: Any, config: TrendConfig | None = None, plausible: dict | None = None) -> "TrendTracker":
        """Rebuild a tracker from :meth:`to_dict`'s output.  ``config`` replaces the saved
        configuration (thresholds may change between runs; width_regression_windows must match).
        Raises :class:`TrendStateError` on anything unusable or untrustworthy
        (:func:`~jident_ros.identify.trend_state.check_state`, ``plausible`` bands)."""
        return state_from_dict(cls, d, config, plausible)

    def save(self, path: str | os.PathLike):
        """Write the state atomically: temp file in the same directory, fsync, os.replace."""
        save_state(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike, config: TrendConfig | None = None,
             plausible: dict | None = None) -> "TrendTracker":
        """Read a state written by :meth:`save`.  TrendStateError when the file is unreadable,
        not JSON, of another kind or version, incomplete or fails the checks naming the field
        (FileNotFoundError when it does not exist)."""
        return load_state(cls, path, config, plausible)


def _isnan(v) -> bool:
    return isinstance(v, (float, np.floating)) and math.isnan(v)
