"""The core of a long coarse gap (gap_free.CORE_VAR_RATIO): the earliest third that fits within a factor of the
tightest, not the tightest alone."""
from pathlib import Path

import numpy as np
import pytest

import jident_ros.identify.gap_free as gap_free

DATA = Path(__file__).parent / "data" / "second_drive_return_traversal_30db.npz"


def _fit():
    z = np.load(DATA)
    model = gap_free.GapModel(torque_offset_nm=float(z["torque_offset_nm"]), changepoint_search_samples=int(z["search"]))
    b = tuple(int(x) for x in z["bounds"])
    ff = gap_free.free_angle_fit(z["alpha1"], z["torque"], float(z["sample_period_s"]), int(z["start"]), int(z["end"]),
                                 model, bounds=None if b[0] < 0 else b)
    return ff, z


def test_return_traversal_fitted_from_its_entry():
    """The second drive's 30 dB return traversal (JointState 2^16, J1 1.16, 164 rows to the re-contact row from delta):
    the fit starts at the entry, where the drive still acts, and J1 comes out within 1 %, its interval ± 5 %."""
    ff, z = _fit()
    assert ff["start"] <= int(z["start"]) + 2
    assert ff["j1"] == pytest.approx(float(z["true_j1"]), rel=0.01)
    assert 1.96 * ff["se"] < 0.05 * ff["j1"]


def test_tightest_third_alone_takes_the_quiet_end(monkeypatch):
    """The rule before (the tightest third): the core in the quiet last part, the start 40+ rows after the entry
    and an interval wider than ± 10 % (the window refused as undetermined)."""
    monkeypatch.setattr(gap_free, "CORE_VAR_RATIO", 1.0)
    ff, z = _fit()
    assert ff["start"] > int(z["start"]) + 40
    assert 1.96 * ff["se"] > 0.10 * ff["j1"]


def test_undeclared_note():
    """The one line a drive that declares nothing gets (jident diagnose's notes, the diagnostic node's status);
    none once any one term is declared."""
    from jident_ros.identify.verdict import VerdictPolicy
    assert "typical drive" in VerdictPolicy().undeclared_note(0.0)
    assert "exact torque estimate" in VerdictPolicy(assume_typical_drive=False).undeclared_note(0.0)
    assert VerdictPolicy(torque_accuracy=0.02).undeclared_note(0.0) == ""
    assert VerdictPolicy(coulomb_friction_max_nm=1.0).undeclared_note(0.0) == ""
    assert VerdictPolicy(torque_lag_max_s=1e-3).undeclared_note(0.0) == ""
    assert VerdictPolicy().undeclared_note(0.01) == ""


def test_typical_drive_for_raw_angles_only_when_nothing_is_declared():
    """TYPICAL_DRIVE on a real drive's window (raw encoder angles) when nothing is declared; the paper detector's
    windows (our simulator's exact torque) and any declaration keep the policy as given; the offset band at least
    as declared."""
    from types import SimpleNamespace

    from jident_ros.identify.verdict import TYPICAL_DRIVE, TYPICAL_FRICTION_REL_BASE, VerdictPolicy
    motor = SimpleNamespace(bearing_friction_nms_per_rad=0.0, base=SimpleNamespace(torque_nm=200.0))
    m = VerdictPolicy().drive_model(True, motor)
    assert m.torque_accuracy == TYPICAL_DRIVE["torque_accuracy"]
    # the motor's bearing friction is there whether declared or not: a band of M_b (6 N m of 200)
    assert m.coulomb_friction_max_nm == pytest.approx(TYPICAL_FRICTION_REL_BASE * 200.0) and m.coulomb_friction_max_nm > 0
    assert m.torque_lag_s == TYPICAL_DRIVE["torque_lag_max_s"]
    assert m.torque_offset_nm == pytest.approx(TYPICAL_DRIVE["torque_offset_rel_base"] * 200.0)
    assert VerdictPolicy(torque_offset_rel_base=0.05).drive_model(True, motor).torque_offset_nm == pytest.approx(10.0)
    exact = VerdictPolicy().drive_model(False, motor)
    assert exact.torque_accuracy == 0.0 and exact.torque_lag_s == 0.0 and exact.coulomb_friction_max_nm == 0.0
    assert VerdictPolicy(assume_typical_drive=False).drive_model(True, motor).torque_accuracy == 0.0
    declared = VerdictPolicy(torque_accuracy=0.01).drive_model(True, motor)
    assert declared.torque_accuracy == 0.01 and declared.torque_lag_s == 0.0
    b1 = SimpleNamespace(bearing_friction_nms_per_rad=0.02, base=SimpleNamespace(torque_nm=200.0))
    assert VerdictPolicy().drive_model(True, b1).torque_accuracy == 0.0


def test_raw_angles_from_the_detector_alone():
    """A flank or dynamics window is a real drive's recording for the drive model (VerdictPolicy.drive_model) also
    without a re-contact row or a K2 of its own; a paper-detector window never."""
    import math as _m
    from types import SimpleNamespace

    from jident_ros.identify.diagnosis import detector_arguments
    w = SimpleNamespace(detector="flank", backlash_width_estimate_m=_m.nan, backlash_width_se_m=_m.nan,
                        recontact_index=-1, backlash_width_m=0.005, channels=("t", "alpha1", "alpha2"))
    args = detector_arguments(w)
    assert args["raw_angles"] is True and args["recontact_index"] is None and args["width_estimate"] is None
    assert detector_arguments(SimpleNamespace(detector="paper")) == {}


def test_cross_check_takes_the_shared_torque_terms_as_a_difference():
    """The a1 and angle fits of one window read the same m_el: a friction band, an offset or a lag moves both J1 the
    same way, so the cross-check's standard error of their difference holds the difference of those terms, not their
    sum in quadrature (the second drive's a1 fit, 25 % off, passed at 2.9 standard errors with a typical drive's
    band and lag in quadrature: scripts/golden.py second_drive_signals).  The fits' own terms stay in quadrature."""
    import math

    from jident_ros.identify.gap import COMMON_TORQUE_TERMS, GapEstimate, GapModel, _difference_se

    def fit(j1, terms):
        se = math.sqrt(sum(v * v for _, v in terms))
        return GapEstimate(j1, se, (j1 - 2 * se, j1 + 2 * se), 0.0, 0, 10, "angle", "detector", std_error_terms=terms)

    shared = (("torque_lag", 0.049), ("torque_offset", 0.04))
    a = fit(1.45, (("statistical", 0.012),) + shared)
    b = fit(1.20, (("statistical", 0.010), ("torque_lag", 0.046), ("torque_offset", 0.04)))
    model = GapModel()
    se = _difference_se(a, b, model)
    assert se == pytest.approx(math.hypot(0.012, 0.010, 0.003), rel=1e-9)
    assert abs(a.inertia_kgm2 - b.inertia_kgm2) / se > 3           # refused: the fits disagree
    in_quadrature = math.hypot(a.std_error_kgm2, b.std_error_kgm2)
    assert abs(a.inertia_kgm2 - b.inertia_kgm2) / in_quadrature < 3  # what passed before
    # a term only one fit has (its constant fitted, no offset band) stays in quadrature
    c = fit(1.45, (("statistical", 0.012), ("torque_drift", 0.02)))
    assert _difference_se(c, b, model) == pytest.approx(math.sqrt(0.012 ** 2 + 0.02 ** 2 + b.std_error_kgm2 ** 2), rel=1e-9)
    assert {"coulomb_band", "torque_offset", "torque_lag"} <= set(COMMON_TORQUE_TERMS)
