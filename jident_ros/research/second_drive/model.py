"""Physics of the second (validation) drive: a vector-controlled induction motor
driving a belt conveyor through a coupling with backlash.

Written independently of ``jident_ros.sim`` (it imports nothing from it); see
docs/second_drive.md for every parameter, its unit and the reason for its value.

Chain::

    speed PI (torque limit, anti-windup) -> torque-producing current lag ->
    rotor-flux model of the induction machine in the controller's (indirect
    field-oriented) frame, rotor time constant mis-estimated -> m_el
    rotor J1 --coupling with backlash (Hertz k pen^1.5, Hunt-Crossley damping)--
    gearbox N (rigid, lossless) -- head drum R_d -- belt + material m_b
    (Coulomb + viscous + quadratic resistance)

State rows (array of shape (N_STATES, n_cases)), SI units::

    0 ISD, 1 ISQ   stator current in the controller frame, A (peak)
    2 PSI_D, 3 PSI_Q  rotor flux linkage in the controller frame, Wb (peak)
    4 XI           speed-PI integrator (torque reference share), N m
    5 WF           filtered speed feedback, rad/s
    6 OMEGA1       motor shaft speed, rad/s
    7 ALPHA1       motor shaft angle, rad
    8 DELTA        relative coupling angle alpha1 - N alpha2, rad, 0 at the centre
                   of the backlash zone; the zone is |DELTA| < theta_b = K2/r
    9 V2           belt speed, m/s (drum speed omega2 = V2/R_d, load angle
                   alpha2 = (alpha1 - DELTA)/N)

Width convention: K2 is the backlash width in metres at the reference radius r
of the coupling (motor side); theta_b = K2/r is the half-zone; the flanks are at
DELTA = +theta_b and -theta_b, so the flank-to-flank travel is 2 K2/r (the same
convention as docs/model.md).

Event: a step of the drive's speed reference towards zero (|omega_ref| drops by
``step_fraction``).  The speed PI swings m_el to the opposite torque limit, the
motor leaves the driving flank (entry: |DELTA| < theta_b), crosses the zone with
zero coupling torque and hits the other flank; when the new speed is reached the
drive pulls the load again and the zone is crossed back.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

ISD, ISQ, PSI_D, PSI_Q, XI, WF, OMEGA1, ALPHA1, DELTA, V2 = range(10)
N_STATES = 10

#: the paper's J1 classes, kg m^2 (nominal first), and backlash widths K2, m
PAPER_INERTIAS_KGM2 = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)
PAPER_WIDTHS_M = (0.0025, 0.00375, 0.005, 0.0075, 0.009, 0.01)


@dataclass(frozen=True)
class Motor:
    """30 kW, 400 V, 50 Hz, 6-pole (3 pole pairs) cage motor, current-fed by its inverter."""

    pole_pairs: int = 3
    magnetizing_inductance_h: float = 0.0366     # L_m
    rotor_inductance_h: float = 0.0381           # L_r = L_m + L_sigma_r (1.5 mH)
    rotor_resistance_ohm: float = 0.080          # R_r (warm)
    rotor_time_constant_error: float = 1.15      # controller's tau_r estimate / true tau_r
    flux_reference_wb: float = 1.0               # rotor flux set-point (peak)
    current_lag_s: float = 1.0e-3                # closed current loop, first-order time constant
    rated_torque_nm: float = 291.0               # 30 kW at 985 rpm
    torque_limit_nm: float = 437.0               # 1.5 x rated
    bearing_friction_nms: float = 0.01           # b_1: J1 domega1/dt = m_el - b1 omega1 - T_c

    @property
    def rotor_time_constant_s(self) -> float:
        return self.rotor_inductance_h / self.rotor_resistance_ohm

    @property
    def torque_constant(self) -> float:
        """k_t in m_el = k_t (psi_d i_q - psi_q i_d), N m/(Wb A)."""
        return 1.5 * self.pole_pairs * self.magnetizing_inductance_h / self.rotor_inductance_h


@dataclass(frozen=True)
class SpeedController:
    """Speed PI with back-calculation anti-windup and a first-order speed filter."""

    kp_nms: float = 79.0          # N m s/rad  (J_total 3.16 kg m^2 x 25 rad/s)
    ki_nm: float = 494.0          # N m/rad    (kp x 25/4 rad/s)
    antiwindup_s: float = 0.05    # back-calculation time constant
    speed_filter_s: float = 1.0e-3


@dataclass(frozen=True)
class Coupling:
    """Jaw coupling with backlash: Hertz contact with Hunt-Crossley damping."""

    reference_radius_m: float = 0.08             # r: K2 is measured at this radius
    hertz_stiffness: float = 8.2e5               # k, N m / rad^1.5
    hertz_exponent: float = 1.5
    hunt_crossley_s_per_rad: float = 0.08        # lambda/k: T = k pen^1.5 (1 + 0.08 dpen/dt)


@dataclass(frozen=True)
class Conveyor:
    """Belt conveyor behind the gearbox, in belt (linear) units."""

    drum_radius_per_ratio_m: float = 0.05        # R_d = 0.05 m x N (same belt speed for every N)
    belt_mass_kg: float = 800.0                  # belt, material, idlers, drum and gear referred to the belt
    coulomb_n: float = 1200.0
    viscous_ns_per_m: float = 320.0
    quadratic_ns2_per_m2: float = 64.0
    coulomb_smoothing_m_s: float = 0.01          # tanh(v/v_eps) instead of sign(v)


@dataclass(frozen=True)
class DriveParams:
    motor: Motor = field(default_factory=Motor)
    controller: SpeedController = field(default_factory=SpeedController)
    coupling: Coupling = field(default_factory=Coupling)
    load: Conveyor = field(default_factory=Conveyor)
    gear_ratio: float = 1.0                      # N: motor speed / drum speed (1 or 4 supported)
    sample_period_s: float = 5.0e-4
    substeps: int = 2                            # RK4 steps per sample
    speed_reference_rad_s: float = 100.0         # |omega_ref| before the event (955 rpm)
    step_fraction: float = 0.20                  # |omega_ref| drops by this fraction at the event

    @property
    def drum_radius_m(self) -> float:
        return self.load.drum_radius_per_ratio_m * self.gear_ratio

    def with_gear(self, n: float) -> "DriveParams":
        return replace(self, gear_ratio=float(n))


# ----------------------------------------------------------------------------------------------
class Drive:
    """Vectorised right-hand side and steady state for n cases.

    Per-case inputs (arrays of shape (n,)): J1 [kg m^2]; the speed reference
    schedule omega_ref(t) = w0 + sum_k dw_k [t >= ts_k]; the half-zone schedule
    theta_b(t) = th0 + sum_k dth_k clip((t - s_k)/d_k, 0, 1) (piecewise linear,
    for a zone that wears between events).
    """

    def __init__(self, p: DriveParams, inertia, w0, theta0, steps=(), ramps=()):
        self.p = p
        m, c, cp, ld = p.motor, p.controller, p.coupling, p.load
        self.J1 = np.asarray(inertia, float)
        n = self.J1.size
        self.n = n
        self.w0 = np.broadcast_to(np.asarray(w0, float), (n,)).copy()
        self.th0 = np.broadcast_to(np.asarray(theta0, float), (n,)).copy()
        # steps: list of (t_k array, dw_k array); ramps: list of (s_k, d_k, dth_k)
        self.steps = [(np.broadcast_to(np.asarray(t, float), (n,)), np.broadcast_to(np.asarray(d, float), (n,)))
                      for t, d in steps]
        self.ramps = [(np.broadcast_to(np.asarray(s, float), (n,)), np.broadcast_to(np.asarray(d, float), (n,)),
                       np.broadcast_to(np.asarray(dth, float), (n,))) for s, d, dth in ramps]
        self.N = float(p.gear_ratio)
        self.Rd = p.drum_radius_m
        self.kt = m.torque_constant
        self.tr = m.rotor_time_constant_s
        self.tr_hat = self.tr * m.rotor_time_constant_error
        self.Lm = m.magnetizing_inductance_h
        self.psi_ref = m.flux_reference_wb
        self.isd_ref = self.psi_ref / self.Lm
        self.tau_i = m.current_lag_s
        self.tmax = m.torque_limit_nm
        self.b1 = m.bearing_friction_nms
        self.kp, self.ki, self.taw, self.tf = c.kp_nms, c.ki_nm, c.antiwindup_s, c.speed_filter_s
        self.kh, self.ex, self.lam = cp.hertz_stiffness, cp.hertz_exponent, cp.hunt_crossley_s_per_rad
        self.mb = ld.belt_mass_kg
        self.fc, self.cv, self.cq, self.veps = (ld.coulomb_n, ld.viscous_ns_per_m, ld.quadratic_ns2_per_m2,
                                                ld.coulomb_smoothing_m_s)

    # -- inputs ---------------------------------------------------------------------------------
    def omega_ref(self, t):
        w = self.w0.copy()
        for ts, dw in self.steps:
            w += np.where(t >= ts, dw, 0.0)
        return w

    def theta_b(self, t):
        th = self.th0.copy()
        for s, d, dth in self.ramps:
            th += dth * np.clip((t - s) / d, 0.0, 1.0)
        return th

    # -- pieces ---------------------------------------------------------------------------------
    def load_force(self, v2):
        """Belt resistance F_L(v2), N (positive opposes forward motion)."""
        return self.fc * np.tanh(v2 / self.veps) + self.cv * v2 + self.cq * v2 * np.abs(v2)

    def coupling_torque(self, delta, ddelta, theta_b):
        """Torque from the motor into the load side, N m; exactly 0 for |delta| <= theta_b."""
        s = np.sign(delta)
        pen = np.abs(delta) - theta_b
        inside = pen <= 0.0
        pen = np.where(inside, 0.0, pen)
        t = self.kh * pen ** self.ex * (1.0 + self.lam * s * ddelta)
        t = np.where(inside, 0.0, np.maximum(t, 0.0))
        return s * t

    def electromagnetic_torque(self, y):
        return self.kt * (y[PSI_D] * y[ISQ] - y[PSI_Q] * y[ISD])

    # -- right-hand side ------------------------------------------------------------------------
    def rhs(self, t, y, out=None, t_ref=None):
        """dy/dt; also returns (m_el, T_c, theta_b, omega_ref) at (t, y).

        ``t_ref``: time at which the (piecewise-constant) speed reference is
        read; the integrator passes the step's midpoint so that a reference step
        on a step boundary acts from that boundary on and not before it.
        """
        if out is None:
            out = np.empty_like(y)
        w1, v2 = y[OMEGA1], y[V2]
        wref = self.omega_ref(t if t_ref is None else t_ref)
        th = self.theta_b(t)
        # speed PI -> torque reference -> current references
        e = wref - y[WF]
        tu = self.kp * e + y[XI]
        ts = np.clip(tu, -self.tmax, self.tmax)
        isq_ref = ts / (self.kt * self.psi_ref)
        wsl = self.Lm * isq_ref / (self.tr_hat * self.psi_ref)   # commanded slip frequency (electrical)
        out[ISD] = (self.isd_ref - y[ISD]) / self.tau_i
        out[ISQ] = (isq_ref - y[ISQ]) / self.tau_i
        out[PSI_D] = (self.Lm * y[ISD] - y[PSI_D]) / self.tr + wsl * y[PSI_Q]
        out[PSI_Q] = (self.Lm * y[ISQ] - y[PSI_Q]) / self.tr - wsl * y[PSI_D]
        out[XI] = self.ki * e + (ts - tu) / self.taw
        out[WF] = (w1 - y[WF]) / self.tf
        m_el = self.electromagnetic_torque(y)
        ddelta = w1 - self.N * v2 / self.Rd
        tc = self.coupling_torque(y[DELTA], ddelta, th)
        out[OMEGA1] = (m_el - self.b1 * w1 - tc) / self.J1
        out[ALPHA1] = w1
        out[DELTA] = ddelta
        out[V2] = (self.N * tc / self.Rd - self.load_force(v2)) / self.mb
        return out, m_el, tc, th, wref

    # -- steady state ---------------------------------------------------------------------------
    def steady_state(self, t0=0.0):
        """Exact steady state at omega_ref(t0), theta_b(t0), load on its driving flank."""
        w1 = self.omega_ref(np.float64(t0))
        th = self.theta_b(np.float64(t0))
        v2 = self.Rd * w1 / self.N
        tc = self.load_force(v2) * self.Rd / self.N
        pen = (np.abs(tc) / self.kh) ** (1.0 / self.ex)
        delta = np.sign(tc) * (th + pen)
        m_req = tc + self.b1 * w1
        # current-fed IM with mis-estimated tau_r: psi = Lm i/(1 + j wsl tau_r),
        # m_el = kt Lm |i|^2 wsl tau_r/(1 + (wsl tau_r)^2), wsl = Lm isq/(tau_r_hat psi_ref)
        isd = self.isd_ref

        def torque(isq):
            x = self.Lm * isq / (self.tr_hat * self.psi_ref) * self.tr
            return self.kt * self.Lm * (isd ** 2 + isq ** 2) * x / (1.0 + x * x)

        hi_lim = 3.0 * self.tmax / (self.kt * self.psi_ref)     # torque(isq) is monotonic up to here
        lo = np.full_like(m_req, -hi_lim)
        hi = np.full_like(m_req, hi_lim)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            f = torque(mid) - m_req
            lo = np.where(f < 0, mid, lo)
            hi = np.where(f < 0, hi, mid)
        isq = 0.5 * (lo + hi)
        x = self.Lm * isq / (self.tr_hat * self.psi_ref) * self.tr
        psi = self.Lm * (isd + 1j * isq) / (1.0 + 1j * x)
        y = np.zeros((N_STATES, self.n))
        y[ISD], y[ISQ] = isd, isq
        y[PSI_D], y[PSI_Q] = psi.real, psi.imag
        y[XI] = isq * self.kt * self.psi_ref
        if np.any(np.abs(y[XI]) >= self.tmax):
            raise ValueError("steady load exceeds the drive's torque limit")
        y[WF] = y[OMEGA1] = w1
        y[DELTA] = delta
        y[V2] = v2
        return y


@dataclass
class Result:
    """Sampled trajectories, arrays of shape (n_samples, n_cases) (t: (n_samples,))."""

    t: np.ndarray
    omega1: np.ndarray
    alpha1: np.ndarray
    delta: np.ndarray
    v2: np.ndarray
    m_el: np.ndarray
    domega1: np.ndarray       # model derivative at the sample instants, rad/s^2
    dv2: np.ndarray           # m/s^2
    coupling_torque: np.ndarray
    theta_b: np.ndarray
    omega_ref: np.ndarray
    gear_ratio: float
    drum_radius_m: float

    @property
    def omega2(self):
        return self.v2 / self.drum_radius_m

    @property
    def alpha2(self):
        return (self.alpha1 - self.delta) / self.gear_ratio


def simulate(drive: Drive, duration_s: float, t0: float = 0.0) -> Result:
    """Fixed-step classical RK4, ``substeps`` steps per sample, all cases at once.

    Starts from the exact steady state at t0.  Reference steps must lie on
    step boundaries (the CLI puts them on samples): within a step the reference
    is read at the step's midpoint, so the state at the step time is still the
    one before the event.
    """
    p = drive.p
    ts = p.sample_period_s
    h = ts / p.substeps
    n_s = int(round(duration_s / ts)) + 1
    y = drive.steady_state(t0)
    names = ("omega1", "alpha1", "delta", "v2", "m_el", "domega1", "dv2", "coupling_torque", "theta_b",
             "omega_ref")
    rec = {k: np.empty((n_s, drive.n)) for k in names}
    k1 = np.empty_like(y)
    k2 = np.empty_like(y)
    k3 = np.empty_like(y)
    k4 = np.empty_like(y)
    t = t0
    for i in range(n_s):
        t = t0 + i * ts
        _, m_el, tc, th, _ = drive.rhs(t, y, k1, t_ref=t + 0.5 * h)
        wref = drive.omega_ref(t)
        rec["omega1"][i] = y[OMEGA1]
        rec["alpha1"][i] = y[ALPHA1]
        rec["delta"][i] = y[DELTA]
        rec["v2"][i] = y[V2]
        rec["m_el"][i] = m_el
        rec["domega1"][i] = k1[OMEGA1]
        rec["dv2"][i] = k1[V2]
        rec["coupling_torque"][i] = tc
        rec["theta_b"][i] = th
        rec["omega_ref"][i] = wref
        if i == n_s - 1:
            break
        for j in range(p.substeps):
            tt = t + j * h
            tm = tt + 0.5 * h
            if j:
                drive.rhs(tt, y, k1, t_ref=tm)
            drive.rhs(tm, y + (0.5 * h) * k1, k2, t_ref=tm)
            drive.rhs(tm, y + (0.5 * h) * k2, k3, t_ref=tm)
            drive.rhs(tt + h, y + h * k3, k4, t_ref=tm)
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return Result(t=t0 + ts * np.arange(n_s), gear_ratio=drive.N, drum_radius_m=drive.Rd, **rec)


def gaps(delta_col, theta_col, start=0):
    """Gap intervals of one case: list of (first index with |delta| < theta_b,
    first index after it with |delta| >= theta_b, or len), from index ``start``."""
    inside = np.abs(np.asarray(delta_col)) < theta_col
    inside[:start] = False
    d = np.diff(inside.astype(np.int8))
    begins = list(np.nonzero(d == 1)[0] + 1)
    ends = list(np.nonzero(d == -1)[0] + 1)
    if inside.size and inside[0]:
        begins.insert(0, 0)
    out = []
    for b in begins:
        e = next((x for x in ends if x > b), len(inside))
        out.append((int(b), int(e)))
    return out
