"""The two channels of the trend tracker (:mod:`jident_ros.identify.trend`): what J1 and the backlash width
share (commissioning, baseline, se scale, CUSUM, re-learning, history, their saved state), J1's Kalman local
level and the width's weighted regression line; and the :class:`ChangeEvent` they report.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from jident_ros.identify.distributions import chi2_ppf
from jident_ros.identify.trend_config import TrendConfig
from jident_ros.identify.trend_maths import SE_SCALE_TEST_LEVEL, Cusum, huber_mean, m_scale, t_normal_score, weighted_mean

COMMISSIONING, MONITORING, RELEARNING = "commissioning", "monitoring", "relearning"
_PHASES = (COMMISSIONING, MONITORING, RELEARNING)


class TrendStateError(ValueError):
    """A saved trend state that cannot be used (corrupt, wrong kind or version, missing field)."""



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
    class_pct: float | None = None   # J1: the nearest of the paper's relative classes (TrendConfig.change_classes_pct)



class Channel:
    """What both quantities share: commissioning, baseline, se scale, CUSUM, re-learning, history."""

    HISTORY = 256

    def __init__(self, cfg: TrendConfig, name: str, given: float | None, given_se: float, floor: float):
        self.cfg, self.name, self.floor = cfg, name, floor
        self.scale = 1.0
        self.cusum = Cusum()
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
                and robust_scale ** 2 > chi2_ppf(SE_SCALE_TEST_LEVEL, dof) / dof:
            self.scale = min(robust_scale, self.cfg.se_scale_max)

    def _scale_down(self):
        """The baseline is refined (it rests on baseline_refine_windows windows): when their scatter about it is
        significantly below what their standard errors say -- the 99 % upper confidence bound of the robust
        scale below 1 -- the later standard errors (and the baseline's) are scaled by that bound (never below
        se_scale_min; once).  An estimator whose errors are over-reported (e.g. a torque-accuracy floor the
        drive's own scatter does not show) then sees a change as large as it is; calibrated or under-reported
        errors are left alone."""
        cfg = self.cfg
        if not cfg.se_scale_down or self.scale != 1.0:
            return
        pts = list(self.history)[-cfg.baseline_refine_windows:]
        n = len(pts)
        if n < 10:
            return
        r = np.array([(p[2] - self.baseline) / p[3] for p in pts])
        upper = m_scale(r, n / (n - 1.0)) * math.sqrt((n - 1) / chi2_ppf(1.0 - SE_SCALE_TEST_LEVEL, n - 1))
        if upper < 1.0:
            self.scale = max(upper, cfg.se_scale_min)
            self.baseline_var *= self.scale ** 2
            self.reference_var = min(self.reference_var, self.baseline_var) if self.reference_var else self.baseline_var
            self.history = deque(((i, tt, yy, sd * self.scale) for i, tt, yy, sd in self.history),
                                 maxlen=self.history.maxlen)

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
        self.cusum = Cusum.from_list(d["cusum"])
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


class InertiaChannel(Channel):
    """J1: Kalman local level; CUSUM on (y - baseline) / sqrt((s se)^2 + var baseline)."""

    def __init__(self, cfg: TrendConfig):
        super().__init__(cfg, "inertia", cfg.inertia_baseline_kgm2, cfg.inertia_baseline_se_kgm2, 0.0)
        self.x = self.baseline
        self.P = self.baseline_var
        self.seg_sw = self.seg_swy = 0.0     # running sums of a re-learnt baseline still being refined
        self.seg_n = 0
        self.base_start: int | None = None   # first window of the current baseline's data (None: given)
        self.scale_ss = 0.0                  # the error scale's data: sum of squared clipped standardised residuals
        self.scale_dof = 0                   # ... and their degrees of freedom (beyond the prior's)
        self.refine_pending: list = []       # refinement windows (1/se^2, winsorised J1, z) held while the
                                             # CUSUM is away from 0

    def update(self, idx: int, t: float, y: float, se: float, k: float, h: float) -> ChangeEvent | None:
        cfg = self.cfg
        if self.first_time is None:
            self.first_time = t
        self.n += 1
        if self.phase == COMMISSIONING:
            p = (idx, t, y, se)
            if not self.comm:
                self.base_start = idx
            self.comm.append(p)
            self.history.append(p)
            self.x, self.P, _ = weighted_mean(self.comm)
            if self._commissioning_done(t):
                m, v, rs = huber_mean(self.comm, estimate_scale=True)
                n_comm = len(self.comm)
                self._set_scale(rs, n_comm - 1)
                self._learn_scale([(q[2] - m) / (q[3] * self.scale) for q in self.comm], n_comm - 1)
                self._commissioned(m, v, idx)
                self.x, self.P = m, self.baseline_var
                self._start_refining(n_comm)
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
        zc = self._scored(zraw)              # the CUSUM's input: the normal score under the learnt error scale
        if self.seg_n:
            # the refinement (the baseline, winsorised, and the error scale) takes a window only once the CUSUM is
            # back at 0: the first windows of a step inside the refinement are held, and dropped when the step is
            # flagged (taken at once, they would move the baseline towards the step and widen the band that
            # should flag it)
            self.refine_pending.append((1.0 / r, self.baseline + z * sd if z != zraw else y, zraw))
        sign = self.cusum.step(zc, k, h, idx)
        if not sign:
            if self.refine_pending and self.cusum.pos == 0.0 and self.cusum.neg == 0.0:
                self._refine(self.refine_pending)
                self.refine_pending = []
            return None
        self.refine_pending = []
        onset = self.cusum.pos_start if sign > 0 else self.cusum.neg_start
        seg = [q for q in self.history if q[0] >= onset] or [p]
        m, v, _ = huber_mean(seg)
        base, base_var = self._level_before(onset)
        size = m - base
        ev = ChangeEvent("inertia", t, idx, seg[0][0], seg[0][1], size, math.sqrt(v + base_var),
                         100.0 * size / base, sign)
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

    def _refine(self, points):
        """The held windows ``points`` (1/se^2, winsorised J1, innovation) into the baseline being refined and into
        the error scale, until the baseline rests on baseline_refine_windows windows (then it is frozen, and the
        errors scaled down if its windows prove them over-reported)."""
        for w, yw, zraw in points:
            if not self.seg_n:
                return
            self.seg_sw += w
            self.seg_swy += w * yw
            self.seg_n += 1
            self.baseline, self.baseline_var = self.seg_swy / self.seg_sw, 1.0 / self.seg_sw
            self._learn_scale([zraw], 1)
            if self.seg_n >= self.cfg.baseline_refine_windows:
                self.seg_n = 0
                self._scale_down()

    def _learn_scale(self, residuals, dof: int):
        """Add standardised residuals (clipped at innovation_clip_sd: one outlier cannot blow the scale up) with
        ``dof`` degrees of freedom to the error scale's data."""
        if self.cfg.error_scale_prior_dof is None:
            return
        for x in residuals:
            c = self._innovation(x)
            self.scale_ss += c * c
        self.scale_dof += dof

    def error_scale(self) -> tuple[float, float] | None:
        """(sigma_hat, nu): the posterior of the drive's error scale (scaled inverse chi^2: prior nu0 dof at 1, then
        the windows' residuals), sigma_hat = sqrt((nu0 + sum r^2) / (nu0 + dof)); None when off."""
        nu0 = self.cfg.error_scale_prior_dof
        if nu0 is None:
            return None
        nu = nu0 + self.scale_dof
        return math.sqrt((nu0 + self.scale_ss) / nu), nu

    def _scored(self, zraw: float) -> float:
        """The CUSUM's input for the standardised innovation ``zraw``: with the error scale learnt, the normal
        score of its Student-t predictive, Φ⁻¹(T_ν(zraw / max(1, sigma_hat))), clipped (N(0, 1) under the model,
        whatever the number of windows the scale rests on: the CUSUM's design holds in the commissioning phase
        too); never narrower than the reported errors (over-reported ones are scaled down by se_scale_down);
        else the clipped zraw."""
        es = self.error_scale()
        if es is None:
            return self._innovation(zraw)
        sig, nu = es
        return self._innovation(t_normal_score(zraw / max(sig, 1.0), nu))

    def _level_before(self, onset: int) -> tuple:
        """(level, variance) a change with this onset is measured from: the baseline, or -- while the baseline is
        still being refined, when it may already hold windows of the new level (a step inside the refinement) --
        the Huber mean of the baseline's own windows before the onset (the history, its standard errors
        scaled)."""
        if self.seg_n and self.base_start is not None:
            pre = [q for q in self.history if self.base_start <= q[0] < onset]
            if pre:
                m, v, _ = huber_mean(pre)
                return m, v
        return self.baseline, self.baseline_var

    def _start_refining(self, n: int):
        """The baseline (on ``n`` windows) keeps being refined by the next windows up to baseline_refine_windows."""
        v = self.baseline_var
        if v is not None and v > 0.0 and n < self.cfg.baseline_refine_windows:
            self.seg_sw, self.seg_swy, self.seg_n = 1.0 / v, self.baseline / v, n
        else:
            self.seg_n = 0

    @property
    def baseline_windows(self) -> int:
        """Windows the current baseline rests on while it is still being refined (0: refined or given)."""
        return self.seg_n

    def _rebaseline(self, idx: int):
        m, v, _ = huber_mean(self.relearn)
        self.baseline, self.baseline_var = m, v
        self.base_start = self.relearn[0][0]
        self._start_refining(len(self.relearn))
        self.relearn = []
        self.phase = MONITORING
        self.cusum.reset(idx + 1)

    def to_dict(self) -> dict:
        d = self._base_dict()
        d.update(x=self.x, P=self.P, seg_sw=self.seg_sw, seg_swy=self.seg_swy, seg_n=self.seg_n,
                 base_start=self.base_start, scale_ss=self.scale_ss, scale_dof=self.scale_dof,
                 refine_pending=[list(p) for p in self.refine_pending])
        return d

    def load(self, d: dict):
        self._load_base(d)
        self.x = None if d["x"] is None else float(d["x"])
        self.P = None if d["P"] is None else float(d["P"])
        self.seg_sw, self.seg_swy, self.seg_n = float(d["seg_sw"]), float(d["seg_swy"]), int(d["seg_n"])
        bs = d.get("base_start")          # optional: states saved before it measure a change from the baseline
        self.base_start = None if bs is None else int(bs)
        # optional: a state saved before the error scale was learnt goes on with the prior alone
        self.scale_ss, self.scale_dof = float(d.get("scale_ss") or 0.0), int(d.get("scale_dof") or 0)
        self.refine_pending = [tuple(float(v) for v in p) for p in (d.get("refine_pending") or [])]
        if any(len(p) != 3 for p in self.refine_pending):
            raise TrendStateError("inertia.refine_pending: each entry must be [1/se^2, J1, z]")


class WidthChannel(Channel):
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

    def new_segment(self, idx: int):
        """A time discontinuity at window ``idx``: the regression line restarts (its slope never spans the
        jump) and so does the CUSUM (it compares with that line); the baseline and the phase carry on."""
        self._reset_segment(0.0)
        self.cusum.reset(idx)

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
                m, v, rs = huber_mean(self.comm, estimate_scale=True)
                if self.fit is not None and self.count >= 3:   # scatter about the line, not the mean (wear)
                    tm, ym, b, s2, sw, sxx = self.fit
                    n = self.count
                    r = (self.y[:n] - ym - b * (self.t[:n] - tm)) * np.sqrt(self.w[:n])
                    rs = m_scale(r, n / (n - 2.0))
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
                size, v, _ = huber_mean(off)
                old_var = self.predict(seg[0][1])[1]
                m, vm, _ = huber_mean(seg)
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
                m, v, _ = huber_mean(self.relearn)
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
