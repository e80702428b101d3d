"""Physics of the third validation drive: motulator's induction machine under motulator's own
current-vector control and speed controller, driving a second mass through a coupling with a
backlash dead zone (docs/vector_drive.md).

What comes from motulator (https://github.com/Aalto-Electric-Drives/motulator, 0.5.x API):
the inverter (``VoltageSourceConverter``, zero-order-hold PWM, one sample of computational
delay), the induction machine (``InductionMachine``, Gamma model, SI, peak-valued space vectors),
the current-vector control with its reduced-order flux observer (``CurrentVectorControl``, sensored
mode), its 2DOF speed PI (``SpeedController``, anti-windup on the current-limited torque) and the
solver loop (``Simulation``: ``solve_ivp`` per control period).

What is ours (motulator has no backlash): the mechanics, :class:`BacklashTwoMass` (a motulator
``Subsystem``), and the drive's measurement chain, :class:`RecordingControl` (a subclass of
motulator's controller that sees quantised encoder angles, computes the lagging speed feedback the
speed PI acts on, and logs the drive's own torque estimate and the true states every period).

Width convention (the same as jident_ros.sim and jident_ros.research.second_drive): K2 is the backlash
width in metres at the reference radius r; the half zone is theta_b = K2/r; the zone is
|delta| < theta_b with delta = theta_M - N theta_L, measured from the zone centre; the
flank-to-flank travel is 2 K2/r.

motulator is imported only inside the functions that build a simulation, so this module imports
without it (:func:`motulator_available`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from types import SimpleNamespace
from typing import Optional

import numpy as np

from jident_ros.research.second_drive.model import gaps  # the gap intervals of a delta series: one home

MOTULATOR_HINT = ("the vector drive needs motulator (Python < 3.12: motulator==0.5.0): "
                  "pip install -e '.[zoo]'")


def motulator_available() -> Optional[str]:
    """None when motulator (0.5.x API) imports, else the reason (one line)."""
    try:
        import motulator.drive.model as model  # noqa: F401
        from motulator.drive.control.im import CurrentVectorControl  # noqa: F401
    except ImportError as exc:
        return f"{MOTULATOR_HINT} ({exc})"
    if not hasattr(model, "StiffMechanicalSystem"):
        return f"motulator {_version()} has the >= 0.6 API; this model is written for 0.5.x ({MOTULATOR_HINT})"
    return None


def _version() -> str:
    try:
        return version("motulator")
    except PackageNotFoundError:   # pragma: no cover - metadata missing
        return "?"


# ------------------------------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class Machine:
    """Induction machine, inverse-Gamma model parameters (SI, peak-valued space vectors).

    The default is motulator's 2.2 kW, 400 V, 50 Hz, 4-pole example machine scaled to
    ``rated_power_w`` at the same voltage (impedances x 2.2 kW / P) with the resistances a further
    ``resistance_scale`` lower (larger machines have lower per-unit resistance).
    """

    rated_power_w: float = 37.0e3
    pole_pairs: int = 2
    stator_resistance_ohm: float = 3.7          # R_s of the 2.2 kW machine (scaled in :meth:`scaled`)
    rotor_resistance_ohm: float = 2.1           # R_R
    leakage_inductance_h: float = 0.021         # L_sgm
    magnetizing_inductance_h: float = 0.224     # L_M
    reference_power_w: float = 2.2e3            # the machine the values above belong to
    resistance_scale: float = 0.4
    rated_speed_rad_s: float = 2 * math.pi * 1475 / 60
    max_current_a: float = 1.5 * math.sqrt(2) * 5.0   # peak, of the 2.2 kW machine (scaled)
    dc_voltage_v: float = 540.0

    def scaled(self) -> dict:
        """Inverse-Gamma parameters of the machine at ``rated_power_w``: n_p, R_s, R_R, L_sgm, L_M (SI)."""
        k = self.reference_power_w / self.rated_power_w
        return {"n_p": self.pole_pairs, "R_s": self.stator_resistance_ohm * k * self.resistance_scale,
                "R_R": self.rotor_resistance_ohm * k * self.resistance_scale,
                "L_sgm": self.leakage_inductance_h * k, "L_M": self.magnetizing_inductance_h * k}

    @property
    def max_current_scaled_a(self) -> float:
        return self.max_current_a * self.rated_power_w / self.reference_power_w

    @property
    def rated_torque_nm(self) -> float:
        return self.rated_power_w / self.rated_speed_rad_s


@dataclass(frozen=True)
class Controller:
    """The drive's control and measurement chain.

    The controller's machine model is off the true machine (``*_estimate_ratio``: a warm rotor
    against its nameplate resistance, a magnetising inductance from a no-load test at another flux),
    so the drive's torque estimate 1.5 n_p |psi_R,est| i_sq has its own error against the true
    air-gap torque.
    """

    control_period_s: float = 250e-6            # current control and speed control period
    current_bandwidth_rad_s: float = 2 * math.pi * 200
    speed_bandwidth_rad_s: float = 2 * math.pi * 5
    inertia_estimate_ratio: float = 1.0         # speed PI tuned on (J1 + J2/N^2) x this
    rotor_resistance_estimate_ratio: float = 0.85
    magnetizing_inductance_estimate_ratio: float = 1.05
    speed_filter_s: float = 0.5e-3              # first-order filter on the encoder difference speed
    torque_limit_ratio: float = 1.5             # |tau_ref| <= this x rated torque


@dataclass(frozen=True)
class Mechanics:
    """Two masses, a coupling with a backlash dead zone, bearing friction on the motor.

    T_c = sign(delta) max(0, k pen + c d(pen)/dt) for pen = |delta| - K2/r > 0, else 0 exactly.
    Motor: J1 dw_M/dt = tau_M - T_c - T_f1, T_f1 = T_coulomb tanh(w_M/w_eps) + b1 w_M.
    Load (at the gear output, N = w_M/w_L in contact): J2 dw_L/dt = N T_c - T_L(t) - T_f2.
    """

    motor_inertia_kgm2: float = 1.16            # J1: rotor + hub + brake disc
    load_inertia_kgm2: float = 2.0              # J2 at the load shaft
    gear_ratio: float = 1.0                     # N
    reference_radius_m: float = 0.1             # r: K2 is an arc length at this radius
    backlash_width_m: float = 0.005             # K2
    stiffness_nm_per_rad: float = 5.0e4         # k
    damping_nms_per_rad: float = 40.0           # c
    motor_coulomb_nm: float = 1.2               # bearing + seal friction, ~0.5 % of rated
    motor_viscous_nms_per_rad: float = 0.02     # b1 (fan, bearing grease)
    load_coulomb_nm: float = 6.0
    load_viscous_nms_per_rad: float = 0.3
    friction_smoothing_rad_s: float = 0.05      # tanh(w/w_eps) in place of sign(w)

    @property
    def half_zone_rad(self) -> float:
        return self.backlash_width_m / self.reference_radius_m


@dataclass(frozen=True)
class DriveParams:
    machine: Machine = field(default_factory=Machine)
    controller: Controller = field(default_factory=Controller)
    mechanics: Mechanics = field(default_factory=Mechanics)
    sample_period_s: float = 5.0e-4             # recording period (a multiple of the control period)
    speed_rad_s: float = 100.0                  # |w_ref| before the event
    base_load_ratio: float = 0.3                # external load torque in steady running, x rated
    light_load_ratio: float = 0.1               # load reversal at light load: coupling torque +-this x rated
    heavy_load_ratio: float = 0.8               # load reversal at heavy load (coupling torque +-this x rated)
    load_ramp_s: float = 0.01                   # load torque changes ramp over this time
    speed_step_ratio: float = 0.2               # speed steps: |w_ref| changes by this fraction
    reversal_ramp_s: float = 0.3                # speed reversal: w_ref ramps to -w_ref over this time
    preroll_s: float = 0.3                      # simulated, not recorded: the start transient settles

    @property
    def decimation(self) -> int:
        d = self.sample_period_s / self.controller.control_period_s
        if abs(d - round(d)) > 1e-9 or round(d) < 1:
            raise ValueError(f"sample_period_s: must be a multiple of the control period "
                             f"{self.controller.control_period_s}, got {self.sample_period_s}")
        return int(round(d))


def small_drive() -> DriveParams:
    """A drive of another size: motulator's own 2.2 kW example machine (unscaled) with its rotor and a
    hub (J1 = 0.03 kg m^2) on a 0.06 kg m^2 load through a 3:1 gear, K2 = 1.5 mm at r = 0.03 m."""
    m = Machine(rated_power_w=2.2e3, resistance_scale=1.0, rated_speed_rad_s=2 * math.pi * 1430 / 60)
    mech = Mechanics(motor_inertia_kgm2=0.03, load_inertia_kgm2=0.06 * 9, gear_ratio=3.0, reference_radius_m=0.03,
                     backlash_width_m=0.0015, stiffness_nm_per_rad=1500.0, damping_nms_per_rad=1.0,
                     motor_coulomb_nm=0.07, motor_viscous_nms_per_rad=5e-4, load_coulomb_nm=0.6,
                     load_viscous_nms_per_rad=0.01)
    return DriveParams(machine=m, mechanics=mech)


#: Event types of the recordings (truth files name them).
EVENTS = ("speed_step_down", "speed_step_up", "speed_reversal", "load_reversal_light", "load_reversal_heavy",
          "load_step_same_flank", "steady")
#: Events after which the coupling crosses the zone (the others must give no entry).
TRAVERSING_EVENTS = ("speed_step_down", "speed_reversal", "load_reversal_light", "load_reversal_heavy")


@dataclass(frozen=True)
class Scenario:
    """One recording's operating point and event (all in the direction's sign)."""

    event: str
    direction: float                  # +1 forward, -1 reverse
    speed_rad_s: float                # w_ref before the event (signed)
    load_before_nm: float             # external load torque before the event (signed, opposing = same sign as w)
    event_time_s: float               # from the start of the recording (after the pre-roll)
    speed_after_rad_s: Optional[float] = None
    load_after_nm: Optional[float] = None
    ramp_s: float = 0.0

    def speed_ref(self, t):
        """w_ref (mechanical rad/s) at recording time t."""
        if self.speed_after_rad_s is None or t < self.event_time_s:
            return self.speed_rad_s
        if self.ramp_s <= 0:
            return self.speed_after_rad_s
        x = min(1.0, (t - self.event_time_s) / self.ramp_s)
        return self.speed_rad_s + x * (self.speed_after_rad_s - self.speed_rad_s)

    def load(self, t):
        if self.load_after_nm is None or t < self.event_time_s:
            return self.load_before_nm
        x = 1.0 if self.ramp_s <= 0 else min(1.0, (t - self.event_time_s) / self.ramp_s)
        return self.load_before_nm + x * (self.load_after_nm - self.load_before_nm)


def scenario(p: DriveParams, event: str, direction: str = "forward", event_time_s: float = 0.5) -> Scenario:
    """The event's operating point and schedule (module constants EVENTS)."""
    if event not in EVENTS:
        raise ValueError(f"event: expected one of {', '.join(EVENTS)}, got {event!r}")
    if direction not in ("forward", "reverse"):
        raise ValueError(f"direction: expected forward or reverse, got {direction!r}")
    s = 1.0 if direction == "forward" else -1.0
    rated = p.machine.rated_torque_nm
    w0, base = s * p.speed_rad_s, s * p.base_load_ratio * rated
    common = dict(event=event, direction=s, speed_rad_s=w0, event_time_s=event_time_s)
    if event == "speed_step_down":
        return Scenario(**common, load_before_nm=base, speed_after_rad_s=w0 * (1 - p.speed_step_ratio))
    if event == "speed_step_up":
        return Scenario(**common, load_before_nm=base, speed_after_rad_s=w0 * (1 + p.speed_step_ratio))
    if event == "speed_reversal":      # a passive load (its friction only): one traversal, braking
        return Scenario(**common, load_before_nm=0.0, speed_after_rad_s=-w0, ramp_s=p.reversal_ramp_s)
    if event in ("load_reversal_light", "load_reversal_heavy"):
        # an active load whose torque reverses: the coupling torque goes from +x rated to -x rated
        x = (p.light_load_ratio if event.endswith("light") else p.heavy_load_ratio) * rated * s
        n = p.mechanics.gear_ratio
        f = float(load_friction(p.mechanics, w0 / n))
        return Scenario(**common, load_before_nm=n * x - f, load_after_nm=-n * x - f, ramp_s=p.load_ramp_s)
    if event == "load_step_same_flank":
        return Scenario(**common, load_before_nm=base, load_after_nm=s * p.heavy_load_ratio * rated,
                        ramp_s=p.load_ramp_s)
    return Scenario(**common, load_before_nm=base)


# ------------------------------------------------------------------------------------------ mechanics
def _subsystem_base():
    from motulator.common.model import Subsystem
    return Subsystem


def coupling_torque(mech: Mechanics, delta, d_delta):
    """T_c (N m, on the motor side) for relative angle delta and its rate (arrays or floats)."""
    delta = np.asarray(delta, float)
    pen = np.abs(delta) - mech.half_zone_rad
    sgn = np.sign(delta)
    t = mech.stiffness_nm_per_rad * pen + mech.damping_nms_per_rad * sgn * np.asarray(d_delta, float)
    return np.where(pen > 0, sgn * np.maximum(t, 0.0), 0.0)


def motor_friction(mech: Mechanics, w):
    w = np.asarray(w, float)
    return mech.motor_coulomb_nm * np.tanh(w / mech.friction_smoothing_rad_s) + mech.motor_viscous_nms_per_rad * w


def load_friction(mech: Mechanics, w):
    w = np.asarray(w, float)
    return mech.load_coulomb_nm * np.tanh(w / mech.friction_smoothing_rad_s) + mech.load_viscous_nms_per_rad * w


def make_mechanics(mech: Mechanics, load_torque):
    """A motulator Subsystem: motor mass, coupling with backlash, load mass (states w_M, theta_M, w_L,
    theta_L; real, the solver may carry them as complex)."""
    Subsystem = _subsystem_base()

    class BacklashTwoMass(Subsystem):
        def __init__(self):
            super().__init__()
            self.par = mech
            self.tau_L = load_torque
            self.state = SimpleNamespace(w_M=0.0, theta_M=0.0, w_L=0.0, theta_L=0.0)
            self.sol_states = SimpleNamespace(w_M=[], theta_M=[], w_L=[], theta_L=[])

        def torques(self, t):
            s = self.state
            w_M, th_M, w_L, th_L = (float(np.real(x)) for x in (s.w_M, s.theta_M, s.w_L, s.theta_L))
            n = mech.gear_ratio
            tau_c = float(coupling_torque(mech, th_M - n * th_L, w_M - n * w_L))
            return w_M, w_L, tau_c, float(motor_friction(mech, w_M)), float(load_friction(mech, w_L)) + \
                float(self.tau_L(t))

        def set_outputs(self, t):
            w_M, w_L, tau_c, f1, tl = self.torques(t)
            self.out.w_M, self.out.w_L = w_M, w_L
            self.out.tau_c, self.out.tau_f1, self.out.tau_L_tot = tau_c, f1, tl

        def rhs(self):
            o = self.out
            d_w_M = (np.real(self.inp.tau_M) - o.tau_c - o.tau_f1) / mech.motor_inertia_kgm2
            d_w_L = (mech.gear_ratio * o.tau_c - o.tau_L_tot) / mech.load_inertia_kgm2
            return [d_w_M, o.w_M, d_w_L, o.w_L]

        def meas_speed(self):
            return float(np.real(self.state.w_M))

        def meas_position(self):
            return float(np.real(self.state.theta_M))

        def post_process_states(self):
            for k in ("w_M", "theta_M", "w_L", "theta_L"):
                setattr(self.data, k, np.real(getattr(self.data, k)))

        def post_process_with_inputs(self):
            pass

    return BacklashTwoMass()


# ------------------------------------------------------------------------------------------ controller
def _make_control(p: DriveParams, log: dict, sc: Scenario, t_offset: float):
    """The drive's controller: motulator's CurrentVectorControl (sensored) with our measurement chain and logger."""
    from motulator.drive.control import SpeedController
    from motulator.drive.control.im import CurrentReferenceCfg, CurrentVectorControl
    from motulator.drive.control.im._current_vector import CurrentController
    from motulator.drive.utils import InductionMachineInvGammaPars

    true = p.machine.scaled()
    c = p.controller
    est = InductionMachineInvGammaPars(n_p=true["n_p"], R_s=true["R_s"],
                                       R_R=true["R_R"] * c.rotor_resistance_estimate_ratio,
                                       L_sgm=true["L_sgm"], L_M=true["L_M"] * c.magnetizing_inductance_estimate_ratio)
    mech = p.mechanics
    j_tot = (mech.motor_inertia_kgm2 + mech.load_inertia_kgm2 / mech.gear_ratio ** 2) * c.inertia_estimate_ratio
    cfg = CurrentReferenceCfg(est, max_i_s=p.machine.max_current_scaled_a, nom_u_s=math.sqrt(2 / 3) * 400,
                              nom_w_s=2 * math.pi * 50)
    n_p = true["n_p"]
    q_enc = 2 * math.pi / 2 ** 20     # the drive's own encoder interface (finer than the recorded ones)

    class RecordingControl(CurrentVectorControl):
        def __init__(self):
            super().__init__(est, cfg, J=j_tot, T_s=c.control_period_s, sensorless=False)
            self.current_ctrl = CurrentController(est, c.current_bandwidth_rad_s)
            self.speed_ctrl = SpeedController(j_tot, c.speed_bandwidth_rad_s,
                                              max_tau_M=c.torque_limit_ratio * p.machine.rated_torque_nm)
            self.ref.w_m = lambda t: n_p * sc.speed_ref(t - t_offset)
            self._enc_prev = None
            self._enc_prev_L = None
            self._w_filt = None
            self._w_filt_L = None

        def get_mechanical_measurements(self, fbk, mdl):
            mech_sys = mdl.mechanics
            th = math.floor(mech_sys.meas_position() / q_enc) * q_enc
            th_L = math.floor(float(np.real(mech_sys.state.theta_L)) / q_enc) * q_enc
            ts = self.T_s
            a = ts / (c.speed_filter_s + ts)
            if self._enc_prev is None:      # start: the true speeds
                self._w_filt = mech_sys.meas_speed()
                self._w_filt_L = float(np.real(mech_sys.state.w_L))
            else:
                self._w_filt += a * ((th - self._enc_prev) / ts - self._w_filt)
                self._w_filt_L += a * ((th_L - self._enc_prev_L) / ts - self._w_filt_L)
            self._enc_prev, self._enc_prev_L = th, th_L
            fbk.w_m = n_p * self._w_filt
            fbk.theta_m = (n_p * th + math.pi) % (2 * math.pi) - math.pi
            fbk.w_L_fbk = self._w_filt_L
            return fbk

        def get_feedback_signals(self, mdl):
            fbk = super().get_feedback_signals(mdl)
            # the true states at this sample instant (the solver's last evaluation is the period's end)
            log_true_state(log, mdl, mdl.t0, t_offset, mech)
            log["w_fbk"].append(fbk.w_m / n_p)
            log["w_L_fbk"].append(fbk.w_L_fbk)
            log["tau_est"].append(1.5 * n_p * fbk.psi_R * float(np.imag(fbk.i_s)))
            return fbk

        def output(self, fbk):
            ref = super().output(fbk)
            log["tau_ref"].append(float(ref.tau_M))
            log["w_ref"].append(ref.w_m / n_p)
            return ref

    return RecordingControl(), est


def log_true_state(log: dict, mdl, t: float, t_offset: float, mech: Mechanics) -> None:
    """Append the true states at ``t`` (the solver's last evaluation, the period's end) to ``log``: t, the angles and
    speeds, the machine's torque, the coupling, friction and load torques, and dω_M/dt (the vector and the DOL mode's
    controllers alike)."""
    w_M, w_L, tau_c, f1, tl = mdl.mechanics.torques(t)
    tau_true = float(mdl.machine.tau_M)
    s = mdl.mechanics.state
    log["t"].append(t - t_offset)
    log["theta_M"].append(float(np.real(s.theta_M)))
    log["w_M"].append(w_M)
    log["theta_L"].append(float(np.real(s.theta_L)))
    log["w_L"].append(w_L)
    log["tau_M"].append(tau_true)
    log["tau_c"].append(tau_c)
    log["tau_f1"].append(f1)
    log["tau_L"].append(tl)
    log["dw_M"].append((tau_true - tau_c - f1) / mech.motor_inertia_kgm2)


LOG_KEYS = ("t", "theta_M", "w_M", "theta_L", "w_L", "tau_M", "tau_c", "tau_f1", "tau_L", "dw_M", "w_fbk",
            "w_L_fbk", "tau_est", "tau_ref", "w_ref")


@dataclass
class Run:
    """One simulated recording at the control period (arrays, SI), before decimation and sensors."""

    params: DriveParams
    scenario: Scenario
    data: dict                  # LOG_KEYS -> (n,) arrays at the control period, t = 0 at the recording start
    motulator_version: str


def _steady_state(p: DriveParams, sc: Scenario):
    """Approximate steady state at w_ref with the external load: mechanics, machine fluxes, controller."""
    mech = p.mechanics
    w_M = sc.speed_rad_s
    n = mech.gear_ratio
    w_L = w_M / n
    tau_c = (float(load_friction(mech, w_L)) + sc.load_before_nm) / n
    tau_M = tau_c + float(motor_friction(mech, w_M))
    pen = abs(tau_c) / mech.stiffness_nm_per_rad
    delta = math.copysign(mech.half_zone_rad + pen, tau_c if tau_c != 0 else sc.direction)
    return w_M, w_L, delta, tau_c, tau_M


def simulate(p: DriveParams, sc: Scenario, duration_s: float) -> Run:
    """Simulate the pre-roll (not recorded), then ``duration_s`` of recording with the scenario's event."""
    reason = motulator_available()
    if reason:
        raise ImportError(reason)
    import motulator.drive.model as model
    from motulator.drive.utils import InductionMachineInvGammaPars, InductionMachinePars

    p.decimation        # validates the periods
    t_off = p.preroll_s
    log = {k: [] for k in LOG_KEYS}
    true = p.machine.scaled()
    par = InductionMachinePars.from_inv_gamma_model_pars(InductionMachineInvGammaPars(**true))
    machine = model.InductionMachine(par)
    mech = make_mechanics(p.mechanics, lambda t: sc.load(t - t_off))
    ctrl, est = _make_control(p, log, sc, t_off)

    # initial state: flux at its reference, the steady load, the coupling on its driving flank
    w_M, w_L, delta, tau_c, tau_M = _steady_state(p, sc)
    psi_R = ctrl.current_reference.cfg.nom_psi_R
    i_sd = psi_R / true["L_M"]
    i_sq = tau_M / (1.5 * true["n_p"] * psi_R)
    i_s = complex(i_sd, i_sq)
    psi_s = psi_R + true["L_sgm"] * i_s
    g = true["L_M"] / (true["L_M"] + true["L_sgm"])
    machine.state.psi_ss, machine.state.psi_rs = complex(psi_s), complex(psi_R / g)
    mech.state.w_M, mech.state.w_L = w_M, w_L
    mech.state.theta_M, mech.state.theta_L = delta, 0.0
    ctrl.observer.est.psi_R = psi_R * est.L_M / true["L_M"]
    ctrl.observer._work.old_i_s = i_s
    sp = ctrl.speed_ctrl          # 2DOF PI: v = u_i - (k_p - k_t) y is the output at zero error
    sp.u_i = tau_M + (sp.k_p - sp.k_t) * w_M
    w_s = true["n_p"] * w_M + true["R_R"] * i_sq / psi_R
    u_s = true["R_s"] * i_s + 1j * w_s * psi_s
    cc = ctrl.current_ctrl
    cc.u_i = u_s + (cc.k_p - cc.k_t) * i_s
    conv = model.VoltageSourceConverter(u_dc=p.machine.dc_voltage_v)
    mdl = model.Drive(converter=conv, machine=machine, mechanics=mech)
    d0 = ctrl.pwm.duty_ratios(u_s, p.machine.dc_voltage_v)
    mdl.delay.data = [list(d0)]
    ctrl.pwm.realized_voltage = ctrl.pwm._old_u_cs = u_s
    sim = model.Simulation(mdl, ctrl)
    ts_c = p.controller.control_period_s
    sim.simulate(t_stop=t_off + duration_s - 0.5 * ts_c)
    data = {k: np.asarray(v, float) for k, v in log.items()}
    keep = data["t"] >= -0.5 * ts_c
    data = {k: v[keep] for k, v in data.items()}
    data["t"] = np.round(data["t"] / ts_c) * ts_c
    if not np.all(np.isfinite(data["w_M"])):
        raise RuntimeError("motulator reported a numerical failure (non-finite states)")
    return Run(p, sc, data, _version())


__all__ = ["Controller", "DriveParams", "EVENTS", "LOG_KEYS", "Machine", "Mechanics", "Run", "Scenario",
           "TRAVERSING_EVENTS", "coupling_torque", "gaps", "load_friction", "motor_friction", "motulator_available",
           "scenario", "simulate", "small_drive"]
