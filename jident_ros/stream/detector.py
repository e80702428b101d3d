"""Streaming backlash-entry detector (pure numpy, never imports rclpy).

The windowing node feeds batches of samples (2-D arrays, one row per sample, columns named) into a
:class:`BacklashDetector`.  It keeps the last 48 samples, watches paper inequality (1)

    |alpha1 - alpha2| < K2 / r

and, when it becomes true after a sample on which it was false (the backlash-zone entry), captures the
48 samples before plus the entry sample and the 1999 after it: a :class:`Window` of 48 + 2000 = 2048
samples with the entry sample at index 48, exactly the simulator's window.

Bad input never raises.  Each problem is returned as a ``drop`` :class:`Event` with a reason from
:data:`REASONS`, counted in :attr:`BacklashDetector.counts`; the window in progress (if any) is
dropped, the history is cleared (continuity is lost), and the detector goes on with the next batch.
The one exception is an empty batch: it carries no sample, so nothing is lost; it is reported and
counted, and the window in progress is kept (the stamp checks of the next batch still guard continuity).

The layouts themselves: :mod:`jident_ros.stream.layout`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from jident_ros.stream.layout import (
    DEFAULT_CHANNELS,
    FLAG_CUT_OFF,
    KNOWN_CHANNELS,
    REQUIRED_CHANNELS,
    LayoutError,
    Window,
    unpack,
)

#: Why a batch or a window was dropped.
REASONS = {
    "layout": "the message layout is not the documented 2-D sample x channel layout",
    "empty": "a batch without samples (reported only: nothing lost, the window in progress is kept)",
    "nonfinite": "NaN or Inf in a used channel",
    "unknown_channel": "a channel name that is not part of the contract",
    "missing_channel": "a channel the detector was configured to capture is absent",
    "out_of_order": "the drive clock t went backwards",
    "repeated_stamp": "the same t twice",
    "gap": "t advanced by more than gap_tolerance x the sample period (samples lost)",
    "irregular_stamp": "t advanced by less than half the sample period",
    "short_history": "a backlash entry with fewer than samples_before_entry samples of history",
    "cut_off": "the data ended before the window was complete (finish(); the event carries the partial window)",
    "swallowed_entry": "an entry inside a window whose own entry shows no traversal (flank detector): the window "
                       "goes out, flagged; the entry inside it gets no window of its own",
    "duplicate_entry": "a traversal's entry found twice, by the contact rule and by a window's edge scan (flank "
                       "detector): one window goes out (reported only: nothing lost)",
    "entry_held": "an entry the zone model moved forward beyond the rows captured for its window, held at the last row "
                  "whose whole window the capture holds (flank detector): the window goes out, its entry up to a few "
                  "rows before the zone model's (reported only: nothing lost)",
}


@dataclass
class Event:
    """What a batch produced: a captured window or a dropped one.

    kind : "window" | "drop"
    reason : one of REASONS (drops only)
    detail : one line for humans
    window : the Window (kind "window")
    window_dropped : True when a window in progress was lost
    """

    kind: str
    reason: str = ""
    detail: str = ""
    window: Window | None = None
    window_dropped: bool = False


# --------------------------------------------------------------------------- detector


@dataclass
class _Capture:
    parts: list | None  # None: the transient is skipped, not captured
    count: int
    entry_time_s: float
    backlash_width_m: float


class BacklashDetector:
    """Streaming detector of the backlash-zone entry (paper inequality 1) and window capture.

    Parameters
    ----------
    backlash_width_m : float       K2 (> 0)
    wheel_radius_m : float         r (> 0)
    sample_period_s : float        T_s (> 0)
    channels : names to capture, must include "t", "alpha1", "alpha2" (window column order)
    samples_before_entry : int     history kept and put in front of the entry (48)
    samples_from_entry : int       samples from the entry sample on (2000)
    gap_tolerance : float          a step of t above gap_tolerance x T_s is a gap (1.5)
    unwrap_angles : bool           alpha1 and alpha2 are unwrapped (True): a step of more than pi rad between two
                                   samples is a wrap of a continuous joint's position (reported in [-pi, pi)), not
                                   motion (it would take 6283 rad/s at 2 kHz); the windows carry the unwrapped angles

    Subclasses that need other channels set :attr:`required_channels` (and :attr:`required_reason`).

    :meth:`push` takes one batch (array (n, k) and its k channel names, in any order, any subset
    of :data:`KNOWN_CHANNELS` that holds ``channels``) and returns the list of events it caused.
    The result does not depend on how a stream is cut into batches.
    """

    #: Channels every batch must carry, and why (one-line errors).
    required_channels = REQUIRED_CHANNELS
    required_reason = "inequality 1 uses t, alpha1, alpha2"
    #: appended to a ``missing_channel`` drop's reason (what to configure instead)
    missing_channel_hint = ""

    def __init__(self, backlash_width_m: float, wheel_radius_m: float, sample_period_s: float,
                 channels: Sequence[str] = DEFAULT_CHANNELS, samples_before_entry: int = 48,
                 samples_from_entry: int = 2000, gap_tolerance: float = 1.5, unwrap_angles: bool = True):
        for name, v in (("wheel_radius_m", wheel_radius_m), ("sample_period_s", sample_period_s),
                        ("gap_tolerance", gap_tolerance)):
            if not _positive(v):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        if not gap_tolerance > 1.0:
            raise ValueError(f"gap_tolerance: must be > 1, got {gap_tolerance!r}")
        channels = tuple(channels)
        for c in channels:
            if c not in KNOWN_CHANNELS:
                raise ValueError(f"channels: unknown channel {c!r} (known: {', '.join(KNOWN_CHANNELS)})")
        if len(set(channels)) != len(channels):
            raise ValueError(f"channels: repeated name in {list(channels)}")
        missing = [c for c in self.required_channels if c not in channels]
        if missing:
            raise ValueError(f"channels: need {missing[0]!r} ({self.required_reason}), got {list(channels)}")
        if int(samples_before_entry) != samples_before_entry or samples_before_entry < 1:
            raise ValueError(f"samples_before_entry: must be an integer >= 1, got {samples_before_entry!r}")
        if int(samples_from_entry) != samples_from_entry or samples_from_entry < 2:
            raise ValueError(f"samples_from_entry: must be an integer >= 2, got {samples_from_entry!r}")
        # output order: "t" first, then the others as given
        self.channels = ("t",) + tuple(c for c in channels if c != "t")
        self.wheel_radius_m = float(wheel_radius_m)
        self.sample_period_s = float(sample_period_s)
        self.samples_before_entry = int(samples_before_entry)
        self.samples_from_entry = int(samples_from_entry)
        self.gap_tolerance = float(gap_tolerance)
        self.unwrap_angles = bool(unwrap_angles)
        #: wraps of alpha1/alpha2 undone so far (information)
        self.wraps_undone = 0
        self._i_t = 0
        self._i_a1 = self.channels.index("alpha1") if "alpha1" in self.channels else -1
        self._i_a2 = self.channels.index("alpha2") if "alpha2" in self.channels else -1
        self.backlash_width_m = 0.0
        self.set_backlash_width(backlash_width_m)
        self.counts = {r: 0 for r in REASONS}
        self.windows_lost: dict = {}        # drop reason -> windows in progress it lost (their entry was found)
        self.windows_captured = 0
        self.samples_seen = 0
        self.batches_seen = 0
        self.last_event: Event | None = None
        self.reset()

    # ------------------------------------------------------------- state
    @property
    def window_length(self) -> int:
        return self.samples_before_entry + self.samples_from_entry

    @property
    def threshold_rad(self) -> float:
        """K2 / r, the right-hand side of inequality (1)."""
        return self.backlash_width_m / self.wheel_radius_m

    @property
    def capturing(self) -> bool:
        """True while a window is being captured."""
        return self._capture is not None and self._capture.parts is not None

    @property
    def dropped_total(self) -> int:
        return sum(v for k, v in self.counts.items() if k != "empty")

    def reset(self) -> None:
        """Forget the history and the window in progress (continuity lost)."""
        self._wrap = {}
        if not hasattr(self, "_rel_range"):
            self._rel_range = (math.inf, -math.inf)
        self._tail = np.empty((0, len(self.channels)))
        self._last_t: float | None = None
        self._prev_inside: bool | None = None
        self._capture: _Capture | None = None

    def set_backlash_width(self, backlash_width_m: float) -> None:
        """Change K2.  A window in progress keeps the width it started with; the next entry must
        again be preceded by a sample outside the new zone (a change alone is not an entry)."""
        if not _positive(backlash_width_m):
            raise ValueError(f"backlash_width_m: must be a finite number > 0, got {backlash_width_m!r}")
        self.backlash_width_m = float(backlash_width_m)
        if getattr(self, "_tail", None) is not None and self._tail.shape[0]:
            self._prev_inside = bool(self._inside(self._tail[-1:])[0])

    # ------------------------------------------------------------- input
    def push_flat(self, data, dims, data_offset: int = 0) -> list:
        """Batch in the Float64MultiArray layout (see :func:`unpack`); a layout error is a drop."""
        try:
            arr, channels, _ = unpack(data, dims, data_offset)
        except LayoutError as exc:
            return [self.reject("layout", str(exc))]
        return self.push(arr, channels)

    def reject(self, reason: str, detail: str = "") -> Event:
        """Record a problem found outside the detector (e.g. a message that cannot be read)."""
        if reason not in REASONS:
            raise ValueError(f"reason: expected one of {sorted(REASONS)}, got {reason!r}")
        lost = self.capturing and reason != "empty"
        if reason != "empty":
            self.reset()
        self.counts[reason] += 1
        if lost:
            self.windows_lost[reason] = self.windows_lost.get(reason, 0) + 1
        ev = Event("drop", reason, detail or REASONS[reason], window_dropped=lost)
        self.last_event = ev
        return ev

    def push(self, array, channels: Sequence[str]) -> list:
        """Consume one batch; returns the events (captured windows, drops) in stream order."""
        self.batches_seen += 1
        try:
            x, problem = self._validate(array, channels)
        except Exception as exc:  # never raise on bad data
            x, problem = None, ("layout", f"unreadable batch: {type(exc).__name__}: {exc}")
        if problem is not None:
            return [self.reject(*problem)]
        self.samples_seen += x.shape[0]
        return self._consume(x)

    def _validate(self, array, channels):
        channels = tuple(str(c) for c in channels)
        a = np.asarray(array)
        if a.ndim != 2:
            return None, ("layout", f"batch: expected a 2-D array (sample, channel), got shape {a.shape}")
        if a.shape[1] != len(channels):
            return None, ("layout", f"batch: {a.shape[1]} columns but {len(channels)} channel names")
        if len(set(channels)) != len(channels):
            return None, ("layout", f"batch: repeated channel name in {list(channels)}")
        if not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
            return None, ("layout", f"batch: expected real numbers, got dtype {a.dtype}")
        if a.shape[0] == 0:
            return None, ("empty", "batch with 0 samples")
        unknown = [c for c in channels if c not in KNOWN_CHANNELS]
        if unknown:
            return None, ("unknown_channel", f"unknown channel {unknown[0]!r} (known: {', '.join(KNOWN_CHANNELS)})")
        missing = [c for c in self.channels if c not in channels]
        if missing:
            return None, ("missing_channel", f"channel {missing[0]!r} missing (batch has {','.join(channels)})"
                                             f"{self.missing_channel_hint}")
        cols = [channels.index(c) for c in self.channels]
        x = np.asarray(a[:, cols], dtype=np.float64)
        bad = ~np.isfinite(x)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            return None, ("nonfinite", f"{x[r, c]!r} in channel {self.channels[c]!r} at sample {r} of the batch")
        t = x[:, self._i_t]
        prev = self._last_t
        tt = t if prev is None else np.concatenate([[prev], t])
        ts = self.sample_period_s
        dt = tt[1:] - tt[:-1]
        # every step within [T_s / 2, gap_tolerance T_s]: none of the checks below can fire (the usual batch; two
        # reductions instead of four masks, issue 25)
        if dt.size and not (dt.min() >= 0.5 * ts and dt.max() <= self.gap_tolerance * ts):
            checks = (("out_of_order", dt < 0), ("repeated_stamp", dt == 0),
                      ("gap", dt > self.gap_tolerance * ts), ("irregular_stamp", (dt > 0) & (dt < 0.5 * ts)))
            first = None
            for reason, mask in checks:
                if mask.any():
                    k = int(np.argmax(mask))
                    if first is None or k < first[1]:
                        first = (reason, k)
            if first is not None:
                reason, k = first
                where = "between batches" if (prev is not None and k == 0) else "inside the batch"
                return None, (reason, f"t {tt[k]!r} -> {tt[k + 1]!r} s (step {dt[k]:.6g} s, "
                                      f"T_s {ts:.6g} s) {where}")
        if self.unwrap_angles:
            self._unwrap(x)
        return x, None

    def _unwrap(self, x: np.ndarray) -> None:
        """Undo the wraps of alpha1 and alpha2 in place, continuing across batches (this batch's first sample
        against the last one of the previous batch included).  A wrap is a step of more than pi and less than
        2 pi between two values that both lie within one turn of zero (a position reported in [-pi, pi) or
        [0, 2 pi)); a larger jump (a simulator starting its next case elsewhere) is left alone.  The state is
        forgotten with the history (reset)."""
        two_pi = 2.0 * math.pi
        lim = two_pi * (1.0 + 1e-9)
        for j in (self._i_a1, self._i_a2):
            if j < 0:
                continue
            raw = x[:, j].copy()
            prev = self._wrap.get(j)            # (last raw value, its unwrapped value)
            seq = raw if prev is None else np.concatenate([[prev[0]], raw])
            step = seq[1:] - seq[:-1]
            shift = 0.0 if prev is None else prev[1] - prev[0]
            if step.size and float(np.abs(step).max()) <= math.pi:     # no step can be a wrap (issue 25: fast path)
                wraps = None
            else:
                wraps = (np.abs(step) > math.pi) & (np.abs(step) < lim) & (np.abs(seq[:-1]) <= lim) \
                    & (np.abs(seq[1:]) <= lim)
            if wraps is not None and wraps.any():
                self.wraps_undone += int(np.count_nonzero(wraps))
                turns = np.cumsum(np.where(wraps, -np.sign(step), 0.0))
                if prev is None:
                    turns = np.concatenate([[0.0], turns])
                x[:, j] = raw + shift + two_pi * turns
            elif shift:
                x[:, j] = raw + shift
            self._wrap[j] = (float(raw[-1]), float(x[-1, j]))

    # ------------------------------------------------------------- detection
    def _inside(self, x: np.ndarray) -> np.ndarray:
        rel = np.abs(x[:, self._i_a1] - x[:, self._i_a2])
        if rel.size:
            lo, hi = float(rel.min()), float(rel.max())
            self._rel_range = (min(self._rel_range[0], lo), max(self._rel_range[1], hi))
        return rel < self.threshold_rad

    def no_entry_reason(self) -> str:
        """Why no entry was found so far, and what to set (one line; '' when a window was captured)."""
        if self.windows_captured or not self.samples_seen:
            return ""
        lo, hi = self._rel_range
        thr = self.threshold_rad
        if lo >= thr:
            return (f"|alpha1 - alpha2| stayed between {lo:.4g} and {hi:.4g} rad, never inside the zone K2/r = "
                    f"{thr:.4g} rad (paper inequality 1 needs zone-centred angles): raw encoder angles with offsets "
                    f"or a gear ratio? use the flank detector (--detector flank / detector: flank, with gear_ratio), "
                    f"which needs no K2 and no zone-centred angles")
        if hi < thr:
            return (f"|alpha1 - alpha2| stayed inside the zone K2/r = {thr:.4g} rad (at most {hi:.4g} rad) and never "
                    f"entered it from outside: K2 = {self.backlash_width_m:g} m too large for wheel_radius_m "
                    f"{self.wheel_radius_m:g}? or use the flank detector (--detector flank), which needs no K2")
        return (f"|alpha1 - alpha2| ranged {lo:.4g}..{hi:.4g} rad around K2/r = {thr:.4g} rad but never entered the "
                f"zone after {self.samples_before_entry} samples outside it")

    def _consume(self, x: np.ndarray) -> list:
        events = []
        n = x.shape[0]
        tail = self._tail
        i = 0
        while i < n:
            if self._capture is not None:
                cap = self._capture
                take = min(self.window_length - cap.count, n - i)
                if cap.parts is not None:
                    cap.parts.append(x[i:i + take])
                cap.count += take
                i += take
                self._prev_inside = bool(self._inside(x[i - 1:i])[0])
                if cap.count == self.window_length:
                    if cap.parts is None:  # skipped transient (short history)
                        self._capture = None
                    else:
                        events.append(self._finish(cap))
                continue
            inside = self._inside(x[i:])
            before = np.empty_like(inside)
            before[1:] = inside[:-1]
            before[0] = True if self._prev_inside is None else self._prev_inside
            entries = np.flatnonzero(inside & ~before)
            if entries.size == 0:
                self._prev_inside = bool(inside[-1])
                break
            k = i + int(entries[0])
            hist = np.concatenate([tail, x[:k]])[-self.samples_before_entry:]
            if hist.shape[0] < self.samples_before_entry:
                events.append(self._short_history(float(x[k, self._i_t]), hist.shape[0], self.samples_before_entry))
                # the transient of this entry is not captured; it still owns its samples, so that
                # a bounce back into the zone is not taken for a new entry
                self._capture = _Capture(None, self.samples_before_entry, float(x[k, self._i_t]),
                                         self.backlash_width_m)
            else:
                self._capture = _Capture([hist], hist.shape[0], float(x[k, self._i_t]), self.backlash_width_m)
            i = k
        self._tail = np.concatenate([tail, x])[-self.samples_before_entry:]
        self._last_t = float(x[-1, self._i_t])
        return events

    def finish(self) -> list:
        """The data ended: a window in progress is reported as ``cut_off`` (a drop, counted); the event
        carries the partial window (FLAG_CUT_OFF set) for an offline report.  Live, the windowing node
        calls it when it shuts down."""
        cap = self._capture
        self._capture = None
        if cap is None or cap.parts is None:
            return []
        return [self._cut_off(np.concatenate(cap.parts), self.samples_before_entry, cap.entry_time_s,
                              cap.backlash_width_m, "paper")]

    def _short_history(self, entry_time_s: float, have: int, need: int) -> Event:
        """The ``short_history`` drop (counted): an entry with fewer history samples than a window needs."""
        ev = Event("drop", "short_history", f"entry at t = {entry_time_s!r} s with {have} of {need} history samples")
        self.counts["short_history"] += 1
        self.last_event = ev
        return ev

    def _cut_off(self, data: np.ndarray, entry_index: int, entry_time_s: float, backlash_width_m: float,
                 detector: str) -> Event:
        """The ``cut_off`` drop (counted) of a partial window: the event carries it, FLAG_CUT_OFF set."""
        w = Window(data, self.channels, entry_index, entry_time_s, backlash_width_m, self.wheel_radius_m,
                   self.sample_period_s, 0, detector=detector, flags=FLAG_CUT_OFF)
        self.counts["cut_off"] += 1
        ev = Event("drop", "cut_off", f"entry at t = {entry_time_s:.6f} s: the data ended after "
                                      f"{data.shape[0] - entry_index} of {self.samples_from_entry} samples from "
                                      f"the entry", window=w, window_dropped=True)
        self.last_event = ev
        return ev

    def _finish(self, cap: _Capture) -> Event:
        self._capture = None
        self.windows_captured += 1
        data = np.concatenate(cap.parts)
        w = Window(data, self.channels, self.samples_before_entry, cap.entry_time_s, cap.backlash_width_m,
                   self.wheel_radius_m, self.sample_period_s, self.windows_captured)
        ev = Event("window", detail=f"window {w.window_id}: entry at t = {cap.entry_time_s:.6f} s", window=w)
        self.last_event = ev
        return ev


def _positive(v) -> bool:
    try:
        return not isinstance(v, bool) and math.isfinite(float(v)) and float(v) > 0
    except (TypeError, ValueError):
        return False


def stream_batches(array: np.ndarray, batch_size: int) -> Iterable[np.ndarray]:
    """Cut an (n, c) stream into consecutive batches (the last one may be shorter)."""
    if int(batch_size) < 1:
        raise ValueError(f"batch_size: must be >= 1, got {batch_size!r}")
    for s in range(0, array.shape[0], int(batch_size)):
        yield array[s:s + int(batch_size)]


def embed_windows(windows, gap_samples: int = 400, start_time_s: float = 1.0,
                  channels: Sequence[str] = DEFAULT_CHANNELS):
    """The continuous sample stream a drive would publish for simulated windows, back to back.

    Each case is preceded by ``gap_samples`` steady-state samples (its first sample held, the angles
    advanced at their steady speeds backwards in time, so |alpha1 - alpha2| stays outside the zone);
    the drive clock ``t`` runs on without a break: row g has t = start_time_s + g * T_s.

    Parameters
    ----------
    windows : jident_ros.sim.WindowSet
    gap_samples : int >= 0
    start_time_s : float, t of the first row
    channels : column names ("t" plus window channels)

    Returns
    -------
    stream : ndarray (n_cases * (gap_samples + n_window), len(channels))
    entry_rows : list of int, the row of each case's entry sample
    """
    gap = int(gap_samples)
    if gap < 0:
        raise ValueError(f"gap_samples: must be >= 0, got {gap_samples!r}")
    ts = float(windows.sample_period_s)
    nw = len(windows.t)
    per = gap + nw
    out = np.empty((len(windows) * per, len(channels)))
    back = (np.arange(gap) - gap) * ts  # -gap*Ts ... -Ts relative to the case's first sample
    entry_rows = []
    for i in range(len(windows)):
        rows = slice(i * per, (i + 1) * per)
        block = out[rows]
        for j, c in enumerate(channels):
            if c == "t":
                continue
            x = windows.signals[c][i]
            col = block[:, j]
            col[gap:] = x
            if c == "alpha1":
                col[:gap] = x[0] + windows.signals["omega1"][i][0] * back
            elif c == "alpha2":
                col[:gap] = x[0] + windows.signals["omega2"][i][0] * back
            else:
                col[:gap] = x[0]
        entry_rows.append(i * per + gap + int(windows.entry_index))
    if "t" in channels:
        out[:, list(channels).index("t")] = start_time_s + np.arange(out.shape[0]) * ts
    return out, entry_rows
