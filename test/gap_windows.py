"""Synthetic and simulated windows shared by the gap estimator's tests (test_gap*.py).

* ``exact_window``: a single mass J1 under a known polynomial torque in the gap, on which each fit's model can be
  exact;
* ``motor_angles``: the same window as a motor encoder sees it (alpha1 = the motor angle);
* ``CFG``, ``R`` (wheel radius, m), ``TS`` (sample period, s), ``N_PRE`` (pre-entry samples of ``exact_window``).
"""
from __future__ import annotations

import numpy as np

from jident_ros.config import load_system_config

CFG = load_system_config()
R = CFG.load.wheel_radius_m
TS = 5e-4
N_PRE = 48


def exact_window(j1, n_gap=20, n_pre=N_PRE, n_after=40, torque=(150.0, 0.0, -8000.0, 2.0e5), omega0=150.0,
                 friction=0.0, acc_noise=0.0, seed=0):
    """Single mass J1 under a polynomial torque m0 + c1 t + c2 t^2 + c3 t^3 (t from the entry) in the gap,
    steady state (a1 = 0, m_el = m0, constant omega1) before it, then a contact between two samples that
    decelerates the motor.  Angles from the zone centre (|alpha1 - alpha2| < K2/r in the gap only); omega1 and
    the motor angle ``alpha_motor`` are the exact integrals.  ``friction``: b1 omega1 is added to m_el."""
    m0, c1, c2, c3 = torque
    n = n_pre + n_gap + n_after
    t = (np.arange(n) - n_pre) * TS
    t_c = (n_gap - 0.5) * TS                                            # the flanks meet between two samples
    tg = np.clip(t, 0.0, t_c)
    m_free = m0 + c1 * tg + c2 * tg ** 2 + c3 * tg ** 3                 # J1 domega/dt in the gap
    omega = omega0 + (m0 * tg + c1 * tg ** 2 / 2 + c2 * tg ** 3 / 3 + c3 * tg ** 4 / 4) / j1
    alpha = 3.0 + omega0 * t + (m0 * tg ** 2 / 2 + c1 * tg ** 3 / 6 + c2 * tg ** 4 / 12 + c3 * tg ** 5 / 20) / j1
    after = t > t_c
    alpha[after] += (omega[after] - omega0) * (t[after] - t_c) - 4000.0 * (t[after] - t_c) ** 2
    omega[after] -= 8000.0 * (t[after] - t_c)
    m = m_free + friction * omega
    a1 = np.where(t >= 0, R * m_free / j1, 0.0)
    a1[after] = -20.0                                                   # the flank impact
    a1 = a1 + acc_noise * np.random.default_rng(seed).standard_normal(n)
    theta = 0.05
    rel = np.full(n, theta + 0.007)
    rel[n_pre:n_pre + n_gap] = np.linspace(0.007, theta - 1e-4, n_gap)
    rel[n_pre + n_gap:] = theta + np.linspace(1e-4, 0.01, n_after)
    return {"m_el": m, "a1": a1, "omega1": omega, "alpha1": rel, "alpha2": np.zeros(n),
            "alpha_motor": alpha}, theta * R


def motor_angles(w):
    """alpha1 = the motor angle, alpha2 = alpha1 - the relative angle (the same gap from inequality 1)."""
    return {"alpha1": w["alpha_motor"], "alpha2": w["alpha_motor"] - w["alpha1"], "m_el": w["m_el"]}
