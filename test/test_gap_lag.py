"""The torque's lag as the motor angle shows it (issue 20 item 3: an interval holds what the data cannot pin down):
jident_ros.identify.gap_lag.torque_lag_estimate and the check estimate_inertia makes with it against the declared
torque_lag_max_s (gap._lag_beyond_declared)."""
import numpy as np
import pytest
from scipy.signal import lfilter

from jident_ros.identify import gap
from jident_ros.identify.gap import estimate_inertia
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.gap_lag import torque_lag_estimate
from jident_ros.identify.gap_terms import STD_ERROR_TERM_SOURCES

TS = 5e-4


def _drive(smoothing_s: float, entry: int = 60, n: int = 200, j1: float = 1.1):
    """A drive at 150 rad/s in contact (100 N m balanced by the coupling) before ``entry``, free after it under a
    torque that swings ± 300 N m with a 30 ms period (not an exponential: a lag of an exponential torque is a scale
    error of it, which no angle can tell from J1); a 2^16 encoder; m_el reported through a first-order low-pass of
    ``smoothing_s`` (a drive's smoothed 'actual torque': a lag of about that much)."""
    fine = 20
    tf = np.arange(n * fine) * TS / fine
    free = tf >= entry * TS
    m_true = np.where(free, 100.0 + 300.0 * np.sin(2 * np.pi * (tf - entry * TS) / 0.03), 100.0)
    w1 = 150.0 + np.cumsum(np.where(free, m_true, 0.0) / j1) * TS / fine
    q = 2 * np.pi / 2 ** 16
    alpha1 = np.floor((np.cumsum(w1) * TS / fine + 0.3)[::fine] / q) * q
    m = m_true[::fine]
    if smoothing_s:
        k = TS / (smoothing_s + TS)
        m = lfilter([k], [1, k - 1], m, zi=[m[0] * (1 - k)])[0]
    return alpha1, m


@pytest.mark.parametrize("smoothing_s", [0.0, 1e-3, 2e-3])
def test_the_lag_estimate_reads_a_smoothed_torque_s_delay(smoothing_s):
    """Over free rows, τ̂ is the low-pass's delay (its time constant, for a torque slow against it) within 15 %, and
    0 within a tenth of a sample for a torque on time."""
    alpha1, m = _drive(smoothing_s)
    tau, se = torque_lag_estimate(alpha1, m, TS, 62, 110)
    assert 0 < se < 0.3e-3
    assert tau == pytest.approx(smoothing_s, abs=max(0.15 * smoothing_s, 0.05 * TS))


def test_an_exponential_torque_hides_its_lag():
    """m = A e^(-t/T): Φ = A T t - T Ψ, the lag's column is the others' combination: no estimate (a large standard
    error or none), never a confident wrong one."""
    t = np.arange(80) * TS
    m = 400.0 * np.exp(-t / 0.008)
    w = 150.0 + np.cumsum(m / 1.1) * TS
    tau, se = torque_lag_estimate(np.cumsum(w) * TS, np.r_[m[0], m[:-1]], TS, 0, 80)
    assert not (np.isfinite(tau) and abs(tau) > 4 * se)


def _estimate(alpha1, m, declared_s):
    return estimate_inertia({"alpha1": alpha1, "m_el": m}, 60, 0.005, 0.08, TS, recontact_index=150,
                            model=GapModel(torque_lag_s=declared_s))


def test_a_lag_beyond_the_declared_widens_the_interval_and_says_so(monkeypatch):
    """A torque 1 ms late on a drive that declares none: the fit is made again with the lag the angle shows, its
    model_choice says so, the term is the data's ('torque_lag_seen', its own source) and the interval is wider than
    without the check; declared (1 ms), or on time, nothing is said."""
    alpha1, m = _drive(1e-3)
    g = _estimate(alpha1, m, 0.0)
    assert "beyond the declared 0 ms" in g.model_choice, g.model_choice
    terms = dict(g.std_error_terms)
    assert "torque_lag_seen" in terms and "torque_lag" not in terms and "torque_lag_seen" in STD_ERROR_TERM_SOURCES
    monkeypatch.setattr(gap, "LAG_Z", np.inf)
    unchecked = _estimate(alpha1, m, 0.0)
    assert "beyond" not in unchecked.model_choice
    assert g.ci95_kgm2[1] - g.ci95_kgm2[0] > unchecked.ci95_kgm2[1] - unchecked.ci95_kgm2[0]
    monkeypatch.undo()
    assert "beyond" not in _estimate(alpha1, m, 1e-3).model_choice
    on_time = _estimate(*_drive(0.0), 0.0)          # τ̂ 0.02 ms at z 3: under a sample's fraction, not a delay
    assert "beyond" not in on_time.model_choice and on_time.inertia_kgm2 == pytest.approx(1.1, rel=0.01)


def test_the_cross_checked_fits_check_the_lag_over_both_fits_rows(monkeypatch):
    """With a1 beside the angle, the lag is read over the angle fit's rows and the a1 fit's (a smoothed torque showed
    over the a1 fit's longer rows alone on the vector drive: J1 -10.4 % outside its interval), and both fits are made
    again with the larger bound."""
    alpha1, m = _drive(1e-3)
    a1 = np.gradient(np.gradient(alpha1, TS), TS) * 0.08
    seen = []
    real = gap._lag_beyond_declared
    monkeypatch.setattr(gap, "_lag_beyond_declared", lambda *a: seen.append(a[2].method) or real(*a))
    g = estimate_inertia({"alpha1": alpha1, "m_el": m, "a1": a1}, 60, 0.005, 0.08, TS, recontact_index=150,
                         model=GapModel())
    assert {"angle"} < set(seen) and len(seen) == 2, seen
    assert "beyond the declared 0 ms" in g.model_choice, g.model_choice


def test_a_lag_under_half_a_sample_is_not_a_delay(monkeypatch):
    """A torque smoothed by 0.1 ms (a fifth of a sample): τ̂ 0.12 ms at z 13, under LAG_MIN_SAMPLES: nothing said; with
    the floor off it would be."""
    from types import SimpleNamespace
    alpha1, m = _drive(1e-4)
    tau, se = torque_lag_estimate(alpha1, m, TS, 62, 110)
    assert 4 * se < tau < 0.5 * TS
    rows = SimpleNamespace(fit_start=62, fit_end=110)
    window = {"alpha1": alpha1, "m_el": m}
    assert gap._lag_beyond_declared(window, 0.0, rows, TS, GapModel()) is None
    monkeypatch.setattr(gap, "LAG_MIN_SAMPLES", 0.0)
    assert gap._lag_beyond_declared(window, 0.0, rows, TS, GapModel())[0] > tau


def test_the_declared_coulomb_friction_is_taken_off_before_the_lag_is_read():
    """A motor with 20 N m of Coulomb friction and a torque on time reads as a 0.4 ms lag (z 10) when the friction is
    left in m_el; taken off (coulomb_nm, the middle of the declared band), as none."""
    fine, n, entry = 20, 200, 60
    tf = np.arange(n * fine) * TS / fine
    free = tf >= entry * TS
    m = np.where(free, 100.0 + 300.0 * np.sin(2 * np.pi * (tf - entry * TS) / 0.03), 100.0)
    w1 = 150.0 + np.cumsum(np.where(free, m - 20.0, 0.0) / 1.1) * TS / fine
    q = 2 * np.pi / 2 ** 16
    alpha1 = np.floor((np.cumsum(w1) * TS / fine + 0.3)[::fine] / q) * q
    tau, se = torque_lag_estimate(alpha1, m[::fine], TS, 62, 110)
    assert tau > 4 * se and tau > 2e-4
    tau, se = torque_lag_estimate(alpha1, m[::fine], TS, 62, 110, coulomb_nm=20.0)
    assert abs(tau) < 3 * se and abs(tau) < 5e-5


def _declared(alpha1, m, **model):
    g = estimate_inertia({"alpha1": alpha1, "m_el": m}, 60, 0.005, 0.08, TS, recontact_index=150,
                         model=GapModel(**model))
    return g.inertia_kgm2 / 1.1 - 1


def test_a_known_delay_declared_is_taken_off():
    """A torque reported two samples late (torque_delay_s, stop 34): read as on time, J1 12 % off; declared, within
    0.5 %; a window without the keys is passed on untouched."""
    alpha1, m = _drive(0.0)
    late = np.r_[m[0], m[0], m[:-2]]
    assert abs(_declared(alpha1, late)) > 0.05
    assert abs(_declared(alpha1, late, torque_delay_s=2 * TS)) < 0.005
    window = {"m_el": late}
    assert gap._delay_taken_off(window, 0.0, 0.0, TS) is window


def test_a_known_smoothing_declared_is_undone():
    """A torque through a 1 ms first-order low-pass (torque_filter_s): undone (m + τ dm/dt), J1 within 1 %; taken as
    a 1 ms delay instead, the filter's attenuation stays (J1 2 % low); not declared, 9.6 % high."""
    alpha1, m = _drive(1e-3)
    assert _declared(alpha1, m) > 0.05
    assert abs(_declared(alpha1, m, torque_filter_s=1e-3)) < 0.01
    assert _declared(alpha1, m, torque_delay_s=1e-3) < -0.015
