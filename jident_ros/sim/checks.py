"""Refuse model inputs that make the fixed-step simulation diverge (issue 15 item 9).

The simulator integrates with classical RK4 at a fixed step h = T_s / integration_substeps
(docs/model.md, "Integration").  RK4 is stable for a linear mode with eigenvalue lambda only while the
amplification |R(h lambda)| <= 1, R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 (on the imaginary axis up to
|h lambda| = 2.83: a clutch mode of sqrt(k_c (1/J_1 + 1/J_w)) rad/s).  An absurd J_1 (1e-9 kg m^2)
puts the clutch mode at ~7e5 Hz, far beyond the 0.25 ms step, and the result is NaN.

:func:`check_step` (via :func:`jident_ros.sim.check_stable`) linearises the model at every case's loaded
steady state (clutch in contact: the stiffest configuration), takes the eigenvalues and refuses, with the
reason, a step that would amplify a physically decaying mode; :func:`check_finite` is the post-check on the result.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from jident_ros.sim.model import CaseArrays, Model

STATE_NAMES = ("stator flux alpha", "stator flux beta", "rotor flux alpha", "rotor flux beta", "rotor speed",
               "rotor angle", "clutch angle", "wheel speed", "line stretch", "mass speed")
#: Largest RK4 substep count :func:`check_stable` proposes before it calls the inputs absurd.
MAX_SUBSTEPS = 10_000


class SimulationDiverges(ValueError):
    """The model inputs would make the simulation diverge (or it did); the message says why."""


def rk4_amplification(z: np.ndarray) -> np.ndarray:
    """|R(z)| of classical RK4 for z = h lambda."""
    return np.abs(1 + z + z * z / 2 + z ** 3 / 6 + z ** 4 / 24)


def _unstable(lam: np.ndarray, h: float) -> np.ndarray:
    """Modes the step h amplifies beyond their physical growth (bool, same shape as lam)."""
    physical = np.exp(np.minimum(lam.real, 0.0) * h)
    return rk4_amplification(lam * h) > np.maximum(physical, 1.0) * (1 + 1e-9) + 1e-12


def linearised_eigenvalues(model: Model, y0: np.ndarray, case: CaseArrays) -> np.ndarray:
    """Eigenvalues (n_cases, 10) of the model's Jacobian at the states ``y0`` (N_STATES, n_cases),
    e.g. the loaded steady states of :func:`jident_ros.sim.steady_state`."""
    f0 = model.rhs(0.0, y0, case)
    n_states, n = y0.shape
    jac = np.empty((n, n_states, n_states))
    scale = np.maximum(np.abs(y0), 1e-3)
    for j in range(n_states):
        eps = 1e-7 * scale[j]
        y = y0.copy()
        y[j] += eps
        jac[:, :, j] = ((model.rhs(0.0, y, case) - f0) / eps).T
    if not np.all(np.isfinite(jac)):
        raise SimulationDiverges("the model is not finite at the loaded steady state; check the parameters")
    return np.linalg.eigvals(jac)


def check_step(model: Model, y0: np.ndarray, case: CaseArrays, cases: Sequence, sample_period_s: float,
               substeps: int) -> None:
    """Raise :class:`SimulationDiverges` (one line: the case, the mode, the step, the remedy) when the RK4
    step ``sample_period_s / substeps`` would amplify a decaying mode of the model linearised at ``y0``
    (the steady states of ``cases``).  :func:`jident_ros.sim.check_stable` computes ``y0`` from a config."""
    ts, sub = float(sample_period_s), int(substeps)
    h = ts / sub
    lam = linearised_eigenvalues(model, y0, case)
    bad = _unstable(lam, h)
    if not bad.any():
        return
    i = int(np.argmax((np.abs(lam) * bad).max(axis=1)))
    fast = lam[i][bad[i]]
    worst = fast[np.argmax(np.abs(fast))]
    need = sub
    while need <= MAX_SUBSTEPS and _unstable(lam, ts / need).any():
        need *= 2
    c = cases[i]
    remedy = (f"raise sampling.integration_substeps to >= {need} (now {sub})" if need <= MAX_SUBSTEPS else
              f"no step down to {ts / MAX_SUBSTEPS * 1e6:.3g} us integrates it")
    raise SimulationDiverges(
        f"case J1 = {c.inertia_kgm2:g} kg m^2, K2 = {c.backlash_width_m:g} m, eta_k = {c.consistency_pa_sn:g} "
        f"Pa s^n: the model's fastest mode ({abs(worst) / (2 * math.pi):.3g} Hz) is too fast for the RK4 step "
        f"of {h * 1e3:.3g} ms (T_s / {sub}); the simulation would diverge. Check J1, the clutch and line "
        f"stiffness and the masses, or {remedy}")


def check_finite(windows) -> None:
    """Post-check: raise :class:`SimulationDiverges` naming the first case and time with a non-finite sample."""
    for name, x in windows.signals.items():
        bad = ~np.isfinite(x)
        if bad.any():
            i, k = np.argwhere(bad)[0]
            c = windows.cases[int(i)]
            raise SimulationDiverges(
                f"case J1 = {c.inertia_kgm2:g} kg m^2, K2 = {c.backlash_width_m:g} m, eta_k = "
                f"{c.consistency_pa_sn:g} Pa s^n: {name} is not finite from t = {windows.t[int(k)]:.4g} s on "
                f"({int(bad.sum())} samples); the simulation diverged")
