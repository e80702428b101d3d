"""Induction motor per-unit equations: steady state from the equivalent circuit.

Per-unit phasors in the synchronous frame (electrical speed 1 p.u.)::

    u_s = r_s i_s + j psi_s            psi_s = x_s i_s + x_m i_r
    0   = r_w i_r + j s psi_r          psi_r = x_m i_s + x_w i_r

so that i_s = u_s / Z(s) with Z(s) = r_s + j x_s + s x_m^2 / (r_w + j s x_w).
The electromagnetic torque is m = Im(conj(psi_s) i_s) (per unit, base
M_b = S_b / Omega_b).  The classic equivalent-circuit torque
|i_r|^2 r_w / s gives the same number and is used as an independent check.
"""
from __future__ import annotations

import numpy as np

from jident_ros.sim.params import MotorParams


def stator_impedance_pu(motor: MotorParams, slip):
    """Input impedance Z(s) of the equivalent circuit, per unit."""
    s = np.asarray(slip, dtype=float)
    rs, rr = motor.stator_resistance_pu, motor.rotor_resistance_pu
    xs, xr, xm = motor.stator_reactance_pu, motor.rotor_reactance_pu, motor.magnetizing_reactance_pu
    return rs + 1j * xs + s * xm ** 2 / (rr + 1j * s * xr)


def steady_state_phasors(motor: MotorParams, slip):
    """Stator/rotor currents and fluxes (complex per-unit phasors) at a slip.

    Returns a dict with keys ``i_s, i_r, psi_s, psi_r, torque_pu``.  Phasors
    are in the synchronous frame with the stator voltage on the real axis.
    """
    s = np.asarray(slip, dtype=float)
    rr = motor.rotor_resistance_pu
    xs, xr, xm = motor.stator_reactance_pu, motor.rotor_reactance_pu, motor.magnetizing_reactance_pu
    i_s = motor.supply_voltage_pu / stator_impedance_pu(motor, s)
    i_r = -1j * s * xm * i_s / (rr + 1j * s * xr)
    psi_s = xs * i_s + xm * i_r
    psi_r = xm * i_s + xr * i_r
    torque = np.imag(np.conj(psi_s) * i_s)
    return {"i_s": i_s, "i_r": i_r, "psi_s": psi_s, "psi_r": psi_r, "torque_pu": torque}


def equivalent_circuit_torque_pu(motor: MotorParams, slip):
    """Air-gap torque |i_r|^2 r_w / s of the classic equivalent circuit, p.u."""
    s = np.asarray(slip, dtype=float)
    ph = steady_state_phasors(motor, s)
    return np.abs(ph["i_r"]) ** 2 * motor.rotor_resistance_pu / s


def breakdown_slip(motor: MotorParams) -> float:
    """Slip of maximum (pull-out) torque, found numerically."""
    s = np.geomspace(1e-4, 1.0, 4001)
    t = steady_state_phasors(motor, s)["torque_pu"]
    k = int(np.argmax(t))
    lo, hi = s[max(k - 1, 0)], s[min(k + 1, s.size - 1)]
    for _ in range(60):  # golden-free ternary refine of a unimodal peak
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        if steady_state_phasors(motor, a)["torque_pu"] < steady_state_phasors(motor, b)["torque_pu"]:
            lo = a
        else:
            hi = b
    return 0.5 * (lo + hi)


def solve_slip(motor: MotorParams, load_torque_nm, n_cases: int):
    """Slip at which the motor torque equals a speed-dependent load torque.

    Parameters
    ----------
    load_torque_nm : callable
        ``load_torque_nm(omega1_rad_s) -> array`` of load torques, N m, for an
        array of mechanical speeds of shape (n_cases,).
    n_cases : int
        Number of cases solved at once.

    Returns
    -------
    slip : ndarray
        Per case, on the stable branch (0, breakdown slip).  Raises
        ValueError naming the case index if the load exceeds pull-out torque.
    """
    base = motor.base
    s_bd = breakdown_slip(motor)
    lo = np.full(n_cases, 1e-9)
    hi = np.full(n_cases, s_bd)

    def excess(s):
        return (steady_state_phasors(motor, s)["torque_pu"] * base.torque_nm
                - np.asarray(load_torque_nm((1.0 - s) * base.mechanical_speed_rad_s), dtype=float))

    bad = excess(hi) < 0
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"load torque of case {i} exceeds the motor's pull-out torque "
                         f"({steady_state_phasors(motor, s_bd)['torque_pu'] * base.torque_nm:.1f} N m)")
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        pos = excess(mid) > 0
        hi = np.where(pos, mid, hi)
        lo = np.where(pos, lo, mid)
    return 0.5 * (lo + hi)
