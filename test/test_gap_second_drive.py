"""The gap estimator on a drive we did not write (issue 12): the 'gap_only' fit and the model choice.

The second drive (jident_ros.research.second_drive, docs/second_drive.md) leaves its flank because its speed controller
swings the torque, so the joint fit's steady pre-entry torque does not hold there.  A few recordings are simulated
in-process, clean and at 30 dB, with raw 2^16-count encoders and no K2; the flank detector cuts the windows.
"""
from __future__ import annotations

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.identify.gap import (
    STEADY_P_VALUE,
    NoGapError,
    _origin_slope,
    estimate_inertia,
    gap_only_fit,
    nearest_class,
    pre_entry_steady,
)
from jident_ros.identify.verdict import classes_in_interval
from jident_ros.research.second_drive import record as R
from jident_ros.research.second_drive.model import DriveParams
from jident_ros.sim import Case, add_measurement_noise, simulate_grid
from jident_ros.stream.detector import stream_batches
from jident_ros.stream.flank import FlankDetector

SYSTEM = load_system_config()
CLASSES = tuple(SYSTEM.grid.inertia_classes_kgm2)
P = DriveParams()
CASES = R.grid_cases(("forward", "reverse"), (1.16, 0.957, 1.218), (0.0025, 0.0075))


def _windows(snr_db):
    """(window, truth) of the first entry of every case, as the flank detector cuts it from the recording."""
    sensors = R.SensorConfig(snr_db=snr_db)
    recs = R.build_grid(P, CASES, sensors, steady_s=0.2, post_s=1.25, seed=11)
    out = []
    for rec in recs:
        tr = rec.truth
        data = np.column_stack([rec.signals[c] for c in R.CSV_CHANNELS])
        det = FlankDetector(tr["reference_radius_m"], tr["sample_period_s"], channels=R.CSV_CHANNELS,
                            encoder_counts_per_rev=65536, nominal_inertia_kgm2=SYSTEM.motor.nominal_inertia_kgm2)
        evs = []
        for b in stream_batches(data, 50):
            evs += det.push(b, R.CSV_CHANNELS)
        evs += det.finish()
        wins = [e.window for e in evs if e.kind == "window"]
        assert wins, tr["name"]
        w = wins[0]
        first = int(round((w.entry_time_s - tr["entry_time_s"]) / tr["sample_period_s"]))
        assert -4 <= first <= 0, (tr["name"], first)       # the entry window, at most a few samples early
        out.append((w, tr))
    return out


@pytest.fixture(scope="module")
def clean():
    return _windows(None)


@pytest.fixture(scope="module")
def noisy():
    return _windows(30.0)


def _fit(w, tr, method=None, **kw):
    """The a1 fits' model choice alone (cross_check=False: the a1/angle cross-check is test_gap_free's)."""
    return estimate_inertia(w.as_dict(), w.entry_index, w.backlash_width_m, w.wheel_radius_m, w.sample_period_s,
                            method=method, bearing_friction_nms_per_rad=tr["bearing_friction_nms"],
                            recontact_index=w.recontact_index, cross_check=False, **kw)


@pytest.mark.parametrize("which", ["clean", "noisy"])
def test_class_right_and_interval_covers_on_the_second_drive(which, request):
    wins = request.getfixturevalue(which)
    covered = 0
    for w, tr in wins:
        g = _fit(w, tr)
        assert g.method == "gap_only" and g.model_choice.startswith("gap_only: pre-entry m_el not steady"), tr["name"]
        j1 = tr["inertia_kgm2"]
        assert CLASSES[nearest_class(g.inertia_kgm2, CLASSES)] == j1, (tr["name"], g.inertia_kgm2)
        assert abs(g.inertia_kgm2 / j1 - 1) < (1e-3 if which == "clean" else 0.01), (tr["name"], g.inertia_kgm2)
        assert len(classes_in_interval(g.ci95_kgm2, CLASSES)) == 1, (tr["name"], g.ci95_kgm2)   # not ambiguous
        covered += g.ci95_kgm2[0] <= j1 <= g.ci95_kgm2[1]
    # clean: every interval; 30 dB: a nominal 95 % interval may miss one of the six
    assert covered >= len(wins) - (0 if which == "clean" else 1), covered


def test_the_joint_fit_is_wrong_there_which_is_why_the_choice_matters(clean):
    """The joint fit's pre-entry anchor does not hold on this drive: it misses the class or is refused as
    undetermined (measured: 6 of 84 right over the grid; here 10 of 12 wrong) -- the default must not use it."""
    wrong = 0
    for w, tr in clean:
        try:
            g = _fit(w, tr, "acceleration")
            wrong += CLASSES[nearest_class(g.inertia_kgm2, CLASSES)] != tr["inertia_kgm2"]
        except NoGapError:
            wrong += 1
        assert pre_entry_steady(w.as_dict()["m_el"][:w.entry_index]).p_value < STEADY_P_VALUE
    assert wrong >= 0.75 * len(clean), wrong


def test_model_choice_keeps_the_joint_fit_on_our_simulator():
    ws = simulate_grid(SYSTEM, [Case(1.16, 0.005, 0.025), Case(0.957, 0.0025, 0.05), Case(1.218, 0.01, 0.0125)])
    r = SYSTEM.load.wheel_radius_m
    for data in (ws, add_measurement_noise(ws, 30.0, 4)):
        for i, c in enumerate(ws.cases):
            win = {k: data.signals[k][i] for k in ("alpha1", "alpha2", "a1", "m_el")}
            test = pre_entry_steady(win["m_el"][:ws.entry_index])
            assert test.steady, test
            auto = estimate_inertia(win, ws.entry_index, c.backlash_width_m, r, ws.sample_period_s, cross_check=False)
            joint = estimate_inertia(win, ws.entry_index, c.backlash_width_m, r, ws.sample_period_s, "acceleration")
            assert auto.method == "acceleration" and auto.model_choice.startswith("acceleration: pre-entry m_el steady")
            assert auto.inertia_kgm2 == joint.inertia_kgm2 and auto.ci95_kgm2 == joint.ci95_kgm2


def test_an_early_entry_or_a_late_recontact_does_not_bias_j1(clean):
    """The in-zone set comes from the dynamics: samples before the zone (the coupling still unloading) and a
    contact sample after it are dropped.  Without the trimming the same windows are off by far more."""
    for w, tr in clean[:4]:
        d = w.as_dict()
        torque = d["m_el"] - tr["bearing_friction_nms"] * d["omega1"]
        acc = d["a1"] / w.wheel_radius_m
        e, g = w.entry_index, w.recontact_index
        j1 = tr["inertia_kgm2"]
        exact = gap_only_fit(torque, acc, e, g)
        assert (exact["start"], exact["end"]) == (e, g)
        moved = gap_only_fit(torque, acc, e - 3, g + 2)
        assert (moved["start"], moved["end"]) == (e, g), tr["name"]
        assert abs(moved["j1"] / j1 - 1) < 1e-4
        blind = gap_only_fit(torque, acc, e - 3, g + 2, max_trim=(0, 0))
        assert abs(blind["j1"] / j1 - 1) > 3e-3, tr["name"]          # measured 0.46-2 %


def test_entry_one_or_two_samples_early_at_30_db(noisy):
    """At 30 dB the detector's entry is 1-2 samples early.  The fit drops what the dynamics show to be out
    of the zone; a sample it keeps carries a load torque within its noise (<= 3 sigma: up to ~0.3 % of J1 over
    a 30-sample gap, within the interval), and J1 stays within 1 %."""
    for w, tr in noisy:
        g = _fit(w, tr)
        true_entry = w.entry_index + int(round((tr["entry_time_s"] - w.entry_time_s) / tr["sample_period_s"]))
        assert (g.gap_start, g.gap_end) == (w.entry_index, w.recontact_index)    # the detector's interval
        assert w.entry_index <= g.fit_start and true_entry - 2 <= g.fit_start <= true_entry + 1, (tr["name"],
                                                                                                   g.fit_start)
        assert abs(g.inertia_kgm2 / tr["inertia_kgm2"] - 1) < 0.01


def test_deming_slope_is_unbiased_when_the_regressor_is_noisy():
    """Errors in both variables: the least-squares slope of y on a noisy x is attenuated, the Deming slope
    through the origin with the right noise ratio is not."""
    rng = np.random.default_rng(1)
    x_true = np.full(4000, 1.0)
    y = 2.0 * x_true + 0.3 * rng.standard_normal(x_true.size)
    x = x_true + 0.5 * rng.standard_normal(x_true.size)
    ols = _origin_slope(y, x, 0.3, 0.0)
    dem = _origin_slope(y, x, 0.3, 0.5)
    assert ols < 1.7                        # 2 / (1 + 0.25) = 1.6
    assert dem == pytest.approx(2.0, rel=0.03)


def test_gap_only_interval_coverage_on_synthetic_windows():
    """A single mass driven by a swinging torque (no steady pre-entry stretch), white noise on both m_el and
    a1: the 95 % interval covers J1 in 90-99.5 % of 300 windows."""
    j1, n_pre, n_gap, n_post = 1.1, 48, 40, 30
    n = n_pre + n_gap + n_post
    k = np.arange(n)
    torque = -450.0 - 40.0 * np.cos(k / 9.0)
    acc = torque / j1
    acc[n_pre + n_gap:] = 300.0                       # contact: the load torque takes over
    acc[:n_pre] = 0.2 * acc[:n_pre]
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(300):
        g = gap_only_fit(torque + 6.0 * rng.standard_normal(n), acc + 3.0 * rng.standard_normal(n),
                         n_pre, n_pre + n_gap)
        hits += abs(g["j1"] - j1) <= 1.99 * g["se"]   # t(39) 97.5 % quantile ~ 2.02
    assert 0.90 <= hits / 300 <= 0.995, hits / 300


def test_steadiness_test_edges():
    assert pre_entry_steady(np.full(48, 221.0)).steady                          # noise-free constant
    assert not pre_entry_steady(np.r_[np.full(40, 221.0), np.linspace(200.0, -400.0, 8)]).steady
    short = pre_entry_steady(np.full(4, 221.0))
    assert not short.steady and "too few" in short.reason
    rng = np.random.default_rng(3)
    rejected = sum(not pre_entry_steady(221.0 + 5.0 * rng.standard_normal(48)).steady for _ in range(2000))
    assert rejected <= 10                              # nominal false rejection 0.1 % (2 of 2000)
    with pytest.raises(NoGapError):
        gap_only_fit(np.zeros(80), np.zeros(80), 48, 60)
