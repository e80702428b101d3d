"""The a1 fits (a1 and m_el measured: an Imu beside the drive's torque; issue 20): the joint ('acceleration') fit and
the 'gap_only' fit, their constant torque and bounded-torque terms, and the check that the joint fit's premise holds at
the detector's rows.  gap.py (``_estimate_inertia``) chooses between them and finishes their standard error; moved out
of gap.py (its 600-line limit, issue 20), the numbers are the same.

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
  the torque model gets a linear term too (the model-form error).  (:func:`_joint_fit`)
* ``"gap_only"`` (a1 and m_el measured; no assumption about the drive before the entry):
  over the in-zone samples only, m_el − b1 ω1 = J1 a1/r sample by sample, the torque taken as
  measured (no torque model, no pre-entry anchoring).  Both sides are noisy, so J1 is the
  errors-in-variables (Deming) slope through the origin with the two noise levels measured on
  the window (robust scale of second differences).  The in-zone sample set comes from the
  dynamics: the interval's end samples whose load torque m_el − b1 ω1 − J1 a1/r is not zero
  within its noise (GAP_ONLY_TRIM_SIGMA) are dropped — an entry found a sample or two early, or a
  re-contact row one late, does not bias J1.  Uncertainty: the residual standard error, and in
  quadrature the model error, the change of J1 when one more sample is dropped at each end of the
  in-zone set.  (:func:`gap_only_fit`)

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from jident_ros.identify import gap_sign, lapack
from jident_ros.identify.gap_eiv import _deming_se, _noise_ratio_term, _origin_slope, _robust_noise
from jident_ros.identify.gap_free import FREE_REL_SE_FLOOR, GapModel
from jident_ros.identify.gap_numerics import _median, _memoised
from jident_ros.identify.gap_types import FitState, NoGapError, _net_torque
from jident_ros.stream.rate import samples as rate_samples

#: 'anchored' fit: gaps shorter than this fit m_el with a straight line (fewer free parameters).
GAP_QUADRATIC_MIN = 12

#: 'acceleration' fit: gaps of at least this many samples model the gap torque as
#: m0 + c2 τ^2 + c3 τ^3, shorter ones as m0 + c2 τ^2.
GAP_CUBIC_MIN = 8


#: 'acceleration' fit: the Newton iteration on the profile stops when J1 changes by less than this fraction.
JOINT_FIT_TOL = 1e-9
JOINT_FIT_MAX_ITER = 30


#: 'gap_only' fit: an end sample of the in-zone set is dropped while its load torque
#: |m_el - b1 w1 - J1 a1/r| exceeds this many standard deviations of the per-sample residual ...
GAP_ONLY_TRIM_SIGMA = 3.0
#: ... or this fraction of the median |m_el| over the gap (the floor for noise-free windows) ...
GAP_ONLY_TRIM_REL = 0.005
#: ... at most this many samples at the entry end and at the re-contact end (at 2 kHz), or the change-point search's
#: span where that is the larger (:func:`gap_only_max_trim`): a detector's entry early by more than 4 samples left
#: contact rows in the fit (the zoo's second drive with the entry moved 12 samples early: J1 +14.7 %, its interval
#: missing the truth; `python -m jident_ros.research.evaluation.zoo --report --results - --entry-shift -12`).
GAP_ONLY_MAX_TRIM = (4, 3)
#: ... and at the entry end a row within the tolerance does not stop the trim while one of the next this many rows
#: exceeds it: a fading contact's torque at 30 dB dips within 3 sigma on single rows (vector set 6's s6-08 with an Imu:
#: the trim stopped at an 11.5 N m row with 21-30 N m on the next five, J1 +11 %).  Noise alone exceeds 3 sigma on
#: 0.3 % of rows.  Not at the re-contact end: a torque smoothed beyond its declared lag leaves a load torque there that
#: is no contact (zoo_variants' 'smoothed torque 5 ms undeclared', its speed reversal with an Imu at 30 dB: the walk on
#: from the re-contact end kept 10 rows, J1 -12.6 %; stop 32's rule kept 30, -3.1 %).  The entry end's walk reads
#: the load torque from the free rows' level (:func:`_free_level`): read from 0, the vector drive's bearing friction
#: with the persistence walked 25 rows into 6 of the zoo's Imu gaps (their J1 then undetermined).
TRIM_PERSIST = 2
#: 'gap_only' fit: relative floor of the standard error (noise-free: the samples' own rounding).
GAP_ONLY_REL_SE_FLOOR = 2e-4


def _a1_contact_rows(window: dict, start: int, end: int, wheel_radius_m: float, b1: float, model: GapModel,
                     sample_period_s: float) -> tuple:
    """(why the joint ('acceleration') fit's premise fails at the detector's rows, or "", the 'gap_only' fit that
    shows it, or None): the motor equation
    m_el − b1 ω1 = J1 a1/r (the 'gap_only' fit's in-zone trim) leaves more than GAP_ONLY_MAX_TRIM rows at an end of
    [start, end) out of the zone, so the detector's entry or re-contact is off by more than the joint fit, which
    takes m_el steady up to the entry row, can hold (the DOL drive with the entry 6-8 samples early: +9 % with an
    interval missing the truth; `zoo.entry_shift`).  Then the 'gap_only' fit over its own rows is the a1 fit."""
    try:
        fit = gap_only_fit(_net_torque(window, b1), np.asarray(window["a1"], float) / wheel_radius_m, start, end,
                           max_trim=gap_only_max_trim(model, sample_period_s), declared=declared_errors(model, sample_period_s))
    except NoGapError:
        return "", None
    early, late = fit["start"] - start, end - fit["end"]
    cap = tuple(rate_samples(int(k), sample_period_s) for k in GAP_ONLY_MAX_TRIM)     # durations counted at 2 kHz
    if early <= cap[0] and late <= cap[1]:
        return "", None
    return (f"the motor equation holds from row {fit['start']} to {fit['end']}, not from the detector's rows "
            f"{start}..{end} (a contact still loaded at an end): no steady entry at the detector's row"), fit


def declared_errors(model: GapModel, sample_period_s: float) -> tuple:
    """gap_only_fit's ``declared``: (T_s, the torque offset bound, the lag bound) of ``model``."""
    return float(sample_period_s), float(model.torque_offset_nm), float(model.torque_lag_s)


def gap_only_max_trim(model: GapModel, sample_period_s: float) -> tuple:
    """The 'gap_only' fit's most samples dropped at (the entry end, the re-contact end): GAP_ONLY_MAX_TRIM (rows at
    2 kHz, converted to ``sample_period_s``'s) or the change-point search span (GapModel.search_rows), whichever is
    larger: the same rows around the detector's entry and re-contact that the angle fit searches for its change
    points."""
    search = model.search_rows(sample_period_s)
    return tuple(max(rate_samples(int(k), sample_period_s), search) for k in GAP_ONLY_MAX_TRIM)


def gap_only_fit(torque: np.ndarray, acc: np.ndarray, start: int, end: int,
                 trim_sigma: float = GAP_ONLY_TRIM_SIGMA, trim_rel: float = GAP_ONLY_TRIM_REL,
                 max_trim: tuple = GAP_ONLY_MAX_TRIM, declared: tuple = (0.0, 0.0, 0.0)) -> dict:
    """The 'gap_only' fit (module docstring): J1 from torque[k] = J1 acc[k] over the in-zone samples.

    ``torque``: m_el − b1 ω1 over the whole window, N m; ``acc``: dω1/dt (a1/r), rad/s^2; [start, end): the
    candidate interval (the entry row to the re-contact row); ``declared``: (T_s, the torque offset bound in N m, the
    lag bound in s) for a J1 at or below zero (gap_sign.nonpositive_slope).  The noise levels of both come from the
    second differences of the pre-entry and candidate samples; J1 is the Deming slope through the origin.
    The in-zone set: J1 fitted on the candidate's core (two samples off each end), then end samples whose load
    torque |torque − J1 acc| exceeds max(trim_sigma x its standard deviation, trim_rel x the median |torque|) are
    dropped (at most ``max_trim`` = (entry end, re-contact end); at the entry end the load torque from the free
    rows' level, :func:`_free_level`, and while one of the next TRIM_PERSIST rows exceeds it too), J1 refitted,
    until the set stays the same. Returns j1, se (kg m^2; residual standard error and model error in quadrature, at
    least GAP_ONLY_REL_SE_FLOOR j1), model_error (|J1 with one more sample off each end − J1|), residual (N m), dof,
    start, end (the fitted samples); raises NoGapError when fewer than 3 samples remain or J1 is not positive."""
    y_all, x_all = np.asarray(torque, float), np.asarray(acc, float)
    sy = _robust_noise(y_all[:start], y_all[start:end])
    sx = _robust_noise(x_all[:start], x_all[start:end])
    if sx <= 1e-9 * float(np.abs(x_all[start:end]).max()):
        sx = 0.0
    if sy <= 1e-9 * float(np.abs(y_all[start:end]).max()):
        sy = 0.0

    def slope(a, b):
        return _origin_slope(y_all[a:b], x_all[a:b], sy, sx)

    core = (start + 2, end - 2) if end - start >= 10 else (start, end)
    j = slope(*core)
    if not math.isfinite(j) or j <= 0:
        raise NoGapError(_nonpositive(j, y_all[core[0]:core[1]], x_all[core[0]:core[1]], declared))
    lo, hi = start, end
    level = float(_median(np.abs(y_all[start:end])))
    for it in range(4):
        res = y_all[start:end] - j * x_all[start:end]
        tol = max(trim_sigma * float(np.hypot(sy, j * sx)), trim_rel * level)
        new_lo, new_hi = start, end
        # at the entry end the load torque from the free rows' level (a friction or offset over every row is no
        # contact), and a row within the tolerance stops the walk only with the next TRIM_PERSIST rows
        off = np.abs(res - _free_level(res, max_trim)) > tol
        while new_lo - start < max_trim[0] and new_hi - new_lo > 3 and off[new_lo - start:][:1 + TRIM_PERSIST].any():
            new_lo += 1
        while end - new_hi < max_trim[1] and new_hi - new_lo > 3 and abs(res[new_hi - 1 - start]) > tol:
            new_hi -= 1
        if (new_lo, new_hi) == (lo, hi) and it > 0:
            break
        lo, hi = new_lo, new_hi
        j = slope(lo, hi)
        if not math.isfinite(j) or j <= 0:
            raise NoGapError(_nonpositive(j, y_all[lo:hi], x_all[lo:hi], declared))
    n = hi - lo
    if n < 3:
        raise NoGapError(f"gap too short: {n} samples in the zone by the dynamics, need >= 3")
    x, y = x_all[lo:hi], y_all[lo:hi]
    res = y - j * x
    dof = n - 1
    se_stat = _deming_se(y, x, j, sy, sx, centred=False)
    ratio = _noise_ratio_term(y, x, j, sy, sx)
    model_error = abs(slope(lo + 1, hi - 1) - j) if n >= 6 else 0.0
    se = max(float(np.sqrt(se_stat ** 2 + ratio ** 2 + model_error ** 2)), GAP_ONLY_REL_SE_FLOOR * j)
    return {"j1": float(j), "se": se, "model_error": float(model_error), "residual": res, "dof": dof,
            "start": int(lo), "end": int(hi), "noise": (sy, sx), "noise_ratio": ratio}


def _nonpositive(j: float, torque: np.ndarray, acc: np.ndarray, declared: tuple) -> str:
    return gap_sign.nonpositive_slope(j, torque, acc, gap_sign.slope_flip(torque, *declared))


def _free_level(load: np.ndarray, max_trim: tuple) -> float:
    """The load torque the 'gap_only' fit leaves where the motor is free: the median of ``load`` (m_el − b1 ω1 −
    J1 a1/r over the candidate rows) beyond the rows its trim may drop (the friction and offset it does not model;
    0 when no row is left)."""
    mid = load[max_trim[0]:load.size - max_trim[1]]
    return float(_median(mid)) if mid.size else 0.0


def _constant_fit(y_all: np.ndarray, x_all: np.ndarray, lo: int, hi: int, sy: float, sx: float) -> dict | None:
    """The 'gap_only' fit with a constant torque F fitted beside J1: torque = J1 acc + F over rows [lo, hi) (the
    motor's Coulomb friction and the torque estimate's offset together; issue 20 item 3: friction fitted where the
    torque varies enough to separate it from J1).  The Deming slope of the centred samples; se from the residual
    with two parameters, and the model error as in :func:`gap_only_fit` (one more sample off each end).  None when
    fewer than 6 samples or J1 is not positive."""
    def fit(a, b):
        x, y = x_all[a:b], y_all[a:b]
        xc, yc = x - x.mean(), y - y.mean()
        j = _origin_slope(yc, xc, sy, sx)
        return j, float(y.mean() - j * x.mean()), y - j * x - float(y.mean() - j * x.mean()), float(xc @ xc)
    if hi - lo < 6:
        return None
    j, f, res, sxx = fit(lo, hi)
    if not (math.isfinite(j) and j > 0 and sxx > 0):
        return None
    j_in = fit(lo + 1, hi - 1)[0]
    x, y = x_all[lo:hi], y_all[lo:hi]
    se_stat = _deming_se(y - y.mean(), x - x.mean(), j, sy, sx, centred=True)
    ratio = _noise_ratio_term(y - y.mean(), x - x.mean(), j, sy, sx)
    model_error = abs(j_in - j) if math.isfinite(j_in) else np.inf
    return {"j1": float(j), "constant_nm": f, "se": float(np.sqrt(se_stat ** 2 + ratio ** 2 + model_error ** 2)),
            "se_stat": se_stat, "noise_ratio": ratio, "model_error": float(model_error), "residual": res,
            "dof": hi - lo - 2}


def _torque_powers(n_gap: int, linear_term: bool = False) -> tuple:
    """Powers of τ in the gap torque model m0 + Σ c_p τ^p shared by the 'acceleration' and 'angle' fits:
    (2, 3), (2,) for gaps shorter than GAP_CUBIC_MIN samples, with 1 in front when ``linear_term``."""
    powers = (2, 3) if n_gap >= GAP_CUBIC_MIN else (2,)
    return (1,) + powers if linear_term else powers


#: Floor of the joint fit's noise levels, relative to the channel's largest value: keeps a noise-free channel's
#: weight finite and the normal equations conditioned (1e-9 let an exact a1 outweigh a noisy m_el by 1e15, below
#: the m_el rows' round-off: kappa then stayed at its starting value, 1.5 % off; no accelerometer or torque
#: estimate is better than 1 ppm of its reading)
JOINT_NOISE_FLOOR_REL = 1e-6


@lru_cache(maxsize=64)
def _joint_design(n: int, linear_term: bool) -> np.ndarray:
    """The joint fit's gap torque model's columns, 1 and τ^p (τ = k/n) over n gap samples (read-only: shared)."""
    tau = np.arange(n) / n
    G = np.column_stack([np.ones(n)] + [tau ** q for q in _torque_powers(n, linear_term)])
    G.flags.writeable = False
    return G


@lru_cache(maxsize=64)
def _joint_constants(n: int, linear_term: bool) -> tuple:
    """The joint fit's constant blocks for n gap samples: e1 (the m0 coordinate), e1 e1ᵀ and GᵀG (read-only)."""
    G = _joint_design(n, linear_term)
    p = G.shape[1]
    e1 = np.zeros(p)
    e1[0] = 1.0
    out = (e1, np.outer(e1, e1), G.T @ G)
    for a in out:
        a.flags.writeable = False
    return out


def _std_ddof1(x: np.ndarray) -> np.float64:
    """``np.std(x, ddof=1)`` of a 1-D float array, bit for bit: numpy's own steps (the mean as the sum over the count,
    the squared deviations' sum over n - 1, its square root) without its generic-axis set-up (most of its cost on the
    joint fit's pre-entry samples)."""
    n = x.size
    d = x - np.add.reduce(x, axis=None, keepdims=True) / n
    np.multiply(d, d, out=d)
    return np.sqrt(np.add.reduce(d, axis=None) / max(n - 1, 0))


@_memoised
def _joint_fit(m_el: np.ndarray, a1: np.ndarray, start: int, end: int, friction=None,
               linear_term: bool = False, warm: dict | None = None, kappa_only: bool = False) -> dict:
    """Weighted joint least squares of m_el (pre-entry and gap) and a1 (gap); see the module docstring.

    Parameters: kappa = r/J1 and beta = (m0, c_1.., c_q) of m_hat(τ) = m0 + Σ c_i τ^p_i,
    τ = (k - start)/n over the n gap samples, powers (2, 3) ((2,) for gaps shorter than
    GAP_CUBIC_MIN), with a linear term added when ``linear_term``.  Model:
    m_el[k] = m0 (k < start), m_el[k] = m_hat (gap), a1[k] = kappa (m_hat - friction[k]) (gap).
    Returns kappa, its standard error (sandwich covariance with per-channel residual
    variances), the a1 residual over the gap, the degrees of freedom and the noise levels.
    ``warm``: the result of the fit without the linear term, to start from (and reuse its
    noise levels).  ``kappa_only``: {"kappa": ...} alone (the model-error fit's use: its residuals and covariance
    are not computed).
    """
    n = end - start
    pre = m_el[:start]
    mg, ag = m_el[start:end], a1[start:end]
    fr = np.zeros(n) if friction is None else np.asarray(friction, float)
    G = _joint_design(n, linear_term)
    p = G.shape[1]
    # noise levels: pre-entry steady state (m_el = m0, a1 = 0); fall back on the gap's
    # own m_el-only fit when there are too few pre-entry samples.  Floors keep noise-free
    # windows finite (then both channels weigh by their size).
    if warm is not None:
        sm, sa = warm["noise"]
    elif pre.size >= 5:
        sm = float(_std_ddof1(pre))
        sa = float(_std_ddof1(a1[:start]))
    else:
        cm, *_ = np.linalg.lstsq(G, mg, rcond=None)
        sm = float(np.sqrt(np.sum((mg - G @ cm) ** 2) / max(n - p, 1)))
        sa = sm * float(np.abs(ag).mean() / max(np.abs(mg).mean(), 1e-300))
    sm = max(sm, JOINT_NOISE_FLOOR_REL * float(np.abs(mg).max()), 1e-300)
    sa = max(sa, JOINT_NOISE_FLOOR_REL * float(np.abs(ag).max()), 1e-300)
    # normal-equation form: every block reduces to p x p sums (the pre-entry block to its count and sum), so an
    # iteration costs no n-length work.  Whitened model: pre m_el = m0, gap m_el = G beta (weight 1/sm^2);
    # gap a1 = kappa (G beta - fr) (weight 1/sa^2).
    na = pre.size
    wm, wa = 1.0 / sm ** 2, 1.0 / sa ** 2
    e1, e11, GG = _joint_constants(n, linear_term)
    Gm, Ga, Gf = G.T @ mg, G.T @ ag, G.T @ fr
    fa, ff = float(fr @ ag), float(fr @ fr)
    s_pre = float(pre.sum())
    Nm = wm * (na * e11 + GG)            # m_el blocks: J_m^T J_m for beta (kappa column is 0)
    b_m = wm * (s_pre * e1 + Gm)
    if warm is not None and linear_term:               # start from the fit without the linear term
        kappa = warm["kappa"]
    else:  # start: m_el alone (the pre-entry rows pin m0), then kappa through the origin (u = m_hat - friction)
        b0 = lapack.solve(Nm, b_m)
        kappa = float(b0 @ Ga - fa) / float(b0 @ GG @ b0 - 2.0 * b0 @ Gf + ff)
    # the cost is quadratic in beta for a given kappa: beta(kappa) in closed form (one p x p solve), and the optimum
    # is the root of h(kappa) = kappa - (the a1-on-u slope at beta(kappa)), found by Newton's method with a
    # finite-difference slope (h is close to linear: 2-4 steps, 2 solves each), stopped on the step, not on h (with a
    # nearly exact a1, h is ~1e-11 everywhere); Gauss-Newton on (kappa, beta) converged linearly (13-30 solves) and
    # stopped unconverged after 30 iterations on the stress bench's load reversal

    def profile(k: float) -> tuple:
        b = lapack.solve(Nm + (wa * k * k) * GG, b_m + (wa * k) * (Ga + k * Gf))
        uu_ = float(b @ GG @ b - 2.0 * float(b @ Gf) + ff)
        return b, (k - float(b @ Ga - fa) / uu_) if uu_ > 0 else np.nan

    beta, h = profile(kappa)
    for _ in range(JOINT_FIT_MAX_ITER):
        if not math.isfinite(h):
            break
        dk = 1e-4 * abs(kappa) if kappa else 1e-12
        _, h2 = profile(kappa + dk)
        slope = (h2 - h) / dk
        if not math.isfinite(slope) or slope == 0.0:
            break
        step = -h / slope
        kappa += step
        beta, h = profile(kappa)
        if abs(step) <= JOINT_FIT_TOL * abs(kappa):
            break
    if kappa_only:
        return {"kappa": float(kappa)}
    # residuals and the sandwich covariance at the solution
    m_hat = G @ beta
    r_a = ag - kappa * (m_hat - fr)
    ss_m = float(np.add.reduce((pre - beta[0]) ** 2) + np.add.reduce((mg - m_hat) ** 2)) * wm    # np.sum's reduction
    ss_a = float(r_a @ r_a) * wa
    Gu = GG @ beta - Gf
    uu = float(beta @ Gu - beta @ Gf + ff)
    Fa = np.empty((p + 1, p + 1))                       # J_a^T J_a
    Fa[0, 0] = wa * uu
    Fa[0, 1:] = Fa[1:, 0] = wa * kappa * Gu
    Fa[1:, 1:] = wa * kappa * kappa * GG
    Fm = np.zeros((p + 1, p + 1))
    Fm[1:, 1:] = Nm
    F_inv = lapack.inv(Fa + Fm)
    s2m = ss_m / max(na + n - p, 1)
    s2a = ss_a / max(n - 1, 1)
    cov = F_inv @ (s2m * Fm + s2a * Fa) @ F_inv
    return {"kappa": float(kappa), "kappa_se": float(np.sqrt(max(cov[0, 0], 0.0))), "beta": beta,
            "a1_residual": r_a, "dof": max(na - 1, 1) if na >= 5 else max(na + 2 * n - p - 1, 1),
            "noise": (sm, sa)}


def _shape_terms(x: np.ndarray, mt: np.ndarray | None, model: GapModel) -> dict:
    """The a1 fits' bounded torque errors that vary through the gap, as terms of J1 (kg m^2), for the regressor ``x``
    (dω1/dt over the fitted rows; centred for a fit with a constant beside J1, which only the variation of x holds):
    'torque_drift', the estimate's error drifting linearly across the rows, -T..+T (T the offset band;
    gap_terms.drift_term): J1 moves by Σ x T(t) / Σ x²; 'torque_lag', its bounded lag τ (the shaft's torque is
    m_el + τ dm_el/dt, ``mt`` the net torque's derivative over the rows): J1 moves by τ Σ x ṁ / Σ x²."""
    out = {}
    if model.torque_offset_nm and x.size > 1:
        ramp = np.linspace(-1.0, 1.0, x.size)
        out["torque_drift"] = abs(float(x @ ramp)) / max(float(x @ x), 1e-300) * model.torque_offset_nm / np.sqrt(3.0)
    if model.torque_lag_s and mt is not None:
        out["torque_lag"] = abs(float(x @ mt)) / max(float(x @ x), 1e-300) * model.torque_lag_s / np.sqrt(3.0)
    return out


def _gap_only_constant(fit: dict, torque: np.ndarray, xm: tuple, model: GapModel, bounded: list, current: tuple,
                       terms: dict, entry_error: float = 0.0) -> tuple:
    """The 'gap_only' fit's unknown constant torque (the Coulomb band, the torque offset: ``bounded``, [(term, its
    bound N m)]): (j, se, res, dof, terms, friction note) from ``current`` (j, se, res, dof), its ``terms`` and
    ``xm`` (dω1/dt and the net torque's derivative over the fitted rows, :func:`_shape_terms`; ``entry_error``: the
    entry's uncertainty, kg m^2, a part of both fits' change-point term).

    Each bound enters as a uniform term (half-width its bound, / sqrt 3) through the fit's own estimator -- J1
    refitted with the torque moved by ± the bound, not the first-order F Σx/Σx² of a least-squares slope: where the
    torque is exact and the acceleration noisy the Deming slope is the reverse regression, whose bias grows with F²
    (a DOL drive's light load reversal, zoo_draws d1-01: +17 % with a 2.5 N m constant against a ± 8 % interval).
    J1 is also fitted with the constant beside it (:func:`_constant_fit`); its drift and lag terms are those of the
    centred regressor (only the variation of dω1/dt holds J1 there: a gap whose acceleration ramps, a vector drive's
    traversal back, reads a drift of the estimate's error as inertia).  Where its total standard error is the
    smaller, that fit is taken and the bounds leave the interval (issue 20 item 3: friction fitted where the torque
    varies enough to separate it from J1); the bounded fit is then the trend's (GapEstimate.trend_fit), the 7th
    element (j, se, terms; () where the bounded fit is taken)."""
    j, se, res, dof = current
    x, mt = xm
    lo, hi = fit["start"], fit["end"]
    y = torque[lo:hi]
    sy, sx = fit["noise"]
    bound_terms = {}
    for name, v in bounded:
        moved = [_origin_slope(y - s * v, x, sy, sx) for s in (-1.0, 1.0)]
        bound_terms[name] = max((abs(m - j) if math.isfinite(m) else np.inf) for m in moved) / np.sqrt(3.0)
    bound_terms.update(_shape_terms(x, mt, model))
    se_bounded = se
    for v in bound_terms.values():
        se_bounded = float(np.hypot(se_bounded, v))
    free = _constant_fit(y, x, 0, hi - lo, sy, sx)       # made here only: a drive that declares no bound never needs it
    if free is not None:
        change = float(np.hypot(free["model_error"], entry_error))
        stat = max(free["se_stat"], GAP_ONLY_REL_SE_FLOOR * free["j1"])
        shape = _shape_terms(x - x.mean(), mt, model)
        if free["noise_ratio"]:
            shape["noise_ratio"] = free["noise_ratio"]
        se_free = float(np.sqrt(stat ** 2 + change ** 2 + sum(v ** 2 for v in shape.values())))
        if se_free < se_bounded:
            out = {k: v for k, v in terms.items() if k not in ("statistical", "change_points", "noise_ratio")}
            out["statistical"] = stat
            if change:
                out["change_points"] = change
            out.update(shape)
            note = (f"fitted: a constant torque {free['constant_nm']:+.3g} N m beside J1 (the Coulomb friction and the "
                    f"torque offset together; J1 through the origin with them bounded: {j:.4g} ± {se_bounded:.2g} "
                    "kg m^2)")
            return free["j1"], se_free, free["residual"], free["dof"], out, note, (j, se_bounded, {**terms, **bound_terms})
    terms.update(bound_terms)
    return j, se_bounded, res, dof, terms, "", ()


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


def _method_gap_only(window: dict, rows: tuple, drive: tuple, model: GapModel, made: dict | None) -> FitState:
    """gap._estimate_inertia's 'gap_only' fit over ``rows`` (start, end): :func:`gap_only_fit`, or ``made`` where the
    model choice has already made it (:func:`_a1_contact_rows`).  ``drive``: (r, b1, T_s)."""
    (start, end), (wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    if "a1" not in window:
        raise NoGapError("method 'gap_only' needs a1 (use 'speed' with omega1)")
    mf = _net_torque(window, bearing_friction_nms_per_rad)
    fit = made if made is not None else gap_only_fit(
        mf, np.asarray(window["a1"], float) / wheel_radius_m, start, end,
        max_trim=gap_only_max_trim(model, sample_period_s), declared=declared_errors(model, sample_period_s))
    return FitState(fit["j1"], fit["se"], fit["residual"], fit["dof"], fit["model_error"], (fit["start"], fit["end"]),
                    made=fit, torque=mf)


def _method_acceleration(window: dict, rows: tuple, drive: tuple, model: GapModel | None = None) -> FitState:
    """gap._estimate_inertia's 'acceleration' fit over ``rows`` (start, end): the joint fit (:func:`_joint_fit`), its
    model error the change of J1 with a linear torque term; a ratio at or below zero is told from a sign error as the
    other fits' (gap_sign.no_positive_ratio, the declared errors of ``model``).  ``drive``: (r, b1, T_s)."""
    (start, end), (wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    if "a1" not in window:
        raise NoGapError("method 'acceleration' needs a1 (use 'speed' with omega1)")
    friction = None
    if bearing_friction_nms_per_rad and "omega1" in window:
        friction = bearing_friction_nms_per_rad * np.asarray(window["omega1"], float)[start:end]
    fit = _joint_fit(np.asarray(window["m_el"], float), np.asarray(window["a1"], float), start, end, friction)
    kappa = fit["kappa"]
    if not kappa > 0:
        flip = 0.0 if model is None else gap_sign.slope_flip(
            _net_torque(window, bearing_friction_nms_per_rad)[start:end], *declared_errors(model, sample_period_s))
        raise NoGapError(gap_sign.no_positive_ratio(kappa, fit["kappa_se"], end - start, flip))
    j = wheel_radius_m / kappa
    alt = _joint_fit(np.asarray(window["m_el"], float), np.asarray(window["a1"], float), start, end, friction,
                     linear_term=True, warm=fit, kappa_only=True)
    model_error = abs(wheel_radius_m / alt["kappa"] - j) if alt["kappa"] > 0 else np.inf
    se = float(np.hypot(wheel_radius_m / kappa ** 2 * fit["kappa_se"], model_error))
    res = fit["a1_residual"] / kappa
    dof = fit["dof"]
    return FitState(j, se, res, dof, model_error, (start, end))


def _method_anchored(window: dict, rows: tuple, drive: tuple) -> FitState:
    """gap._estimate_inertia's 'anchored' fit over ``rows`` (start, end): the first release's (gap.py's docstring).
    ``drive``: (r, b1, T_s)."""
    (start, end), (wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    n = end - start
    m = _net_torque(window, bearing_friction_nms_per_rad)[start:end]
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
    return FitState(j, se, res, dof, 0.0, (start, end))


def _a1_bounded(f: FitState, window: dict, method: str, drive: tuple, model: GapModel, bounded: list,
                entry_error: float) -> None:
    """gap._estimate_inertia's bounded torque terms of the a1 fits (``f`` changed in place; ``bounded``: [(term, its
    bound N m)], ``entry_error``: the entry's uncertainty, kg m^2; ``drive``: (r, b1, T_s)): a constant torque F
    moves J1 (the slope of the torque on dω1/dt) by F Σx/Σx² over the fitted samples; the 'gap_only' fit takes the
    bounds through its own estimator or fits the constant (:func:`_gap_only_constant`); the drift and lag terms
    (:func:`_shape_terms`)."""
    wheel_radius_m, bearing_friction_nms_per_rad, sample_period_s = drive
    fit_span = f.span
    x = np.asarray(window["a1"], float)[fit_span[0]:fit_span[1]] / wheel_radius_m
    terms = dict(f.extra.get("std_error_terms", ()))
    mt = (np.gradient(_net_torque(window, bearing_friction_nms_per_rad), sample_period_s)[fit_span[0]:fit_span[1]]
          if model.torque_lag_s else None)
    if method == "gap_only" and bounded:
        f.j, f.se, f.res, f.dof, terms, note, trend = _gap_only_constant(f.made, f.torque, (x, mt), model, bounded,
                                                                         (f.j, f.se, f.res, f.dof), terms, entry_error)
        if note:
            f.extra["friction"] = note
            f.extra["trend_fit"] = _trend_finished(*trend, model)
            f.model_error = float(terms.get("change_points", 0.0))
    else:
        sens = abs(float(x.sum())) / max(float(x @ x), 1e-300)
        for name, v in bounded:
            terms[name] = sens * v / np.sqrt(3.0)
            f.se = float(np.hypot(f.se, terms[name]))
        for name, v in _shape_terms(x, mt, model).items():
            terms[name] = v
            f.se = float(np.hypot(f.se, v))
    f.extra["std_error_terms"] = tuple(terms.items())
