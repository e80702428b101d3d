"""The vector drive's DOL mode: motulator's induction machine on a stiff 50 Hz grid (drive-on-line, no speed or
current control), driving the same two-mass coupling with a backlash dead zone (:class:`model.BacklashTwoMass`),
the torque a user of such a drive really has: an estimate from the measured stator voltages and currents
(docs/vector_drive.md, "DOL mode").

What comes from motulator (0.5.x): the induction machine (``InductionMachine``, Γ model, SI, peak-valued space
vectors), the voltage-source converter it is connected through (here :class:`StiffGrid`, a
``VoltageSourceConverter`` whose output is the grid's sinusoid itself, continuous in time: a stiff grid, no PWM),
the control-system loop (``ControlSystem``: the "controller" only outputs the grid voltage reference and measures)
and the solver loop (``Simulation``).  What is ours: the mechanics (model.make_mechanics), the measurement chain
(:class:`_DolMeasurement`: encoders, encoder speed, the torque estimate) and the steady state the runs start from.

The torque estimate (what a condition-monitoring box or a DOL soft-starter computes):
psi_s = leaky integral of (u_s - R_s,est i_s) (a first-order high-pass against the pure integrator's drift, corner
``flux_highpass_hz``, its gain and phase corrected at the grid frequency, which the user knows), sampled at the
control period, tau = 1.5 n_p Im(conj(psi_s) i_s).  R_s,est is the nameplate (cold) resistance, ``stator_resistance
_estimate_ratio`` x the true (warm) one, so the estimate misses part of the stator copper loss: an error
1.5 n_p dR |i_s|^2 / w_g, about 0.8 N m at no load (the magnetising current) and 1.5 N m at 0.7 rated.

Width convention, events' signs: as model.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
from scipy.optimize import brentq

from .model import (
    LOG_KEYS,
    Machine,
    Mechanics,
    Run,
    Scenario,
    _version,
    load_friction,
    log_true_state,
    make_mechanics,
    motor_friction,
    motulator_available,
)


def dol_mechanics() -> Mechanics:
    """The DOL drive's mechanics: the vector drive's coupling and bearing friction, the paper's kind of load
    (a capstan wheel 0.12 kg m^2 pulling a 50 kg mass on a line at r = 0.1 m: J2 = 0.12 + 50 x 0.1^2 ≈ 0.6
    kg m^2, lighter than J1 = 1.16 as in the paper) and a load friction that is mostly Coulomb (the line's guide)."""
    return Mechanics(load_inertia_kgm2=0.6, load_coulomb_nm=6.0, load_viscous_nms_per_rad=0.05)


@dataclass(frozen=True)
class DolParams:
    """A DOL drive: the machine on the grid, the mechanics, the measurement chain, the events' load levels."""

    machine: Machine = field(default_factory=Machine)
    mechanics: Mechanics = field(default_factory=dol_mechanics)
    grid_line_voltage_v: float = 400.0          # rms, line to line
    grid_frequency_hz: float = 50.0
    control_period_s: float = 250e-6            # the measurement chain's period (currents, voltages, encoders)
    sample_period_s: float = 5.0e-4             # the recording's period
    stator_resistance_estimate_ratio: float = 0.85   # nameplate (20 °C) against a warm winding
    flux_highpass_hz: float = 1.0               # the voltage model's leaky-integrator corner
    speed_filter_s: float = 0.5e-3              # encoder-difference speed, first-order filter (as the vector drive)
    base_load_ratio: float = 0.3                # steady running, and before a same-flank step
    slip_load_ratio: float = 0.7                # the paper's operating point: 0.7 p.u. before the slip
    light_load_ratio: float = 0.1
    heavy_load_ratio: float = 0.8
    slip_ramp_s: float = 1.0e-3                 # the slip: the load torque goes in 1 ms
    wheel_inertia_kgm2: float = 0.12            # slip_drop: what stays on the load side when the line slips
    sliding_load_ratio: float = 0.0             # slip_drop: the sliding line's torque on the wheel, x the load before
    load_ramp_s: float = 0.01                   # a process load change, as the vector drive's
    preroll_s: float = 0.3

    @property
    def decimation(self) -> int:
        d = self.sample_period_s / self.control_period_s
        if abs(d - round(d)) > 1e-9 or round(d) < 1:
            raise ValueError(f"sample_period_s: must be a multiple of the control period {self.control_period_s}, "
                             f"got {self.sample_period_s}")
        return int(round(d))

    @property
    def grid_peak_phase_v(self) -> float:
        return math.sqrt(2.0 / 3.0) * self.grid_line_voltage_v

    @property
    def grid_w_rad_s(self) -> float:
        return 2 * math.pi * self.grid_frequency_hz

    @property
    def controller(self):
        """What record.py's truth file reads of the vector drive's controller (the speed measurement)."""
        return SimpleNamespace(speed_filter_s=self.speed_filter_s, control_period_s=self.control_period_s)


#: the DOL events (truth files name them)
DOL_EVENTS = ("slip_drop", "slip_reversal", "load_reversal_light", "load_reversal_heavy", "load_step_same_flank",
              "steady")
#: events after which the coupling leaves its flank (the others must give no entry)
DOL_TRAVERSING_EVENTS = ("slip_drop", "slip_reversal", "load_reversal_light", "load_reversal_heavy")
#: the paper's case: the load lets go suddenly and the motor, at full torque, runs into the zone
SLIP_EVENTS = ("slip_drop", "slip_reversal")


# ------------------------------------------------------------------------------------------ steady state
def gamma_pars(p: DolParams) -> dict:
    """The machine's Γ-model parameters (motulator's conversion): R_s, R_r, L_ell, L_s, n_p."""
    t = p.machine.scaled()
    g = t["L_M"] / (t["L_M"] + t["L_sgm"])
    return {"R_s": t["R_s"], "R_r": t["R_R"] / g ** 2, "L_ell": t["L_sgm"] / g, "L_s": t["L_M"] + t["L_sgm"],
            "n_p": t["n_p"]}


def steady_fluxes(p: DolParams, w_slip: float):
    """(psi_s, psi_r, i_s, torque N m) in the synchronous frame (grid voltage real) at slip angular frequency
    ``w_slip`` (electrical rad/s), forward phase sequence."""
    g = gamma_pars(p)
    w, u = p.grid_w_rad_s, p.grid_peak_phase_v
    k = g["R_r"] / (g["R_r"] + 1j * w_slip * g["L_ell"])          # psi_r = k psi_s
    # u = R_s i_s + j w psi_s,  i_s = psi_s / L_s - (psi_r - psi_s) / L_ell
    coef = 1j * w + g["R_s"] * (1 / g["L_s"] - (k - 1) / g["L_ell"])
    psi_s = u / coef
    psi_r = k * psi_s
    i_s = psi_s / g["L_s"] - (psi_r - psi_s) / g["L_ell"]
    tau = 1.5 * g["n_p"] * float(np.imag(i_s * np.conj(psi_s)))
    return psi_s, psi_r, i_s, tau


def pull_out(p: DolParams):
    """(slip angular frequency, torque) at the motoring pull-out point."""
    ws = np.linspace(1e-3, 0.6 * p.grid_w_rad_s, 4000)
    t = np.array([steady_fluxes(p, w)[3] for w in ws])
    k = int(np.argmax(t))
    return float(ws[k]), float(t[k])


def slip_for_torque(p: DolParams, torque_nm: float) -> float:
    """The slip angular frequency (electrical rad/s) at which the machine gives ``torque_nm`` (>= 0) on the
    stable branch."""
    ws_po, t_po = pull_out(p)
    if not 0 <= torque_nm < t_po:
        raise ValueError(f"load torque: must be in [0, the pull-out torque {t_po:.0f} N m), got {torque_nm:.1f}")
    if torque_nm == 0:
        return 0.0
    return float(brentq(lambda w: steady_fluxes(p, w)[3] - torque_nm, 0.0, ws_po, xtol=1e-12))


# ------------------------------------------------------------------------------------------ scenario
def dol_scenario(p: DolParams, event: str, direction: str = "forward", event_time_s: float = 0.6) -> Scenario:
    """The event's load schedule (model.Scenario; its speed fields: the steady speed before the event, not a
    reference: a DOL drive has none)."""
    if event not in DOL_EVENTS:
        raise ValueError(f"event: expected one of {', '.join(DOL_EVENTS)}, got {event!r}")
    if direction not in ("forward", "reverse"):
        raise ValueError(f"direction: expected forward or reverse, got {direction!r}")
    s = 1.0 if direction == "forward" else -1.0
    rated = p.machine.rated_torque_nm
    n = p.mechanics.gear_ratio

    def common(load_before):
        return dict(event=event, direction=s, speed_rad_s=s * steady_speed(p, abs(load_before)),
                    event_time_s=event_time_s, load_before_nm=s * load_before)
    if event in SLIP_EVENTS:
        x = p.slip_load_ratio * rated
        after = p.sliding_load_ratio * x if event == "slip_drop" else -0.5 * x
        return Scenario(**common(x), load_after_nm=s * after, ramp_s=p.slip_ramp_s)
    if event in ("load_reversal_light", "load_reversal_heavy"):
        # an active load whose torque reverses: the coupling torque from +x rated to -x rated (net of the load's
        # friction at the speed before; after the reversal the speed is above synchronous, the friction alike)
        x = (p.light_load_ratio if event.endswith("light") else p.heavy_load_ratio) * rated
        w0 = steady_speed(p, x) / n
        f = float(load_friction(p.mechanics, w0))
        sc = Scenario(**common(x), load_after_nm=0.0, ramp_s=p.load_ramp_s)
        return Scenario(**{**sc.__dict__, "load_before_nm": s * (n * x - f), "load_after_nm": s * (-n * x - f)})
    base = p.base_load_ratio * rated
    if event == "load_step_same_flank":
        return Scenario(**common(base), load_after_nm=s * p.heavy_load_ratio * rated, ramp_s=p.load_ramp_s)
    return Scenario(**common(base))


def _shaft_torque(p: DolParams, load_nm: float, w_M: float) -> float:
    """The machine torque in steady state: the external load and the load's friction through the gear, the motor's
    friction (>= 0)."""
    m = p.mechanics
    return (load_nm + float(load_friction(m, w_M / m.gear_ratio))) / m.gear_ratio + float(motor_friction(m, w_M))


def steady_speed(p: DolParams, load_nm: float) -> float:
    """|w_M| in steady state under the external load ``load_nm`` (>= 0, coupling side), friction included."""
    w_sync = p.grid_w_rad_s / p.machine.pole_pairs
    w = w_sync
    for _ in range(50):           # fixed point: the friction depends on the speed a little
        w_slip = slip_for_torque(p, _shaft_torque(p, load_nm, w))
        w_new = (p.grid_w_rad_s - w_slip) / p.machine.pole_pairs
        if abs(w_new - w) < 1e-12:
            break
        w = w_new
    return w


# ------------------------------------------------------------------------------------------ simulation
def load_inertia(p: DolParams, sc: Scenario, t: float) -> float:
    """J2 at recording time t: slip_drop's line slips off the wheel at the event (only the wheel stays), else J2."""
    if sc.event == "slip_drop" and t >= sc.event_time_s:
        return p.wheel_inertia_kgm2
    return p.mechanics.load_inertia_kgm2


def _mechanics(p: DolParams, sc: Scenario, t_off: float):
    """model.make_mechanics' BacklashTwoMass with the load inertia of :func:`load_inertia` (the same equations)."""
    mech = p.mechanics
    base = type(make_mechanics(mech, lambda t: sc.load(t - t_off)))

    class SlippingLineTwoMass(base):
        _t = 0.0

        def set_outputs(self, t):
            super().set_outputs(t)
            self._t = t

        def rhs(self):
            o = self.out
            d_w_M = (np.real(self.inp.tau_M) - o.tau_c - o.tau_f1) / mech.motor_inertia_kgm2
            d_w_L = (mech.gear_ratio * o.tau_c - o.tau_L_tot) / load_inertia(p, sc, self._t - t_off)
            return [d_w_M, o.w_M, d_w_L, o.w_L]

    return SlippingLineTwoMass()


def _stiff_grid(p: DolParams, sign: float):
    from motulator.drive.model import VoltageSourceConverter
    u, w = p.grid_peak_phase_v, sign * p.grid_w_rad_s

    class StiffGrid(VoltageSourceConverter):
        """The grid as the machine's source: u_s(t) = U exp(j w_g t), continuous (no PWM, no delay)."""

        def __init__(self):
            super().__init__(u_dc=2.0 * u)

        def voltage(self, t):
            return u * complex(np.exp(1j * w * t))

        def set_outputs(self, t):
            self.out.u_cs = self.voltage(t)
            self.out.u_dc = self.u_dc

    return StiffGrid()


class TorqueEstimate:
    """The voltage-model torque estimate at the control period: psi = leaky trapezoidal integral of
    e = u - R_s,est i (corner w_c), corrected at the grid frequency w_g (the discrete filter's exact response
    there), tau = 1.5 n_p Im(conj(psi) i)."""

    def __init__(self, r_s_est: float, n_p: int, period_s: float, w_c: float, w_g: float):
        self.r, self.n_p, self.ts, self.w_c = r_s_est, n_p, period_s, w_c
        a = w_c * period_s / 2
        self.k_old, self.k_e = (1 - a) / (1 + a), (period_s / 2) / (1 + a)
        z = np.exp(1j * w_g * period_s)
        h = self.k_e * (z + 1) / (z - self.k_old)      # the leaky trapezoid's response at w_g
        self.correction = (1 / (1j * w_g)) / h
        self.w_g = w_g
        self.psi = None
        self.e_old = None

    def start(self, u, i):
        """The estimator in its own steady state (it has run for a long time on the grid)."""
        self.e_old = (u - self.r * i) * np.exp(-1j * self.w_g * self.ts)    # its input one period before ...
        self.psi = self.e_old / self.correction / (1j * self.w_g)        # ... and its steady output then

    def __call__(self, u, i) -> float:
        e = u - self.r * i
        self.psi = self.k_old * self.psi + self.k_e * (e + self.e_old)
        self.e_old = e
        psi_s = self.correction * self.psi
        return 1.5 * self.n_p * float(np.imag(np.conj(psi_s) * i))


def _make_measurement(p: DolParams, log: dict, t_offset: float, sign: float, grid):
    from motulator.common.control import ControlSystem

    g = gamma_pars(p)
    n_p = g["n_p"]
    mech = p.mechanics
    q_enc = 2 * math.pi / 2 ** 20     # the encoder interface (finer than the recorded encoders), as the vector drive
    est = TorqueEstimate(g["R_s"] * p.stator_resistance_estimate_ratio, n_p, p.control_period_s,
                         2 * math.pi * p.flux_highpass_hz, sign * p.grid_w_rad_s)
    u_dc = 2.0 * p.grid_peak_phase_v

    class _DolMeasurement(ControlSystem):
        """No control: outputs the grid voltage reference (the converter is a stiff source), measures."""

        def __init__(self):
            super().__init__(p.control_period_s)
            self._enc_prev = self._enc_prev_L = None
            self._w_filt = self._w_filt_L = None

        def get_feedback_signals(self, mdl):
            fbk = SimpleNamespace()
            t = mdl.t0
            m = mdl.machine
            fbk.i_ss = complex(m.i_ss)
            fbk.u_ss = grid.voltage(t)
            if est.psi is None:
                est.start(fbk.u_ss, fbk.i_ss)
            tau_est = est(fbk.u_ss, fbk.i_ss)
            s = mdl.mechanics.state
            th = math.floor(float(np.real(s.theta_M)) / q_enc) * q_enc
            th_L = math.floor(float(np.real(s.theta_L)) / q_enc) * q_enc
            ts = self.T_s
            a = ts / (p.speed_filter_s + ts)
            if self._enc_prev is None:
                self._w_filt = float(np.real(s.w_M))
                self._w_filt_L = float(np.real(s.w_L))
            else:
                self._w_filt += a * ((th - self._enc_prev) / ts - self._w_filt)
                self._w_filt_L += a * ((th_L - self._enc_prev_L) / ts - self._w_filt_L)
            self._enc_prev, self._enc_prev_L = th, th_L
            log_true_state(log, mdl, t, t_offset, mech)
            log["w_fbk"].append(self._w_filt)
            log["w_L_fbk"].append(self._w_filt_L)
            log["tau_est"].append(tau_est)
            log["tau_ref"].append(math.nan)     # no torque reference: no control
            log["w_ref"].append(math.nan)
            log["i_s_abs"].append(abs(fbk.i_ss))
            return fbk

        def output(self, fbk):
            ref = super().output(fbk)
            ref.d_abc = self.pwm.duty_ratios(fbk.u_ss, u_dc)     # the grid voltage reference (ignored by StiffGrid)
            return ref

        def update(self, fbk, ref):
            super().update(fbk, ref)

        def save(self, **kwargs):       # the log above is the record; motulator's per-period copies are not needed
            pass

    return _DolMeasurement()


DOL_LOG_KEYS = LOG_KEYS + ("i_s_abs",)


def simulate_dol(p: DolParams, sc: Scenario, duration_s: float) -> Run:
    """Simulate the pre-roll (not recorded), then ``duration_s`` of recording with the scenario's event."""
    reason = motulator_available()
    if reason:
        raise ImportError(reason)
    import motulator.drive.model as model
    from motulator.drive.utils import InductionMachineInvGammaPars, InductionMachinePars

    p.decimation
    t_off = p.preroll_s
    sign = 1.0 if sc.direction > 0 else -1.0
    log = {k: [] for k in DOL_LOG_KEYS}
    par = InductionMachinePars.from_inv_gamma_model_pars(InductionMachineInvGammaPars(**p.machine.scaled()))
    machine = model.InductionMachine(par)
    mech = _mechanics(p, sc, t_off)
    grid = _stiff_grid(p, sign)
    ctrl = _make_measurement(p, log, t_off, sign, grid)

    # the steady state under the load before the event (forward solution, mirrored for reverse: conjugates)
    m = p.mechanics
    n = m.gear_ratio
    load = abs(sc.load_before_nm)
    w_M = steady_speed(p, load)
    w_slip = p.grid_w_rad_s - p.machine.pole_pairs * w_M
    psi_s, psi_r, _, _ = steady_fluxes(p, w_slip)
    if sign < 0:
        psi_s, psi_r = np.conj(psi_s), np.conj(psi_r)
    machine.state.psi_ss, machine.state.psi_rs = complex(psi_s), complex(psi_r)     # grid angle 0 at t = 0
    tau_c = (load + float(load_friction(m, w_M / n))) / n
    pen = tau_c / m.stiffness_nm_per_rad
    mech.state.w_M, mech.state.w_L = sign * w_M, sign * w_M / n
    mech.state.theta_M, mech.state.theta_L = sign * (m.half_zone_rad + pen), 0.0
    mdl = model.Drive(converter=grid, machine=machine, mechanics=mech)
    sim = model.Simulation(mdl, ctrl)
    ts_c = p.control_period_s
    sim.simulate(t_stop=t_off + duration_s - 0.5 * ts_c)
    data = {k: np.asarray(v, float) for k, v in log.items()}
    keep = data["t"] >= -0.5 * ts_c
    data = {k: v[keep] for k, v in data.items()}
    data["t"] = np.round(data["t"] / ts_c) * ts_c
    if not np.all(np.isfinite(data["w_M"])):
        raise RuntimeError("motulator reported a numerical failure (non-finite states)")
    return Run(p, sc, data, _version())


def estimate_error_nm(p: DolParams, i_s_abs, direction: float = 1.0) -> np.ndarray:
    """The steady-state error of the torque estimate from the stator resistance's mismatch alone,
    sign(direction) 1.5 n_p (R_s - R_s,est) |i_s|^2 / w_g (N m; the estimate reads the stator copper loss it misses
    as air-gap power): what a user computes from the nameplate and a winding temperature range."""
    g = gamma_pars(p)
    d_r = g["R_s"] * (1 - p.stator_resistance_estimate_ratio)
    return math.copysign(1.0, direction) * 1.5 * g["n_p"] * d_r * np.asarray(i_s_abs, float) ** 2 / p.grid_w_rad_s


__all__ = ["DOL_EVENTS", "DOL_LOG_KEYS", "DOL_TRAVERSING_EVENTS", "DolParams", "SLIP_EVENTS", "TorqueEstimate",
           "dol_mechanics", "dol_scenario", "estimate_error_nm", "gamma_pars", "pull_out", "simulate_dol",
           "slip_for_torque", "steady_fluxes", "steady_speed"]

