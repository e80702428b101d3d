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
import json
import math
import os
import tempfile
from dataclasses import asdict, dataclass
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

#: Levels, same values as diagnostic_msgs/DiagnosticStatus (and jident_ros.ros_io).
OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}

STATE_KIND = "jident_ros.identify.trend"
STATE_VERSION = 1


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
               width_m: float | None = None, width_se_m: float | None = None) -> TrendUpdate:
        """One window.  A quantity whose value and standard error are both None is not updated;
        a non-finite or non-positive input (or a value without its standard error, or a time
        not after the previous window's) refuses the whole window: the returned update has
        ``skipped=True`` and the reason, and the state is unchanged (the window is still counted)."""
        idx = self.n_windows
        self.n_windows += 1
        t, reason = _check_time(time_s)
        if reason is None and self.last_time_s is not None and t <= self.last_time_s:
            # equal: the same window again (e.g. re-delivered by a latched drive/window after a restart)
            reason = (f"time_s: {t!r} is before the previous window's {self.last_time_s!r}" if t < self.last_time_s
                      else f"time_s: {t!r} is the previous window's (the same window again)")
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
                reason = "no estimate in this window"
        if reason is not None:
            return self._snapshot(idx, t if t is not None else float("nan"), True, reason, ())
        self.last_time_s = t
        events = []
        y, se = vals["inertia_kgm2"]
        if y is not None:
            ev = self._inertia.update(idx, t, y, se, self._k, self._h)
            if ev is not None:
                events.append(ev)
        y, se = vals["width_m"]
        if y is not None:
            ev = self._width.update(idx, t, y, se, self._k, self._h)
            if ev is not None:
                events.append(ev)
        if events:
            self.changes.extend(events)
            del self.changes[:-self.config.max_changes_kept]
        return self._snapshot(idx, t, False, None, tuple(events))

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
            ttl, ttl_lo, ttl_hi, bool(events), events, OK, "")
        level, message = self._health(u)
        if skipped:
            message = f"window skipped ({reason}); {message}"
        return dataclasses.replace(u, level=level, message=message)

    def _health(self, u: TrendUpdate) -> tuple[int, str]:
        """(level, one-line message) of the tracker after the window of update ``u`` (its level/message unset)."""
        cfg = self.config
        J, Wd = self._inertia, self._width
        idx, jx, jb, jd, jdse, jdr = (u.window_index, u.inertia_kgm2, u.inertia_baseline_kgm2, u.inertia_drift_pct,
                                      u.inertia_drift_se_pct, u.inertia_drift_from_reference_pct)
        wx, rate, rate_se = u.width_m, u.wear_rate_m_per_s, u.wear_rate_se_m_per_s
        ttl, ttl_lo, ttl_hi = u.time_to_limit_s, u.time_to_limit_low_s, u.time_to_limit_high_s
        parts, level = [], OK
        if J.n == 0 and Wd.n == 0:
            return OK, f"learning the baseline: 0 of {cfg.commissioning_windows} windows (no estimate yet)"
        # J1
        if J.phase == COMMISSIONING:
            if J.n > 0 or J.baseline is None:
                parts.append(f"J1 learning the baseline: {J.progress()}"
                             + (f" (J1 {jx:.5g} kg m^2)" if jx is not None else ""))
        else:
            txt = f"J1 {jx:.5g} kg m^2 ({_fmt_pm(jd, jdse)} % of baseline {jb:.5g}"
            if J.reference != jb:
                txt += f"; {jdr:+.2f} % of commissioned {J.reference:.5g}"
            txt += ")"
            lv = _beyond(max(abs(jd), abs(jdr)), cfg.drift_warn_pct, cfg.drift_alarm_pct)
            level = max(level, lv)
            txt += _beyond_text(lv, f"{cfg.drift_warn_pct:g} % warning", f"{cfg.drift_alarm_pct:g} % alarm")
            if J.phase == RELEARNING:
                txt += f", re-learning the baseline ({len(J.relearn)} of {cfg.relearn_windows})"
            level, txt = self._with_change(level, txt, J, idx,
                                           lambda ev: f"; change {ev.size_pct:+.2f} % ({ev.size:+.4g} kg m^2)")
            parts.append(txt)
        # width
        if Wd.n > 0:
            if Wd.phase == COMMISSIONING and wx is None:
                parts.append(f"width learning the baseline: {Wd.progress()}")
            elif wx is not None:
                txt = f"width {wx * 1e3:.4g} mm"
                if rate is not None:
                    txt += f", wear {rate * SECONDS_PER_DAY * 1e3:.3g} ± {rate_se * SECONDS_PER_DAY * 1e3:.2g} mm/day"
                if ttl is not None:
                    txt += (f", limit {cfg.width_limit_m * 1e3:.4g} mm in {ttl / SECONDS_PER_DAY:.3g} d "
                            f"[{ttl_lo / SECONDS_PER_DAY:.3g}, {ttl_hi / SECONDS_PER_DAY:.3g}]")
                lv = _beyond(wx, cfg.width_warn_limit_m, cfg.width_limit_m)
                txt += _beyond_text(lv, f"{cfg.width_warn_limit_m * 1e3:.4g} mm warning",
                                    f"{cfg.width_limit_m * 1e3:.4g} mm limit")
                if lv == OK and ttl is not None and cfg.time_to_limit_warn_s is not None \
                        and ttl < cfg.time_to_limit_warn_s:
                    lv = WARN
                    txt += f" (< {cfg.time_to_limit_warn_s / SECONDS_PER_DAY:.3g} d)"
                level = max(level, lv)
                if Wd.phase == COMMISSIONING:
                    txt += f" (learning the baseline: {Wd.progress()})"
                level, txt = self._with_change(level, txt, Wd, idx, lambda ev: f"; width change {ev.size * 1e3:+.3g} mm")
                parts.append(txt)
        return level, "; ".join(parts)

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

    # -- state --------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-serialisable state (with the configuration), versioned."""
        return {"kind": STATE_KIND, "version": STATE_VERSION, "config": self.config.to_dict(),
                "n_windows": self.n_windows, "last_time_s": self.last_time_s,
                "changes": [asdict(c) for c in self.changes],
                "inertia": self._inertia.to_dict(), "width": self._width.to_dict()}

    @classmethod
    def from_dict(cls, d: Any, config: TrendConfig | None = None) -> "TrendTracker":
        """Rebuild a tracker from :meth:`to_dict`'s output.  ``config`` replaces the saved
        configuration (thresholds may change between runs; width_regression_windows must match).
        Raises :class:`TrendStateError` on anything unusable."""
        if not isinstance(d, dict):
            raise TrendStateError(f"trend state: expected a JSON object, got {type(d).__name__}")
        if d.get("kind") != STATE_KIND:
            raise TrendStateError(f"trend state: kind {d.get('kind')!r}, expected {STATE_KIND!r}")
        if d.get("version") != STATE_VERSION:
            raise TrendStateError(f"trend state: version {d.get('version')!r}, this code reads version {STATE_VERSION}")
        try:
            cfg = config if config is not None else TrendConfig.from_dict(d["config"])
            tr = cls(cfg)
            tr.n_windows = int(d["n_windows"])
            tr.last_time_s = None if d["last_time_s"] is None else float(d["last_time_s"])
            tr.changes = [ChangeEvent(**c) for c in d["changes"]]
            tr._inertia.load(d["inertia"])
            tr._width.load(d["width"])
        except TrendStateError:
            raise
        except KeyError as e:
            raise TrendStateError(f"trend state: missing field {e.args[0]!r}") from e
        except (TypeError, ValueError, IndexError) as e:
            raise TrendStateError(f"trend state: bad content ({e})") from e
        return tr

    def save(self, path: str | os.PathLike):
        """Write the state atomically: temp file in the same directory, fsync, os.replace."""
        path = os.fspath(path)
        directory = os.path.dirname(os.path.abspath(path))
        text = json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":"))
        fd, tmp = tempfile.mkstemp(prefix=os.path.basename(path) + ".", suffix=".tmp", dir=directory)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
        try:
            dfd = os.open(directory, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass

    @classmethod
    def load(cls, path: str | os.PathLike, config: TrendConfig | None = None) -> "TrendTracker":
        """Read a state written by :meth:`save`.  TrendStateError when the file is unreadable,
        not JSON, of another kind or version, or incomplete (FileNotFoundError when it does not exist)."""
        path = os.fspath(path)
        try:
            with open(path, encoding="utf-8") as f:
                d = json.load(f)
        except FileNotFoundError:
            raise
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise TrendStateError(f"{path}: not a readable trend state ({e})") from e
        try:
            return cls.from_dict(d, config)
        except TrendStateError as e:
            raise TrendStateError(f"{path}: {e}") from e


def _isnan(v) -> bool:
    return isinstance(v, (float, np.floating)) and math.isnan(v)
