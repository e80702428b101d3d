"""The configuration of the trend tracker (:class:`TrendConfig`) and the mapping of the diagnostic node's
``trend_*`` parameters onto it (:data:`PARAMETER_FIELDS`; 0 stands for None where ROS parameters cannot be None).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

from jident_ros.identify.trend_maths import cusum_threshold_for_arl
from jident_ros.parameters import TREND_FIELDS, TREND_NODE_ONLY, TREND_PARAMS

SECONDS_PER_DAY = 86400.0


@dataclass(frozen=True)
class TrendConfig:
    """Parameters of :class:`TrendTracker`; units in the names, ``_sd`` = in standard deviations of
    the standardised innovation, ``_pct`` = per cent of the baseline."""

    #: commissioning: number of windows with an estimate (per quantity) that give the first baseline (issue 21:
    #: few; the baseline's uncertainty is carried into the change test, and it keeps being refined, see below)
    commissioning_windows: int = 5
    #: after commissioning, J1's baseline keeps being refined by the monitored windows (winsorised at
    #: innovation_clip_sd) until it rests on this many windows; changes are flagged meanwhile against a band
    #: widened by its uncertainty (z = (y - b) / sqrt(se^2 + var b)).  <= commissioning_windows: no refinement
    baseline_refine_windows: int = 20
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
    #: when the J1 baseline is refined (baseline_refine_windows), scale the later standard errors DOWN to the
    #: 99 % upper bound of the baseline windows' scatter when that is below 1 (over-reported errors), not below
    #: se_scale_min
    se_scale_down: bool = True
    se_scale_min: float = 0.25
    #: the drive's J1 error scale sigma (true scatter / reported se) is learnt from its own windows: a prior of
    #: this many degrees of freedom at sigma = 1 (the reported errors are right), updated by the commissioning's
    #: residuals and the refinement's innovations (clipped at innovation_clip_sd) until the baseline is refined;
    #: the CUSUM then takes the normal score of the innovation under the Student-t predictive,
    #: Φ⁻¹(T_ν(z / max(1, sigma_hat))), ν = this + the windows' dof (docs/trend.md, "The drive's error scale").
    #: None: the Gaussian z of the reported errors (the design before)
    error_scale_prior_dof: float | None = 4.0
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
    #: the drive's torque-estimate accuracy (1 sd, % of the torque): a scale error that moves every absolute J1
    #: alike and cancels in J1 relative to the drive's own baseline; it widens only the absolute J1's interval
    torque_accuracy_pct: float = 0.0
    #: a window more than this much drive time after the previous one (or any window before it: the drive's
    #: clock went back, e.g. a restart) starts a new time segment: reported, the wear line restarts, nothing
    #: is skipped for ever, s (default 7 days)
    time_discontinuity_s: float = 7.0 * SECONDS_PER_DAY
    #: the paper's J1 classes relative to the nominal, per cent: a change is named by the nearest
    #: (1.131, 1.102, 1.073, 0.957, 1.189, 1.218 against 1.16); not a node parameter
    change_classes_pct: tuple = (-2.5, -5.0, -7.5, -17.5, 2.5, 5.0)

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
        count("baseline_refine_windows", 0)
        for n in ("commissioning_duration_s", "inertia_baseline_kgm2", "width_baseline_m", "cusum_threshold_sd",
                  "width_warn_m", "time_to_limit_warn_s"):
            pos(n, allow_none=True)
        for n in ("inertia_baseline_se_kgm2", "width_baseline_se_m", "inertia_process_sd_pct_per_window",
                  "width_se_floor_m", "torque_accuracy_pct"):
            pos(n, allow_zero=True)
        for n in ("cusum_reference_sd", "innovation_clip_sd", "drift_warn_pct", "drift_alarm_pct", "width_limit_m",
                  "wear_significance_sd", "time_discontinuity_s"):
            pos(n)
        if not isinstance(self.change_classes_pct, tuple) or not self.change_classes_pct or not all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) and c != 0
                for c in self.change_classes_pct):
            bad("change_classes_pct", "a non-empty tuple of finite non-zero per cents")
        pos("target_arl_windows")
        if self.target_arl_windows <= 1:
            bad("target_arl_windows", "> 1")
        pos("se_scale_max")
        if self.se_scale_max < 1:
            bad("se_scale_max", ">= 1")
        pos("se_scale_min")
        pos("error_scale_prior_dof", allow_none=True)
        if self.se_scale_min > 1:
            bad("se_scale_min", "<= 1")
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
        d = dict(d)
        if isinstance(d.get("change_classes_pct"), list):        # JSON has no tuples
            d["change_classes_pct"] = tuple(d["change_classes_pct"])
        return cls(**d)


#: parameter name -> TrendConfig field; the fields whose None is 0 in the parameters; the node's own trend
#: parameters; the integer and boolean fields: all from the one schema (jident_ros.parameters.TREND_PARAMS).
PARAMETER_FIELDS = dict(TREND_FIELDS)
ZERO_IS_NONE = {TREND_FIELDS[n] for n, p in TREND_PARAMS.items() if p.zero_is_none}
NODE_ONLY = set(TREND_NODE_ONLY)
_INT_FIELDS = {f for n, f in TREND_FIELDS.items()
               if isinstance(TREND_PARAMS[n].default, int) and not isinstance(TREND_PARAMS[n].default, bool)}
_BOOL_FIELDS = {f for n, f in TREND_FIELDS.items() if isinstance(TREND_PARAMS[n].default, bool)}
#: TrendConfig fields that are not node parameters.
NOT_PARAMETERS = {"change_classes_pct", "error_scale_prior_dof"}


def _positive_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0


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
    if not kw.get("torque_accuracy_pct") and _positive_number(params.get("torque_accuracy") if hasattr(params, "get")
                                                              else None):
        # the drive's declared torque accuracy (the gap estimator's ``torque_accuracy``: a uniform bound, fraction)
        # as the absolute J1's 1-sd term, unless trend_torque_accuracy_pct sets its own
        kw["torque_accuracy_pct"] = 100.0 * float(params["torque_accuracy"]) / math.sqrt(3.0)
    try:
        return cls(**kw)
    except ValueError as exc:
        text = str(exc)
        for pname, fname in PARAMETER_FIELDS.items():
            if text.startswith(fname + ":"):
                raise ValueError("trend_" + text) from None
        raise
