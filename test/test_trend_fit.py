"""The J1 the trend reads (GapEstimate.trend_fit, issue 20 item 3 with the trend of issue 14): where the published fit
took the motor's friction free, or a friction band's term made the a1 fit lose the publication to a fit that scatters
more, the trend reads a J1 whose bias is a constant of the drive (jident_ros.identify.gap, trend_status)."""
from types import SimpleNamespace

import numpy as np
import pytest

from jident_ros.identify import gap
from jident_ros.identify.gap import GapEstimate, estimate_inertia, within_drive_se
from jident_ros.identify.gap_free import GapModel, free_angle_fit
from jident_ros.identify.trend_status import refusal_kind, trend_inputs
from jident_ros.research.evaluation.gap_stress import StressDrive, simulate

TS, R = 5e-4, 0.08


def _estimate(j, terms, trend_fit=()):
    se = float(np.sqrt(sum(v * v for _, v in terms)))
    return GapEstimate(j, se, (j - 2 * se, j + 2 * se), 0.0, 0, 10, "angle", "detector", std_error_terms=tuple(terms),
                       trend_fit=trend_fit)


def test_the_trend_reads_the_trend_fit_without_the_drive_s_constant_terms():
    """A published J1 with a trend fit beside it: the trend gets the trend fit's J1 and its standard error without
    the terms that are constants of the drive; without one, the published J1 as before."""
    tf = (1.20, float(np.hypot(0.004, 0.03)), (("statistical", 0.004), ("coulomb_band", 0.03)))
    g = _estimate(1.15, (("statistical", 0.02), ("coulomb_band", 0.01)), tf)
    d = SimpleNamespace(gap=g, status="ambiguous", inertia_kgm2=1.15, refused_reason=None, width=None)
    ti = trend_inputs(d)
    assert (ti.inertia_kgm2, ti.inertia_se_kgm2) == (1.20, pytest.approx(0.004))
    assert refusal_kind(d) is None
    d.gap = _estimate(1.15, (("statistical", 0.02), ("coulomb_band", 0.01)))
    ti = trend_inputs(d)
    assert (ti.inertia_kgm2, ti.inertia_se_kgm2) == (1.15, pytest.approx(0.02))
    # a trend fit that is not finite is no J1 for the trend
    d.gap = _estimate(1.15, (("statistical", 0.02),), (float("nan"), 0.01, ()))
    assert refusal_kind(d) == "no_gap"


def test_a_free_angle_fit_under_a_coulomb_band_gives_the_trend_the_same_rows_at_zero_friction():
    """The light load reversal (bearing friction 0.8 N m), JointState: under the band [0, 1.5] N m the free angle fit
    takes F_c free; the trend reads the same rows fitted with F_c = 0, as the a1 fits and the steady-entry fit take
    it (a drive-constant bias).  Without a band there is nothing to bound: no trend fit."""
    rec = simulate(StressDrive(j1_kgm2=1.16), "load_reversal", seed=5)
    w = dict(rec["window"])
    w.pop("a1")
    g = estimate_inertia(w, rec["entry"], 0.005, R, TS, method="angle", recontact_index=rec["recontact"],
                         model=GapModel(coulomb_friction_max_nm=1.5))
    assert g.friction.startswith("fitted") and len(g.trend_fit) == 3
    at_zero = free_angle_fit(w["alpha1"], w["m_el"], TS, g.fit_start, g.fit_end, GapModel(), fixed=True)
    assert g.trend_fit[0] == pytest.approx(at_zero["j1"], rel=1e-9)
    # its standard error: the published fit's, relative (the same rows and regressors)
    assert g.trend_fit[1] / g.trend_fit[0] == pytest.approx(g.std_error_kgm2 / g.inertia_kgm2, rel=1e-9)
    assert abs(g.trend_fit[0] / g.inertia_kgm2 - 1) > 0.1          # the friction's bias, a constant of the drive
    step = simulate(StressDrive(j1_kgm2=1.16), "speed_step", seed=3)
    w = dict(step["window"])
    w.pop("a1")
    for band, n in ((0.0, 0), (1.5, 3)):
        g = estimate_inertia(w, step["entry"], 0.005, R, TS, method="angle", recontact_index=step["recontact"],
                             model=GapModel(coulomb_friction_max_nm=band))
        assert len(g.trend_fit) == n


def test_the_gap_only_fit_s_free_constant_gives_the_trend_the_fit_through_the_origin():
    """The gap-only fit with a constant torque fitted beside J1 (the bounded fit's J1 named in its friction text):
    the trend reads that bounded fit's J1 (the constant at 0, the band a term)."""
    t = np.arange(248) * TS
    tg = t[48:] - t[48]
    m = np.concatenate([np.full(48, -30.0), -30.0 + 29.0 * np.sin(np.pi * tg / 0.1) ** 2 + 60.0 * tg])
    acc = np.concatenate([np.zeros(48), (m[48:] + 2.5) / 1.16])
    w = {"m_el": m, "a1": R * (acc + np.random.default_rng(0).normal(0.0, 0.05, t.size))}
    g = estimate_inertia(w, 48, 0.005, R, TS, method="gap_only", recontact_index=248,
                         model=GapModel(coulomb_friction_max_nm=2.6))
    assert g.friction.startswith("fitted: a constant torque")
    named = float(g.friction.split("bounded: ")[1].split(" ")[0])
    assert g.trend_fit[0] == pytest.approx(named, rel=1e-3) and g.trend_fit[0] != g.inertia_kgm2


def test_the_cross_check_gives_the_trend_the_fit_that_scatters_less():
    """Cross-checked (a1 and alpha1): the published fit is the one with the smaller total standard error; the trend's
    is the one with the smaller standard error without the drive's constant terms (a friction band's term, first
    order in the a1 fit, made the angle fit win 39 of the wear scenario's 40 windows: its J1 scatters 2-4 times more)."""
    angle = _estimate(1.13, (("torque_noise", 0.013), ("coulomb_band", 0.014), ("torque_offset", 0.019)))
    a1 = _estimate(1.16, (("statistical", 0.006), ("coulomb_band", 0.029), ("torque_offset", 0.019)))
    assert angle.std_error_kgm2 < a1.std_error_kgm2
    assert within_drive_se(a1.std_error_kgm2, a1.std_error_terms) == pytest.approx(0.006)
    chosen = gap._trend_choice(angle, a1)
    assert chosen.inertia_kgm2 == 1.13 and chosen.trend_fit == (1.16, a1.std_error_kgm2, a1.std_error_terms)
    # the other way round, or an a1 fit that scatters more: the published fit's own
    assert gap._trend_choice(a1, angle).trend_fit == ()
    noisy = _estimate(1.16, (("statistical", 0.02), ("coulomb_band", 0.029)))
    assert gap._trend_choice(angle, noisy).trend_fit == ()
