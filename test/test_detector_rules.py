"""The streaming detector's documented rules on hand-built streams (docs/interfaces.md "The detector",
detector.py docstrings).

A tiny detector makes every window checkable by eye: K2 = 0.5 m, r = 1 m (K2/r = 0.5 rad exactly), T_s = 1 s
(t = 0, 1, 2, ... exact in binary), 3 samples before the entry and 4 from it (7-sample windows); the streams carry
t, alpha1 and alpha2 = 0, so |alpha1 - alpha2| is the alpha1 column.  Rules tested:

* inequality (1) is strict; an entry is an inside sample right after an outside one; the first sample of a
  stream, or after a reset, cannot be an entry; the window is the 3 samples before, the entry and 3 more;
* no entry is looked for while a window is captured, and detection resumes at once after it;
* an entry with too little history is a ``short_history`` drop and its samples are skipped;
* stamp checks (out of order, repeated, gap above 1.5 T_s, step below T_s/2) at their exact limits, within and
  between batches, the earliest problem reported; every drop counted, ``empty`` kept apart;
* a change of K2 is never an entry by itself; a window keeps the K2 it started with;
* the result does not depend on how the stream is cut into batches.
Pure numpy, milliseconds.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from jident_ros.stream.detector import REASONS, BacklashDetector, embed_windows, stream_batches
from jident_ros.stream.layout import pack

CH = ("t", "alpha1", "alpha2")
OUT, IN = 0.9, 0.1           # |alpha1 - alpha2| outside / inside the zone (K2/r = 0.5)


def det(**kw):
    args = dict(backlash_width_m=0.5, wheel_radius_m=1.0, sample_period_s=1.0, channels=CH,
                samples_before_entry=3, samples_from_entry=4)
    args.update(kw)
    return BacklashDetector(**args)


def stream(rel, t0=0.0):
    rel = np.asarray(rel, float)
    return np.column_stack([t0 + np.arange(rel.size), rel, np.zeros(rel.size)])


def feed(d, data, batch=None):
    batch = batch or max(len(data), 1)
    return [e for b in stream_batches(data, batch) for e in d.push(b, CH)]


def windows(events):
    return [e.window for e in events if e.kind == "window"]


def entry_rows(events):
    return [int(w.entry_time_s) for w in windows(events)]


# --------------------------------------------------------------------------- entries
@pytest.mark.parametrize("batch", [1, 2, 3, 5, 100])
def test_first_sample_of_a_stream_is_not_an_entry(batch):
    """The stream starts inside the zone: the first entry is where it comes back in after leaving."""
    rel = [IN, IN, OUT, OUT, OUT, IN, IN, OUT, IN, OUT, OUT, OUT]
    d = det()
    ev = feed(d, stream(rel), batch)
    (w,) = windows(ev)
    assert w.entry_time_s == 5.0 and w.entry_index == 3 and len(w) == 7
    np.testing.assert_array_equal(w.column("t"), np.arange(2.0, 9.0))     # 3 before, the entry, 3 after
    np.testing.assert_array_equal(w.column("alpha1"), rel[2:9])
    assert w.channels == CH and w.window_id == 1
    assert (w.backlash_width_m, w.wheel_radius_m, w.sample_period_s) == (0.5, 1.0, 1.0)
    assert d.dropped_total == 0 and d.windows_captured == 1


def test_first_sample_after_a_reset_is_not_an_entry():
    d = det()
    assert feed(d, stream([OUT, OUT, OUT, OUT])) == []
    bad = stream([OUT, np.nan], t0=4.0)
    (drop,) = feed(d, bad)
    assert drop.kind == "drop" and drop.reason == "nonfinite"
    # continuity lost: the next batch starts inside, which is not an entry although the last good sample was out
    assert feed(d, stream([IN, IN, IN, IN, IN], t0=6.0)) == []
    ev = feed(d, stream([OUT, OUT, OUT, IN, IN, IN, IN], t0=11.0))
    assert entry_rows(ev) == [14]


def test_inequality_1_is_strict():
    """|alpha1 - alpha2| = K2/r exactly is outside the zone."""
    d = det()
    ev = feed(d, stream([OUT, OUT, 0.5, 0.5, 0.49, 0.5, 0.4, 0.5, 0.9, 0.9]))
    assert entry_rows(ev) == [4]
    assert d.threshold_rad == 0.5
    # with alpha2 moving too: the difference counts, in absolute value
    data = stream([0.0] * 8)
    data[:, 1] = [5.0, 5.0, 5.0, 5.0, 4.6, 4.0, 3.0, 2.0]
    data[:, 2] = [4.0, 4.0, 4.0, 4.0, 5.0, 4.2, 3.0, 2.0]
    assert entry_rows(feed(det(), data)) == [4]


def test_no_entry_while_capturing_and_detection_resumes_at_once():
    # entry at 3; its window is samples 0..6; the bounce back in at 5 is part of it; sample 6 (the last of the
    # window) is outside, sample 7 inside: an entry right after the window
    rel = [OUT, OUT, OUT, IN, OUT, IN, OUT, IN, IN, IN, IN, OUT]
    ev = feed(det(), stream(rel))
    assert entry_rows(ev) == [3, 7]
    w1, w2 = windows(ev)
    np.testing.assert_array_equal(w2.column("t"), np.arange(4.0, 11.0))    # history = the last window's samples
    assert (w1.window_id, w2.window_id) == (1, 2)
    # the window's last sample inside and the next one inside too: no entry
    rel = [OUT, OUT, OUT, IN, OUT, OUT, IN, IN, IN, OUT, OUT, OUT]
    assert entry_rows(feed(det(), stream(rel), 4)) == [3]


def test_entry_without_enough_history_is_dropped_and_its_samples_skipped():
    d = det()
    # entry at sample 1 with 1 history sample of 3; samples 1..4 belong to it (the bounce at 3 is not an entry);
    # the next entry at 6 has its 3 history samples
    rel = [OUT, IN, OUT, IN, OUT, OUT, IN, IN, IN, IN, OUT]
    ev = feed(d, stream(rel), 2)
    assert [e.kind for e in ev] == ["drop", "window"]
    assert ev[0].reason == "short_history" and "1 of 3" in ev[0].detail
    assert ev[0].window_dropped is False                          # no window was in progress
    assert entry_rows(ev) == [6]
    assert d.counts["short_history"] == 1 and d.dropped_total == 1 and d.windows_captured == 1
    # exactly enough history: captured
    assert entry_rows(feed(det(), stream([OUT, OUT, OUT, IN, IN, IN, IN]))) == [3]
    # one sample short
    ev = feed(det(), stream([OUT, OUT, IN, IN, IN, IN, IN, IN]))
    assert [e.reason for e in ev] == ["short_history"]


def test_window_length_is_before_plus_from_entry():
    d = det(samples_before_entry=1, samples_from_entry=2)
    assert d.window_length == 3
    (w,) = windows(feed(d, stream([OUT, IN, IN, IN])))
    np.testing.assert_array_equal(w.column("t"), [0.0, 1.0, 2.0])
    assert w.entry_index == 1


@pytest.mark.parametrize("batch", [1, 2, 3, 4, 7, 50])
def test_batching_does_not_change_the_windows(batch):
    rng = np.random.default_rng(2)
    rel = np.where(rng.random(60) < 0.5, IN, OUT)
    ref = feed(det(), stream(rel))
    got = feed(det(), stream(rel), batch)
    assert [e.kind for e in got] == [e.kind for e in ref] and len(windows(ref)) >= 3
    for a, b in zip(windows(got), windows(ref)):
        np.testing.assert_array_equal(a.data, b.data)


# --------------------------------------------------------------------------- K2 changes
def test_a_width_change_alone_is_not_an_entry():
    d = det()
    assert feed(d, stream([0.7, 0.7, 0.7, 0.7])) == []
    d.set_backlash_width(0.8)                        # the last sample (0.7) is now inside: no entry follows
    assert feed(d, stream([0.7, 0.7], t0=4.0)) == []
    d.set_backlash_width(0.5)                        # outside again
    ev = feed(d, stream([0.4, 0.4, 0.4, 0.4], t0=6.0))
    assert entry_rows(ev) == [6] and windows(ev)[0].backlash_width_m == 0.5
    with pytest.raises(ValueError, match="backlash_width_m"):
        d.set_backlash_width(-1.0)


def test_a_window_keeps_the_width_it_started_with():
    d = det()
    feed(d, stream([OUT, OUT, OUT, IN, IN]))
    assert d.capturing
    d.set_backlash_width(0.95)
    (w,) = windows(feed(d, stream([IN, IN], t0=5.0)))
    assert w.backlash_width_m == 0.5 and d.backlash_width_m == 0.95 and not d.capturing


# --------------------------------------------------------------------------- stamps and drops
@pytest.mark.parametrize("step, reason", [(1.5, None), (1.5000001, "gap"), (0.5, None), (0.4999999, "irregular_stamp"),
                                          (0.0, "repeated_stamp"), (-0.5, "out_of_order")])
def test_stamp_checks_at_their_limits(step, reason):
    for where in ("inside", "between"):
        d = det()
        t = np.array([0.0, 1.0, 2.0, 2.0 + step, 3.0 + step])
        data = np.column_stack([t, np.full(5, OUT), np.zeros(5)])
        ev = d.push(data, CH) if where == "inside" else d.push(data[:3], CH) + d.push(data[3:], CH)
        if reason is None:
            assert ev == [] and d.dropped_total == 0
        else:
            (e,) = ev
            assert e.reason == reason and d.counts[reason] == 1 and d.dropped_total == 1
            assert ("between batches" if where == "between" else "inside the batch") in e.detail


def test_gap_tolerance_parameter():
    d = det(gap_tolerance=3.0)
    data = stream([OUT] * 4)
    data[2:, 0] += 2.0                          # a step of 3 T_s: not above 3
    assert d.push(data, CH) == []
    data = stream([OUT] * 4)
    data[2:, 0] += 2.01
    assert [e.reason for e in det(gap_tolerance=3.0).push(data, CH)] == ["gap"]


def test_the_earliest_problem_of_a_batch_is_reported():
    t = np.array([0.0, 1.0, 1.0, 5.0, 4.0])     # repeated at 1->2, gap at 2->3, out of order at 3->4
    (e,) = det().push(np.column_stack([t, np.full(5, OUT), np.zeros(5)]), CH)
    assert e.reason == "repeated_stamp"
    t = np.array([0.0, 1.0, 0.5, 0.5])
    (e,) = det().push(np.column_stack([t, np.full(4, OUT), np.zeros(4)]), CH)
    assert e.reason == "out_of_order"


def test_a_drop_loses_the_window_in_progress_and_an_empty_batch_does_not():
    d = det()
    feed(d, stream([OUT, OUT, OUT, IN, IN]))
    (e,) = d.push(np.empty((0, 3)), CH)
    assert e.reason == "empty" and e.window_dropped is False and d.capturing
    assert d.counts["empty"] == 1 and d.dropped_total == 0
    (w,) = windows(feed(d, stream([IN, IN], t0=5.0)))              # completed
    feed(d, stream([OUT, OUT, IN, IN], t0=7.0))
    assert d.capturing
    (e,) = d.push(stream([OUT], t0=20.0), CH)                         # a gap: the window is lost
    assert e.reason == "gap" and e.window_dropped is True and not d.capturing
    assert d.last_event is e and d.dropped_total == 1
    assert d.push(stream([OUT], t0=22.0), CH) == []                    # afresh after the reset: no stamp check
    (e,) = d.push(np.array([[23.0, np.nan, 0.0]]), CH)
    assert e.reason == "nonfinite" and e.window_dropped is False      # nothing in progress to lose
    assert d.reject("layout").window_dropped is False
    assert d.windows_lost == {"gap": 1}                                # the lost window, counted by reason
    assert d.counts["layout"] == 1 and d.dropped_total == 3


def test_a_window_cut_off_by_the_end_of_the_data_is_a_counted_drop():
    """finish(): a window in progress is reported as 'cut_off' (counted once, window_dropped), carrying the partial
    window unnumbered (window_id 0: not a captured window); with nothing in progress finish() reports nothing."""
    d = det()
    feed(d, stream([OUT, OUT, OUT, IN, IN]))
    assert d.capturing
    (e,) = d.finish()
    assert e.kind == "drop" and e.reason == "cut_off" and e.window_dropped is True and d.last_event is e
    assert d.counts["cut_off"] == 1 and d.dropped_total == 1 and d.windows_captured == 0
    assert e.window.window_id == 0 and e.window.data.shape[0] == 5 and not d.capturing
    assert "2 of 4 samples from the entry" in e.detail
    assert d.finish() == [] and d.counts["cut_off"] == 1


def test_reject_needs_a_known_reason():
    d = det()
    with pytest.raises(ValueError, match="reason"):
        d.reject("because")
    e = d.reject("layout")
    assert e.detail == REASONS["layout"] and d.counts["layout"] == 1


@pytest.mark.parametrize("array, names, reason, detail", [
    (np.zeros(3), CH, "layout", "2-D"),
    (np.zeros((2, 2)), CH, "layout", "2 columns but 3"),
    (np.zeros((2, 3)), ("t", "alpha1", "alpha1"), "layout", "repeated"),
    (np.zeros((2, 3), dtype=complex), CH, "layout", "real numbers"),
    (np.array([["a", "b", "c"]]), CH, "layout", "real numbers"),
    (np.zeros((2, 3)), ("t", "alpha1", "torque"), "unknown_channel", "'torque'"),
    (np.zeros((2, 3)), ("t", "alpha1", "a1"), "missing_channel", "'alpha2'"),
    (np.array([[0.0, 1.0, 0.0], [1.0, 1.0, np.inf]]), CH, "nonfinite", "'alpha2' at sample 1"),
    ("not an array", CH, "layout", ""),
])
def test_bad_batches_are_drops_with_a_reason(array, names, reason, detail):
    d = det()
    (e,) = d.push(array, names)
    assert e.kind == "drop" and e.reason == reason and detail in e.detail
    assert d.counts[reason] == 1 and d.batches_seen == 1 and d.samples_seen == 0


def test_counters():
    d = det()
    feed(d, stream([OUT, OUT, OUT, IN, IN, IN, IN, OUT]), 3)
    assert (d.batches_seen, d.samples_seen, d.windows_captured) == (3, 8, 1)
    d.push(np.empty((0, 3)), CH)
    assert (d.batches_seen, d.samples_seen) == (4, 8)


def test_push_flat_reads_the_layout_and_a_layout_error_is_a_drop():
    data = stream([OUT, OUT, OUT, IN, IN, IN, IN])
    flat, dims, off = pack(data, CH)
    assert entry_rows(det().push_flat(flat, dims, off)) == [3]
    (e,) = det().push_flat(flat[:-1], dims, off)
    assert e.reason == "layout"


def test_extra_and_reordered_channels_keep_the_configured_order():
    d = det(channels=("alpha2", "t", "alpha1", "m_el"))
    assert d.channels == ("t", "alpha2", "alpha1", "m_el")
    data = stream([OUT, OUT, OUT, IN, IN, IN, IN])
    extra = np.column_stack([data[:, 1], np.arange(7.0), data[:, 2], data[:, 0], np.zeros(7)])
    (w,) = windows(d.push(extra, ("alpha1", "m_el", "alpha2", "t", "a1")))
    np.testing.assert_array_equal(w.column("m_el"), np.arange(7.0))
    assert w.channels == ("t", "alpha2", "alpha1", "m_el")


# --------------------------------------------------------------------------- configuration
@pytest.mark.parametrize("kw", [dict(samples_before_entry=1), dict(samples_from_entry=2), dict(gap_tolerance=1.0001),
                                dict(backlash_width_m=1e-9), dict(channels=("t", "alpha1", "alpha2", "clutch_torque"))])
def test_configuration_limits_accepted(kw):
    det(**kw)


@pytest.mark.parametrize("kw, why", [
    (dict(samples_before_entry=0), "samples_before_entry"),
    (dict(samples_before_entry=2.5), "samples_before_entry"),
    (dict(samples_from_entry=1), "samples_from_entry"),
    (dict(samples_from_entry=3.5), "samples_from_entry"),
    (dict(gap_tolerance=1.0), "gap_tolerance"),
    (dict(gap_tolerance=math.inf), "gap_tolerance"),
    (dict(wheel_radius_m=True), "wheel_radius_m"),
    (dict(wheel_radius_m="abc"), "wheel_radius_m"),
    (dict(sample_period_s=-1.0), "sample_period_s"),
    (dict(backlash_width_m=math.nan), "backlash_width_m"),
    (dict(channels=("t", "alpha1", "alpha2", "alpha1")), "repeated"),
    (dict(channels=("t", "alpha2")), "'alpha1'"),
])
def test_bad_configuration_raises_with_the_name(kw, why):
    with pytest.raises(ValueError, match=why):
        det(**kw)


def test_stream_batches_cuts_consecutive_batches():
    data = np.arange(20.0).reshape(10, 2)
    parts = list(stream_batches(data, 3))
    assert [len(p) for p in parts] == [3, 3, 3, 1]
    np.testing.assert_array_equal(np.concatenate(parts), data)
    assert [len(p) for p in stream_batches(data, 1)] == [1] * 10
    with pytest.raises(ValueError, match="batch_size"):
        list(stream_batches(data, 0))


class _Windows:
    """The attributes of a sim.WindowSet that embed_windows reads."""

    def __init__(self, n_cases, n, ts=0.5, entry_index=2):
        self.sample_period_s, self.entry_index = ts, entry_index
        self.t = np.arange(n) * ts
        rng = np.random.default_rng(0)
        self.signals = {c: rng.random((n_cases, n)) for c in ("alpha1", "alpha2", "omega1", "omega2", "a1")}

    def __len__(self):
        return self.signals["a1"].shape[0]


def test_embed_windows_holds_the_first_sample_and_runs_the_clock_on():
    ws = _Windows(2, 5)
    channels = ("t", "alpha1", "alpha2", "a1")
    out, rows = embed_windows(ws, gap_samples=3, start_time_s=1.0, channels=channels)
    assert out.shape == (16, 4) and rows == [5, 13]
    np.testing.assert_array_equal(out[:, 0], 1.0 + 0.5 * np.arange(16))
    for i in range(2):
        block = out[i * 8:(i + 1) * 8]
        np.testing.assert_array_equal(block[3:, 3], ws.signals["a1"][i])
        np.testing.assert_array_equal(block[:3, 3], ws.signals["a1"][i][0])
        for a, w in (("alpha1", "omega1"), ("alpha2", "omega2")):
            col = block[:, channels.index(a)]
            np.testing.assert_allclose(col[:3], ws.signals[a][i][0] + ws.signals[w][i][0] * np.array([-1.5, -1.0, -0.5]))
    out0, rows0 = embed_windows(ws, gap_samples=0, channels=channels)
    assert rows0 == [2, 7] and out0.shape == (10, 4)
    assert out0[0, 0] == 1.0                                          # the drive clock starts at 1 s by default
    with pytest.raises(ValueError, match="gap_samples"):
        embed_windows(ws, gap_samples=-1)
