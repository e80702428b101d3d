"""Long-run scenarios of the simulated drive (condition monitoring, issue 14).  Plain numpy.

:func:`wear_scenario`: one backlash-zone entry ("event", "window") every ``interval_s`` seconds of
drive time; the backlash width K2 grows linearly in time (wear) and J1 steps by ``j1_step_pct`` % at a
given window (e.g. a coupling or a mass added to the shaft).  It returns the :class:`~jident_ros.sim.Case`
of every event (simulated with :func:`jident_ros.sim.simulate_grid`) and the drive time of each entry
sample; turning them into a recording is the CLI's job (``jident simulate --scenario wear``,
:func:`jident_ros.cli.scenario.write_scenario_recording`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from jident_ros.sim.params import SystemConfig
from jident_ros.sim.simulate import Case, CaseTruths

SECONDS_PER_DAY = 86400.0
#: Scenario names understood by ``jident simulate --scenario``.
SCENARIOS = ("wear",)


@dataclass(frozen=True)
class Scenario(CaseTruths):
    """A long run of backlash entries.

    cases : list of Case, one per event (J1, K2, eta_k at that event)
    entry_times_s : ndarray (n,), drive clock t of each event's entry sample, s (increasing)
    j1_step_at_window : index of the first event with the stepped J1, or None
    j1_step_time_s : its entry time, s, or None
    wear_rate_m_per_s : the true dK2/dt, m/s
    """

    name: str
    cases: list
    entry_times_s: np.ndarray
    j1_step_at_window: Optional[int]
    j1_step_time_s: Optional[float]
    wear_rate_m_per_s: float

    def __len__(self):
        return len(self.cases)

    @property
    def wear_rate_m_per_day(self) -> float:
        return self.wear_rate_m_per_s * SECONDS_PER_DAY


def _finite(name, v, positive=True, allow_zero=False):
    ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)
    if ok and positive:
        ok = v > 0 or (allow_zero and v == 0)
    if not ok:
        raise ValueError(f"{name}: must be a finite number{' > 0' if positive else ''}, got {v!r}")
    return float(v)


def wear_scenario(system: SystemConfig, n_windows: int, interval_s: float = 3600.0, width_start_m: float = 0.0025,
                  width_end_m: Optional[float] = None, width_growth_m_per_day: Optional[float] = None,
                  j1_kgm2: Optional[float] = None, j1_step_at_window: Optional[int] = None,
                  j1_step_pct: float = 2.5, eta: Optional[float] = None,
                  start_time_s: Optional[float] = None) -> Scenario:
    """A drive whose backlash wears and whose J1 steps once.

    Parameters
    ----------
    system : SystemConfig (nominal J1 and the pattern eta_k are the defaults)
    n_windows : number of events (backlash entries), >= 1
    interval_s : drive time between two events, s (3600: one window an hour)
    width_start_m : K2 at the first event, m
    width_end_m : K2 at the last event, m (linear in time in between); or
    width_growth_m_per_day : dK2/dt in m per day (one of the two; neither: 0.0035 m at the end)
    j1_kgm2 : J1 before the step (default ``system.motor.nominal_inertia_kgm2``)
    j1_step_at_window : first event (0-based) with J1 (1 + j1_step_pct/100); None: no step
    j1_step_pct : size of the step, % (may be negative)
    eta : consistency index eta_k of every event, Pa s^n (default ``system.grid.pattern_consistency_pa_sn``)
    start_time_s : drive time of the first entry (default ``interval_s``), s

    Returns a :class:`Scenario`; entry i is at ``start_time_s + i * interval_s``.
    """
    if isinstance(n_windows, bool) or int(n_windows) != n_windows or n_windows < 1:
        raise ValueError(f"n_windows: must be an integer >= 1, got {n_windows!r}")
    n = int(n_windows)
    interval_s = _finite("interval_s", interval_s)
    width_start_m = _finite("width_start_m", width_start_m)
    if width_end_m is not None and width_growth_m_per_day is not None:
        raise ValueError("width_end_m and width_growth_m_per_day: give one of them, not both")
    if width_growth_m_per_day is not None:
        rate = _finite("width_growth_m_per_day", width_growth_m_per_day, positive=False) / SECONDS_PER_DAY
    else:
        end = 0.0035 if width_end_m is None else _finite("width_end_m", width_end_m)
        rate = 0.0 if n == 1 else (end - width_start_m) / ((n - 1) * interval_s)
    j1 = float(system.motor.nominal_inertia_kgm2) if j1_kgm2 is None else _finite("j1_kgm2", j1_kgm2)
    eta = float(system.grid.pattern_consistency_pa_sn) if eta is None else _finite("eta", eta)
    j1_step_pct = _finite("j1_step_pct", j1_step_pct, positive=False)
    if j1_step_pct <= -100:
        raise ValueError(f"j1_step_pct: must be > -100, got {j1_step_pct!r}")
    if j1_step_at_window is not None and (isinstance(j1_step_at_window, bool) or
                                          int(j1_step_at_window) != j1_step_at_window or
                                          not 0 <= j1_step_at_window < n):
        raise ValueError(f"j1_step_at_window: must be an integer in [0, {n - 1}] or None, got {j1_step_at_window!r}")
    t0 = interval_s if start_time_s is None else _finite("start_time_s", start_time_s, positive=False)
    times = t0 + interval_s * np.arange(n)
    widths = width_start_m + rate * (times - times[0])
    if not np.all(widths > 0):
        raise ValueError(f"the width reaches {widths.min():.4g} m: the scenario needs K2 > 0 throughout")
    j1s = np.full(n, j1)
    if j1_step_at_window is not None:
        j1s[int(j1_step_at_window):] *= 1.0 + j1_step_pct / 100.0
    cases = [Case(float(a), float(b), eta) for a, b in zip(j1s, widths)]
    step = None if j1_step_at_window is None else int(j1_step_at_window)
    return Scenario("wear", cases, times, step, None if step is None else float(times[step]), float(rate))


__all__ = ["SCENARIOS", "Scenario", "wear_scenario"]
