"""What the gap fits share (issue 20, gap.py split by fit): the estimate they return (:class:`GapEstimate`), the refusal
they raise (:class:`NoGapError`), the torque they fit (:func:`_net_torque`, m_el − b1 ω1) and one fit's numbers while
gap._estimate_inertia finishes them (:class:`FitState`).  Moved out of gap.py with its fits (gap_a1.py, gap_angle.py,
gap_speed.py, gap_steady.py, gap_cross.py, gap_interval.py, gap_width.py), which import them from here and never import
gap.py; gap.py re-exports them.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class NoGapError(ValueError):
    """The window holds no usable backlash gap."""


@dataclass(frozen=True)
class GapEstimate:
    """J1 from the gap.

    Attributes
    ----------
    inertia_kgm2 : float            J1 estimate, kg m^2
    std_error_kgm2 : float          standard error, kg m^2
    ci95_kgm2 : (float, float)      95 % confidence interval, kg m^2
    residual_rms : float            RMS of the fit residual: of a1 expressed as torque, (a1 - (r/J1) m_hat) J1/r,
                                    in N m for 'acceleration' and 'anchored'; N m s for 'speed'; rad of α1
                                    for 'angle'
    model_error_kgm2 : float        'acceleration': |J1 with a linear torque term - J1|; 'angle': the same for
                                    its torque model; included in std_error_kgm2 (0 for the other fits)
    gap_start, gap_end : int        the gap interval's sample indices (entry row, re-contact row = end exclusive), as
                                    ``interval`` found it; the width estimate reads the re-contact at gap_end
    method : str                    'acceleration', 'gap_only', 'anchored', 'angle' or 'speed'
    interval : str                  'angles', 'signature' or 'detector' (how the gap interval was found)
    fit_start, fit_end : int        the samples the fit used ('gap_only' drops end samples of the interval that the
                                    dynamics show to be out of the zone; -1: the gap interval itself)
    model_choice : str              how the fit was chosen: '' when the caller named it, else the
                                    pre-entry steadiness test's verdict (:func:`pre_entry_steady`)
    change_point_error_kgm2 : float 'angle': the change of J1 when the estimated gap interval loses 1 or 2
                                    samples at an end (included in std_error_kgm2)
    friction : str                  'angle': how the motor's bearing friction was treated (fitted or bounded)
    std_error_terms : tuple         ((term, kg m^2), ...): the parts of std_error_kgm2, in quadrature
                                    (statistical, torque noise, change points, friction band, torque accuracy)
    trend_fit : tuple               (J1 kg m^2, its standard error kg m^2, its std_error_terms) of the fit the
                                    trend reads (trend_status.trend_inputs) where it is not this one, () where it
                                    is: a J1 whose bias is a constant of the drive, the motor's Coulomb friction
                                    F_c (J1 dω1/dt = m_el − F_c sgn ω1 − b1 ω1) taken as 0 with the band a term, as
                                    the a1 fits and the steady-entry fit take it.  The free angle fit under a
                                    Coulomb band (F_c fitted free or at the band's middle): its rows at F_c = 0
                                    (:func:`_angle_trend_refit`); the gap-only fit with its constant free: that fit
                                    through the origin.  Cross-checked (a1 and alpha1): the other fit's where its
                                    standard error without the drive's constant terms (:func:`within_drive_se`) is
                                    the smaller (a friction band's term can make the a1 fit lose the publication to
                                    the angle fit, whose J1 scatters more)
    """

    inertia_kgm2: float
    std_error_kgm2: float
    ci95_kgm2: tuple
    residual_rms: float
    gap_start: int
    gap_end: int
    method: str
    interval: str
    model_error_kgm2: float = 0.0
    model_choice: str = ""
    fit_start: int = -1
    fit_end: int = -1
    change_point_error_kgm2: float = 0.0
    friction: str = ""
    std_error_terms: tuple = ()
    trend_fit: tuple = ()

    @property
    def n_samples(self) -> int:
        return self.gap_end - self.gap_start

    @property
    def fitted_rows(self) -> tuple:
        """(first, end exclusive) of the rows the fit used: fit_start..fit_end, the gap interval where they are -1."""
        return (int(self.fit_start), int(self.fit_end)) if self.fit_start >= 0 else (int(self.gap_start),
                                                                                     int(self.gap_end))


def _net_torque(window: dict, bearing_friction_nms_per_rad: float) -> np.ndarray:
    """m_el − b1·ω1 over the whole window: the torque that accelerates J1 (m_el alone without b1 or ω1)."""
    torque = np.asarray(window["m_el"], float)
    if bearing_friction_nms_per_rad and "omega1" in window:
        torque = torque - bearing_friction_nms_per_rad * np.asarray(window["omega1"], float)
    return torque


@dataclass
class FitState:
    """One fit's numbers while gap._estimate_inertia finishes them: its locals until it became one function per fit
    (gap_a1's, gap_angle's and gap_speed's ``_method_*``) and the steps after them (issue 20).

    j, se : J1 and its standard error, kg m^2
    res : the residual (GapEstimate.residual_rms's), dof : its degrees of freedom
    model_error : GapEstimate.model_error_kgm2
    span : the fitted rows (GapEstimate.fit_start, fit_end)
    extra : GapEstimate's optional fields (change_point_error_kgm2, friction, std_error_terms, trend_fit)
    choice : the 'angle' fit's phrases for the model choice
    made, torque : the 'gap_only' fit's dict (gap_a1.gap_only_fit) and the net torque over the window it fitted
    """

    j: float
    se: float
    res: np.ndarray
    dof: int
    model_error: float = 0.0
    span: tuple = (-1, -1)
    extra: dict = field(default_factory=dict)
    choice: str = ""
    made: dict | None = None
    torque: np.ndarray | None = None
