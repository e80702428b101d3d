"""Simulate the backlash-entry transient for many cases at once.

The scenario (see docs/model.md):

1. start every case in its loaded steady state, computed directly from the
   equivalent circuit and the load balance (no start-up run), 48 samples
   before the event;
2. at t = 0 the line slips on the drive wheel by the backlash width K2: the
   clutch relative angle drops by K2/r, so |alpha_1 - alpha_2| < K2/r
   (paper eq. 1) holds from that sample on and the load moment on the motor
   is zero while it does;
3. the motor accelerates freely through the zone, the flanks meet again and
   the load is taken up; 2000 samples from the entry sample are recorded.

All cases are integrated together by a fixed-step RK4 on arrays of shape
(N_STATES, n_cases).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from jident_ros.sim.checks import check_finite, check_step
from jident_ros.sim.model import (
    ALPHA1,
    DELTA,
    LINE_STRETCH,
    N_STATES,
    OMEGA1,
    OMEGA2,
    PSI_RA,
    PSI_RB,
    PSI_SA,
    PSI_SB,
    V2,
    CaseArrays,
    Model,
)
from jident_ros.sim.motor import solve_slip, steady_state_phasors
from jident_ros.sim.params import SystemConfig

#: Channel order of a window, as on /drive/signals (after the time column).
CHANNELS = ("alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2")
#: The five state signals the paper analyses, in the paper's order a)-e).
PAPER_SIGNALS = ("a1", "m_el", "omega1", "a2", "v2")
#: SI unit of each channel.
UNITS = {"t": "s", "alpha1": "rad", "alpha2": "rad", "omega2": "rad/s", "a1": "m/s^2",
         "m_el": "N m", "omega1": "rad/s", "a2": "m/s^2", "v2": "m/s", "clutch_torque": "N m"}


@dataclass(frozen=True)
class Case:
    """One simulated case.

    Attributes
    ----------
    inertia_kgm2 : float
        J_1, kg m^2 (a K_1 entry for the paper's grid).
    backlash_width_m : float
        Backlash zone width at the wheel circumference, m (a K_2 entry).
    consistency_pa_sn : float
        Lubricant consistency index eta_k, Pa s^n1.
    """

    inertia_kgm2: float
    backlash_width_m: float
    consistency_pa_sn: float

    def __post_init__(self):
        for name in ("inertia_kgm2", "backlash_width_m", "consistency_pa_sn"):
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v) or v <= 0:
                raise ValueError(f"Case.{name} must be a finite number > 0, got {v!r}")


class CaseTruths:
    """The true values of a ``cases`` list (Case per window or event), as arrays indexed by case: a
    mixin of the classes that carry such a list (robustness sweeps, long-run scenarios)."""

    @property
    def true_inertia_kgm2(self) -> np.ndarray:
        """J_1 of every case, kg m^2."""
        return np.array([c.inertia_kgm2 for c in self.cases])

    @property
    def true_width_m(self) -> np.ndarray:
        """Backlash width K_2 of every case, m."""
        return np.array([c.backlash_width_m for c in self.cases])


def paper_grid_cases(config: SystemConfig, consistencies: Iterable[float] | None = None) -> list[Case]:
    """The paper's grid: every eta_k x every J_1 class x every backlash width.

    Order: eta_k outermost, then J_1 (K_1 order), then width (K_2 order).
    """
    g = config.grid
    etas = g.consistency_indices_pa_sn if consistencies is None else tuple(consistencies)
    return [Case(float(j), float(b), float(e))
            for e in etas for j in g.inertia_classes_kgm2 for b in g.backlash_widths_m]


@dataclass
class WindowSet:
    """Simulated windows of many cases.

    Attributes
    ----------
    t : ndarray, shape (n_samples,)
        Time relative to the backlash-entry sample, s (0 at ``entry_index``).
    signals : dict of str -> ndarray, shape (n_cases, n_samples)
        Channels named in ``CHANNELS`` (SI, see ``UNITS``) plus
        ``clutch_torque`` (the load moment on the motor, N m).
    cases : list of Case
    entry_index : int
        Index of the backlash-entry sample (48).
    sample_period_s : float
    initial_slip : ndarray, shape (n_cases,)
        Steady-state slip before the event.
    """

    t: np.ndarray
    signals: dict
    cases: list
    entry_index: int
    sample_period_s: float
    initial_slip: np.ndarray
    metadata: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.cases)

    def case(self, i: int) -> dict:
        """Channels of case i as a dict of 1-D arrays (plus ``t``)."""
        out = {"t": self.t}
        out.update({k: v[i] for k, v in self.signals.items()})
        return out

    def as_array(self, channels: Sequence[str] = CHANNELS) -> np.ndarray:
        """Stack channels: shape (n_cases, n_samples, n_channels)."""
        return np.stack([self.signals[c] for c in channels], axis=-1)

    def save_npz(self, path) -> None:
        """Write the windows and their cases to a NumPy .npz file, uncompressed (``np.savez``): the float64
        signals compress by only ~14 % at any zlib level (168 cases: 24.8 MB raw, 21.2 MB at level 1, 21.4 MB at
        numpy's savez_compressed level 6), and compressing took 0.67 s (level 1) to 1.2 s (level 6) of CPU, a
        third to a half of `jident simulate --grid --out` (issue 23); ``np.load`` reads either.  A path without the
        .npz suffix gets it, as with ``np.savez``."""
        np.savez(
            path, t=self.t, entry_index=self.entry_index, sample_period_s=self.sample_period_s,
            initial_slip=self.initial_slip,
            inertia_kgm2=np.array([c.inertia_kgm2 for c in self.cases]),
            backlash_width_m=np.array([c.backlash_width_m for c in self.cases]),
            consistency_pa_sn=np.array([c.consistency_pa_sn for c in self.cases]),
            **{f"signal_{k}": v for k, v in self.signals.items()})

    @classmethod
    def load_npz(cls, path) -> "WindowSet":
        with np.load(path) as z:
            cases = [Case(float(a), float(b), float(c)) for a, b, c in
                     zip(z["inertia_kgm2"], z["backlash_width_m"], z["consistency_pa_sn"])]
            signals = {k[len("signal_"):]: z[k] for k in z.files if k.startswith("signal_")}
            return cls(z["t"], signals, cases, int(z["entry_index"]), float(z["sample_period_s"]),
                       z["initial_slip"])


def _case_arrays(cases: Sequence[Case], config: SystemConfig):
    j1 = np.array([c.inertia_kgm2 for c in cases], dtype=float)
    width = np.array([c.backlash_width_m for c in cases], dtype=float)
    eta = np.array([c.consistency_pa_sn for c in cases], dtype=float)
    return j1, width / config.load.wheel_radius_m, eta


def steady_state(config: SystemConfig, cases: Sequence[Case], t0: float):
    """Loaded steady state of every case at time t0 (s), before the event.

    Returns (y0 of shape (N_STATES, n_cases), slip of shape (n_cases,)).
    The clutch is in contact on its driving flank: delta = K2/r + T_c/k_c.
    """
    model = Model(config)
    ld = config.load
    j1, theta_b, eta = _case_arrays(cases, config)
    n = len(cases)

    def load_torque(omega1):
        v2 = ld.wheel_radius_m * omega1
        return (ld.wheel_radius_m * (ld.process_force_n + model.film_force(v2, eta))
                + config.motor.bearing_friction_nms_per_rad * omega1)

    slip = solve_slip(config.motor, load_torque, n)
    ph = steady_state_phasors(config.motor, slip)
    rot = np.exp(1j * model.wb * t0)  # synchronous frame -> stator frame at t0
    omega = (1.0 - slip) * model.base.mechanical_speed_rad_s
    v2 = ld.wheel_radius_m * omega
    f_line = ld.process_force_n + model.film_force(v2, eta)
    tc = ld.wheel_radius_m * f_line
    y = np.empty((N_STATES, n))
    psi_s, psi_r = ph["psi_s"] * rot, ph["psi_r"] * rot
    y[PSI_SA], y[PSI_SB] = psi_s.real, psi_s.imag
    y[PSI_RA], y[PSI_RB] = psi_r.real, psi_r.imag
    y[OMEGA1] = omega
    y[ALPHA1] = omega * t0
    y[DELTA] = theta_b + tc / ld.clutch_stiffness_nm_per_rad
    y[OMEGA2] = omega
    y[LINE_STRETCH] = f_line / ld.line_stiffness_n_per_m
    y[V2] = v2
    return y, slip


def check_stable(config: SystemConfig, cases: Sequence[Case], sample_period_s: float | None = None,
                 substeps: int | None = None) -> None:
    """Refuse (:class:`~jident_ros.sim.checks.SimulationDiverges`, a ValueError, one line with the reason)
    cases whose RK4 step would diverge, before anything is integrated (:func:`checks.check_step`).
    A steady state the motor cannot reach (overload) raises the ValueError of :func:`steady_state`."""
    cases = list(cases)
    s = config.sampling
    ts = s.sample_period_s if sample_period_s is None else float(sample_period_s)
    sub = s.integration_substeps if substeps is None else int(substeps)
    y, _ = steady_state(config, cases, 0.0)
    check_step(Model(config), y, CaseArrays(*_case_arrays(cases, config)), cases, ts, sub)


def _rk4_window(model: Model, y: np.ndarray, case: CaseArrays, t0: float, dt: float,
                substeps: int, n_samples: int, event_index: int, on_event, progress=None):
    """Integrate, recording the state at every sample; returns (n_samples, N_STATES, n)."""
    rec = np.empty((n_samples,) + y.shape)
    k1, k2, k3, k4 = (np.empty_like(y) for _ in range(4))
    tmp = np.empty_like(y)
    rhs = model.fast_rhs(case)
    h = dt / substeps
    # supply voltage at every RK4 stage time t0 + i h/2, computed once
    bias = model.bias_table(t0 + np.arange(2 * max(n_samples - 1, 0) * substeps + 1) * (0.5 * h))
    for k in range(n_samples):
        if k == event_index:
            on_event(y)
        rec[k] = y
        if progress is not None:
            progress(k)
        if k == n_samples - 1:
            break
        for j in range(substeps):
            i = 2 * (k * substeps + j)
            rhs(bias[i], y, k1)
            np.multiply(k1, 0.5 * h, out=tmp)
            tmp += y
            rhs(bias[i + 1], tmp, k2)
            np.multiply(k2, 0.5 * h, out=tmp)
            tmp += y
            rhs(bias[i + 1], tmp, k3)
            np.multiply(k3, h, out=tmp)
            tmp += y
            rhs(bias[i + 2], tmp, k4)
            k2 += k3
            k2 *= 2.0
            k2 += k1
            k2 += k4
            k2 *= h / 6.0
            y += k2
    return rec


def _rk4_window_one(model: Model, y: np.ndarray, case: CaseArrays, t0: float, dt: float,
                    substeps: int, n_samples: int, event_index: int, slip_rad: float, progress=None):
    """:func:`_rk4_window` for one case (``y`` of shape (N_STATES, 1)) on Python floats.

    The same RK4 on the same right-hand side (:meth:`Model.fast_rhs`, every operation in the same order on
    the same constants), written out on scalars: for one case the vectorised path costs numpy's per-call
    overhead (~50 us a right-hand side of ~25 numpy calls on 1-element arrays, 16,376 of them), not
    arithmetic.  The only difference is the summation order of the 10 x 10 matrix product, so the result
    equals the vectorised one to rounding (test_simulator_fast.py: 1e-12 relative).  ``slip_rad`` is
    subtracted from the clutch angle at sample ``event_index`` (the backlash entry; 0: no event).
    Returns (n_samples, N_STATES, 1).
    """
    A = model.linear_matrix()
    a_ss, a_sr = float(A[PSI_SA, PSI_SA]), float(A[PSI_SA, PSI_RA])
    a_rs, a_rr = float(A[PSI_RA, PSI_SA]), float(A[PSI_RA, PSI_RA])
    a_ww, a_we, a_wv = (float(A[OMEGA2, j]) for j in (OMEGA2, LINE_STRETCH, V2))
    a_ew, a_ev = float(A[LINE_STRETCH, OMEGA2]), float(A[LINE_STRETCH, V2])
    a_vw, a_ve, a_vv = (float(A[V2, j]) for j in (OMEGA2, LINE_STRETCH, V2))
    (j1,), (theta_b,), (eta,) = case.inertia_kgm2, case.backlash_angle_rad, case.consistency_pa_sn
    j1, theta_b, eta = float(j1), float(theta_b), float(eta)
    inv_j = 1.0 / j1
    k_torque = model._c_te * model._c_sr * inv_j
    film = model.film_gain * eta / model.m2
    pp, ir, cc, kc, ijw, b1 = model.pp, model.inv_ramp, model.cc, model.kc, model._inv_jw, model.b1
    b1_j = b1 * inv_j
    eps2, ex = model.eps2, (model.n1 - 1.0) / 2.0
    h = dt / substeps
    hh, h6 = 0.5 * h, h / 6.0
    bias = model.bias_table(t0 + np.arange(2 * max(n_samples - 1, 0) * substeps + 1) * (0.5 * h))
    bias_a, bias_b = bias[:, PSI_SA, 0].tolist(), bias[:, PSI_SB, 0].tolist()
    bias_v = float(bias[0, V2, 0])

    def rhs(ba, bb, y0, y1, y2, y3, y4, y5, y6, y7, y8, y9):
        wr = pp * y4
        drel = y4 - y7
        if y6 > 0.0:
            s, pen = 1.0, y6 - theta_b
        elif y6 < 0.0:
            s, pen = -1.0, -y6 - theta_b
        else:
            s, pen = 0.0, -theta_b
        if pen > 0.0:
            damp = pen * ir
            if damp > 1.0:
                damp = 1.0
            tc = pen * kc + damp * drel * s * cc
            tc = tc * s if tc > 0.0 else 0.0
        else:
            tc = 0.0
        acc = (y1 * y2 - y0 * y3) * k_torque
        if b1:
            acc -= b1_j * y4
        return (a_ss * y0 + a_sr * y2 + ba,
                a_ss * y1 + a_sr * y3 + bb,
                a_rs * y0 + a_rr * y2 - wr * y3,
                a_rs * y1 + a_rr * y3 + wr * y2,
                acc - tc * inv_j,
                y4,
                drel,
                a_ww * y7 + a_we * y8 + a_wv * y9 + tc * ijw,
                a_ew * y7 + a_ev * y9,
                a_vw * y7 + a_ve * y8 + a_vv * y9 + bias_v - (y9 * y9 + eps2) ** ex * y9 * film)

    y0, y1, y2, y3, y4, y5, y6, y7, y8, y9 = (float(v) for v in y[:, 0])
    rec = []
    for k in range(n_samples):
        if k == event_index:
            y6 -= slip_rad
        rec.append((y0, y1, y2, y3, y4, y5, y6, y7, y8, y9))
        if progress is not None:
            progress(k)
        if k == n_samples - 1:
            break
        for j in range(substeps):
            i = 2 * (k * substeps + j)
            a0, a1, a2 = bias_a[i], bias_a[i + 1], bias_a[i + 2]
            b0, b1_, b2 = bias_b[i], bias_b[i + 1], bias_b[i + 2]
            p0, p1, p2, p3, p4, p5, p6, p7, p8, p9 = rhs(a0, b0, y0, y1, y2, y3, y4, y5, y6, y7, y8, y9)
            q0, q1, q2, q3, q4, q5, q6, q7, q8, q9 = rhs(
                a1, b1_, p0 * hh + y0, p1 * hh + y1, p2 * hh + y2, p3 * hh + y3, p4 * hh + y4, p5 * hh + y5,
                p6 * hh + y6, p7 * hh + y7, p8 * hh + y8, p9 * hh + y9)
            r0, r1, r2, r3, r4, r5, r6, r7, r8, r9 = rhs(
                a1, b1_, q0 * hh + y0, q1 * hh + y1, q2 * hh + y2, q3 * hh + y3, q4 * hh + y4, q5 * hh + y5,
                q6 * hh + y6, q7 * hh + y7, q8 * hh + y8, q9 * hh + y9)
            s0, s1, s2, s3, s4, s5, s6, s7, s8, s9 = rhs(
                a2, b2, r0 * h + y0, r1 * h + y1, r2 * h + y2, r3 * h + y3, r4 * h + y4, r5 * h + y5,
                r6 * h + y6, r7 * h + y7, r8 * h + y8, r9 * h + y9)
            y0 += ((q0 + r0) * 2.0 + p0 + s0) * h6
            y1 += ((q1 + r1) * 2.0 + p1 + s1) * h6
            y2 += ((q2 + r2) * 2.0 + p2 + s2) * h6
            y3 += ((q3 + r3) * 2.0 + p3 + s3) * h6
            y4 += ((q4 + r4) * 2.0 + p4 + s4) * h6
            y5 += ((q5 + r5) * 2.0 + p5 + s5) * h6
            y6 += ((q6 + r6) * 2.0 + p6 + s6) * h6
            y7 += ((q7 + r7) * 2.0 + p7 + s7) * h6
            y8 += ((q8 + r8) * 2.0 + p8 + s8) * h6
            y9 += ((q9 + r9) * 2.0 + p9 + s9) * h6
    return np.array(rec)[:, :, None]


def simulate_grid(config: SystemConfig, cases: Sequence[Case], *, sample_period_s: float | None = None,
                  substeps: int | None = None, event: bool = True, progress=None, check: bool = True,
                  vectorised: bool = False) -> WindowSet:
    """Simulate the backlash-entry window of every case (vectorised).

    Parameters
    ----------
    config : SystemConfig
    cases : sequence of Case
    sample_period_s, substeps : optional overrides of ``config.sampling``.
    event : bool
        False runs the steady state on without the slip (for validation).
    progress : callable(k, n) or None
        Called after each recorded sample.
    check : bool
        Refuse inputs whose RK4 step would diverge before integrating and a non-finite result after
        (:mod:`jident_ros.sim.checks`; :class:`~jident_ros.sim.checks.SimulationDiverges`, a ValueError).
    vectorised : bool
        True integrates a single case with the numpy path too (by default one case runs on Python floats,
        :func:`_rk4_window_one`, ~10x faster and equal to rounding; for tests and benchmarks).

    Returns
    -------
    WindowSet with n_samples = 48 + 2000 by default.
    """
    cases = list(cases)
    if not cases:
        raise ValueError("cases: need at least one case, got an empty list")
    s = config.sampling
    ts = s.sample_period_s if sample_period_s is None else float(sample_period_s)
    sub = s.integration_substeps if substeps is None else int(substeps)
    if not ts > 0:
        raise ValueError(f"sample_period_s must be > 0, got {ts!r}")
    if sub < 1:
        raise ValueError(f"substeps must be >= 1, got {sub!r}")
    n_pre, n_samples = s.samples_before_entry, s.window_length
    t0 = -n_pre * ts
    model = Model(config)
    j1, theta_b, eta = _case_arrays(cases, config)
    y, slip = steady_state(config, cases, t0)
    case = CaseArrays(j1, theta_b, eta)
    if check:
        check_step(model, y, case, cases, ts, sub)

    def on_event(state):
        if event:
            state[DELTA] -= theta_b  # the line slips by K2 on the wheel

    prog = None if progress is None else (lambda k: progress(k, n_samples))
    if len(cases) == 1 and not vectorised:     # one case: scalar floats, same numbers (_rk4_window_one)
        rec = _rk4_window_one(model, y, case, t0, ts, sub, n_samples, n_pre,
                              float(theta_b[0]) if event else 0.0, prog)
    else:
        rec = _rk4_window(model, y, case, t0, ts, sub, n_samples, n_pre, on_event, prog)
    t = (np.arange(n_samples) - n_pre) * ts
    signals = derived_signals(model, rec, t, case)
    out = WindowSet(t, signals, cases, n_pre, ts, slip, metadata={"substeps": sub, "event": event})
    if check:
        check_finite(out)
    return out


def derived_signals(model: Model, rec: np.ndarray, t: np.ndarray, case: CaseArrays) -> dict:
    """Output channels from recorded states of shape (n_samples, N_STATES, n_cases)."""
    y = np.moveaxis(rec, 1, 0)  # (N_STATES, n_samples, n_cases)
    dy = model.rhs(t[:, None], y, case)
    r = model.r
    tc = model.clutch_torque(y[DELTA], y[OMEGA1] - y[OMEGA2], case.backlash_angle_rad)
    sig = {
        "alpha1": y[ALPHA1],
        "alpha2": y[ALPHA1] - y[DELTA],
        "omega2": y[OMEGA2],
        "a1": r * dy[OMEGA1],
        "m_el": model.electromagnetic_torque(y),
        "omega1": y[OMEGA1],
        "a2": dy[V2],
        "v2": y[V2],
        "clutch_torque": tc,
    }
    return {k: np.ascontiguousarray(v.T) for k, v in sig.items()}


def add_measurement_noise(windows: WindowSet, snr_db: float, seed: int,
                          channels: Sequence[str] = PAPER_SIGNALS + ("omega2",)) -> WindowSet:
    """White Gaussian noise at a given SNR per channel and case.

    SNR is measured as in MATLAB's ``awgn(x, snr, 'measured')``: noise power =
    mean(x^2) over the window / 10^(snr/10).  Same seed, same output.  The
    angles are left alone by default: an SNR relative to an ever-growing angle
    means nothing; encoders are modelled by :func:`quantise_encoders`.
    """
    if not np.isfinite(snr_db):
        raise ValueError(f"snr_db must be finite, got {snr_db!r}")
    rng = np.random.default_rng(seed)
    sig = dict(windows.signals)
    for c in channels:
        x = sig[c]
        p = np.mean(x * x, axis=1, keepdims=True) / 10.0 ** (snr_db / 10.0)
        sig[c] = x + rng.standard_normal(x.shape) * np.sqrt(p)
    return WindowSet(windows.t, sig, windows.cases, windows.entry_index, windows.sample_period_s,
                     windows.initial_slip, dict(windows.metadata, snr_db=snr_db, seed=seed))


def quantise_encoders(windows: WindowSet, counts_per_rev: int) -> WindowSet:
    """Quantise the angle channels alpha1, alpha2 to an encoder's resolution."""
    if int(counts_per_rev) < 1:
        raise ValueError(f"counts_per_rev must be >= 1, got {counts_per_rev!r}")
    q = 2.0 * np.pi / int(counts_per_rev)
    sig = dict(windows.signals)
    for c in ("alpha1", "alpha2"):
        sig[c] = np.floor(sig[c] / q) * q
    return WindowSet(windows.t, sig, windows.cases, windows.entry_index, windows.sample_period_s,
                     windows.initial_slip, dict(windows.metadata, counts_per_rev=int(counts_per_rev)))
