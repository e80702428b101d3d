"""The 'speed' fit (ω1 and m_el, no accelerometer; issue 20 item 2): J1 from the motor speed in integral form, no
differentiation.  Moved out of gap.py (its 600-line limit); the numbers are the same.

In the gap ω1_k = ω1_0 + (1/J1) ∫_{t0}^{tk} m_el dt, and ω1 is regressed on the integral (:func:`speed_fit`: the noisy
speed is the regressand; the residual's autocorrelation and the interval's end rows go into the uncertainty).
Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import numpy as np

from jident_ros.identify.gap_numerics import _ar1_inflation
from jident_ros.identify.gap_types import FitState, NoGapError, _net_torque

#: The speed fit's model error: J1 refitted with this many samples dropped at each end of the interval.
SPEED_TRIM_SAMPLES = (1, 2)


def speed_fit(omega1: np.ndarray, torque: np.ndarray, sample_period_s: float, lag: bool = False) -> tuple:
    """(J1, standard error, residual, degrees of freedom) of the ``"speed"`` fit over the gap samples.

    In the gap ω1(t_k) = ω1(t_0) + Y_k / J1 with Y_k = ∫_{t0}^{tk} m_el dt (trapezoid).  The measured speed
    carries white noise and the integral hardly any (it averages the torque noise), so ω1 is regressed on Y:
    ordinary least squares for (ω1(t_0), 1/J1), J1 = 1 / slope.  The model check: the residual's lag-1
    autocorrelation rho (a load torque left in the interval, a differenced encoder's correlated error) inflates
    the slope's variance by (1 + rho) / (1 - rho) (the AR(1) factor; rho < 0 is not credited), and the change of
    J1 when one or two samples are dropped at each end of the interval (the larger) is added in quadrature (the
    interval's end rows: an entry found early, a re-contact row late).
    Regressing Y on ω1 instead (the first release) put the speed noise in the regressor: on the second drive at
    30 dB its interval was far too narrow and 52 of 84 published J1 were more than 10 % off (docs/results.md).

    ``lag`` (estimate_inertia's 'speed' fit): the drive's speed feedback lags the shaft (a filter, a
    differenced encoder): ω1_meas(t) ≈ ω1(t − τ) ≈ ω1(t) − τ dω1/dt = ω1_0 + Y/J1 − (τ/J1) m_el, so the torque
    itself is a third regressor and τ is fitted with J1 (issue 20: −3 … −7 % with a 0.4 ms lag unmodelled)."""
    n = omega1.size
    y = np.concatenate([[0.0], np.cumsum(0.5 * (torque[1:] + torque[:-1])) * sample_period_s])

    def slope(w, yy, mm=None):
        A = np.column_stack([np.ones(w.size), yy] + ([] if mm is None else [mm]))
        coef, *_ = np.linalg.lstsq(A, w, rcond=None)
        return coef, A

    if n < 6:
        raise NoGapError(f"speed fit: {n} gap samples, at least 6 are needed")
    tq = np.asarray(torque, float) if lag else None
    coef, A = slope(omega1, y, tq)
    kappa = float(coef[1])
    if not kappa > 0:
        raise NoGapError(f"gap fit gave a non-physical J1 = 1/{kappa:.4g} (dω1 against ∫m_el dt)")
    res = omega1 - A @ coef
    dof = n - A.shape[1]
    cov = (res @ res) / dof * np.linalg.pinv(A.T @ A) * _ar1_inflation(res)
    j = 1.0 / kappa
    se_stat = float(np.sqrt(cov[1, 1])) / kappa ** 2
    model_error = 0.0
    for k in SPEED_TRIM_SAMPLES:
        if n - 2 * k < 6:
            break
        trimmed, _ = slope(omega1[k:n - k], y[k:n - k] - y[k], None if tq is None else tq[k:n - k])
        model_error = max(model_error, abs(1.0 / trimmed[1] - j) if trimmed[1] > 0 else np.inf)
    return j, float(np.hypot(se_stat, model_error)), res * j, dof


def _method_speed(window: dict, rows: tuple, drive: tuple) -> FitState:
    """gap._estimate_inertia's 'speed' fit over ``rows`` (start, end): :func:`speed_fit` with the speed feedback's lag
    fitted.  ``drive``: (r, b1, T_s)."""
    (start, end), (_, bearing_friction_nms_per_rad, sample_period_s) = rows, drive
    if "omega1" not in window:
        raise NoGapError("method 'speed' needs omega1")
    m = _net_torque(window, bearing_friction_nms_per_rad)[start:end]
    j, se, res, dof = speed_fit(np.asarray(window["omega1"], float)[start:end], m, sample_period_s, lag=True)
    return FitState(j, se, res, dof, 0.0, (start, end))


def _speed_bounded(f: FitState, m_el: np.ndarray, rows: tuple, sample_period_s: float, bounded: list) -> None:
    """gap._estimate_inertia's bounded constant torques of the 'speed' fit (``f`` changed in place; ``bounded``:
    [(term, its bound N m)]): a constant torque F is F t in ∫m_el dt, which moves J1 by J1 F (r_κ · t) (r_κ: the
    least-squares row of 1/J1)."""
    start, end = rows
    n = end - start
    tq = np.asarray(m_el, float)[start:end]
    yint = np.concatenate([[0.0], np.cumsum(0.5 * (tq[1:] + tq[:-1])) * sample_period_s])
    A = np.column_stack([np.ones(n), yint, tq])
    row = np.linalg.pinv(A)[1]
    sens = f.j * abs(float(row @ (np.arange(n) * sample_period_s)))
    terms = dict(f.extra.get("std_error_terms", ()))
    for name, v in bounded:
        terms[name] = sens * v / np.sqrt(3.0)
        f.se = float(np.hypot(f.se, terms[name]))
    f.extra["std_error_terms"] = tuple(terms.items())
