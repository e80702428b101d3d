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

Evaluation helpers: :func:`simulate_series` (synthetic estimate series with miscalibrated standard
errors and occasional outliers) and :func:`measure_targets` (detection delay, false-alarm rate,
wear-rate accuracy).
"""
from __future__ import annotations

import functools
import json
import math
import os
import tempfile
from collections import deque
from dataclasses import asdict, dataclass, fields
from typing import Any, Sequence

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2, norm

#: Levels, same values as diagnostic_msgs/DiagnosticStatus (and jident_ros.ros_io).
OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}

STATE_KIND = "jident_ros.identify.trend"
STATE_VERSION = 1
SECONDS_PER_DAY = 86400.0
#: Siegmund's correction of the threshold for the overshoot: b = h + 2 * 0.583 (unit-variance increments).
SIEGMUND_OVERSHOOT = 1.166

COMMISSIONING, MONITORING, RELEARNING = "commissioning", "monitoring", "relearning"
_PHASES = (COMMISSIONING, MONITORING, RELEARNING)


class TrendStateError(ValueError):
    """A saved trend state that cannot be used (corrupt, wrong kind or version, missing field)."""


# --------------------------------------------------------------------------------------------------
# CUSUM design (Siegmund's approximation)
# --------------------------------------------------------------------------------------------------

def siegmund_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0) -> float:
    """Average run length (windows) of a one-sided upper CUSUM S = max(0, S + z - k) > h whose
    increments z are N(shift, 1): Siegmund's approximation
    ARL = (exp(-2 D b) + 2 D b - 1) / (2 D^2), D = shift - k, b = h + 1.166 (b^2 when D = 0)."""
    d = shift_sd - reference_sd
    b = threshold_sd + SIEGMUND_OVERSHOOT
    if abs(d) < 1e-9:
        return b * b
    return (math.exp(-2.0 * d * b) + 2.0 * d * b - 1.0) / (2.0 * d * d)


def two_sided_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0) -> float:
    """ARL of the two-sided CUSUM (upper and lower, same k and h): 1/ARL = 1/ARL+ + 1/ARL-."""
    return 1.0 / (1.0 / siegmund_arl(threshold_sd, reference_sd, shift_sd)
                  + 1.0 / siegmund_arl(threshold_sd, reference_sd, -shift_sd))


def cusum_arl(threshold_sd: float, reference_sd: float, shift_sd: float = 0.0, sd: float = 1.0,
              two_sided: bool = True, nodes: int = 64) -> float:
    """Average run length of the CUSUM whose increments are N(shift, sd^2), from the integral equation
    L(u) = 1 + L(0) P(z <= k - u) + int_0^h L(x) f(x + k - u) dx (Page; Brook & Evans' continuous form),
    solved by Nystrom's method on ``nodes`` Gauss-Legendre points: exact up to the quadrature (the
    clipping of the increments at +-innovation_clip_sd is neglected).  Two-sided: 1/ARL = 1/ARL+ + 1/ARL-."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x = 0.5 * threshold_sd * (x + 1.0)
    w = 0.5 * threshold_sd * w
    u = np.concatenate(([0.0], x))

    def one(mu):
        arg = (x[None, :] + reference_sd - u[:, None] - mu) / sd
        A = np.zeros((nodes + 1, nodes + 1))
        A[:, 0] = -norm.cdf((reference_sd - u - mu) / sd)
        A[:, 1:] = -w[None, :] * norm.pdf(arg) / sd
        A[np.arange(nodes + 1), np.arange(nodes + 1)] += 1.0
        return float(np.linalg.solve(A, np.ones(nodes + 1))[0])

    up = one(shift_sd)
    if not two_sided:
        return up
    return 1.0 / (1.0 / up + 1.0 / one(-shift_sd))


@functools.lru_cache(maxsize=64)
def cusum_threshold_for_arl(arl_windows: float, reference_sd: float, two_sided: bool = True,
                            method: str = "integral") -> float:
    """The threshold h (in standard deviations) whose in-control ARL (N(0, 1) increments) is
    ``arl_windows`` windows: ``method="integral"`` (default) from :func:`cusum_arl`, ``"siegmund"``
    from Siegmund's closed form (which overestimates the ARL for large k: at k = 2 by ~1.7x at 2e4)."""
    if not arl_windows > 1.0:
        raise ValueError(f"arl_windows: must be > 1, got {arl_windows!r}")
    if method == "siegmund":
        arl = lambda h: two_sided_arl(h, reference_sd) if two_sided else siegmund_arl(h, reference_sd)  # noqa: E731
        hi = min(1.0e4, 340.0 / reference_sd)      # keeps exp(2 k b) finite
    elif method == "integral":
        arl = lambda h: cusum_arl(h, reference_sd, two_sided=two_sided)  # noqa: E731
        hi = cusum_threshold_for_arl(arl_windows, reference_sd, two_sided, "siegmund") + 5.0
    else:
        raise ValueError(f"method: 'integral' or 'siegmund', got {method!r}")
    f = lambda h: math.log(arl(h)) - math.log(arl_windows)  # noqa: E731
    return float(brentq(f, 1e-6, hi, xtol=1e-9))


def coverage_to_se_scale(coverage: float) -> float:
    """True standard deviation / reported standard error for which the reported 95 % interval
    (+-1.96 se) covers the truth with probability ``coverage`` (Gaussian errors)."""
    return float(norm.ppf(0.975) / norm.ppf(0.5 + coverage / 2.0))


# --------------------------------------------------------------------------------------------------
# Configuration and results
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TrendConfig:
    """Parameters of :class:`TrendTracker`; units in the names, ``_sd`` = in standard deviations of
    the standardised innovation, ``_pct`` = per cent of the baseline."""

    #: commissioning: number of windows with an estimate (per quantity) used to learn the baseline
    commissioning_windows: int = 20
    #: commissioning by duration instead (s since the quantity's first window; >= 3 windows); None: by count
    commissioning_duration_s: float | None = None
    #: given baselines (skip the J1 / width commissioning); standard errors of the given values
    inertia_baseline_kgm2: float | None = None
    inertia_baseline_se_kgm2: float = 0.0
    width_baseline_m: float | None = None
    width_baseline_se_m: float = 0.0
    #: in-control two-sided average run length (windows) the CUSUM threshold is designed for (the ARL
    #: integral equation, :func:`cusum_arl`): the designed false-change rate is 1 / this per window, i.e.
    #: 1e4 / this per 10,000 steady windows (default 0.033 with calibrated standard errors, 0.38 when they are
    #: 12 % too small -- a 92 % coverage of the 95 % interval; the target is <= 1)
    target_arl_windows: float = 3.0e5
    #: CUSUM reference value k (half the standardised shift it is tuned to).  1.5 rather than the 2.5
    #: half of a 2.5 % step at se 0.5 %: the gap estimator's se varies 0.4-1.3 % between windows, and a
    #: window with a large se (z ~ 2 after the step) must still add to the sum (docs/results.md)
    cusum_reference_sd: float = 1.5
    #: CUSUM threshold h; None: from target_arl_windows and cusum_reference_sd
    cusum_threshold_sd: float | None = None
    #: standardised innovations are clipped to +-this (outlier robustness, CUSUM and J1 smoother);
    #: innovation_clip_sd - cusum_reference_sd < h keeps a single outlier from firing (3 < 3.83 by default)
    innovation_clip_sd: float = 4.5
    #: learn a factor s >= 1 for the reported standard errors from the commissioning scatter
    se_scale_from_commissioning: bool = False
    se_scale_max: float = 3.0
    #: J1 local-level random walk, per cent of the baseline per window (1 sd)
    inertia_process_sd_pct_per_window: float = 0.02
    #: windows (since the estimated onset) averaged into the new baseline after a change
    relearn_windows: int = 5
    #: a detected change keeps the level at WARN for this many windows
    change_hold_windows: int = 24
    #: J1 drift from the baseline (and from the commissioned reference): WARN / ERROR beyond, per cent
    drift_warn_pct: float = 2.0
    drift_alarm_pct: float = 5.0
    #: backlash width limit (ERROR beyond) and warning width (None: 90 % of the limit), m
    width_limit_m: float = 0.012
    width_warn_m: float | None = None
    #: WARN when the projected time to width_limit_m is shorter (None: no such warning), s
    time_to_limit_warn_s: float | None = 30.0 * SECONDS_PER_DAY
    #: width regression: number of most recent windows of the current segment
    width_regression_windows: int = 50
    #: floor of the width standard error (model error of the width estimate), m
    width_se_floor_m: float = 1.0e-6
    #: run the CUSUM on the width (abrupt jumps off the wear line)
    width_change_detection: bool = True
    #: the wear rate is "significantly positive" when slope > this * se; also the interval half-width
    wear_significance_sd: float = 1.96
    #: change events kept in the state
    max_changes_kept: int = 100

    def __post_init__(self):
        def bad(name, rule):
            raise ValueError(f"{name}: must be {rule}, got {getattr(self, name)!r}")

        def pos(name, allow_none=False, allow_zero=False):
            v = getattr(self, name)
            if v is None and allow_none:
                return
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0 or (v == 0 and not allow_zero):
                bad(name, "a finite number >= 0" if allow_zero else "a finite number > 0")

        def count(name, minimum):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
                bad(name, f"an integer >= {minimum}")

        count("commissioning_windows", 2)
        count("relearn_windows", 1)
        count("change_hold_windows", 0)
        count("width_regression_windows", 3)
        count("max_changes_kept", 1)
        for n in ("commissioning_duration_s", "inertia_baseline_kgm2", "width_baseline_m", "cusum_threshold_sd",
                  "width_warn_m", "time_to_limit_warn_s"):
            pos(n, allow_none=True)
        for n in ("inertia_baseline_se_kgm2", "width_baseline_se_m", "inertia_process_sd_pct_per_window",
                  "width_se_floor_m"):
            pos(n, allow_zero=True)
        for n in ("cusum_reference_sd", "innovation_clip_sd", "drift_warn_pct", "drift_alarm_pct", "width_limit_m",
                  "wear_significance_sd"):
            pos(n)
        pos("target_arl_windows")
        if self.target_arl_windows <= 1:
            bad("target_arl_windows", "> 1")
        pos("se_scale_max")
        if self.se_scale_max < 1:
            bad("se_scale_max", ">= 1")
        if self.innovation_clip_sd <= self.cusum_reference_sd:
            bad("innovation_clip_sd", f"> cusum_reference_sd ({self.cusum_reference_sd})")
        if self.drift_alarm_pct < self.drift_warn_pct:
            bad("drift_alarm_pct", f">= drift_warn_pct ({self.drift_warn_pct})")

    @property
    def threshold_sd(self) -> float:
        """The CUSUM threshold h in use."""
        if self.cusum_threshold_sd is not None:
            return float(self.cusum_threshold_sd)
        return cusum_threshold_for_arl(self.target_arl_windows, self.cusum_reference_sd)

    @property
    def width_warn_limit_m(self) -> float:
        return self.width_warn_m if self.width_warn_m is not None else 0.9 * self.width_limit_m

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_parameters(cls, params) -> "TrendConfig":
        """From node parameters (``trend_*`` names, :data:`PARAMETER_FIELDS`; defaults in
        jident_ros.parameters.TREND): 0 stands for None where the field takes None (ROS parameters
        cannot be None); other keys are ignored, missing ones keep the default.  ValueError naming the
        parameter and its value on a bad one."""
        return _config_from_parameters(cls, params)

    @classmethod
    def from_dict(cls, d: dict) -> "TrendConfig":
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"{sorted(unknown)[0]}: unknown trend parameter")
        return cls(**d)


#: parameter name -> TrendConfig field, for the parameters that map one to one.
PARAMETER_FIELDS = {
    "trend_commissioning_windows": "commissioning_windows",
    "trend_commissioning_duration_s": "commissioning_duration_s",
    "trend_inertia_baseline_kgm2": "inertia_baseline_kgm2",
    "trend_inertia_baseline_se_kgm2": "inertia_baseline_se_kgm2",
    "trend_width_baseline_m": "width_baseline_m",
    "trend_width_baseline_se_m": "width_baseline_se_m",
    "trend_target_arl_windows": "target_arl_windows",
    "trend_cusum_reference_sd": "cusum_reference_sd",
    "trend_cusum_threshold_sd": "cusum_threshold_sd",
    "trend_innovation_clip_sd": "innovation_clip_sd",
    "trend_se_scale_from_commissioning": "se_scale_from_commissioning",
    "trend_se_scale_max": "se_scale_max",
    "trend_inertia_process_sd_pct_per_window": "inertia_process_sd_pct_per_window",
    "trend_relearn_windows": "relearn_windows",
    "trend_change_hold_windows": "change_hold_windows",
    "trend_drift_warn_pct": "drift_warn_pct",
    "trend_drift_alarm_pct": "drift_alarm_pct",
    "trend_width_limit_m": "width_limit_m",
    "trend_width_warn_m": "width_warn_m",
    "trend_time_to_limit_warn_s": "time_to_limit_warn_s",
    "trend_width_regression_windows": "width_regression_windows",
    "trend_width_se_floor_m": "width_se_floor_m",
    "trend_width_change_detection": "width_change_detection",
    "trend_wear_significance_sd": "wear_significance_sd",
    "trend_max_changes_kept": "max_changes_kept",
}
#: Fields whose "not set" (None) is given as 0 in the parameters.
ZERO_IS_NONE = {"commissioning_duration_s", "inertia_baseline_kgm2", "width_baseline_m", "cusum_threshold_sd",
                "width_warn_m", "time_to_limit_warn_s"}
#: Node parameters of the trend that are not TrendConfig fields.
NODE_ONLY = {"trend_enabled", "trend_state_file"}
_INT_FIELDS = {"commissioning_windows", "relearn_windows", "change_hold_windows", "width_regression_windows",
               "max_changes_kept"}
_BOOL_FIELDS = {"se_scale_from_commissioning", "width_change_detection"}


def _config_from_parameters(cls, params) -> "TrendConfig":
    kw = {}
    for pname, fname in PARAMETER_FIELDS.items():
        if pname not in params:
            continue
        v = params[pname]
        if fname in _BOOL_FIELDS:
            if not isinstance(v, bool):
                raise ValueError(f"{pname}: must be true or false, got {v!r}")
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"{pname}: must be a number, got {v!r}")
        elif fname in _INT_FIELDS:
            if float(v) != int(v):
                raise ValueError(f"{pname}: must be an integer, got {v!r}")
            v = int(v)
        elif fname in ZERO_IS_NONE and v == 0:
            v = None
        else:
            v = float(v)
        kw[fname] = v
    try:
        return cls(**kw)
    except ValueError as exc:
        text = str(exc)
        for pname, fname in PARAMETER_FIELDS.items():
            if text.startswith(fname + ":"):
                raise ValueError("trend_" + text) from None
        raise



@dataclass(frozen=True)
class ChangeEvent:
    """A detected change of J1 ("inertia", kg m^2) or of the width ("width", m)."""

    quantity: str
    time_s: float               # time of the window at which it was detected
    window_index: int           # index of that window (counting every update call from 0)
    onset_window_index: int     # estimated first window of the new level (CUSUM's last reset)
    onset_time_s: float
    size: float                 # new level - old baseline (width: - the old line's prediction), kg m^2 or m
    size_se: float
    size_pct: float             # per cent of the old baseline
    sign: int                   # +1 increase, -1 decrease


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


# --------------------------------------------------------------------------------------------------
# Channels
# --------------------------------------------------------------------------------------------------

class _Cusum:
    """Two-sided CUSUM on clipped standardised innovations; remembers the onset of each excursion."""

    __slots__ = ("pos", "neg", "pos_start", "neg_start")

    def __init__(self):
        self.reset(0)

    def reset(self, next_index: int):
        self.pos = self.neg = 0.0
        self.pos_start = self.neg_start = next_index

    def step(self, z: float, k: float, h: float, index: int) -> int:
        p = self.pos + z - k
        if p <= 0.0:
            p = 0.0
            self.pos_start = index + 1
        n = self.neg - z - k
        if n <= 0.0:
            n = 0.0
            self.neg_start = index + 1
        self.pos, self.neg = p, n
        if p > h or n > h:
            return 1 if p >= n else -1
        return 0

    @property
    def stat(self) -> float:
        return self.pos if self.pos >= self.neg else self.neg

    def to_list(self):
        return [self.pos, self.neg, self.pos_start, self.neg_start]

    @classmethod
    def from_list(cls, v):
        c = cls()
        c.pos, c.neg = float(v[0]), float(v[1])
        c.pos_start, c.neg_start = int(v[2]), int(v[3])
        return c


def _wmean(points) -> tuple[float, float, float]:
    """Weighted mean of (index, t, y, se) points: (mean, 1/sum w, chi^2 about the mean)."""
    sw = swy = 0.0
    for p in points:
        w = 1.0 / (p[3] * p[3])
        sw += w
        swy += w * p[2]
    m = swy / sw
    c2 = 0.0
    for p in points:
        r = (p[2] - m) / p[3]
        c2 += r * r
    return m, 1.0 / sw, c2


#: The commissioning scatter scales the reported standard errors only when significant at this level.
SE_SCALE_TEST_LEVEL = 0.99
#: Huber's tuning constant (standardised residuals) for the robust baseline means and the se-scale estimate.
HUBER_C = 2.5
#: E[min(Z^2, c^2)] for Z ~ N(0, 1): consistency of Huber's proposal-2 scale.
_HUBER_KAPPA = float((2 * norm.cdf(HUBER_C) - 1) - 2 * HUBER_C * norm.pdf(HUBER_C)
                     + 2 * HUBER_C ** 2 * norm.sf(HUBER_C))


def _m_scale(r: np.ndarray, dof_factor: float = 1.0) -> float:
    """Robust scale of standardised residuals r (Huber's proposal 2, started from the MAD): ~1 when
    the reported standard errors are right, insensitive to a few outliers."""
    r = np.asarray(r, dtype=float)
    if not np.any(r):
        return 0.0
    s = 1.4826 * float(np.median(np.abs(r)))
    if not s > 0.0:
        s = math.sqrt(float(np.mean(r * r))) or 1.0
    for _ in range(50):
        s_new = s * math.sqrt(float(np.mean(np.minimum((r / s) ** 2, HUBER_C ** 2))) / _HUBER_KAPPA * dof_factor)
        if abs(s_new - s) <= 1e-10 * s:
            break
        s = s_new
    return s


def _huber_mean(points, estimate_scale: bool = False) -> tuple[float, float, float]:
    """Huber M-estimate of the level of (index, t, y, se) points.  Returns (mean, 1 / sum(1/se^2),
    scale) where scale is the robust scale of the standardised residuals when ``estimate_scale``
    (else 1): one outlier moves the mean by at most ~HUBER_C * se / n."""
    y = np.array([p[2] for p in points])
    se = np.array([p[3] for p in points])
    w0 = 1.0 / (se * se)
    n = y.size
    m = float(np.median(y)) if n > 2 else float(w0 @ y / w0.sum())
    s = 1.0
    for _ in range(50):
        r = (y - m) / se
        if estimate_scale and n > 2:
            s = _m_scale(r, n / (n - 1.0))
        a = np.abs(r) / max(s, 1e-300)
        wt = w0 * np.minimum(1.0, HUBER_C / np.maximum(a, 1e-300))
        m_new = float(wt @ y / wt.sum())
        if abs(m_new - m) <= 1e-13 * max(abs(m), 1e-300):
            m = m_new
            break
        m = m_new
    return m, 1.0 / float(w0.sum()), s


class _Channel:
    """What both quantities share: commissioning, baseline, se scale, CUSUM, re-learning, history."""

    HISTORY = 256

    def __init__(self, cfg: TrendConfig, name: str, given: float | None, given_se: float, floor: float):
        self.cfg, self.name, self.floor = cfg, name, floor
        self.scale = 1.0
        self.cusum = _Cusum()
        self.history: deque = deque(maxlen=max(self.HISTORY, cfg.width_regression_windows))
        self.comm: list = []           # commissioning points (index, t, y, se_eff)
        self.relearn: list = []
        self.first_time: float | None = None
        self.n = 0                      # windows with a value
        self.last_change_index: int | None = None
        if given is not None:
            self.phase = MONITORING
            self.baseline, self.baseline_var = float(given), float(given_se) ** 2
            self.reference, self.reference_var = self.baseline, self.baseline_var
        else:
            self.phase = COMMISSIONING
            self.baseline = self.baseline_var = self.reference = self.reference_var = None

    # -- shared pieces ------------------------------------------------------------------------------
    def _commissioning_done(self, t: float) -> bool:
        cfg = self.cfg
        if cfg.commissioning_duration_s is not None:
            return len(self.comm) >= 3 and t - self.first_time >= cfg.commissioning_duration_s
        return len(self.comm) >= cfg.commissioning_windows

    def progress(self) -> str:
        cfg = self.cfg
        if cfg.commissioning_duration_s is not None:
            done = 0.0 if self.first_time is None or not self.history else self.history[-1][1] - self.first_time
            return f"{len(self.comm)} windows, {done:.0f} of {cfg.commissioning_duration_s:.0f} s"
        return f"{len(self.comm)} of {cfg.commissioning_windows} windows"

    def _set_scale(self, robust_scale: float, dof: int):
        """Apply the commissioning scatter's scale factor when it is significantly above 1
        (robust scale^2 above the 99 % quantile of chi^2_dof / dof), capped at se_scale_max."""
        if self.cfg.se_scale_from_commissioning and dof > 0 \
                and robust_scale ** 2 > chi2.ppf(SE_SCALE_TEST_LEVEL, dof) / dof:
            self.scale = min(robust_scale, self.cfg.se_scale_max)

    def _commissioned(self, m: float, v: float, idx: int):
        """End of commissioning at window ``idx``: the baseline (and the kept reference) m with variance
        v x scale^2, the history's standard errors scaled, monitoring from the next window."""
        self.baseline, self.baseline_var = m, v * self.scale ** 2
        self.reference, self.reference_var = self.baseline, self.baseline_var
        self.history = deque(((i, tt, yy, s * self.scale) for i, tt, yy, s in self.history),
                             maxlen=self.history.maxlen)
        self.comm = []
        self.phase = MONITORING
        self.cusum.reset(idx + 1)

    def _innovation(self, z: float) -> float:
        c = self.cfg.innovation_clip_sd
        return c if z > c else (-c if z < -c else z)

    def _base_dict(self) -> dict:
        return {"phase": self.phase, "scale": self.scale, "cusum": self.cusum.to_list(),
                "history": [list(p) for p in self.history], "comm": [list(p) for p in self.comm],
                "relearn": [list(p) for p in self.relearn], "first_time": self.first_time, "n": self.n,
                "last_change_index": self.last_change_index, "baseline": self.baseline,
                "baseline_var": self.baseline_var, "reference": self.reference, "reference_var": self.reference_var}

    def _load_base(self, d: dict):
        if d["phase"] not in _PHASES:
            raise TrendStateError(f"{self.name}.phase: unknown phase {d['phase']!r}")
        self.phase = d["phase"]
        self.scale = float(d["scale"])
        self.cusum = _Cusum.from_list(d["cusum"])
        pt = lambda p: (int(p[0]), float(p[1]), float(p[2]), float(p[3]))  # noqa: E731
        self.history = deque((pt(p) for p in d["history"]), maxlen=self.history.maxlen)
        self.comm = [pt(p) for p in d["comm"]]
        self.relearn = [pt(p) for p in d["relearn"]]
        self.first_time = None if d["first_time"] is None else float(d["first_time"])
        self.n = int(d["n"])
        self.last_change_index = None if d["last_change_index"] is None else int(d["last_change_index"])
        opt = lambda v: None if v is None else float(v)  # noqa: E731
        self.baseline, self.baseline_var = opt(d["baseline"]), opt(d["baseline_var"])
        self.reference, self.reference_var = opt(d["reference"]), opt(d["reference_var"])


class _InertiaChannel(_Channel):
    """J1: Kalman local level; CUSUM on (y - baseline) / sqrt((s se)^2 + var baseline)."""

    def __init__(self, cfg: TrendConfig):
        super().__init__(cfg, "inertia", cfg.inertia_baseline_kgm2, cfg.inertia_baseline_se_kgm2, 0.0)
        self.x = self.baseline
        self.P = self.baseline_var
        self.seg_sw = self.seg_swy = 0.0     # running sums of a re-learnt baseline still being refined
        self.seg_n = 0

    def update(self, idx: int, t: float, y: float, se: float, k: float, h: float) -> ChangeEvent | None:
        cfg = self.cfg
        if self.first_time is None:
            self.first_time = t
        self.n += 1
        if self.phase == COMMISSIONING:
            p = (idx, t, y, se)
            self.comm.append(p)
            self.history.append(p)
            self.x, self.P, _ = _wmean(self.comm)
            if self._commissioning_done(t):
                m, v, rs = _huber_mean(self.comm, estimate_scale=True)
                self._set_scale(rs, len(self.comm) - 1)
                self._commissioned(m, v, idx)
                self.x, self.P = m, self.baseline_var
            return None
        se = se * self.scale
        p = (idx, t, y, se)
        self.history.append(p)
        r = se * se
        # Kalman local level with clipped innovation
        if self.x is None:
            self.x, self.P = y, r
        else:
            q = (cfg.inertia_process_sd_pct_per_window * 0.01 * self.baseline) ** 2
            P = self.P + q
            S = P + r
            nu = y - self.x
            lim = cfg.innovation_clip_sd * math.sqrt(S)
            if nu > lim:
                nu = lim
            elif nu < -lim:
                nu = -lim
            K = P / S
            self.x += K * nu
            self.P = (1.0 - K) * P
        if self.phase == RELEARNING:
            self.relearn.append(p)
            if len(self.relearn) >= cfg.relearn_windows:
                self._rebaseline(idx)
            return None
        sd = math.sqrt(r + self.baseline_var)
        zraw = (y - self.baseline) / sd
        z = self._innovation(zraw)
        if self.seg_n:
            # re-learnt baseline: refined by the following windows (winsorised) up to commissioning_windows
            w = 1.0 / r
            self.seg_sw += w
            self.seg_swy += w * (self.baseline + z * sd if z != zraw else y)
            self.seg_n += 1
            self.baseline, self.baseline_var = self.seg_swy / self.seg_sw, 1.0 / self.seg_sw
            if self.seg_n >= cfg.commissioning_windows:
                self.seg_n = 0
        sign = self.cusum.step(z, k, h, idx)
        if not sign:
            return None
        onset = self.cusum.pos_start if sign > 0 else self.cusum.neg_start
        seg = [q for q in self.history if q[0] >= onset] or [p]
        m, v, _ = _huber_mean(seg)
        size = m - self.baseline
        ev = ChangeEvent("inertia", t, idx, seg[0][0], seg[0][1], size, math.sqrt(v + self.baseline_var),
                         100.0 * size / self.baseline, sign)
        # restart the smoother on the new segment, re-learn the baseline from it
        self.x, self.P = m, v
        self.relearn = list(seg)
        self.phase = RELEARNING
        self.last_change_index = idx
        self.seg_n = 0
        self.cusum.reset(idx + 1)
        if len(self.relearn) >= cfg.relearn_windows:
            self._rebaseline(idx)
        return ev

    def _rebaseline(self, idx: int):
        m, v, _ = _huber_mean(self.relearn)
        self.baseline, self.baseline_var = m, v
        self.seg_sw, self.seg_swy, self.seg_n = 1.0 / v, m / v, len(self.relearn)
        if self.seg_n >= self.cfg.commissioning_windows:
            self.seg_n = 0
        self.relearn = []
        self.phase = MONITORING
        self.cusum.reset(idx + 1)

    def to_dict(self) -> dict:
        d = self._base_dict()
        d.update(x=self.x, P=self.P, seg_sw=self.seg_sw, seg_swy=self.seg_swy, seg_n=self.seg_n)
        return d

    def load(self, d: dict):
        self._load_base(d)
        self.x = None if d["x"] is None else float(d["x"])
        self.P = None if d["P"] is None else float(d["P"])
        self.seg_sw, self.seg_swy, self.seg_n = float(d["seg_sw"]), float(d["seg_swy"]), int(d["seg_n"])


class _WidthChannel(_Channel):
    """Width: weighted linear regression over the last W windows of the segment; CUSUM on the
    one-step prediction error."""

    def __init__(self, cfg: TrendConfig):
        super().__init__(cfg, "width", cfg.width_baseline_m, cfg.width_baseline_se_m, cfg.width_se_floor_m)
        W = cfg.width_regression_windows
        self.t = np.zeros(W)
        self.y = np.zeros(W)
        self.w = np.zeros(W)
        self.count = 0
        self.pos = 0
        self.t0 = 0.0
        self.fit = None      # (t_mean_rel, y_mean, slope, s2, sum_w, sxx) or None

    def _reset_segment(self, t0: float):
        self.count = self.pos = 0
        self.t0 = t0
        self.fit = None

    def _add(self, t: float, y: float, se: float):
        if self.count == 0:
            self.t0 = t
        W = self.t.shape[0]
        self.t[self.pos] = t - self.t0
        self.y[self.pos] = y
        self.w[self.pos] = 1.0 / (se * se)
        self.pos = (self.pos + 1) % W
        if self.count < W:
            self.count += 1
        self._refit()

    def _refit(self):
        n = self.count
        t, y, w = self.t[:n], self.y[:n], self.w[:n]
        sw = float(w.sum())
        tm = float(w @ t) / sw
        ym = float(w @ y) / sw
        dt = t - tm
        wdt = w * dt
        sxx = float(wdt @ dt)
        if n >= 2 and sxx > 0.0:
            b = float(wdt @ (y - ym)) / sxx
            if n > 2:
                r = y - ym - b * dt
                c2 = float(w @ (r * r))
                s2 = max(1.0, c2 / (n - 2))
            else:
                s2 = 1.0
        else:
            b, s2, sxx = 0.0, 1.0, 0.0
        self.fit = (tm, ym, b, s2, sw, sxx)

    def predict(self, t: float) -> tuple[float, float] | None:
        """Regression line at time t: (value, variance)."""
        if self.fit is None:
            return None
        tm, ym, b, s2, sw, sxx = self.fit
        d = t - self.t0 - tm
        var = s2 / sw + (s2 * d * d / sxx if sxx > 0.0 else 0.0)
        return ym + b * d, var

    def slope(self) -> tuple[float, float] | None:
        if self.fit is None or self.fit[5] <= 0.0 or self.count < 3:
            return None
        tm, ym, b, s2, sw, sxx = self.fit
        return b, s2 / sxx

    def update(self, idx: int, t: float, y: float, se: float, k: float, h: float) -> ChangeEvent | None:
        cfg = self.cfg
        if self.first_time is None:
            self.first_time = t
        self.n += 1
        se = max(se, self.floor)
        if self.phase == COMMISSIONING:
            p = (idx, t, y, se)
            self.comm.append(p)
            self.history.append(p)
            self._add(t, y, se)
            if self._commissioning_done(t):
                m, v, rs = _huber_mean(self.comm, estimate_scale=True)
                if self.fit is not None and self.count >= 3:   # scatter about the line, not the mean (wear)
                    tm, ym, b, s2, sw, sxx = self.fit
                    n = self.count
                    r = (self.y[:n] - ym - b * (self.t[:n] - tm)) * np.sqrt(self.w[:n])
                    rs = _m_scale(r, n / (n - 2.0))
                    dof = n - 2
                else:
                    dof = len(self.comm) - 1
                self._set_scale(rs, dof)
                self.w[:self.count] /= self.scale ** 2
                self._refit()
                self._commissioned(m, v, idx)
            return None
        se = se * self.scale
        p = (idx, t, y, se)
        self.history.append(p)
        ev = None
        y_fit = y
        if self.count >= 3:
            pred, pvar = self.predict(t)
            sd = math.sqrt(se * se + pvar)
            zraw = (y - pred) / sd
            z = self._innovation(zraw)
            if z != zraw:                       # winsorised into the regression (outlier robustness)
                y_fit = pred + z * sd
            sign = self.cusum.step(z, k, h, idx) \
                if self.phase == MONITORING and cfg.width_change_detection else 0
            if sign:
                onset = self.cusum.pos_start if sign > 0 else self.cusum.neg_start
                seg = [q for q in self.history if q[0] >= onset] or [p]
                off = [(q[0], q[1], q[2] - self.predict(q[1])[0], q[3]) for q in seg]
                size, v, _ = _huber_mean(off)
                old_var = self.predict(seg[0][1])[1]
                m, vm, _ = _huber_mean(seg)
                ev = ChangeEvent("width", t, idx, seg[0][0], seg[0][1], size, math.sqrt(v + old_var),
                                 100.0 * size / self.baseline, sign)
                self._reset_segment(seg[0][1])
                for q in seg:
                    self._add(q[1], q[2], q[3])
                self.relearn = list(seg)
                self.phase = RELEARNING
                self.last_change_index = idx
                self.cusum.reset(idx + 1)
                if len(self.relearn) >= cfg.relearn_windows:
                    self.baseline, self.baseline_var = m, vm
                    self.relearn = []
                    self.phase = MONITORING
                return ev
        self._add(t, y_fit, se)
        if self.phase == RELEARNING:
            self.relearn.append(p)
            if len(self.relearn) >= cfg.relearn_windows:
                m, v, _ = _huber_mean(self.relearn)
                self.baseline, self.baseline_var = m, v
                self.relearn = []
                self.phase = MONITORING
                self.cusum.reset(idx + 1)
        return ev

    def to_dict(self) -> dict:
        d = self._base_dict()
        d.update(t=self.t.tolist(), y=self.y.tolist(), w=self.w.tolist(), count=self.count, pos=self.pos, t0=self.t0)
        return d

    def load(self, d: dict):
        self._load_base(d)
        W = self.t.shape[0]
        arrs = [np.asarray(d[k], dtype=float) for k in ("t", "y", "w")]
        if any(a.shape != (W,) for a in arrs):
            raise TrendStateError(f"width regression buffer: {arrs[0].shape[0]} windows saved, the configuration "
                                  f"has width_regression_windows = {W}")
        self.t, self.y, self.w = arrs
        self.count, self.pos, self.t0 = int(d["count"]), int(d["pos"]), float(d["t0"])
        if not (0 <= self.count <= W and 0 <= self.pos < W):
            raise TrendStateError("width regression buffer: count/pos out of range")
        if self.count:
            self._refit()
        else:
            self.fit = None


# --------------------------------------------------------------------------------------------------
# Tracker
# --------------------------------------------------------------------------------------------------

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
        self._inertia = _InertiaChannel(self.config)
        self._width = _WidthChannel(self.config)
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
        self._inertia = _InertiaChannel(self.config)
        self._width = _WidthChannel(self.config)

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
        level, message = self._health(idx, jx, jb, jd, jdse, jdr, wx, wse, rate, rate_se, ttl, ttl_lo, ttl_hi,
                                      events)
        if skipped:
            message = f"window skipped ({reason}); {message}"
        commissioning = (J.phase == COMMISSIONING and (J.n > 0 or Wd.n == 0)) or \
                        (J.n == 0 and Wd.phase == COMMISSIONING)
        return TrendUpdate(
            idx, t, skipped, reason, commissioning,
            jx, jse, jb, jbse, J.reference, jd, jdse, jdr, J.cusum.stat,
            wx, wse, Wd.baseline, math.sqrt(Wd.baseline_var) if Wd.baseline_var is not None else None, wd, wdse,
            Wd.cusum.stat, rate, rate_se,
            None if rate is None else rate * SECONDS_PER_DAY, None if rate_se is None else rate_se * SECONDS_PER_DAY,
            ttl, ttl_lo, ttl_hi, bool(events), events, level, message)

    def _health(self, idx, jx, jb, jd, jdse, jdr, wx, wse, rate, rate_se, ttl, ttl_lo, ttl_hi, events):
        cfg = self.config
        J, Wd = self._inertia, self._width
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

    def _with_change(self, level: int, txt: str, ch: _Channel, idx: int, what) -> tuple[int, str]:
        """(level, txt) with the channel's held change (:meth:`_held_change`) appended and WARN raised."""
        phrase = self._held_change(ch, idx, what)
        return (level, txt) if phrase is None else (max(level, WARN), txt + phrase)

    def _held_change(self, ch: _Channel, idx: int, what) -> str | None:
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


# --------------------------------------------------------------------------------------------------
# Simulation and targets
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SimulatedSeries:
    """Synthetic per-window estimates (what the gap estimator would report) and the truth."""

    time_s: np.ndarray
    inertia_kgm2: np.ndarray
    inertia_se_kgm2: np.ndarray
    width_m: np.ndarray
    width_se_m: np.ndarray
    true_inertia_kgm2: np.ndarray
    true_width_m: np.ndarray
    step_at: int | None
    se_scale: float            # true sd / reported se
    coverage: float            # probability that the reported 95 % interval covers the truth (Gaussian part)


def simulate_series(n_windows: int, step_at: int | None = None, step_pct: float = 2.5, j1_se_pct: float = 0.5,
                    width_growth_m_per_window: float = 1.0e-5, seed: int | None = None, *,
                    inertia_kgm2: float = 1.16, width_m: float = 0.0025, width_se_pct: float = 0.05,
                    window_period_s: float = 3600.0, start_time_s: float = 0.0,
                    coverage: float | None = None, se_jitter: float = 0.2,
                    outlier_prob: float = 0.002, outlier_sd: float = 6.0,
                    width_step_at: int | None = None, width_step_m: float = 0.0) -> SimulatedSeries:
    """Synthetic J1/K2 estimate series, one window every ``window_period_s`` (default an hour).

    * True J1 = ``inertia_kgm2``, times (1 + step_pct/100) from window ``step_at`` (0-based) on.
    * True width = ``width_m`` + ``width_growth_m_per_window`` * i (+ ``width_step_m`` from ``width_step_at``).
    * Reported se: J1 ``j1_se_pct`` % and width ``width_se_pct`` % of the true value, each window times
      exp(N(0, se_jitter^2)) (the estimator's se varies with the window).
    * Errors: reported se * se_scale * N(0, 1), se_scale from ``coverage`` (the 95 % interval's coverage;
      None: drawn uniformly in [0.92, 0.99] per series, i.e. se_scale in [0.76, 1.12]); with probability
      ``outlier_prob`` per window and quantity an outlier N(0, outlier_sd^2) in units of the true sd.
    """
    rng = np.random.default_rng(seed)
    if coverage is None:
        coverage = float(rng.uniform(0.92, 0.99))
    s = coverage_to_se_scale(coverage)
    i = np.arange(n_windows)
    t = start_time_s + window_period_s * i
    tj = np.full(n_windows, float(inertia_kgm2))
    if step_at is not None:
        tj[step_at:] *= 1.0 + step_pct / 100.0
    tw = width_m + width_growth_m_per_window * i
    if width_step_at is not None:
        tw[width_step_at:] += width_step_m

    def noisy(truth, se_pct):
        se = truth * se_pct / 100.0 * np.exp(se_jitter * rng.standard_normal(n_windows))
        e = rng.standard_normal(n_windows)
        out = rng.random(n_windows) < outlier_prob
        e[out] = outlier_sd * rng.standard_normal(int(out.sum()))
        return truth + s * se * e, se

    yj, sej = noisy(tj, j1_se_pct)
    yw, sew = noisy(tw, width_se_pct)
    return SimulatedSeries(t, yj, sej, yw, sew, tj, tw, step_at, s, coverage)


def run_series(series: SimulatedSeries, config: TrendConfig | None = None, width: bool = True) -> list[TrendUpdate]:
    """A fresh tracker over a simulated series."""
    tr = TrendTracker(config)
    return tr.batch(series.time_s, series.inertia_kgm2, series.inertia_se_kgm2,
                    series.width_m if width else None, series.width_se_m if width else None)


def detection_delays(trials: int = 200, seed: int = 0, config: TrendConfig | None = None, step_pct: float = 2.5,
                     pre_windows: int = 30, post_windows: int = 20) -> dict:
    """J1 step of +-step_pct % after commissioning + ``pre_windows`` steady windows, per-window se
    uniform in 0.4-0.6 % of J1, coverage uniform in 92-99 %.  Delay = windows from the step window
    (delay 1: detected at the step window) to the first J1 change at or after it; ``missed`` when none
    within ``post_windows``."""
    cfg = config if config is not None else TrendConfig()
    rng = np.random.default_rng(seed)
    step_at = cfg.commissioning_windows + pre_windows

    def series(trial):
        sign = 1 if trial % 2 == 0 else -1
        s = simulate_series(step_at + post_windows, step_at=step_at, step_pct=sign * step_pct,
                            j1_se_pct=float(rng.uniform(0.4, 0.6)), seed=int(rng.integers(2 ** 63)))
        return s.time_s, s.inertia_kgm2, s.inertia_se_kgm2, sign
    return step_trials(trials, series, cfg, step_at)


def step_trials(trials: int, make_series, config: TrendConfig, step_at: int) -> dict:
    """:func:`delay_summary` over ``trials`` series, each from ``make_series(trial)`` -> (time_s, inertia_kgm2,
    inertia_se_kgm2, sign of the step at window ``step_at``), each through a fresh tracker."""
    delays, missed, false_before = [], 0, 0
    for trial in range(trials):
        t, j, se, sign = make_series(trial)
        found, false = step_delay(TrendTracker(config), t, j, se, step_at, sign)
        false_before += false
        if found is None:
            missed += 1
        else:
            delays.append(found)
    return delay_summary(trials, delays, missed, false_before)


def step_delay(tracker: "TrendTracker", time_s, inertia_kgm2, inertia_se_kgm2, step_at: int,
               sign: int) -> tuple[int | None, int]:
    """Feed J1 windows to ``tracker`` until the first J1 change of ``sign`` at or after window ``step_at``:
    (delay in windows, 1 = detected at the step window, or None; J1 changes detected before the step)."""
    false_before = 0
    for i in range(len(time_s)):
        u = tracker.update(time_s[i], inertia_kgm2[i], inertia_se_kgm2[i])
        for ev in u.changes:
            if ev.quantity != "inertia":
                continue
            if i < step_at:
                false_before += 1
            elif ev.sign == sign:
                return i - step_at + 1, false_before
    return None, false_before


def delay_summary(trials: int, delays: Sequence[int], missed: int, false_before: int) -> dict:
    """The detection-delay statistics of :func:`detection_delays` (and of the evaluation on real windows):
    trials, detected, missed, false changes before the step, median / p95 / max delay (inf when none was
    detected) and the histogram {delay: trials}."""
    d = np.array(delays, dtype=float)
    return {"trials": trials, "detected": len(delays), "missed": missed, "false_before_step": false_before,
            "median": float(np.median(d)) if d.size else math.inf,
            "p95": float(np.percentile(d, 95)) if d.size else math.inf,
            "max": float(d.max()) if d.size else math.inf,
            "histogram": {int(k): int(v) for k, v in zip(*np.unique(d, return_counts=True))}}


def false_alarms(monitored_windows: int = 100_000, seed: int = 0, config: TrendConfig | None = None,
                 series_windows: int = 1000, width_growth_m_per_window: float = 1.0e-5) -> dict:
    """Steady J1 (and a steady linear width growth) over ``monitored_windows`` windows after
    commissioning, in series of ``series_windows`` (each with its own commissioning, se level and
    miscalibration, outliers included).  Counts the detected changes per quantity."""
    cfg = config if config is not None else TrendConfig()
    rng = np.random.default_rng(seed)
    n_series = max(1, math.ceil(monitored_windows / series_windows))
    comm = cfg.commissioning_windows
    fa_j = fa_w = monitored = 0
    for _ in range(n_series):
        n = comm + series_windows
        s = simulate_series(n, j1_se_pct=float(rng.uniform(0.4, 0.6)), seed=int(rng.integers(2 ** 63)),
                            width_growth_m_per_window=width_growth_m_per_window,
                            width_se_pct=float(rng.uniform(0.01, 0.1)))
        for u in run_series(s, cfg):
            for ev in u.changes:
                if ev.quantity == "inertia":
                    fa_j += 1
                else:
                    fa_w += 1
        monitored += series_windows
    return {"monitored_windows": monitored, "series": n_series, "inertia_changes": fa_j, "width_changes": fa_w,
            "inertia_per_10k": 1e4 * fa_j / monitored, "width_per_10k": 1e4 * fa_w / monitored,
            # one-sided 95 % Poisson upper bound of the rate (Garwood)
            "inertia_per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (fa_j + 1))) / 2 / monitored,
            "width_per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (fa_w + 1))) / 2 / monitored,
            "design_arl_windows": cfg.target_arl_windows, "threshold_sd": cfg.threshold_sd}


def wear_rate_accuracy(trials: int = 100, seed: int = 0, config: TrendConfig | None = None, after_windows: int = 20,
                       growth_m_per_window: float = 1.0e-5, window_period_s: float = 3600.0) -> dict:
    """Width 0.0025 m growing by ``growth_m_per_window`` (default: 0.0025 -> 0.0035 m over 100 windows),
    width se uniform in 0.01-0.1 %, one window per ``window_period_s``: relative error of the wear rate
    (m/s) after ``after_windows`` windows."""
    rng = np.random.default_rng(seed)
    truth = growth_m_per_window / window_period_s
    errs = []
    for _ in range(trials):
        s = simulate_series(after_windows, width_growth_m_per_window=growth_m_per_window,
                            width_se_pct=float(rng.uniform(0.01, 0.1)), window_period_s=window_period_s,
                            seed=int(rng.integers(2 ** 63)))
        u = run_series(s, config)[-1]
        errs.append(abs(u.wear_rate_m_per_s - truth) / truth if u.wear_rate_m_per_s is not None else math.inf)
    e = np.array(errs)
    return {"trials": trials, "after_windows": after_windows, "truth_m_per_s": truth,
            "truth_m_per_day": truth * SECONDS_PER_DAY, "median_rel_error": float(np.median(e)),
            "max_rel_error": float(e.max()), "within_10pct": float(np.mean(e <= 0.10))}


def siegmund_check(arl_windows: float = 200.0, runs: int = 400, seed: int = 0, reference_sd: float = 2.0,
                   se_scale: float = 1.0) -> dict:
    """Verifies the threshold design: ``runs`` two-sided CUSUMs with h = cusum_threshold_for_arl(arl_windows)
    on N(0, se_scale^2) increments (se_scale > 1: under-reported standard errors), each run to its first
    alarm; returns the simulated mean run length and Siegmund's prediction (k/se_scale, h/se_scale)."""
    h = cusum_threshold_for_arl(arl_windows, reference_sd)
    rng = np.random.default_rng(seed)
    pos = np.zeros(runs)
    neg = np.zeros(runs)
    length = np.zeros(runs)
    alive = np.ones(runs, dtype=bool)
    n = 0
    while alive.any():
        n += 1
        z = se_scale * rng.standard_normal(runs)
        pos = np.maximum(0.0, pos + z - reference_sd)
        neg = np.maximum(0.0, neg - z - reference_sd)
        fired = alive & ((pos > h) | (neg > h))
        length[fired] = n
        alive &= ~fired
    return {"design_arl": arl_windows, "threshold_sd": h, "se_scale": se_scale,
            "predicted_arl": cusum_arl(h, reference_sd, sd=se_scale),
            "siegmund_arl": two_sided_arl(h / se_scale, reference_sd / se_scale),
            "simulated_arl": float(length.mean()), "simulated_arl_se": float(length.std(ddof=1) / math.sqrt(runs)),
            "runs": runs}


def measure_targets(seed: int = 0, detection_trials: int = 200, steady_windows: int = 100_000,
                    wear_trials: int = 100, config: TrendConfig | None = None) -> dict:
    """All targets of issue 14 (the tracker-update time is in bench/bench_trend.py)."""
    return {"detection": detection_delays(detection_trials, seed, config),
            "false_alarms": false_alarms(steady_windows, seed + 1, config),
            "wear": wear_rate_accuracy(wear_trials, seed + 2, config),
            "siegmund": siegmund_check(2000.0, 400, seed + 3,
                                       (config if config is not None else TrendConfig()).cusum_reference_sd)}


def format_targets(r: dict) -> str:
    d, f, w, s = r["detection"], r["false_alarms"], r["wear"], r["siegmund"]
    return "\n".join([
        f"J1 2.5 % step, {d['trials']} trials: detected {d['detected']}, missed {d['missed']}, delay median "
        f"{d['median']:g}, p95 {d['p95']:g}, max {d['max']:g} windows (histogram {d['histogram']}); "
        f"false changes before the step {d['false_before_step']}",
        f"steady drive, {f['monitored_windows']} monitored windows in {f['series']} series: J1 changes "
        f"{f['inertia_changes']} ({f['inertia_per_10k']:.3g} per 10,000, 95 % upper bound "
        f"{f['inertia_per_10k_upper95']:.2g}), width changes {f['width_changes']} ({f['width_per_10k']:.3g} per "
        f"10,000, upper bound {f['width_per_10k_upper95']:.2g}); h = {f['threshold_sd']:.3f} sd for a design ARL "
        f"{f['design_arl_windows']:.3g}",
        f"wear rate after {w['after_windows']} windows, {w['trials']} trials (truth {w['truth_m_per_day'] * 1e3:.3g} "
        f"mm/day): median error {100 * w['median_rel_error']:.2f} %, max {100 * w['max_rel_error']:.2f} %, "
        f"within 10 %: {100 * w['within_10pct']:.0f} %",
        f"Siegmund check (bare CUSUM, N(0,1)): design ARL {s['design_arl']:g} (h = {s['threshold_sd']:.3f}), "
        f"simulated {s['simulated_arl']:.0f} ± {s['simulated_arl_se']:.0f} over {s['runs']} runs"])


if __name__ == "__main__":  # pragma: no cover
    import argparse
    ap = argparse.ArgumentParser(description="measure the trend tracker's targets (issue 14)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="20,000 steady windows instead of 100,000")
    a = ap.parse_args()
    print(format_targets(measure_targets(a.seed, steady_windows=20_000 if a.quick else 100_000)))
