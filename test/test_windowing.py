"""The streaming backlash-entry detector and the Float64MultiArray layouts (pure numpy, no ROS).

Cost: one simulate_grid call of 3 cases (module-scoped, about 0.5 s); everything else is fast.
"""
from __future__ import annotations

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.sim import CHANNELS, Case, simulate_grid
from jident_ros.stream.detector import REASONS, BacklashDetector, embed_windows, stream_batches
from jident_ros.stream.layout import DEFAULT_CHANNELS, WINDOW_HEADER, LayoutError, Window, pack, unpack

GAP = 300
CASES = [Case(1.16, 0.005, 0.025), Case(1.073, 0.005, 0.0375), Case(1.218, 0.01, 0.0125)]


@pytest.fixture(scope="module")
def system():
    return load_system_config()


@pytest.fixture(scope="module")
def sim(system):
    return simulate_grid(system, CASES)


@pytest.fixture(scope="module")
def stream(sim):
    """Cases 0 and 1 (same width) back to back, 300 steady-state samples before each."""
    sub = type(sim)(sim.t, {k: v[:2] for k, v in sim.signals.items()}, sim.cases[:2], sim.entry_index,
                    sim.sample_period_s, sim.initial_slip[:2])
    return embed_windows(sub, GAP, start_time_s=1.0)


def detector(system, width=0.005, **kw):
    return BacklashDetector(width, system.load.wheel_radius_m, system.sampling.sample_period_s, **kw)


def run(det, data, batch=50, channels=DEFAULT_CHANNELS):
    return [e for b in stream_batches(data, batch) for e in det.push(b, channels)]


def windows_of(events):
    return [e.window for e in events if e.kind == "window"]


def assert_same_window(w: Window, sim, i, stream_rows):
    for c in CHANNELS:
        np.testing.assert_array_equal(w.column(c), sim.signals[c][i], err_msg=c)
    np.testing.assert_array_equal(w.column("t"), stream_rows[:, 0])


# --------------------------------------------------------------------------- detection


def test_entry_at_sample_48_and_the_window_is_the_simulated_one(system, sim, stream):
    data, entry_rows = stream
    events = run(detector(system), data)
    assert [e.kind for e in events] == ["window", "window"]
    for i, (w, row) in enumerate(zip(windows_of(events), entry_rows)):
        assert w.entry_index == 48 and len(w) == 2048 and w.channels == DEFAULT_CHANNELS
        assert row == i * (GAP + 2048) + GAP + 48
        assert w.entry_time_s == data[row, 0]
        assert w.backlash_width_m == 0.005 and w.wheel_radius_m == system.load.wheel_radius_m
        assert w.window_id == i + 1
        assert_same_window(w, sim, i, data[row - 48:row + 2000])
        rel = np.abs(w.column("alpha1") - w.column("alpha2"))
        theta = 0.005 / system.load.wheel_radius_m
        assert rel[47] >= theta > rel[48]  # inequality (1): false before, true at the entry


def test_each_case_with_its_own_width(system, sim):
    for i, case in enumerate(sim.cases):
        one = type(sim)(sim.t, {k: v[i:i + 1] for k, v in sim.signals.items()}, [case], sim.entry_index,
                        sim.sample_period_s, sim.initial_slip[i:i + 1])
        data, (row,) = embed_windows(one, 100, start_time_s=5.0)
        (w,) = windows_of(run(detector(system, case.backlash_width_m), data, batch=64))
        assert_same_window(w, sim, i, data[row - 48:row + 2000])


@pytest.mark.parametrize("batch", [1, 3, 49, 50, 2048, 10**6])
def test_batching_does_not_change_the_windows(system, stream, batch):
    data, _ = stream
    ref = windows_of(run(detector(system), data, batch=len(data)))
    got = windows_of(run(detector(system), data, batch=batch))
    assert len(got) == len(ref) == 2
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a.data, b.data)
        assert (a.entry_time_s, a.entry_index) == (b.entry_time_s, b.entry_index)


def test_random_batch_cuts_do_not_change_the_windows(system, stream):
    data, _ = stream
    ref = windows_of(run(detector(system), data, batch=len(data)))
    rng = np.random.default_rng(4)
    cuts = np.unique(rng.integers(1, len(data), 300))
    det = detector(system)
    events = [e for part in np.split(data, cuts) for e in det.push(part, DEFAULT_CHANNELS)]
    for a, b in zip(windows_of(events), ref):
        np.testing.assert_array_equal(a.data, b.data)
    assert len(windows_of(events)) == 2 and det.dropped_total == 0


def test_channels_in_any_order_and_extra_known_channels(system, stream):
    data, _ = stream
    ref = windows_of(run(detector(system), data))
    perm = list(reversed(range(data.shape[1])))
    names = [DEFAULT_CHANNELS[j] for j in perm] + ["clutch_torque"]
    shuffled = np.column_stack([data[:, perm], np.zeros(len(data))])
    got = windows_of(run(detector(system), shuffled, channels=names))
    assert [w.channels for w in got] == [DEFAULT_CHANNELS] * 2
    for a, b in zip(got, ref):
        np.testing.assert_array_equal(a.data, b.data)


def test_a_subset_of_channels(system, stream):
    data, _ = stream
    want = ("alpha2", "m_el", "t", "alpha1", "a1")
    events = run(detector(system, channels=want), data)
    (w1, w2) = windows_of(events)
    assert w1.channels == ("t", "alpha2", "m_el", "alpha1", "a1")
    np.testing.assert_array_equal(w1.column("m_el"), windows_of(run(detector(system), data))[0].column("m_el"))


def test_no_entry_without_leaving_the_zone_and_width_changes_are_not_entries(system, sim, stream):
    data, entry_rows = stream
    steady = data[:GAP]  # outside the zone at K2 = 0.005 (delta = K2/r + T_c/k_c)
    det = detector(system)
    assert run(det, steady) == []
    det.set_backlash_width(0.01)  # the steady state is now inside the wider zone: no entry
    assert run(det, data[GAP:GAP + 10]) == []
    det.set_backlash_width(0.005)
    events = run(det, data[GAP + 10:])
    assert len(windows_of(events)) == 2


def test_a_width_change_during_a_capture_keeps_the_window_width(system, stream):
    data, entry_rows = stream
    det = detector(system)
    first = run(det, data[:entry_rows[0] + 100])
    det.set_backlash_width(0.004)  # still below the steady-state |alpha1 - alpha2| r = 5.7 mm
    rest = run(det, data[entry_rows[0] + 100:])
    w1, w2 = windows_of(first + rest)
    assert (w1.backlash_width_m, w2.backlash_width_m) == (0.005, 0.004)


# --------------------------------------------------------------------------- layout


def test_pack_unpack_signals_layout(stream):
    data, _ = stream
    flat, dims, off = pack(data[:50], DEFAULT_CHANNELS)
    assert dims == [("sample", 50, 50 * 9), ("t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2", 9, 9)]
    assert off == 0
    arr, names, head = unpack(flat, dims, off)
    np.testing.assert_array_equal(arr, data[:50])
    assert names == DEFAULT_CHANNELS and head.size == 0


def test_window_pack_unpack_round_trip(system, stream):
    data, _ = stream
    w = windows_of(run(detector(system), data))[1]
    flat, dims, off = w.pack()
    assert off == len(WINDOW_HEADER) and dims[0] == ("sample", 2048, 2048 * 9)
    back = Window.unpack(flat, dims, off)
    np.testing.assert_array_equal(back.data, w.data)
    assert (back.channels, back.entry_index, back.entry_time_s, back.backlash_width_m, back.wheel_radius_m,
            back.sample_period_s, back.window_id) == (w.channels, 48, w.entry_time_s, 0.005, 0.1, 5e-4, 2)


@pytest.mark.parametrize("dims, off, n, why", [
    ([("sample", 2, 4)], 0, 4, "2 dimensions"),
    ([("samples", 2, 4), ("t,alpha1", 2, 2)], 0, 4, r"dim\[0\]\.label"),
    ([("sample", 2, 4), ("t,alpha1", 3, 3)], 0, 6, "does not match"),
    ([("sample", 2, 4), ("t,,alpha1", 3, 3)], 0, 6, "comma-separated"),
    ([("sample", 2, 4), ("t,t", 2, 2)], 0, 4, "repeated channel"),
    ([("sample", 2, 2), ("t,alpha1", 2, 2)], 0, 4, "strides"),
    ([("sample", 2, 4), ("t,alpha1", 2, 2)], 0, 5, "expected data_offset"),
    ([("sample", 2, 4), ("t,alpha1", 2, 2)], 1, 4, "expected data_offset"),
])
def test_layout_errors(dims, off, n, why):
    with pytest.raises(LayoutError, match=why):
        unpack(np.zeros(n), dims, off)


def test_window_header_errors(system, stream):
    data, _ = stream
    w = windows_of(run(detector(system), data))[0]
    flat, dims, off = w.pack()
    with pytest.raises(LayoutError, match="header values"):
        Window.unpack(flat[1:], dims, off - 1)
    bad = flat.copy()
    bad[1] = 5000
    with pytest.raises(LayoutError, match="entry_index"):
        Window.unpack(bad, dims, off)


@pytest.mark.parametrize("kw, why", [
    (dict(backlash_width_m=0.0), "backlash_width_m"),
    (dict(backlash_width_m=float("nan")), "backlash_width_m"),
    (dict(wheel_radius_m=-1.0), "wheel_radius_m"),
    (dict(sample_period_s=0.0), "sample_period_s"),
    (dict(channels=("t", "alpha1")), "alpha2"),
    (dict(channels=("t", "alpha1", "alpha2", "torque")), "unknown channel"),
    (dict(samples_before_entry=0), "samples_before_entry"),
    (dict(gap_tolerance=1.0), "gap_tolerance"),
])
def test_bad_detector_configuration_raises_with_the_name(kw, why):
    args = dict(backlash_width_m=0.005, wheel_radius_m=0.1, sample_period_s=5e-4)
    args.update(kw)
    with pytest.raises(ValueError, match=why):
        BacklashDetector(**args)


# --------------------------------------------------------------------------- bad input


def _corrupt(data, entry_rows, kind):
    """The stream cut into 50-sample batches with one bad batch inside the first window's capture.

    Returns a list of (array, channel names) batches.
    """
    bad_at = entry_rows[0] + 500  # the capture of window 1 is in progress
    names = list(DEFAULT_CHANNELS)
    before = [(b, names) for b in stream_batches(data[:bad_at], 50)]
    after = [(b, names) for b in stream_batches(data[bad_at + 50:], 50)]
    b = data[bad_at:bad_at + 50].copy()
    if kind == "nan":
        b[10, names.index("m_el")] = np.nan
        bad = [(b, names)]
    elif kind == "inf":
        b[0, names.index("alpha1")] = np.inf
        bad = [(b, names)]
    elif kind == "out_of_order":
        b[20, 0] = b[19, 0] - 1e-4
        bad = [(b, names)]
    elif kind == "out_of_order_batch":  # an old batch sent again
        bad = [(data[bad_at - 200:bad_at - 150], names)]
        after = [(data[bad_at:bad_at + 50], names)] + after
    elif kind == "repeated_stamp":
        b[5, 0] = b[4, 0]
        bad = [(b, names)]
    elif kind == "repeated_batch_edge":  # the last sample sent again at the head of the next batch
        bad = [(np.vstack([data[bad_at - 1:bad_at], b]), names)]
    elif kind == "gap":
        bad = [(data[bad_at + 3:bad_at + 50], names)]
    elif kind == "irregular_stamp":
        b[7, 0] = b[6, 0] + 1e-5
        bad = [(b, names)]
    elif kind == "missing_channel":
        k = names.index("m_el")
        bad = [(np.delete(b, k, axis=1), names[:k] + names[k + 1:])]
    elif kind == "unknown_channel":
        bad = [(np.column_stack([b, np.ones(len(b))]), names + ["foo"])]
    elif kind == "layout_1d":
        bad = [(b.ravel(), names)]
    elif kind == "layout_names":
        bad = [(b, names[:-1])]
    else:
        raise AssertionError(kind)
    return before + bad + after


@pytest.mark.parametrize("kind, reason", [
    ("nan", "nonfinite"), ("inf", "nonfinite"),
    ("out_of_order", "out_of_order"), ("out_of_order_batch", "out_of_order"),
    ("repeated_stamp", "repeated_stamp"), ("repeated_batch_edge", "repeated_stamp"),
    ("gap", "gap"), ("irregular_stamp", "irregular_stamp"),
    ("missing_channel", "missing_channel"), ("unknown_channel", "unknown_channel"),
    ("layout_1d", "layout"), ("layout_names", "layout"),
])
def test_bad_batch_drops_the_window_and_the_next_one_is_captured(system, sim, stream, kind, reason):
    data, entry_rows = stream
    det = detector(system)
    events = []
    for arr, names in _corrupt(data, entry_rows, kind):
        events += det.push(arr, names)  # never raises
    drops = [e for e in events if e.kind == "drop"]
    assert len(drops) == 1, [(e.reason, e.detail) for e in drops]
    (d,) = drops
    assert d.reason == reason and d.window_dropped and d.detail
    assert det.counts[reason] == 1 and det.dropped_total == 1
    (w,) = windows_of(events)  # window 1 lost, window 2 captured exactly
    row = entry_rows[1]
    assert_same_window(w, sim, 1, data[row - 48:row + 2000])


def test_wrong_layout_message_is_a_drop(system, stream):
    data, entry_rows = stream
    det = detector(system)
    events = run(det, data[:entry_rows[0] + 100])
    ev = det.push_flat(np.zeros(10), [("sample", 5, 10), ("t,alpha1", 2, 2)], 1)
    assert len(ev) == 1 and ev[0].reason == "layout" and ev[0].window_dropped
    assert "data_offset" in ev[0].detail
    events += run(det, data[entry_rows[0] + 100:])
    assert len(windows_of(events)) == 1 and det.counts["layout"] == 1


def test_good_message_through_push_flat(system, stream):
    data, _ = stream
    det = detector(system)
    events = [e for b in stream_batches(data, 100) for e in det.push_flat(*pack(b, DEFAULT_CHANNELS))]
    assert len(windows_of(events)) == 2


def test_empty_batch_is_reported_but_loses_nothing(system, sim, stream):
    data, entry_rows = stream
    det = detector(system)
    events = run(det, data[:entry_rows[0] + 100])
    ev = det.push(np.empty((0, 9)), DEFAULT_CHANNELS)
    assert [(e.kind, e.reason, e.window_dropped) for e in ev] == [("drop", "empty", False)]
    events += run(det, data[entry_rows[0] + 100:])
    assert len(windows_of(events)) == 2 and det.counts["empty"] == 1 and det.dropped_total == 0


def test_entry_without_enough_history(system, sim, stream):
    """Reported once; the bounces of its transient back into the zone are not new entries."""
    data, entry_rows = stream
    det = detector(system)
    events = run(det, data[entry_rows[0] - 10:])
    assert [(e.kind, e.reason) for e in events] == [("drop", "short_history"), ("window", "")]
    row = entry_rows[1]
    assert_same_window(events[1].window, sim, 1, data[row - 48:row + 2000])


def test_every_reason_is_documented():
    import pathlib
    doc = (pathlib.Path(__file__).resolve().parents[1] / "docs" / "interfaces.md").read_text()
    for r in REASONS:
        assert f"`{r}`" in doc, r
