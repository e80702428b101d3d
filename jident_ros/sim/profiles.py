"""Drive profiles: the film's share of the load at the pattern eta_k (docs/model.md, section 2).

The lubricant film (Ostwald-de Waele, F_film = A eta_k (|v_2|/h)^n_1) is one part of the load on the
mass m_2; the process force F_p is the other.  How much of the load the film carries at the pattern
consistency index decides how much the eta_k test groups differ from the pattern runs, and with it
whether the paper's image method can work (docs/method.md, "How well it works").
:func:`with_film_share` rescales the film area A and the process force F_p so that the film carries
a given share of the load at the pattern eta_k while the total load there (and so the slip, the speed
and the line speed) stays the same.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from jident_ros.sim.params import SystemConfig
from jident_ros.sim.simulate import Case, steady_state


def steady_line_speed(system: SystemConfig, consistency_pa_sn: float | None = None) -> float:
    """Steady-state speed v_2 of the mass, m/s, at eta_k (default: the pattern eta_k), nominal J1."""
    g = system.grid
    eta = g.pattern_consistency_pa_sn if consistency_pa_sn is None else float(consistency_pa_sn)
    y, _ = steady_state(system, [Case(system.motor.nominal_inertia_kgm2, g.backlash_widths_m[0], eta)], 0.0)
    return float(y[9, 0])


def film_share(system: SystemConfig, consistency_pa_sn: float | None = None) -> float:
    """Share of the film friction in the load force F_p + F_film at eta_k (steady state), 0..1."""
    g = system.grid
    eta = g.pattern_consistency_pa_sn if consistency_pa_sn is None else float(consistency_pa_sn)
    v2 = steady_line_speed(system, eta)
    film = float(system.load.film_force_n(v2, eta))
    return film / (system.load.process_force_n + film)


def with_film_share(system: SystemConfig, share: float) -> SystemConfig:
    """``system`` with the film carrying ``share`` (0 < share < 1) of the load at the pattern eta_k.

    The film area A scales with the share and the process force F_p takes the rest, so the load at
    the pattern eta_k is unchanged (same v_2, slip and torque: the film force at a fixed v_2 is
    proportional to A).  The other eta_k groups then differ from the pattern group in load by
    share x (eta_k / eta_pattern - 1) of it."""
    if not 0.0 < float(share) < 1.0:
        raise ValueError(f"film share: must be in (0, 1), got {share!r}")
    ld = system.load
    eta = system.grid.pattern_consistency_pa_sn
    v2 = steady_line_speed(system, eta)
    film = float(ld.film_force_n(v2, eta))
    total = ld.process_force_n + film
    area = ld.film_area_m2 * float(share) * total / film
    load = dataclasses.replace(ld, film_area_m2=float(np.float64(area)), process_force_n=float(total * (1 - share)))
    return dataclasses.replace(system, load=load)
