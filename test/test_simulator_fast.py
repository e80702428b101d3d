"""The single-case path of the simulator (issue 23): one case on Python floats equals the vectorised numpy path
to 1e-12 relative on every channel; the .npz writer keeps every array."""
from __future__ import annotations

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.sim import PAPER_SIGNALS, Case, WindowSet, simulate_grid

CFG = load_system_config()
#: nominal; the lightest J1 with the widest zone (longest free run, hardest impact); the heaviest with the
#: narrowest zone at the stiffest film
CASES = [Case(1.16, 0.005, 0.025), Case(0.957, 0.01, 0.05), Case(1.218, 0.0025, 0.0125)]


def assert_same(a: WindowSet, b: WindowSet, rtol: float = 1e-12, scale_of: WindowSet | None = None):
    """Every channel equal to ``rtol`` relative to the channel's largest magnitude in ``scale_of`` (default
    ``b``): a1, a2 and the clutch torque cross zero, so a per-sample relative error means nothing there, and
    without the event a1 and a2 are rounding noise (~1e-5 m/s^2), so their scale is the transient's."""
    assert a.cases == b.cases and a.entry_index == b.entry_index and a.sample_period_s == b.sample_period_s
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.initial_slip, b.initial_slip)
    assert set(a.signals) == set(b.signals)
    for name in a.signals:
        x, y = a.signals[name], b.signals[name]
        assert x.shape == y.shape, name
        scale = np.max(np.abs((scale_of or b).signals[name]), axis=1, keepdims=True)
        err = np.max(np.abs(x - y) / scale)
        assert err <= rtol, f"{name}: max |difference| / max |signal| = {err:.3g}"


def test_one_case_equals_the_vectorised_path():
    fast = simulate_grid(CFG, CASES[:1])
    slow = simulate_grid(CFG, CASES[:1], vectorised=True)
    assert_same(fast, slow)
    # the five signals the paper analyses move (not a trivially equal constant)
    for name in PAPER_SIGNALS:
        assert np.ptp(fast.signals[name][0, fast.entry_index:]) > 0, name


def test_one_case_equals_its_row_of_a_grid():
    """Each case alone (scalar path) against the same case in one vectorised run of all three."""
    grid = simulate_grid(CFG, CASES)
    for i, case in enumerate(CASES):
        one = simulate_grid(CFG, [case])
        row = WindowSet(grid.t, {k: v[i:i + 1] for k, v in grid.signals.items()}, [case], grid.entry_index,
                        grid.sample_period_s, grid.initial_slip[i:i + 1])
        assert_same(one, row)


@pytest.mark.parametrize("kwargs", [dict(event=False), dict(substeps=3, sample_period_s=0.00025)])
def test_one_case_options_follow_the_vectorised_path(kwargs):
    case = CASES[1]
    assert_same(simulate_grid(CFG, [case], **kwargs), simulate_grid(CFG, [case], vectorised=True, **kwargs),
                scale_of=simulate_grid(CFG, [case], **dict(kwargs, event=True)))


def test_the_event_and_the_impact_happen_on_the_single_case_path():
    """Not just equal to the other path: the zone is entered at the entry sample (no clutch torque), and the
    flanks meet again later (torque back)."""
    w = simulate_grid(CFG, [CASES[0]])
    tc = w.signals["clutch_torque"][0]
    k = w.entry_index
    assert tc[k - 1] > 100 and tc[k] == 0.0
    assert np.any(tc[k:] > 100)
    no_event = simulate_grid(CFG, [CASES[0]], event=False).signals["clutch_torque"][0]
    assert np.all(no_event > 100)


def test_single_case_progress_is_called_once_per_sample():
    seen = []
    simulate_grid(CFG, [CASES[0]], progress=lambda k, n: seen.append((k, n)))
    n = CFG.sampling.window_length
    assert seen == [(k, n) for k in range(n)]


def test_npz_keeps_every_array_and_adds_the_suffix(tmp_path):
    w = simulate_grid(CFG, CASES[:2])
    w.save_npz(tmp_path / "w")                       # no suffix: written as w.npz, as np.savez does
    back = WindowSet.load_npz(tmp_path / "w.npz")
    assert back.cases == w.cases and back.entry_index == w.entry_index
    assert back.sample_period_s == w.sample_period_s
    np.testing.assert_array_equal(back.t, w.t)
    np.testing.assert_array_equal(back.initial_slip, w.initial_slip)
    assert set(back.signals) == set(w.signals)
    for name, x in w.signals.items():
        np.testing.assert_array_equal(back.signals[name], x)
