#!/usr/bin/env python3
"""Simulator benchmark: jident_ros against motulator and gym-electric-motor.

Run (peers installed only in the benchmark venv, see bench/README.md)::

    .venv-bench/bin/python bench/bench_simulator.py [--repeats 5] [--peer-repeats M]
                                                    [--quick] [--no-peers] [--json out.json]

A peer that is not installed is reported as "not installed"; ours is timed
anyway (so ``.venv/bin/python bench/bench_simulator.py`` works too).

What is timed
-------------
Every simulator produces the same record: ``n`` output samples every
``Ts`` (from config/system.yaml: 48 + 2000 = 2048 samples at Ts = 0.5 ms), i.e.
it integrates ``(n - 1) * Ts = 1.0235 s``.  Wall time is reported per
simulated second, and each peer is compared by the ratio
``peer wall per simulated s / ours wall per simulated s``.

* ours, grid: ``simulate_grid(cfg, paper_grid_cases(cfg))``, the paper's 168
  cases in one vectorised fixed-step RK4 run (2 RK4 steps per sample), incl.
  the steady-state initialisation and the derived output channels.  "Grid per
  case" is that wall time / 168.
* ours, single case: the same call for ``Case(1.16, 0.005, 0.025)`` (J1, K2,
  eta_k).
* peers: one case each (below).

Every simulator gets one untimed warm-up run, then ``--repeats`` (>= 5)
rounds; in each round every simulator runs once (round-robin, the order
rotating), so that load changes on this shared machine hit all of them alike.
Peers run in every round unless ``--peer-repeats`` (>= 3) asks for fewer.
Reported: the median wall time (and median process CPU time; wall >> CPU
means other processes took the CPU, and the script warns).

The peers' scenario (closest to ours that each supports)
--------------------------------------------------------
Neither peer has a clutch with backlash, an elastic line or a lubricant film,
and both feed the machine from a converter model.  So each runs the *same
induction motor* as ours (config/system.yaml: 33.3 kVA base, 4-pole, 50 Hz,
400 V; r_s = 0.059, r_w = 0.048, x_s = x_w = 1.92, x_m = 1.82 p.u. converted to
SI: R_s = 0.284 ohm, R_r = 0.231 ohm, L_s = L_r = 29.38 mH, L_m = 27.85 mH),
fed with a 50 Hz, 1 p.u. (326.6 V peak phase) voltage, on a stiff shaft of
J = 1.16 kg m^2 with a constant load torque equal to our case's loaded steady
state (about 147.6 N m), started in that steady state (same fluxes and speed
as ours), for the same simulated length and output period:

* motulator (Aalto): ``Drive`` = ``VoltageSourceConverter(u_dc=650 V)`` (ideal,
  averaged: the default zero-order-hold PWM, no carrier comparison) +
  ``InductionMachine`` (Gamma model of the parameters above) + stiff
  mechanics (0.5.x: ``StiffMechanicalSystem(J, tau_L)``; >= 0.6:
  ``MechanicalSystem(J)`` + ``set_external_load_torque``), run by its
  ``Simulation.simulate`` (scipy ``solve_ivp`` RK45, its defaults) with open-loop
  V/Hz control sampled every Ts = 0.5 ms (one output per Ts): 0.5.x uses its
  ``VHzControl`` with ``k_u = k_w = 0`` and zero resistance estimates, which
  its docstring names the open-loop special case, and no speed-ramp limit;
  >= 0.6 has no open-loop V/Hz class, so a minimal open-loop ``VHzController``
  (u_s = j w psi_nom, 50 Hz) is plugged into its ``VHzControlSystem``.  The
  one-sample computational delay buffer is pre-filled with the first duty
  ratios and the initial fluxes are rotated to the controller's voltage angle.
* gym-electric-motor: ``gem.make("Cont-SC-SCIM-v0", tau=Ts)`` (squirrel-cage
  IM, continuous B6 bridge = averaged converter, ideal 700 V DC supply,
  its default ``scipy.integrate.ode`` dopri5 solver) with the motor parameters
  above, ``PolynomialStaticLoad(a = load torque, j_load ~ 0)``, one
  ``env.step`` = 0.5 ms = one output sample, driven by an open-loop action:
  the 3-phase 50 Hz sine duty cycles (amplitude 326.6 V / 350 V), computed at
  the middle of each step.  No visualisation and no constraints (both only
  cost time); the speed reference generator and reward of the env run as
  usual.  Its motor initializer rejects a loaded flux state ("within nominal
  boundaries" check), so after ``env.reset()`` the ODE state is set to the
  steady state directly.  Env creation is inside the timed run.

Both peers hold a zero-order-hold (piecewise-constant over 0.5 ms) voltage,
ours a continuous sinusoid; all three stay at the loaded steady state (the
"omega end" column checks that; ours: median over the cases, after the
transient).  The peers integrate the motor and a rigid shaft only (flux or
current vectors, speed, angle); ours 10 states per case (plus clutch, wheel,
line and mass) and goes through the backlash impact transient.
"""
from __future__ import annotations

import argparse
import cmath
import gc
import importlib.metadata as md
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
try:
    import jident_ros  # noqa: F401  (installed, e.g. pip install -e .)
except ImportError:  # run from a checkout without `pip install -e .`
    sys.path.insert(0, str(REPO))

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.sim import Case, paper_grid_cases, simulate_grid, steady_state
from jident_ros.sim.motor import steady_state_phasors

SINGLE_CASE = (1.16, 0.005, 0.025)  # J1 kg m^2, K2 m, eta_k Pa s^n1
TARGET_GRID_S = 1.0
TARGET_RATIO = 100.0
#: issue 23: one case (the scalar path) >= this many times faster than the faster peer, in the same run
TARGET_SINGLE_RATIO = 5.0
GEM_DC_V = 700.0        # B6 bridge: phase amplitude <= u_dc / 2
MOTULATOR_DC_V = 650.0  # SVPWM: amplitude <= u_dc / sqrt(3)


# ----------------------------------------------------------------------------- helpers
def version_of(dist: str) -> str | None:
    try:
        return md.version(dist)
    except md.PackageNotFoundError:
        return None


def machine_info() -> dict:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()
    return {
        "nproc": usable, "cpu_count": os.cpu_count(), "cpu": cpu,
        "python": platform.python_version(), "implementation": platform.python_implementation(),
        "platform": platform.platform(), "numpy": np.__version__, "scipy": version_of("scipy"),
        "loadavg_start": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }


class Job:
    """One simulator run, timed in rounds interleaved with the other jobs."""

    def __init__(self, key, label, scenario, fn, sim_s, n_cases=1, version=None):
        self.key, self.label, self.scenario, self.fn = key, label, scenario, fn
        self.sim_s, self.n_cases, self.version = sim_s, n_cases, version
        self.wall, self.cpu, self.result, self.status = [], [], None, "ok"

    def run(self, timed=True):
        gc.collect()
        c0, t0 = time.process_time(), time.perf_counter()
        self.result = self.fn()
        t1, c1 = time.perf_counter(), time.process_time()
        if timed:
            self.wall.append(t1 - t0)
            self.cpu.append(c1 - c0)

    def summary(self) -> dict:
        med = statistics.median(self.wall)
        cpu = statistics.median(self.cpu)
        return {"label": self.label, "scenario": self.scenario, "version": self.version, "status": self.status,
                "runs": len(self.wall), "wall_s": self.wall, "cpu_s": self.cpu, "median_s": med,
                "min_s": min(self.wall), "max_s": max(self.wall), "median_cpu_s": cpu,
                "simulated_s": self.sim_s, "n_cases": self.n_cases, "wall_per_sim_s": med / self.sim_s,
                "cpu_per_sim_s": cpu / self.sim_s, "wall_per_case_per_sim_s": med / self.n_cases / self.sim_s,
                "cpu_per_case_per_sim_s": cpu / self.n_cases / self.sim_s}


# ----------------------------------------------------------------------------- scenario
class Scenario:
    """Our single case converted to SI for the peers (see the module docstring)."""

    def __init__(self, cfg, n_samples: int):
        m, b = cfg.motor, cfg.motor.base
        self.cfg = cfg
        self.ts = cfg.sampling.sample_period_s
        self.n_samples = n_samples
        self.n_intervals = n_samples - 1
        self.sim_s = self.n_intervals * self.ts
        self.n_p = m.pole_pairs
        self.w_e = b.electrical_speed_rad_s
        self.u_peak = m.supply_voltage_pu * b.voltage_peak_v
        z_b = b.impedance_ohm
        l_b = z_b / self.w_e
        self.psi_b = b.voltage_peak_v / self.w_e
        self.i_b = b.current_peak_a
        self.R_s, self.R_r = m.stator_resistance_pu * z_b, m.rotor_resistance_pu * z_b
        self.L_s, self.L_r = m.stator_reactance_pu * l_b, m.rotor_reactance_pu * l_b
        self.L_m = m.magnetizing_reactance_pu * l_b
        self.J = SINGLE_CASE[0]
        case = Case(*SINGLE_CASE)
        y, slip = steady_state(cfg, [case], 0.0)  # stator frame, voltage on the real axis at t = 0
        self.slip = float(slip[0])
        self.psi_s_pu = complex(y[0, 0], y[1, 0])
        self.psi_r_pu = complex(y[2, 0], y[3, 0])
        w = m.sigma_determinant_pu
        self.i_s_pu = (m.rotor_reactance_pu * self.psi_s_pu - m.magnetizing_reactance_pu * self.psi_r_pu) / w
        self.omega_m = float(y[4, 0])
        self.load_torque = float(steady_state_phasors(m, slip)["torque_pu"][0] * b.torque_nm)

    def describe(self) -> dict:
        return {k: getattr(self, k) for k in ("ts", "n_samples", "sim_s", "n_p", "u_peak", "R_s", "R_r",
                                              "L_s", "L_r", "L_m", "J", "slip", "omega_m", "load_torque")}


def _duty_ratios(u_ab: complex, u_dc: float):
    """Space-vector PWM duty ratios (min-max zero sequence) of a voltage vector."""
    u_abc = [(u_ab * cmath.exp(-2j * math.pi * k / 3)).real for k in range(3)]
    u0 = 0.5 * (max(u_abc) + min(u_abc))
    return [(u - u0) / u_dc + 0.5 for u in u_abc]


# ----------------------------------------------------------------------------- ours
def ours_result(ws) -> dict:
    om = ws.signals["omega1"]
    return {"omega_end": float(np.median(om[:, -1])), "omega_start": float(np.median(om[:, 0])),
            "shape_m_el": list(ws.signals["m_el"].shape)}


def rhs_diagnostics(cfg) -> dict:
    """Cost of one Model.rhs call (best of 3 x 2000 calls; internal API, best effort)."""
    from jident_ros.sim.model import CaseArrays, Model
    from jident_ros.sim.simulate import _case_arrays
    model = Model(cfg)
    s = cfg.sampling
    calls = (s.window_length - 1) * s.integration_substeps * 4
    out = {"rhs_calls_per_run": calls}
    for label, cases in (("1", [Case(*SINGLE_CASE)]), ("168", paper_grid_cases(cfg))):
        y, _ = steady_state(cfg, cases, 0.0)
        case = CaseArrays(*_case_arrays(cases, cfg))
        buf = np.empty_like(y)
        n = 2000
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            for _ in range(n):
                model.rhs(1e-3, y, case, buf)
            best = min(best, (time.perf_counter() - t0) / n)
        out[f"rhs_us_{label}_cases"] = best * 1e6
        out[f"rhs_total_s_{label}_cases"] = best * calls
    return out


# ----------------------------------------------------------------------------- motulator
class Motulator:
    name, dist = "motulator", "motulator"

    def __init__(self, sc: Scenario, n_intervals: int):
        # imports here, outside the timed runs (ImportError -> "not installed")
        import motulator.drive.control.im as control
        import motulator.drive.model as model
        self.sc, self.n = sc, n_intervals
        self.model, self.control = model, control
        self.new_api = hasattr(model, "MechanicalSystem")  # >= 0.6; 0.5.x has StiffMechanicalSystem
        if self.new_api:
            from motulator.drive.control._common import References
            self.References = References
        elif hasattr(model, "StiffMechanicalSystem"):
            from motulator.drive.utils import InductionMachineInvGammaPars, InductionMachinePars
            self.InvGammaPars, self.GammaPars = InductionMachineInvGammaPars, InductionMachinePars
        else:
            raise RuntimeError("unsupported motulator API (neither MechanicalSystem nor StiffMechanicalSystem)")
        sc_ = sc
        g = sc_.L_m / sc_.L_r  # T model -> inverse-Gamma model
        self.ig = dict(n_p=sc_.n_p, R_s=sc_.R_s, R_R=g * g * sc_.R_r, L_sgm=sc_.L_s - g * sc_.L_m, L_M=g * sc_.L_m)
        # The controller's voltage is j*U*exp(j w t) (V/Hz in its own frame, angle 0 at t = 0):
        # rotate our initial state (voltage on the real axis at t = 0) by +90 degrees.
        rot = 1j
        self.psi_s0 = sc_.psi_s_pu * sc_.psi_b * rot
        self.psi_R0 = sc_.psi_r_pu * sc_.psi_b * rot * (sc_.L_s / sc_.L_m)  # Gamma-model rotor flux
        self.d0 = _duty_ratios(1j * sc_.u_peak * cmath.exp(0.5j * sc_.w_e * sc_.ts), MOTULATOR_DC_V)
        self.t_stop = (self.n - 0.5) * sc_.ts

    def run(self) -> dict:
        return self._run_new() if self.new_api else self._run_old()

    def _run_old(self) -> dict:  # motulator 0.5.x
        model, control, sc = self.model, self.control, self.sc
        InductionMachineInvGammaPars, InductionMachinePars = self.InvGammaPars, self.GammaPars
        par = InductionMachinePars.from_inv_gamma_model_pars(InductionMachineInvGammaPars(**self.ig))
        machine = model.InductionMachine(par)
        machine.state.psi_ss, machine.state.psi_rs = self.psi_s0, self.psi_R0
        load = self.sc.load_torque
        mechanics = model.StiffMechanicalSystem(J=sc.J, tau_L=lambda t: load)
        mechanics.state.w_M = sc.omega_m
        mdl = model.Drive(converter=model.VoltageSourceConverter(u_dc=MOTULATOR_DC_V),
                          machine=machine, mechanics=mechanics)
        mdl.delay.data = [list(self.d0)]
        est = InductionMachineInvGammaPars(n_p=sc.n_p, R_s=0.0, R_R=0.0,
                                           L_sgm=self.ig["L_sgm"], L_M=self.ig["L_M"])
        ctrl = control.VHzControl(control.VHzControlCfg(est, nom_psi_s=sc.psi_b, T_s=sc.ts, k_u=0, k_w=0,
                                                        rate_limit=math.inf))
        w_ref = sc.w_e  # electrical rad/s in 0.5.x
        ctrl.ref.w_m = lambda t: w_ref
        sim = model.Simulation(mdl, ctrl)
        sim.simulate(t_stop=self.t_stop)
        return {"t_end": float(sim.mdl.t0), "n_ctrl": int(len(sim.ctrl.data.ref.t)),
                "omega_end": float(sim.mdl.mechanics.data.w_M[-1])}

    def _run_new(self) -> dict:  # motulator >= 0.6 (checked on 0.18)
        from dataclasses import dataclass

        model, control, sc, References = self.model, self.control, self.sc, self.References

        @dataclass
        class Fbk:
            theta_c: float = 0.0
            w_c: float = 0.0
            i_s: complex = 0j
            u_s_zoh: complex = 0j
            u_s: complex = 0j
            u_dc: float = 0.0

        class OpenLoopVHz:
            """u_s = j w psi_nom in a frame rotating at the reference frequency."""

            k_comp = 1.5

            def __init__(self, T_s, psi, n_p):
                self.T_s, self.psi, self.n_p, self.theta = T_s, psi, n_p, 0.0

            def get_feedback(self, u_s_ab, i_s_ab, w_M_ref):
                return Fbk(theta_c=self.theta, w_c=self.n_p * w_M_ref,
                           i_s=cmath.exp(-1j * self.theta) * i_s_ab)

            def compute_output(self, fbk):
                return References(T_s=self.T_s, u_s=1j * fbk.w_c * self.psi)

            compute_standby_output = compute_output

            def update(self, ref, fbk):
                self.theta = (self.theta + self.T_s * fbk.w_c + math.pi) % (2 * math.pi) - math.pi

            def post_process(self, ts):
                pass

        machine = model.InductionMachine(model.InductionMachineInvGammaPars(**self.ig))
        machine.state.psi_s_ab, machine.state.psi_r_ab = self.psi_s0, self.psi_R0
        mechanics = model.MechanicalSystem(J=sc.J)
        mechanics.set_external_load_torque(sc.load_torque)
        mechanics.state.w_M = sc.omega_m
        mdl = model.Drive(machine, mechanics, model.VoltageSourceConverter(u_dc=MOTULATOR_DC_V))
        mdl.delay.data = [list(self.d0)]
        ctrl = control.VHzControlSystem(OpenLoopVHz(sc.ts, sc.psi_b, sc.n_p))
        ctrl.set_speed_ref(sc.w_e / sc.n_p)  # mechanical rad/s in >= 0.6
        sim = model.Simulation(mdl, ctrl, show_progress=False)
        res = sim.simulate(t_stop=self.t_stop)
        if not res.success:
            raise RuntimeError("motulator reported a numerical failure")
        return {"t_end": float(sim.mdl.t0), "n_ctrl": int(len(res.ctrl.t)),
                "omega_end": float(res.mdl.mechanics.w_M[-1])}


# ----------------------------------------------------------------------------- gym-electric-motor
class GymElectricMotor:
    name, dist = "gym-electric-motor", "gym-electric-motor"

    def __init__(self, sc: Scenario, n_intervals: int):
        import gym_electric_motor as gem  # noqa: F401  (ImportError -> not installed)
        self.gem, self.sc, self.n = gem, sc, n_intervals
        self.amp = sc.u_peak / (0.5 * GEM_DC_V)
        if self.amp > 1.0:
            raise RuntimeError("GEM_DC_V too low for the motor voltage")
        i_s = sc.i_s_pu * sc.i_b
        psi_r = sc.psi_r_pu * sc.psi_b
        # ODE state of the SCIM system: [omega, i_salpha, i_sbeta, psi_ralpha, psi_rbeta, epsilon]
        self.y0 = np.array([sc.omega_m, i_s.real, i_s.imag, psi_r.real, psi_r.imag, 0.0])

    def run(self) -> dict:
        sc = self.sc
        env = self.gem.make(
            "Cont-SC-SCIM-v0",
            motor=dict(
                motor_parameter=dict(p=sc.n_p, r_s=sc.R_s, r_r=sc.R_r, l_m=sc.L_m, l_sigs=sc.L_s - sc.L_m,
                                     l_sigr=sc.L_r - sc.L_m, j_rotor=sc.J),
                limit_values=dict(i=1000.0, omega=400.0, u=GEM_DC_V, torque=2000.0),
                nominal_values=dict(i=300.0, omega=160.0, u=GEM_DC_V, torque=500.0)),
            load=dict(load_parameter=dict(a=sc.load_torque, b=0.0, c=0.0, j_load=1e-9),
                      load_initializer=dict(states=dict(omega=sc.omega_m))),
            supply=dict(u_nominal=GEM_DC_V), tau=sc.ts, visualization=(), constraints=())
        env.reset(seed=0)
        ps = env.unwrapped.physical_system
        ps._ode_solver.set_initial_value(self.y0.copy(), 0.0)  # loaded steady state (see docstring)
        w, ts, amp = sc.w_e, sc.ts, self.amp
        shifts = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)
        act = np.empty(3)
        state = None
        for k in range(self.n):
            ph = w * (k + 0.5) * ts
            act[0], act[1], act[2] = (amp * math.cos(ph - s) for s in shifts)
            (state, _ref), _r, terminated, _tr, _ = env.step(act)
            if terminated:
                raise RuntimeError(f"env terminated at step {k}")
        omega = float(state[ps.OMEGA_IDX] * ps.limits[ps.OMEGA_IDX])
        env.close()
        return {"t_end": float(ps._ode_solver.t), "n_steps": self.n, "omega_end": omega}


# ----------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5,
                    help="timing rounds (>= 5); ours runs once per round, default 5")
    ap.add_argument("--peer-repeats", type=int, default=None,
                    help="timed runs per peer (>= 3), spread over the rounds; default: one per round")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 2 rounds, 1 short peer run (1/8 of the length), no peer warm-up; "
                         "NOT a benchmark result")
    ap.add_argument("--no-peers", action="store_true", help="time ours only")
    ap.add_argument("--json", metavar="PATH", help="write all results as JSON")
    args = ap.parse_args(argv)
    if args.quick:
        rounds, peer_repeats, peer_warmup = 2, 1, 0
    else:
        rounds, peer_warmup = args.repeats, 1
        peer_repeats = rounds if args.peer_repeats is None else args.peer_repeats
        if rounds < 5 or peer_repeats < 3:
            ap.error("--repeats must be >= 5 and --peer-repeats >= 3 (use --quick for a smoke run)")
        peer_repeats = min(peer_repeats, rounds)

    info = machine_info()
    print("# jident_ros simulator benchmark" + ("  (QUICK MODE: not a benchmark result)" if args.quick else ""))
    print(f"machine: nproc={info['nproc']} ({info['cpu']}), Python {info['python']}, numpy {info['numpy']}, "
          f"scipy {info['scipy']}, {info['platform']}")
    la = info["loadavg_start"]
    if la is not None:
        busy = la[0] > 0.5 * (info["nproc"] or 1)
        print(f"load average at start: {la[0]:.2f} {la[1]:.2f} {la[2]:.2f}"
              + ("  <-- busy: other processes were running; timings may be inflated and noisy" if busy else ""))
    print("note: wall-clock timings on this shared 2-core machine are noisy when other processes run. The runs of "
          "all simulators are interleaved (round-robin) so that the ratios see the same load; the CPU-time "
          "column is less sensitive to other processes than wall time.\n")

    cfg = load_system_config()
    s = cfg.sampling
    n_samples = s.window_length
    sc = Scenario(cfg, n_samples)
    cases = paper_grid_cases(cfg)
    single = [Case(*SINGLE_CASE)]
    peer_intervals = max(2, (n_samples - 1) // 8) if args.quick else n_samples - 1
    own_version = version_of("jident_ros") or "checkout"

    grid = Job("ours_grid", "jident_ros", f"paper grid, {len(cases)} cases, vectorised RK4",
               lambda: ours_result(simulate_grid(cfg, cases)), sc.sim_s, len(cases), own_version)
    one = Job("ours_single", "jident_ros", "1 case", lambda: ours_result(simulate_grid(cfg, single)),
              sc.sim_s, 1, own_version)
    one_vec = Job("ours_single_vectorised", "jident_ros", "1 case, vectorised numpy path (vectorised=True)",
                  lambda: ours_result(simulate_grid(cfg, single, vectorised=True)), sc.sim_s, 1, own_version)
    jobs, peers = [grid, one, one_vec], {}
    print(f"ours: {len(cases)}-case grid and 1 case (J1, K2, eta_k = {SINGLE_CASE}), {n_samples} samples at "
          f"Ts = {s.sample_period_s * 1e3:g} ms ({sc.sim_s:.4f} s simulated), {s.integration_substeps} RK4 "
          f"steps/sample; 1 warm-up + {rounds} timed runs each", flush=True)
    if not args.no_peers:
        for cls in (Motulator, GymElectricMotor):
            job = Job(cls.name, f"{cls.name} {version_of(cls.dist) or ''}".strip(),
                      "1 case: same IM, stiff shaft + const. load, open-loop 50 Hz", None,
                      peer_intervals * sc.ts, 1, version_of(cls.dist))
            peers[cls.name] = job
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    job.fn = cls(sc, peer_intervals).run
            except ImportError as e:
                job.status = "not installed"
                print(f"{cls.name}: not installed ({e})")
                continue
            except Exception as e:  # a peer's API change must not kill the benchmark
                job.status = f"failed: {type(e).__name__}: {e}"
                print(f"{cls.name}: FAILED: {job.status}")
                continue
            print(f"{job.label}: {peer_intervals} x {sc.ts * 1e3:g} ms ({job.sim_s:.4f} s simulated); "
                  f"{peer_warmup} warm-up + {peer_repeats} timed runs", flush=True)
            jobs.append(job)

    # warm-up, then round-robin rounds (the order rotates each round)
    peer_rounds = {round(i * (rounds - 1) / max(peer_repeats - 1, 1)) for i in range(peer_repeats)}
    active = []
    for job in jobs:
        is_peer = job.key in peers
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for _ in range(peer_warmup if is_peer else 1):
                    job.run(timed=False)
            active.append(job)
        except Exception as e:
            if not is_peer:
                raise
            job.status = f"failed: {type(e).__name__}: {e}"
            print(f"{job.key}: FAILED in warm-up: {job.status}")
    for r in range(rounds):
        order = active[r % len(active):] + active[:r % len(active)]
        for job in order:
            if job.key in peers and r not in peer_rounds:
                continue
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    job.run()
            except Exception as e:
                if job.key not in peers:
                    raise
                job.status = f"failed: {type(e).__name__}: {e}"
                print(f"{job.key}: FAILED: {job.status}")
                active.remove(job)
        print(f"  round {r + 1}/{rounds} done", flush=True)

    res = {j.key: dict(j.summary(), **(j.result or {})) for j in jobs if j.wall and j.status == "ok"}
    g, o, ov = res["ours_grid"], res["ours_single"], res["ours_single_vectorised"]
    # the single-case path equals the vectorised one (issue 23): largest |difference| / largest |signal|
    a, b = simulate_grid(cfg, single), simulate_grid(cfg, single, vectorised=True)
    same = {k: float(np.max(np.abs(a.signals[k] - b.signals[k])) / np.max(np.abs(b.signals[k])))
            for k in ("a1", "m_el", "omega1", "a2", "v2")}
    per_case = dict(g, median_s=g["median_s"] / g["n_cases"], min_s=g["min_s"] / g["n_cases"],
                    max_s=g["max_s"] / g["n_cases"], median_cpu_s=g["median_cpu_s"] / g["n_cases"],
                    wall_per_sim_s=g["wall_per_case_per_sim_s"], cpu_per_sim_s=g["cpu_per_case_per_sim_s"],
                    n_cases=1, scenario=f"grid per case (grid / {g['n_cases']})")
    for k in ("wall_s", "cpu_s"):
        per_case.pop(k)
    peer_res = {}
    for name, job in peers.items():
        p = res.get(name, {"label": job.label, "version": job.version, "status": job.status})
        if "wall_per_sim_s" in p:
            if abs(p["t_end"] - job.sim_s) > 0.5 * sc.ts:
                p["status"] = f"ok, but ran to t = {p['t_end']:.4f} s instead of {job.sim_s:.4f} s"
            for basis in ("wall", "cpu"):
                p[f"ratio_{basis}_vs_ours_single"] = p[f"{basis}_per_sim_s"] / o[f"{basis}_per_sim_s"]
                p[f"ratio_{basis}_vs_ours_grid_per_case"] = p[f"{basis}_per_sim_s"] / g[f"{basis}_per_case_per_sim_s"]
        peer_res[name] = p

    try:
        diag = rhs_diagnostics(cfg)
    except Exception as e:  # internal API, best effort
        diag = {"error": f"{type(e).__name__}: {e}"}

    # ------------------------------------------------------------------ report
    print("\n## Results (median of the timed runs; ratios = peer wall per simulated s / ours)\n")
    print("| simulator | scenario | runs | median wall [s] | min–max wall [s] | median CPU [s] | simulated [s] "
          "| wall / simulated s | peer ÷ ours single | peer ÷ ours grid-per-case | ω end [rad/s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")

    def row(r, ratio1="", ratio2=""):
        print(f"| {r['label']} | {r['scenario']} | {r['runs']} | {r['median_s']:.4g} | "
              f"{r['min_s']:.4g}–{r['max_s']:.4g} | {r['median_cpu_s']:.4g} | {r['simulated_s']:.4f} | "
              f"{r['wall_per_sim_s']:.4g} | {ratio1} | {ratio2} | {r.get('omega_end', float('nan')):.2f} |")

    row(g)
    row(o)
    row(ov)
    row(per_case)
    for name, p in peer_res.items():
        if "wall_per_sim_s" in p:
            row(p, f"**{p['ratio_wall_vs_ours_single']:.3g}×**", f"**{p['ratio_wall_vs_ours_grid_per_case']:.3g}×**")
        else:
            print(f"| {p['label']} | {p['status']} | | | | | | | | | |")

    print("\n## Targets\n")
    g_ok = g["median_s"] <= TARGET_GRID_S
    targets = {"grid_le_1s": {"value_s": g["median_s"], "cpu_s": g["median_cpu_s"], "target_s": TARGET_GRID_S,
                              "pass": g_ok}}
    miss = "" if g_ok else (f" — misses by {g['median_s'] - TARGET_GRID_S:.3g} s "
                            f"({g['median_s'] / TARGET_GRID_S:.2f}x the budget)")
    print(f"- whole grid <= {TARGET_GRID_S:g} s: {g['median_s']:.3f} s wall (CPU {g['median_cpu_s']:.3f} s) -> "
          f"{'PASS' if g_ok else 'MISS'}{miss}")
    for name, p in peer_res.items():
        if "ratio_wall_vs_ours_single" not in p:
            print(f"- >= {TARGET_RATIO:g}x faster than {name}: not measured ({p['status']})")
            continue
        rg, r1 = p["ratio_wall_vs_ours_grid_per_case"], p["ratio_wall_vs_ours_single"]
        targets[f"ratio_{name}"] = {"grid_per_case": rg, "single": r1, "target": TARGET_RATIO,
                                    "pass_grid_per_case": rg >= TARGET_RATIO, "pass_single": r1 >= TARGET_RATIO,
                                    "grid_per_case_cpu": p["ratio_cpu_vs_ours_grid_per_case"],
                                    "single_cpu": p["ratio_cpu_vs_ours_single"]}
        print(f"- >= {TARGET_RATIO:g}x faster than {name} per simulated second: grid-per-case {rg:.3g}x "
              f"(CPU {p['ratio_cpu_vs_ours_grid_per_case']:.3g}x) -> {'PASS' if rg >= TARGET_RATIO else 'MISS'}; "
              f"single case {r1:.3g}x (CPU {p['ratio_cpu_vs_ours_single']:.3g}x) -> "
              f"{'PASS' if r1 >= TARGET_RATIO else 'MISS'}")

    fastest = min((p for p in peer_res.values() if "wall_per_sim_s" in p), key=lambda p: p["wall_per_sim_s"],
                  default=None)
    print(f"- one case, max |scalar - vectorised| / max |signal| over a1, m_el, omega1, a2, v2: "
          f"{max(same.values()):.2g} (<= 1e-12: {'PASS' if max(same.values()) <= 1e-12 else 'MISS'}); "
          f"the scalar path is {ov['median_s'] / o['median_s']:.3g}x faster than the vectorised one on one case")
    if fastest is None:
        print(f"- one case >= {TARGET_SINGLE_RATIO:g}x faster than the faster peer: not measured (no peer ran)")
    else:
        r1 = fastest["ratio_wall_vs_ours_single"]
        targets["single_vs_faster_peer"] = {"peer": fastest["label"], "ratio_wall": r1,
                                            "ratio_cpu": fastest["ratio_cpu_vs_ours_single"],
                                            "target": TARGET_SINGLE_RATIO, "pass": r1 >= TARGET_SINGLE_RATIO,
                                            "max_rel_difference_to_vectorised": same}
        print(f"- one case >= {TARGET_SINGLE_RATIO:g}x faster than the faster peer ({fastest['label']}): {r1:.3g}x "
              f"(CPU {fastest['ratio_cpu_vs_ours_single']:.3g}x) -> {'PASS' if r1 >= TARGET_SINGLE_RATIO else 'MISS'}")

    if "error" not in diag:
        print(f"\nours, diagnostics: one Model.rhs call = {diag['rhs_us_1_cases']:.1f} µs (1 case) / "
              f"{diag['rhs_us_168_cases']:.1f} µs (168 cases); {diag['rhs_calls_per_run']} calls per run "
              f"-> {diag['rhs_total_s_1_cases']:.2f} s / {diag['rhs_total_s_168_cases']:.2f} s of RHS per run "
              f"(per-call numpy overhead: almost independent of the number of cases)")
    la_end = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    if la_end:
        print(f"load average at end: {la_end[0]:.2f} {la_end[1]:.2f} {la_end[2]:.2f} (1/5/15-min averages, they lag)")
    preempted = {k: r["median_s"] / r["median_cpu_s"] for k, r in res.items() if r["median_s"] > 1.1 * r["median_cpu_s"]}
    if preempted:
        print("WARNING: wall time exceeded CPU time by > 10 % for " + ", ".join(
            f"{k} ({v:.2f}x)" for k, v in preempted.items())
              + ": other processes took the CPU during those runs; repeat the benchmark on a quieter machine.")
    else:
        print("wall ~= CPU time for every simulator: the runs were not noticeably preempted.")

    if args.json:
        doc = {"quick": args.quick, "machine": dict(info, loadavg_end=la_end),
               "settings": {"rounds": rounds, "peer_repeats": peer_repeats, "peer_warmup": peer_warmup,
                            "ours_warmup": 1, "single_case": SINGLE_CASE, "n_samples": n_samples,
                            "sample_period_s": s.sample_period_s, "substeps": s.integration_substeps,
                            "peer_intervals": peer_intervals},
               "scenario": sc.describe(),
               "ours": {"grid": g, "single": o, "single_vectorised": ov, "grid_per_case": per_case,
                        "diagnostics": diag, "single_max_rel_difference_to_vectorised": same},
               "peers": peer_res, "targets": targets, "preempted_wall_over_cpu": preempted}
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(doc, f, indent=2, default=float)
        print(f"JSON written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
