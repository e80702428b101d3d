"""Parameter dataclasses of the motor–load model (units in every docstring).

The induction motor is the paper's per-unit (relative-unit) model, so its
electrical parameters are dimensionless per-unit values; everything on the
mechanical side is SI (REP 103).  Paper symbols are given in brackets.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MotorParams:
    """Induction motor, 5th-order alpha-beta (stator-frame) per-unit model.

    Attributes
    ----------
    stator_resistance_pu : float
        Stator resistance [r_s], per unit.
    rotor_resistance_pu : float
        Rotor resistance referred to the stator [r_w], per unit.
    stator_reactance_pu : float
        Total stator reactance (leakage + magnetising) [x_s], per unit.
    rotor_reactance_pu : float
        Total rotor reactance [x_w], per unit.
    magnetizing_reactance_pu : float
        Magnetising (mutual) reactance [x_m], per unit.
    mechanical_time_constant_s : float
        Mechanical time constant [T_m] in seconds at the nominal inertia.
    nominal_inertia_kgm2 : float
        Nominal moment of inertia of the masses stiffly connected with the
        rotor [J_1 nominal], kg m^2.  Together with T_m it fixes the base power.
    pole_pairs : int
        Number of pole pairs (chosen, not in the paper).
    supply_frequency_hz : float
        Supply frequency, Hz.  The electrical base angular speed is 2 pi f.
    supply_voltage_pu : float
        Amplitude of the stator voltage space vector, per unit.
    rated_line_voltage_v : float
        RMS line-to-line voltage that is 1 p.u. (only used to state base
        current and impedance in SI; it does not change the dynamics).
    bearing_friction_nms_per_rad : float
        Viscous friction on the motor shaft, N m s/rad (0 = the paper's model).
    """

    stator_resistance_pu: float = 0.059
    rotor_resistance_pu: float = 0.048
    stator_reactance_pu: float = 1.92
    rotor_reactance_pu: float = 1.92
    magnetizing_reactance_pu: float = 1.82
    mechanical_time_constant_s: float = 0.86
    nominal_inertia_kgm2: float = 1.16
    pole_pairs: int = 2
    supply_frequency_hz: float = 50.0
    supply_voltage_pu: float = 1.0
    rated_line_voltage_v: float = 400.0
    bearing_friction_nms_per_rad: float = 0.0

    @property
    def sigma_determinant_pu(self) -> float:
        """[w] = x_s x_w - x_m^2 (the paper's w = 0.374)."""
        return (self.stator_reactance_pu * self.rotor_reactance_pu
                - self.magnetizing_reactance_pu ** 2)

    @property
    def base(self) -> "BaseValues":
        return BaseValues.from_motor(self)


@dataclass(frozen=True)
class BaseValues:
    """Base values of the per-unit system (all SI).

    ``power_va`` follows from the mechanical time constant:
    T_m = J_1 * Omega_b / M_b = J_1 * Omega_b**2 / S_b, so
    S_b = J_1 * Omega_b**2 / T_m.
    """

    electrical_speed_rad_s: float   # omega_b = 2 pi f
    mechanical_speed_rad_s: float   # Omega_b = omega_b / pole pairs
    power_va: float                 # S_b
    torque_nm: float                # M_b = S_b / Omega_b
    voltage_peak_v: float           # U_b, peak phase voltage
    current_peak_a: float           # I_b = S_b / (1.5 U_b)
    impedance_ohm: float            # Z_b = U_b / I_b

    @classmethod
    def from_motor(cls, m: MotorParams) -> "BaseValues":
        we = 2.0 * math.pi * m.supply_frequency_hz
        wm = we / m.pole_pairs
        sb = m.nominal_inertia_kgm2 * wm ** 2 / m.mechanical_time_constant_s
        ub = m.rated_line_voltage_v * math.sqrt(2.0 / 3.0)
        ib = sb / (1.5 * ub)
        return cls(we, wm, sb, sb / wm, ub, ib, ub / ib)


@dataclass(frozen=True)
class LoadParams:
    """Working machine: clutch with backlash, drive wheel, elastic line, mass.

    Attributes
    ----------
    wheel_radius_m : float
        Radius of the drive wheel [r], m.  Converts the backlash width K2 (m,
        at the wheel circumference) into the angle K2/r of inequality (1).
    wheel_inertia_kgm2 : float
        Moment of inertia of the drive wheel (load half of the clutch), kg m^2.
    clutch_stiffness_nm_per_rad : float
        Torsional stiffness of the clutch when its flanks are in contact.
    clutch_damping_nms_per_rad : float
        Torsional damping of the clutch in contact, N m s/rad.
    clutch_damping_ramp_rad : float
        Flank penetration over which the contact damping fades in, rad, so
        that the clutch torque is continuous at impact.
    line_stiffness_n_per_m : float
        Axial stiffness of the line between wheel and mass, N/m.
    line_damping_ns_per_m : float
        Axial damping of the line, N s/m.
    mass_kg : float
        Translating mass [m_2] pulled by the line, kg.
    process_force_n : float
        Constant process (technological) force opposing the motion of m_2, N.
    film_area_m2 : float
        Wetted area of the lubricant film under m_2 (A), m^2.
    film_thickness_m : float
        Lubricant film thickness (h), m.
    flow_index : float
        Ostwald-de Waele flow (creep) index [n_1], dimensionless.
    film_regularisation_speed_m_s : float
        Speed below which the power law is smoothed to stay finite-slope at
        v_2 = 0, m/s.
    """

    wheel_radius_m: float = 0.1
    wheel_inertia_kgm2: float = 0.12
    clutch_stiffness_nm_per_rad: float = 2.0e4
    clutch_damping_nms_per_rad: float = 6.0
    clutch_damping_ramp_rad: float = 1.0e-3
    line_stiffness_n_per_m: float = 2.0e5
    line_damping_ns_per_m: float = 316.0
    mass_kg: float = 50.0
    process_force_n: float = 1475.219
    film_area_m2: float = 1.4226e-4
    film_thickness_m: float = 5.0e-5
    flow_index: float = 0.93
    film_regularisation_speed_m_s: float = 0.01

    def film_force_n(self, speed_m_s, consistency_pa_sn):
        """Ostwald-de Waele lubricant-film friction force on m_2, N.

        F = A * eta_k * (|v|/h)**n1 * sign(v), regularised as
        A * eta_k / h**n1 * v * (v**2 + v_eps**2)**((n1 - 1)/2).
        """
        v = np.asarray(speed_m_s, dtype=float)
        eps2 = self.film_regularisation_speed_m_s ** 2
        n1 = self.flow_index
        return (self.film_area_m2 * np.asarray(consistency_pa_sn, dtype=float)
                / self.film_thickness_m ** n1 * v * (v * v + eps2) ** ((n1 - 1.0) / 2.0))


@dataclass(frozen=True)
class SamplingParams:
    """How the window is sampled and integrated.

    Attributes
    ----------
    sample_period_s : float
        Output sample period T_s, s.
    samples_before_entry : int
        Samples kept before the backlash-entry sample (the paper's 48).
    samples_from_entry : int
        Samples from the backlash-entry sample on, entry included (2000).
    integration_substeps : int
        Fixed RK4 steps per sample period.
    """

    sample_period_s: float = 5.0e-4
    samples_before_entry: int = 48
    samples_from_entry: int = 2000
    integration_substeps: int = 2

    @property
    def window_length(self) -> int:
        return self.samples_before_entry + self.samples_from_entry


@dataclass(frozen=True)
class GridParams:
    """The paper's experiment grid.

    Attributes
    ----------
    inertia_classes_kgm2 : tuple of float
        [K_1], the seven J_1 classes in the paper's order, kg m^2.
    backlash_widths_m : tuple of float
        [K_2], backlash zone widths at the wheel circumference, m.
    consistency_indices_pa_sn : tuple of float
        [eta_k], consistency indices of the lubricant, Pa s^n1.
    pattern_consistency_pa_sn : float
        The eta_k whose runs make the pattern library (0.025).
    """

    inertia_classes_kgm2: tuple = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)
    backlash_widths_m: tuple = (0.0025, 0.00375, 0.005, 0.0075, 0.009, 0.01)
    consistency_indices_pa_sn: tuple = (0.0125, 0.025, 0.0375, 0.05)
    pattern_consistency_pa_sn: float = 0.025


@dataclass(frozen=True)
class SystemConfig:
    """Everything that defines a simulated case set."""

    motor: MotorParams = field(default_factory=MotorParams)
    load: LoadParams = field(default_factory=LoadParams)
    sampling: SamplingParams = field(default_factory=SamplingParams)
    grid: GridParams = field(default_factory=GridParams)
