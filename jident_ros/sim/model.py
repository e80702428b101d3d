"""Right-hand side of the motor–clutch–wheel–line–mass model, vectorised over cases.

State vector (rows of an array of shape (N_STATES, n_cases))::

    0 PSI_SA, 1 PSI_SB   stator flux linkage, alpha/beta, per unit
    2 PSI_RA, 3 PSI_RB   rotor flux linkage, alpha/beta, per unit
    4 OMEGA1             rotor (motor shaft) mechanical speed omega_1, rad/s
    5 ALPHA1             rotor angle alpha_1, rad
    6 DELTA              clutch relative angle delta = alpha_1 - alpha_2, rad,
                         measured from the centre of the backlash zone
    7 OMEGA2             drive-wheel speed omega_2, rad/s
    8 LINE_STRETCH       elongation of the line, m
    9 V2                 speed of the mass v_2, m/s

Electrical equations (stator frame, time in seconds, omega_b = 2 pi f)::

    d psi_s/dt = omega_b (u_s - r_s i_s)
    d psi_r/dt = omega_b (-r_w i_r + j p omega_1/omega_b psi_r)
    i_s = (x_w psi_s - x_m psi_r)/w,  i_r = (x_s psi_r - x_m psi_s)/w
    m_el = M_b (psi_sa i_sb - psi_sb i_sa)

Mechanics (SI)::

    J_1 d omega_1/dt = m_el - T_c - b_1 omega_1
    J_w d omega_2/dt = T_c - r F_line
    m_2 d v_2/dt     = F_line - F_p - F_film(v_2, eta_k)
    pen = max(|delta| - theta_b, 0)           (flank penetration, rad)
    T_c = sign(delta) max(0, k_c pen + c_c min(pen/pen_ramp, 1) sign(delta)(omega_1 - omega_2))
    (zero inside the zone; the damping fades in over pen_ramp so the force is
    continuous at impact and never pulls the flanks together)
    F_line = k_l e + c_l (r omega_2 - v_2),  de/dt = r omega_2 - v_2
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jident_ros.sim.params import SystemConfig

PSI_SA, PSI_SB, PSI_RA, PSI_RB, OMEGA1, ALPHA1, DELTA, OMEGA2, LINE_STRETCH, V2 = range(10)
N_STATES = 10


@dataclass
class CaseArrays:
    """Per-case parameters as arrays of shape (n_cases,) (SI)."""

    inertia_kgm2: np.ndarray         # J_1
    backlash_angle_rad: np.ndarray   # theta_b = K2 / r (0 before the event)
    consistency_pa_sn: np.ndarray    # eta_k


class Model:
    """The vectorised model; one instance per configuration."""

    def __init__(self, config: SystemConfig):
        m, ld = config.motor, config.load
        self.config = config
        b = m.base
        self.base = b
        self.wb = b.electrical_speed_rad_s
        self.pp = m.pole_pairs
        self.rs, self.rr = m.stator_resistance_pu, m.rotor_resistance_pu
        self.xs, self.xr, self.xm = m.stator_reactance_pu, m.rotor_reactance_pu, m.magnetizing_reactance_pu
        self.w = m.sigma_determinant_pu
        self.us = m.supply_voltage_pu
        self.mb = b.torque_nm
        self.b1 = m.bearing_friction_nms_per_rad
        self.r = ld.wheel_radius_m
        self.jw = ld.wheel_inertia_kgm2
        self.kc, self.cc = ld.clutch_stiffness_nm_per_rad, ld.clutch_damping_nms_per_rad
        self.inv_ramp = 1.0 / ld.clutch_damping_ramp_rad
        self.kl, self.cl = ld.line_stiffness_n_per_m, ld.line_damping_ns_per_m
        self.m2 = ld.mass_kg
        self.fp = ld.process_force_n
        self.n1 = ld.flow_index
        self.eps2 = ld.film_regularisation_speed_m_s ** 2
        self.film_gain = ld.film_area_m2 / ld.film_thickness_m ** ld.flow_index  # times eta_k
        # folded constants of the hot path
        self._c_ss, self._c_sr = self.xr / self.w, self.xm / self.w
        self._c_rs = self.wb * self.rs
        self._c_us = self.wb * self.us
        # d psi_r/dt = -wb r_w i_r = -wb r_w (x_s psi_r - x_m psi_s)/w
        self._c_rr = self.wb * self.rr * self.xs / self.w
        self._c_rm = self.wb * self.rr * self.xm / self.w
        self._c_te = self.mb
        self._inv_jw, self._inv_m2 = 1.0 / self.jw, 1.0 / self.m2

    # -- pieces -----------------------------------------------------------------
    def clutch_torque(self, delta, omega_rel, theta_b):
        """Torque transmitted by the clutch with backlash (dead zone), N m."""
        sgn = np.sign(delta)
        pen = np.abs(delta)
        pen -= theta_b
        np.maximum(pen, 0.0, out=pen)
        damping = np.minimum(pen * self.inv_ramp, 1.0)
        damping *= self.cc
        damping *= omega_rel
        damping *= sgn
        pen *= self.kc
        pen += damping
        np.maximum(pen, 0.0, out=pen)
        pen *= sgn
        return pen

    def film_force(self, v2, eta):
        """Regularised Ostwald-de Waele friction force, N."""
        return self.film_gain * eta * v2 * (v2 * v2 + self.eps2) ** ((self.n1 - 1.0) / 2.0)

    def electromagnetic_torque(self, y):
        """m_el in N m from the flux states (any trailing shape)."""
        isa = (self.xr * y[PSI_SA] - self.xm * y[PSI_RA]) / self.w
        isb = (self.xr * y[PSI_SB] - self.xm * y[PSI_RB]) / self.w
        return self.mb * (y[PSI_SA] * isb - y[PSI_SB] * isa)

    # -- full right-hand side -------------------------------------------------------
    def rhs(self, t, y, case: CaseArrays, out=None):
        """dy/dt for states y of shape (N_STATES, ...) at time t (s).

        Also usable on a stack of samples (N_STATES, n_samples, n_cases) with
        case arrays broadcastable against it and t of shape (n_samples, 1).
        Written with few whole-block numpy operations: it is the simulator's
        hot path.
        """
        if out is None:
            out = np.empty_like(y)
        psi_s, psi_r = y[0:2], y[2:4]
        # currents scaled by w: i_s = (x_w psi_s - x_m psi_r)/w, i_r = (x_s psi_r - x_m psi_s)/w
        i_s = self._c_ss * psi_s - self._c_sr * psi_r
        ph = self.wb * t
        d_s = out[0:2]
        np.multiply(i_s, -self._c_rs, out=d_s)
        d_s[0] += self._c_us * np.cos(ph)
        d_s[1] += self._c_us * np.sin(ph)
        d_r = out[2:4]
        np.multiply(psi_s, self._c_rm, out=d_r)
        d_r -= self._c_rr * psi_r
        wr = self.pp * y[OMEGA1]
        d_r[0] -= wr * y[PSI_RB]
        d_r[1] += wr * y[PSI_RA]
        m_el = self._c_te * (y[PSI_SA] * i_s[1] - y[PSI_SB] * i_s[0])
        omega1, omega2, v2 = y[OMEGA1], y[OMEGA2], y[V2]
        omega_rel = omega1 - omega2
        tc = self.clutch_torque(y[DELTA], omega_rel, case.backlash_angle_rad)
        rw2_minus_v2 = self.r * omega2 - v2
        f_line = self.kl * y[LINE_STRETCH] + self.cl * rw2_minus_v2
        if self.b1:
            m_el = m_el - self.b1 * omega1
        out[OMEGA1] = (m_el - tc) / case.inertia_kgm2
        out[ALPHA1] = omega1
        out[DELTA] = omega_rel
        out[OMEGA2] = (tc - self.r * f_line) * self._inv_jw
        out[LINE_STRETCH] = rw2_minus_v2
        out[V2] = (f_line - self.fp - self.film_force(v2, case.consistency_pa_sn)) * self._inv_m2
        return out

    # -- the integrator's hot path ----------------------------------------------------
    def fast_rhs(self, case: CaseArrays):
        """A closure ``rhs(bias, y, out)`` equal to :meth:`rhs`, with fewer numpy calls.

        Everything linear in the state (flux equations without the rotation
        term, the wheel-line-mass chain) is one 10 x 10 matrix product; the
        time-dependent supply and the constant process force come in as a
        precomputed ``bias`` column (see :meth:`bias_table`).  The torque uses
        m_el = M_b x_m / w (psi_sb psi_ra - psi_sa psi_rb), algebraically equal
        to the current form.  Tested equal to :meth:`rhs` to 1e-12.
        """
        A = self.linear_matrix()
        inv_j = 1.0 / case.inertia_kgm2
        k_torque = self._c_te * self._c_sr * inv_j
        film = self.film_gain * case.consistency_pa_sn / self.m2
        theta_b = case.backlash_angle_rad
        pp, ir, cc, kc, ijw, b1 = self.pp, self.inv_ramp, self.cc, self.kc, self._inv_jw, self.b1
        eps2, ex = self.eps2, (self.n1 - 1.0) / 2.0
        matmul, sign, absolute, maximum, minimum = np.matmul, np.sign, np.abs, np.maximum, np.minimum

        def rhs(bias, y, out):
            matmul(A, y, out=out)
            out += bias
            wr = pp * y[OMEGA1]
            out[PSI_RA] -= wr * y[PSI_RB]
            out[PSI_RB] += wr * y[PSI_RA]
            acc = y[PSI_SB] * y[PSI_RA]
            acc -= y[PSI_SA] * y[PSI_RB]
            acc *= k_torque                       # m_el / J1
            d = y[DELTA]
            s = sign(d)
            tc = absolute(d)
            tc -= theta_b
            maximum(tc, 0.0, out=tc)
            damp = tc * ir
            minimum(damp, 1.0, out=damp)
            damp *= out[DELTA]                    # omega_1 - omega_2
            damp *= s
            damp *= cc
            tc *= kc
            tc += damp
            maximum(tc, 0.0, out=tc)
            tc *= s                               # clutch torque T_c
            if b1:
                acc -= (b1 * inv_j) * y[OMEGA1]
            acc -= tc * inv_j
            out[OMEGA1] = acc
            out[OMEGA2] += tc * ijw
            v = y[V2]
            f = v * v
            f += eps2
            f **= ex
            f *= v
            f *= film
            out[V2] -= f
            return out
        return rhs

    def linear_matrix(self) -> np.ndarray:
        """The 10 x 10 matrix of everything linear in the state (:meth:`fast_rhs`)."""
        A = np.zeros((N_STATES, N_STATES))
        A[PSI_SA, PSI_SA] = A[PSI_SB, PSI_SB] = -self._c_rs * self._c_ss
        A[PSI_SA, PSI_RA] = A[PSI_SB, PSI_RB] = self._c_rs * self._c_sr
        A[PSI_RA, PSI_SA] = A[PSI_RB, PSI_SB] = self._c_rm
        A[PSI_RA, PSI_RA] = A[PSI_RB, PSI_RB] = -self._c_rr
        A[ALPHA1, OMEGA1] = 1.0
        A[DELTA, OMEGA1], A[DELTA, OMEGA2] = 1.0, -1.0
        r, jw, m2, kl, cl = self.r, self.jw, self.m2, self.kl, self.cl
        A[OMEGA2, LINE_STRETCH], A[OMEGA2, OMEGA2], A[OMEGA2, V2] = -r * kl / jw, -r * cl * r / jw, r * cl / jw
        A[LINE_STRETCH, OMEGA2], A[LINE_STRETCH, V2] = r, -1.0
        A[V2, LINE_STRETCH], A[V2, OMEGA2], A[V2, V2] = kl / m2, cl * r / m2, -cl / m2
        return A

    def bias_table(self, times):
        """Bias columns for :meth:`fast_rhs` at the given times: shape (n_times, N_STATES, 1)."""
        times = np.asarray(times, dtype=float)
        bias = np.zeros((times.size, N_STATES, 1))
        bias[:, PSI_SA, 0] = self._c_us * np.cos(self.wb * times)
        bias[:, PSI_SB, 0] = self._c_us * np.sin(self.wb * times)
        bias[:, V2, 0] = -self.fp / self.m2
        return bias
