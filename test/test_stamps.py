"""The stream's time base (jident_ros/stream/stamps.py): stamps as the sampling instants, or only the stamping's
jitter.  A motor turning at 100 rad/s, 2 kHz, a 2^16 encoder."""
import math

import numpy as np
import pytest

from jident_ros.stream.inputs import JointStateAdapter
from jident_ros.stream.stamps import DECIDE_ROWS, StampGrid

TS = 5e-4
Q = 2 * math.pi / 65536


def _angle(t):
    return 100.0 * t + 40.0 * t * t           # rad: 100 rad/s, accelerating at 80 rad/s^2


def _rows(n, jitter_s, instants, seed=1):
    k = np.arange(n) * TS
    e = np.clip(np.random.default_rng(seed).normal(0.0, jitter_s, n), -3 * jitter_s, 3 * jitter_s)
    taken = k + e if instants else k          # when the encoder was read
    stamps = k + e + 1.0                      # what the stamps say
    a = np.floor(_angle(taken) / Q) * Q
    return np.column_stack([stamps, a, np.full(n, 5.0)])


def _feed(grid, x, block=50):
    out = [grid.feed(x[i:i + block]) for i in range(0, x.shape[0], block)]
    assert all(o.shape[0] for o in out)                                        # nothing held back
    return np.concatenate(out)


def test_stamps_that_are_the_instants_put_the_rows_on_the_grid():
    x = _rows(2000, 25e-6, instants=True)
    g = StampGrid(TS, 1)
    y = _feed(g, x)
    assert g.mode == "stamps" and g.ratio < 0.1 and g.jitter_rms_s == pytest.approx(25e-6, rel=0.1)
    k = DECIDE_ROWS                                                             # the block that decided goes through
    assert np.array_equal(y[:k], x[:k]) and np.allclose(np.diff(y[k - 1:, 0]), TS)   # then on the grid
    assert y.shape[0] >= x.shape[0] - 2 and g.resampled == y.shape[0] - k
    err = y[k:, 1] - _angle(y[k:, 0] - 1.0)
    assert np.max(np.abs(err)) < 3 * Q                                     # the angle where it was
    assert np.max(np.abs(x[:, 1] - _angle(np.arange(x.shape[0]) * TS))) > 20 * Q   # on the index: 26 counts off
    assert np.all(y[:, 2] == 5.0)                                               # a constant stays constant


def test_stamps_jittered_alone_leave_the_rows_as_they_are():
    x = _rows(2000, 50e-6, instants=False)
    g = StampGrid(TS, 1)
    y = _feed(g, x)
    assert g.mode == "index" and g.ratio > 10 and g.resampled == 0
    assert np.array_equal(y, x)


def test_stamps_on_their_grid_and_a_drive_at_rest_go_through():
    x = _rows(2000, 0.0, instants=True)
    g = StampGrid(TS, 1)
    assert np.array_equal(_feed(g, x), x) and g.mode == "index" and math.isnan(g.ratio)
    rest = _rows(2000, 50e-6, instants=True)
    rest[:, 1] = 0.3                                                            # at rest: nothing tells
    g = StampGrid(TS, 1)
    assert np.array_equal(_feed(g, rest), rest) and g.mode == "undecided"


def test_a_gap_is_not_bridged_and_out_of_order_stamps_go_through():
    x = _rows(2000, 25e-6, instants=True)
    x = np.delete(x, np.s_[1000:1003], axis=0)                                  # 3 samples lost
    g = StampGrid(TS, 1)
    y = _feed(g, x)
    steps = np.diff(y[:, 0])
    assert g.mode == "stamps" and np.sum(steps > 1.5 * TS) == 1                # the gap is still there
    x2 = _rows(2000, 25e-6, instants=True)
    x2[1500, 0] = x2[1499, 0]                                                   # a repeated stamp
    y2 = _feed(StampGrid(TS, 1), x2)
    assert np.sum(np.diff(y2[:, 0]) <= 0) == 1                                  # the detector's to count
    x3 = _rows(2000, 25e-6, instants=True)
    x3[1500:, 0] -= 0.5                                                         # the clock set back 0.5 s
    g3 = StampGrid(TS, 1)
    y3 = _feed(g3, x3)
    steps = np.diff(y3[:, 0])
    assert np.sum(steps < 0) == 1 and np.allclose(steps[steps > 0][-400:], TS)  # one jump, then the grid again
    assert y3.shape[0] >= 1995


def test_the_jointstate_adapter_resamples_and_says_so():
    x = _rows(3 * DECIDE_ROWS, 50e-6, instants=True)
    ad = JointStateAdapter(TS, batch_size=50, channels=("alpha1", "m_el"))
    out = []
    for t, a, m in x:
        out += ad.push(t, ["motor", "load"], [a, 0.0], [], [m, 0.0])
    out += ad.flush()
    y = np.concatenate([b for b, _ in out])
    assert all(b.shape[0] <= 50 for b, _ in out) and np.allclose(np.diff(y[DECIDE_ROWS - 1:, 0]), TS)
    j = ad.jitter()
    assert j["time_base"] == "stamps" and j["rows_resampled"] == y.shape[0] - DECIDE_ROWS


@pytest.mark.parametrize("step, k", [(TS / 2, 2), (TS / 4, 4), (TS, 1), (0.7 * TS, 1), (TS / 2.5, 1)])
def test_a_faster_recording_is_decimated_to_t_s_and_said(step, k):
    """Stamps stepping by T_s/k (k an integer): every k-th row from the first, across batch boundaries (batches of
    7); any other step: nothing decimated (the detector's stamp checks then speak)."""
    n = 700
    x = np.column_stack([1.0 + step * np.arange(n), _angle(step * np.arange(n)), np.arange(n, dtype=float)])
    g = StampGrid(TS, 1)
    y = _feed(g, x, block=7)
    assert g.decimation == k and g.summary()["decimated_by"] == k
    assert np.array_equal(y[:, 2], np.arange(0, n, k))
    assert (f"every {k}nd sample" in g.said() or f"every {k}th sample" in g.said()) if k > 1 else g.said() == ""


def test_the_adapter_decimates_a_4_khz_stream_and_its_period_matches():
    ad = JointStateAdapter(TS, batch_size=50, channels=("alpha1", "m_el"))
    out = []
    for i in range(1000):
        out += ad.push(1.0 + i * TS / 2, ["motor", "load"], [_angle(i * TS / 2), 0.0], [], [float(i), 0.0])
    out += ad.flush()
    y = np.concatenate([b for b, _ in out])
    assert y.shape[0] == 500 and np.allclose(np.diff(y[:, 0]), TS)
    j = ad.jitter()
    assert j["decimated_by"] == 2 and j["period_matches"]
