"""Raw-encoder inputs of the entry detectors (issue 20 item 4, issue 24's spike): wrapped positions, encoder
spikes, same-flank torque changes, a missing K2, the default detector on drive/signals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector
from jident_ros.stream.detector import BacklashDetector, stream_batches
from jident_ros.stream.flank import FlankDetector


@pytest.fixture(scope="module")
def system():
    return load_system_config()


def wrap(x):
    """A continuous joint's position as ROS reports it, in [-pi, pi)."""
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi


def _wrapped(rec):
    data = rec.data.copy()
    for c in ("alpha1", "alpha2"):
        j = rec.channels.index(c)
        data[:, j] = wrap(data[:, j])
    return data


@pytest.mark.parametrize("batch_size", [50, 1, 7])
def test_wrapped_positions_give_the_windows_of_the_unwrapped_ones(system, batch_size):
    """Every entry found on wrapped positions, at the same sample, with the same K2 (batch size 1: a wrap at
    every batch boundary); the windows carry the unwrapped angles (whole turns apart from the raw ones)."""
    recs = raw_recordings(system, (1.16, 0.957), (0.0025, 0.01), steady_s=0.5, seed=3)
    for rec in recs:
        ref = [e.window for e in run_detector(flank_detector(system), rec, batch_size) if e.kind == "window"]
        det = flank_detector(system)
        evs = []
        for b in stream_batches(_wrapped(rec), batch_size):
            evs += det.push(b, rec.channels)
        got = [e.window for e in evs + det.finish() if e.kind == "window"]
        assert det.wraps_undone > 10
        assert len(got) == len(ref) == 1
        assert got[0].entry_time_s == ref[0].entry_time_s == rec.data[rec.entry_row, 0]
        assert got[0].backlash_width_estimate_m == pytest.approx(ref[0].backlash_width_estimate_m, rel=1e-9)
        for c in ("alpha1", "alpha2"):
            turns = (got[0].column(c) - ref[0].column(c)) / (2 * math.pi)
            np.testing.assert_allclose(turns, np.round(turns[0]), atol=1e-9)   # one whole-turn shift, no jump


def test_without_unwrapping_wrapped_positions_are_not_found(system):
    """The test above depends on the unwrapping (wrapped positions and unwrap_angles off: not every entry)."""
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.5, seed=3)[0]
    s = system.sampling
    det = FlankDetector(system.load.wheel_radius_m, s.sample_period_s, unwrap_angles=False,
                        nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2, encoder_counts_per_rev=65536)
    evs = []
    for b in stream_batches(_wrapped(rec), 50):
        evs += det.push(b, rec.channels)
    wins = [e.window for e in evs if e.kind == "window"]
    assert [w.entry_time_s for w in wins] != [rec.data[rec.entry_row, 0]]


def test_unwrap_continues_across_batches_and_restarts_after_a_reset():
    ts, w = 5e-4, 400.0
    t = 1.0 + np.arange(3000) * ts
    a = 0.3 + w * (t - 1.0)
    data = np.column_stack([t, wrap(a), wrap(0.2 * a)])
    det = BacklashDetector(0.005, 0.1, ts, channels=("t", "alpha1", "alpha2"))
    x, problem = det._validate(data[:1000], ("t", "alpha1", "alpha2"))
    y, _ = det._validate(data[1000:1001], ("t", "alpha1", "alpha2"))     # the next sample alone
    assert problem is None
    np.testing.assert_allclose(x[:, 1], a[:1000], atol=1e-9)
    np.testing.assert_allclose(y[:, 1], a[1000:1001], atol=1e-9)
    np.testing.assert_allclose(x[:, 2], 0.2 * a[:1000], atol=1e-9)
    det.reset()                                                         # continuity lost: start again
    z, _ = det._validate(data[2000:2010], ("t", "alpha1", "alpha2"))
    np.testing.assert_allclose(z[0, 1], wrap(a[2000]), atol=1e-9)
