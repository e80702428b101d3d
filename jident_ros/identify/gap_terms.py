"""The parts of a gap J1's standard error that a drive's declared bands make (issue 20 item 3): what each part is
and which parameter bounds it, and the bounded-error terms that more than one fit computes (the torque offset's
drift across the gap, the encoder's angle error).  Moved out of gap_free.py in stop 40 (its 600-line limit).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import numpy as np

#: The parts of a gap J1's standard error (``GapEstimate.std_error_terms``): what each is, and the drive parameter
#: (config/nodes.yaml, docs/your_drive.md) that bounds it, None where only the data narrow it (a longer gap, more
#: torque in it, a finer encoder, less noise).  The "undetermined" refusal names its largest term from here.
STD_ERROR_TERM_SOURCES = {
    "statistical": ("the samples themselves (encoder quantisation and noise through the fit)", None),
    "torque_noise": ("the noise on the torque estimate m_el", None),
    "noise_ratio": ("the ratio of the torque's noise to the acceleration's, which the samples show only roughly", None),
    "coulomb_band": ("the motor's Coulomb friction band", "coulomb_friction_max_nm"),
    "viscous_band": ("the viscous friction band", "viscous_friction_band_nms_per_rad"),
    "torque_offset": ("an unknown constant torque in the gap (the torque estimate's offset)", "torque_offset_rel_base"),
    "torque_drift": ("a drift of that unknown torque across the gap", "torque_offset_rel_base"),
    "torque_lag": ("the torque estimate's lag", "torque_lag_max_s"),
    "torque_lag_seen": ("the torque estimate's lag as the motor angle shows it, beyond the declared one", None),
    "encoder_error": ("the motor encoder's angle error (once and twice per revolution)", "encoder_accuracy_rad"),
    "change_points": ("where the gap begins and ends (the change points)", None),
    "model_form": ("the fit's model form (with and without a constant torque term)", None),
    "model_floor": ("the model's own error (a floor: the sampled torque's double integral)", None),
    "torque_accuracy": ("the torque estimate's scale accuracy", "torque_accuracy"),
}


#: A gap J1 is published only with a 95 % interval within ± this fraction of it: a wider one could hold a J1 this
#: far off (issue 20's target: no published J1 more than 10 % off); it is not published, as undetermined, whatever
#: classes it holds (the vector drive's heavy load reversal: ± 14 % around −30 %, one class inside, was published).
#: Such a window is 'ambiguous' (like an interval over two classes): a fact about this window's resolution, not
#: the monitor's configuration, so its level follows the nominal (OK when the interval is consistent with it, WARN
#: when it excludes it), and the trend takes its J1 with its standard error (issue 21).  The gap stage's cross-check
#: reads it too (gap._cross_checked: a disagreement where the better fit could not publish either is the window's
#: resolution).  Moved here from verdict.py in stop 46 (verdict imports gap; it re-exports the name).
MAX_CI95_HALF_WIDTH_REL = 0.10


def largest_term(std_error_terms) -> tuple | None:
    """(name, standard error) of the largest finite part of a gap J1's standard error, None when there is none."""
    best = None
    for name, value in std_error_terms or ():
        v = float(value)
        if np.isfinite(v) and v > 0.0 and (best is None or v > best[1]):
            best = (str(name), v)
    return best


def encoder_error_term(row: np.ndarray, alpha1: np.ndarray, j1: float, error_rad: float) -> float:
    """J1's standard uncertainty from the motor encoder's angle error: e(α) = A₁ sin(α + φ₁) + A₂ sin(2α + φ₂), each
    amplitude ``error_rad`` (the encoder's accuracy: a disc off centre, an elliptic one, a resolver's error), the
    phases unknown and uniform.  The fit's 1/J1 = row·α1 moves by row·e: for one harmonic A(cos φ row·sin kα + sin φ
    row·cos kα), of variance A² ρ_k²/2, ρ_k = |(row·sin kα1, row·cos kα1)| (the encoder's zero, unknown, only shifts
    φ); J1 moves by J1² that.  A fast gap sweeps the error's curvature: 1 mrad on the vector drive's speed events
    is 2 % (once) and 5-8 % (twice per revolution) of J1 (docs/results.md stop 26)."""
    if not error_rad or alpha1.size < 2:
        return 0.0
    rho2 = sum(float(row @ np.sin(k * alpha1)) ** 2 + float(row @ np.cos(k * alpha1)) ** 2 for k in (1, 2))
    return float(j1 * j1 * error_rad * np.sqrt(rho2 / 2.0))


def drift_term(row: np.ndarray, tt: np.ndarray, j1: float, offset_nm: float) -> float:
    """J1's standard uncertainty from a torque error that drifts linearly across the gap, from −offset to +offset
    (or back): T(t) = T_d (2 (t − t_mid)/D − 1 + 1), |T_d| <= offset_nm, uniform.  The drive's torque estimate is off
    by an amount that moves with the operating point (a rotor-resistance mismatch: with the slip), and a gap whose
    torque is small shows it most (the vector drive's return traversals: 19 N m of gap torque, an estimate off by
    1-3 N m across it).  Its double integral from the gap's first row, (T_d/J1)(2/D)(t³/6 − t_mid t²/2); θ0 and ω0
    absorb nothing of it; J1 moves by J1 (r_κ · that)."""
    if not offset_nm or tt.size < 2:
        return 0.0
    return float(j1 * abs(float(row @ drift_column(tt))) * offset_nm / np.sqrt(3.0))


def drift_column(tt: np.ndarray) -> np.ndarray:
    """The double integral from the gap's first row of a torque error drifting linearly from −1 to +1 across the
    rows' times ``tt`` (s): (2/D)(t³/6 − t_mid t²/2), t from the first row, D the span (:func:`drift_term`)."""
    t0 = tt - tt[0]
    dur = max(float(t0[-1]), 1e-300)
    return (2.0 / dur) * (t0 ** 3 / 6.0 - 0.5 * dur * t0 ** 2 / 2.0)
