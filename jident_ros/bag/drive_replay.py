"""A drive recording -> its backlash-entry windows, cut the way the windowing node cuts them.

Shared by ``jident diagnose`` (:mod:`jident_ros.cli.offline`) and ``jident build-patterns
--from-recordings`` (:mod:`jident_ros.cli.calibration`): both read the drive topics of a recording
(docs/interfaces.md), feed ``drive/signals`` batch after batch through the windowing node's own
:class:`~jident_ros.stream.detector.BacklashDetector`, follow ``drive/backlash_width`` when asked, and
look up each window's true J1 in ``drive/case`` / ``drive/true_inertia``.  The callers keep their
own error types and messages (passed in as callables).

The ``drive/signals`` batches are taken in the order of their samples' drive time (the ``t`` column),
not in the order they were received: a recording's receive times are whatever clock its recorder used
(:func:`in_sample_time_order`).  A batch that cannot be read (undecodable, or not in the drive/signals
layout) is dropped and counted as the windowing node does -- also the first one.

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from typing import Any, Callable, Iterator, Optional

import numpy as np

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.messages import deserialize
from jident_ros.bag.reader import in_publish_order, read_bag
from jident_ros.stream.layout import (
    CASE_TOPIC,
    DRIVE_TOPICS,
    KNOWN_CHANNELS,
    SIGNALS_TOPIC,
    TRUE_INERTIA_TOPIC,
    WIDTH_TOPIC,
    LayoutError,
    Window,
    topic_matches,
    unpack,
)


def read_drive_messages(path, error: type, note: Callable[[str], Any] = lambda text: None) -> tuple[list, list]:
    """(the drive-topic messages of a recording as (topic, type, raw CDR) in publish order -- the order the
    drive sent them, :func:`~jident_ros.bag.reader.in_publish_order`; receive order in a bag without publish
    times -- every topic name).  An unreadable or damaged recording raises ``error`` with one line naming the file and the
    problem; a file its recorder never finalised (killed) is read by salvaging it, and ``note`` gets one
    line saying so."""
    kept, seen = [], set()
    try:
        for m in in_publish_order(read_bag(path, raw=True, on_salvage=note)):
            seen.add(m.topic)
            if any(topic_matches(m.topic, rel) for rel in DRIVE_TOPICS):
                kept.append((m.topic, m.msg_type, m.message))
    except RecordingError as exc:
        raise error(f"recording {exc}") from None
    except OSError as exc:
        raise error(f"recording {path}: {exc.strerror or exc}") from None
    return kept, sorted(seen)


def _first_t(msg_type: str, raw, unpacked: Optional[dict] = None) -> Optional[float]:
    """Drive time ``t`` of the first sample of a drive/signals batch, or None (unreadable, empty, no t column).
    With ``unpacked``, a readable batch's (array, channels) is kept there under ``id(raw)``."""
    try:
        msg = deserialize(msg_type, raw)
        arr, channels, _ = unpack(msg.data, msg.layout.dim, msg.layout.data_offset)
    except (ValueError, LayoutError, AttributeError):
        return None
    if unpacked is not None:
        unpacked[id(raw)] = (arr, channels)
    if not arr.shape[0] or "t" not in channels:
        return None
    return float(arr[0, channels.index("t")])


def in_sample_time_order(messages: list, signals_topic: str, unpacked: Optional[dict] = None) -> list:
    """``messages`` ((topic, type, raw) in receive order) with the ``signals_topic`` batches sorted by the
    drive time of their first sample (stable).  Every other message keeps its place before the batch
    that was received after it; an unreadable batch keeps its place after the batch before it.
    ``unpacked``: a dict that receives every readable batch decoded, {id(raw): (array, channels)}, for
    :class:`DriveReplay` (each batch is then decoded once, not twice: a tenth of ``jident trend``'s time)."""
    keys = [None] * len(messages)
    last = float("-inf")
    for i, (topic, msg_type, raw) in enumerate(messages):
        if topic == signals_topic:
            t = _first_t(msg_type, raw, unpacked)
            last = last if t is None else t
            keys[i] = (last, 1)
    following = (float("inf"), 0)
    for i in range(len(messages) - 1, -1, -1):
        if keys[i] is None:
            keys[i] = (following[0], 0)
        else:
            following = keys[i]
    order = sorted(range(len(messages)), key=lambda i: (keys[i], i))
    return [messages[i] for i in order]


class DriveReplay:
    """Replays one drive's recorded topics through a backlash detector.

    Parameters
    ----------
    names : {relative drive topic: its recorded name}, e.g. ``{"drive/signals": "/press3/drive/signals", ...}``
    width : K2 to start with, m
    follow_width : apply every ``drive/backlash_width`` message to the detector (as the windowing node
        with ``backlash_width_from_topic``)
    decode : (topic, type, raw) -> message
    read_width, read_truth : (message, topic) -> float; may raise the caller's error
    make_detector : (channels of the first readable batch, topic, K2) -> BacklashDetector; may raise
    log : gets one-line notes (a drive/case message or a drive/signals batch that could not be read)
    unpacked : {id(raw): (array, channels)} of batches decoded already (:func:`in_sample_time_order`'s);
        each is used once instead of decoding the batch again

    After :meth:`windows`: ``detector`` (None when drive/signals held no readable batch),
    ``widths_used`` (m), ``dropped_before_start`` (reasons of the unreadable batches before the first
    readable one; they are counted in the detector's ``layout`` drops once it exists), ``clock_jumps``
    (times the drive clock jumped forward between two batches while no window was being
    captured: a recording that resumes after a pause, e.g. one transient an hour; the detector's history
    restarts there, so the first batch after the jump is kept and cannot fake an entry; a jump inside a
    window is left to the detector, which drops that window as a ``gap``).
    """

    def __init__(self, names: dict, width: float, follow_width: bool, *, decode: Callable,
                 read_width: Callable, read_truth: Callable, make_detector: Callable,
                 log: Callable[[str], Any] = lambda text: None, unpacked: Optional[dict] = None):
        self.names = names
        self.width = float(width)
        self.follow_width = follow_width
        self.decode, self.read_width, self.read_truth = decode, read_width, read_truth
        self.make_detector, self.log = make_detector, log
        self.unpacked = unpacked if unpacked is not None else {}
        self.dropped_before_start: list = []
        self.detector = None
        self.widths_used = [self.width]
        self.cases: list = []   # (entry_time_s, J1) rows of drive/case
        self.truth: list = []   # (t of the first sample after the message, J1) from drive/true_inertia
        self.clock_jumps = 0
        self._last_t: Optional[float] = None

    def windows(self, messages) -> Iterator[Window]:
        """Every window the detector captures from ``messages`` ((topic, type, raw) in receive order).

        Consecutive drive/signals batches (same channels, nothing else in between) are pushed to the
        detector as one array when they are clean (finite, known channels, every step of t within
        [T_s/2, gap_tolerance T_s]): the detector's result does not depend on how the stream is cut
        into batches, and its per-batch cost (~0.1 ms) dominated long recordings.  Any other run is
        pushed batch by batch, so drops are counted exactly as the windowing node counts them."""
        names = self.names
        pending_truth = None
        run: list = []                  # clean-looking decoded batches not yet pushed: (array, channels)
        for topic, msg_type, raw in messages:
            if topic != names[SIGNALS_TOPIC]:
                yield from self._windows_of(self._push_run(run))
                run = []
            if topic == names[WIDTH_TOPIC]:
                if self.follow_width:
                    w = self.read_width(self.decode(topic, msg_type, raw), topic)
                    if self.detector is not None and w != self.detector.backlash_width_m:
                        self.detector.set_backlash_width(w)
                    self.width = w
                    if w not in self.widths_used:
                        self.widths_used.append(w)
                continue
            if topic == names[TRUE_INERTIA_TOPIC]:
                pending_truth = self.read_truth(self.decode(topic, msg_type, raw), topic)
                continue
            if topic == names[CASE_TOPIC]:
                msg = self.decode(topic, msg_type, raw)
                try:
                    rows, cols, _ = unpack(msg.data, msg.layout.dim, msg.layout.data_offset)
                except LayoutError as exc:
                    self.log(f"{topic}: message skipped: {exc}")
                    continue
                if "inertia_kgm2" in cols and "entry_time_s" in cols:
                    for row in rows:
                        self.cases.append((float(row[cols.index("entry_time_s")]),
                                           float(row[cols.index("inertia_kgm2")])))
                continue
            try:
                hit = self.unpacked.pop(id(raw), None)     # decoded already by in_sample_time_order
                if hit is not None:
                    arr, channels = hit
                else:
                    msg = self.decode(topic, msg_type, raw)
                    arr, channels, _ = unpack(msg.data, msg.layout.dim, msg.layout.data_offset)
            except Exception as exc:  # undecodable CDR (the caller's error) or LayoutError: drop the batch
                arr, channels, layout_error = None, None, str(exc)
                self.log(f"{topic}: batch dropped (layout): {layout_error}")
            if self.detector is None:
                if arr is None:
                    self.dropped_before_start.append(layout_error)
                    continue
                self.detector = self.make_detector(channels, topic, self.width)
                for reason in self.dropped_before_start:
                    self.detector.reject("layout", reason)
            if arr is None:
                yield from self._windows_of(self._push_run(run))
                run = []
                yield from self._windows_of([self.detector.reject("layout", layout_error)])
                continue
            if pending_truth is not None and arr.shape[0] and "t" in channels:
                self.truth.append((float(arr[0, channels.index("t")]), pending_truth))
                pending_truth = None
            if run and (tuple(channels) != tuple(run[0][1]) or not arr.shape[0] or
                        sum(a.shape[0] for a, _ in run) >= self.MAX_RUN_SAMPLES):
                yield from self._windows_of(self._push_run(run))
                run = []
            run.append((arr, channels))
        yield from self._windows_of(self._push_run(run))

    #: longest run of batches pushed as one array, samples
    MAX_RUN_SAMPLES = 50_000

    @staticmethod
    def _windows_of(events) -> Iterator[Window]:
        for ev in events:
            if ev.kind == "window":
                yield ev.window

    def _clean_run(self, arr, channels) -> bool:
        """True when pushing ``arr`` (several batches joined) cannot produce a drop."""
        d = self.detector
        if "t" not in channels or any(c not in KNOWN_CHANNELS for c in channels) or \
                any(c not in channels for c in d.channels) or not np.isfinite(arr).all():
            return False
        dt = np.diff(arr[:, list(channels).index("t")])
        ts = d.sample_period_s
        return bool(np.all(dt >= 0.5 * ts) and np.all(dt <= d.gap_tolerance * ts))

    def _push_run(self, run) -> list:
        if not run:
            return []
        if len(run) > 1:
            arr = np.concatenate([a for a, _ in run])
            if self._clean_run(arr, run[0][1]):
                events = self._push(arr, run[0][1])
                self.detector.batches_seen += len(run) - 1     # count the recorded batches
                return events
        events = []
        for a, ch in run:
            events += self._push(a, ch)
        return events

    def _push(self, arr, channels) -> list:
        t_col = channels.index("t") if arr.shape[0] and "t" in channels else None
        if t_col is not None:
            self._resume_after_jump(float(arr[0, t_col]))
        events = self.detector.push(arr, channels)
        if any(ev.kind == "drop" and ev.reason not in ("empty", "short_history") for ev in events):
            self._last_t = None          # the detector was reset
        elif t_col is not None:
            self._last_t = float(arr[-1, t_col])
        return events

    def _resume_after_jump(self, t_first: float) -> None:
        """A forward jump of the drive clock between batches, outside a window: restart the detector's
        history (counted in ``clock_jumps``) instead of letting it drop the batch as a ``gap``."""
        d = self.detector
        if self._last_t is not None and t_first - self._last_t > d.gap_tolerance * d.sample_period_s \
                and not d.capturing:
            d.reset()
            self.clock_jumps += 1

    def true_inertia(self, entry_time_s: float, sample_period_s: float) -> tuple[Optional[float], str]:
        """(J1 in kg m^2, the topic it came from) of the window entering the zone at ``entry_time_s``:
        the drive/case row with that entry time (within T_s/2), else the last drive/true_inertia
        received before it; (None, "") when the recording has neither."""
        for t_case, j in self.cases:
            if abs(t_case - entry_time_s) <= 0.5 * sample_period_s:
                return j, self.names[CASE_TOPIC]
        best = None
        for t_from, j in self.truth:
            if t_from <= entry_time_s + 0.5 * sample_period_s:
                best = j
        return (best, self.names[TRUE_INERTIA_TOPIC]) if best is not None else (None, "")
