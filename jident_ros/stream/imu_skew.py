"""The Imu and the JointState clocks matched by their data (issue 24): an Imu whose stamps agree with the
JointState's while its data do not (a stamp taken late) gives a J1 off by percents (a 2 ms skew: -2.5 %).

* :func:`imu_skew` estimates how far a1 lags the motor encoder's acceleration (the second difference of alpha1, else
  the first difference of omega1, smoothed alike), to a fraction of a sample;
* :func:`check_imu_skew` says whether a captured window's skew is within :data:`IMU_SKEW_TOLERANCE_SAMPLES`
  (half a sample: 0.25 ms at 2 kHz, the stamp matching's own tolerance);
* beyond it the input goes on without a1 (:meth:`jident_ros.stream.inputs.JointStateAdapter.drop_a1`), the
  detector replaced by one on the encoder's acceleration, and the window is detected again by it from the rows
  kept (:class:`ImuSkewGuard`, the node's and ``jident diagnose``'s one chain): no J1 from the skewed a1, and the
  window is not lost (issue 20: before, the window in which the skew was found was dropped).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from jident_ros.stream import rate

__all__ = ["IMU_SKEW_MIN_CORRELATION", "IMU_SKEW_TOLERANCE_SAMPLES", "ImuSkewGuard",
           "SKEW_REFEED_MARGIN_SAMPLES", "check_imu_skew", "imu_skew", "skew_line"]

#: Imu a1 may be this many sample periods out of step with the encoder before a1 is left out of a window.
IMU_SKEW_TOLERANCE_SAMPLES = 0.5
#: A window whose a1 is out of step is detected again without a1 from this many samples before its first sample
#: (the new detector learns the flank level there: contact_samples 32 and the confirmation; samples at 2 kHz, the
#: same 32 ms at another rate: jident_ros.stream.rate)
SKEW_REFEED_MARGIN_SAMPLES = 64
#: The smallest correlation of a1 with the encoder's acceleration at which a skew estimate is trusted.
IMU_SKEW_MIN_CORRELATION = 0.5


def imu_skew(a1, sample_period_s: float, alpha1=None, omega1=None, max_lag_samples: Optional[int] = None,
             smooth_samples: Optional[int] = None) -> Optional[dict]:
    """How far a1 lags the motor encoder, estimated from the data (the stamps may agree while the data do
    not): the lag maximising the correlation of a1 with the encoder's acceleration (the second difference of
    alpha1 when it correlates, else the first difference of omega1 -- the drive's speed feedback, which may lag;
    both signals smoothed alike by a ``smooth_samples`` moving average), refined by a parabola through the peak.
    Returns ``{"skew_s", "skew_samples", "correlation", "reference": "omega1"|"alpha1"}`` (skew > 0: a1 comes late)
    or None when no encoder channel is given, the data are too short or flat, or the peak correlation is below
    :data:`IMU_SKEW_MIN_CORRELATION` (no estimate).  ``max_lag_samples`` and ``smooth_samples`` default to 20 ms and
    7.5 ms (40 and 15 samples at 2 kHz; the moving average over the same time keeps the second difference's noise
    as at 2 kHz)."""
    max_lag_samples = rate.samples(40, sample_period_s) if max_lag_samples is None else max_lag_samples
    smooth_samples = rate.samples(15, sample_period_s) if smooth_samples is None else smooth_samples
    a = np.asarray(a1, dtype=float)
    found = []
    if omega1 is not None:
        ref = np.diff(np.asarray(omega1, dtype=float)) / sample_period_s
        found.append(_lag(0.5 * (a[1:] + a[:-1]), ref, "omega1", 1, max_lag_samples, smooth_samples))
    if alpha1 is not None:
        ref = np.diff(np.asarray(alpha1, dtype=float), 2) / sample_period_s ** 2
        found.append(_lag(a[1:-1], ref, "alpha1", 2, max_lag_samples, smooth_samples))
    found = [f for f in found if f is not None]
    if not found:
        return None
    # the encoder angle when it correlates: omega1 is the drive's speed feedback, which lags (a filter: the vector
    # drive's 0.5 ms) and read an a1 in step as 1.2 samples early when its correlation was the higher one (a window
    # of the DOL zoo's slip reversal, 4 samples later: a1 left out and the window lost its J1)
    angle = [f for f in found if f[2] == "alpha1"]
    best = angle[0] if angle else max(found, key=lambda f: f[1])
    samples, corr, name = best
    return {"skew_s": samples * sample_period_s, "skew_samples": samples, "correlation": corr, "reference": name}


def _lag(a, ref, name, passes, m, smooth):
    """(lag in samples, peak correlation, name) of ``a`` against ``ref`` (module docstring), or None."""
    n = min(a.size, ref.size)
    a, ref = a[:n], ref[:n]
    if not (np.isfinite(a).all() and np.isfinite(ref).all()):
        return None
    if smooth > 1:
        kernel = np.ones(int(smooth)) / int(smooth)
        for _ in range(passes):
            if a.size < kernel.size:
                return None
            a, ref = np.convolve(a, kernel, "valid"), np.convolve(ref, kernel, "valid")
    n = a.size
    if n < 4 * m:
        return None
    a = a - a.mean()
    ref = ref - ref.mean()
    if not (a.std() > 0 and ref.std() > 0):
        return None
    rc = ref[m:n - m]
    lags = np.arange(-m, m + 1)
    corr = np.empty(lags.size)
    for k, lag in enumerate(lags):        # a1[i + lag] against ref[i]: lag > 0 means a1 comes late
        ak = a[m + lag:n - m + lag]
        den = np.sqrt(np.dot(ak, ak) * np.dot(rc, rc))
        corr[k] = np.dot(ak, rc) / den if den > 0 else 0.0
    k = int(np.argmax(corr))
    best = float(corr[k])
    if not best >= IMU_SKEW_MIN_CORRELATION:
        return None
    frac = 0.0
    if 0 < k < lags.size - 1:
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        den = y0 - 2 * y1 + y2
        frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5)) if den < 0 else 0.0
    return float(lags[k]) + frac, best, name


def check_imu_skew(window, tolerance_samples: float = IMU_SKEW_TOLERANCE_SAMPLES) -> Optional[dict]:
    """The Imu skew of a captured window holding a1: None without a1, else ``{"skew_s"`` (None when no
    estimate was possible: :func:`imu_skew`), ``"tolerance_s"``, ``"correlation"``, ``"reference"``,
    ``"within"`` (False only for an estimate beyond the tolerance)}.  A window beyond the tolerance must not
    give a J1: its a1 is out of step, and the detector placed the entry and the re-contact with it -- it is
    detected again without a1 (:class:`ImuSkewGuard`).  Without an estimate a1 is kept (the stamps
    matched within T_s/2)."""
    chans = tuple(window.channels)
    if "a1" not in chans:
        return None
    ts = float(window.sample_period_s)
    est = imu_skew(window.column("a1"), ts, alpha1=window.column("alpha1") if "alpha1" in chans else None,
                   omega1=window.column("omega1") if "omega1" in chans else None)
    tol_s = tolerance_samples * ts
    return {"skew_s": None if est is None else est["skew_s"], "tolerance_s": tol_s,
            "correlation": None if est is None else est["correlation"],
            "reference": None if est is None else est["reference"],
            "within": est is None or abs(est["skew_s"]) <= tol_s}


def skew_line(report: dict, window_id, outcome: str = "lost") -> str:
    """One line for a window whose Imu skew is beyond the tolerance (:func:`check_imu_skew`); ``outcome``: "again"
    (the window detected again without a1), "capturing" (... its window still being captured) or "lost"."""
    late = "late" if report["skew_s"] > 0 else "early"
    head = f"window {window_id}" if outcome != "lost" else f"window {window_id} not diagnosed"
    tail = {"again": "the window is detected again from the encoder",
            "capturing": "the window is being detected again from the encoder",
            "lost": "the encoder found no window there again (lost, counted in imu_skew)"}[outcome]
    return (f"{head}: Imu a1 is {1e3 * abs(report['skew_s']):.2f} ms {late} against the "
            f"encoder (a1 against the derivative of {report['reference']}, correlation {report['correlation']:.2f}); "
            f"beyond the tolerance {1e3 * report['tolerance_s']:.2f} ms: no J1 from a1, a1 left out from now on "
            f"(the encoder gives the acceleration); {tail}")


class ImuSkewGuard:
    """The one home of :func:`check_imu_skew` in a running chain (the windowing node with ``use_imu`` and
    ``jident diagnose`` on a JointState + Imu bag push every batch through :meth:`push`).

    Each window the detector gives is checked; a window whose a1 is out of step is **detected again without a1**:
    the adapter goes on without a1 (:meth:`JointStateAdapter.drop_a1`), a new detector (``remake(channels)``, the
    owner's factory) takes over, counts and window ids carried over, and is fed the recent rows it
    keeps (from :data:`SKEW_REFEED_MARGIN_SAMPLES` before the skewed window's first sample, also inside the window
    before it: a traversal back lies there; a window found again at or before that window's entry is dropped, a
    duplicate; entries inside it are traversals back, ``inside_window_until_s``) without a1: the window comes out
    again with its entry placed from the encoder, under the same window id.  Only a window that this second pass
    does not find (nor keeps capturing) is lost, counted in :attr:`dropped`.  :attr:`skews` counts the windows whose
    check found the skew, :attr:`report` is the last check.
    ``log`` gets one line per skew found (:func:`skew_line`) and per window lost.
    """

    def __init__(self, adapter, remake, log=lambda text: None, keep_rows: int = 0):
        self.adapter, self.remake, self.log = adapter, remake, log
        self.skews = 0          # windows whose Imu check found a1 out of step (a1 left out after the first)
        self.dropped = 0        # ... of them, windows lost (not found again without a1)
        self.report: Optional[dict] = None
        self.keep_rows = int(keep_rows)
        self._kept: list = []   # recent (array, channels) batches the detector took, since its last drop
        self._kept_rows = 0
        self._last_end_t = -math.inf     # the last sample of the last window given out
        self._last_entry_t = -math.inf   # ... and its entry
        self.last_lost = False

    def reset(self) -> None:
        """The owner reset its detector (continuity lost): the rows kept so far are not fed again."""
        self._kept, self._kept_rows = [], 0

    def strip(self, arr, channels):
        """A batch made before a1 was left out, without its a1 column."""
        if self.adapter is not None and self.adapter.a1_dropped and "a1" in channels:
            keep = [j for j, c in enumerate(channels) if c != "a1"]
            return arr[:, keep], tuple(channels[j] for j in keep)
        return arr, channels

    def push(self, detector, arr, channels) -> tuple:
        """One batch through ``detector`` (None: made by ``remake`` from the batch's channels); returns (the
        detector that goes on, its events in stream order)."""
        arr, channels = self.strip(arr, channels)
        if detector is None:
            detector = self.remake(tuple(channels))
        if not (self.adapter is not None and self.adapter.use_imu):
            return detector, self._seen(detector.push(arr, channels))
        if self.keep_rows <= 0:
            self.keep_rows = 2 * int(detector.window_length) + rate.samples(SKEW_REFEED_MARGIN_SAMPLES,
                                                                            detector.sample_period_s)
        self._keep(arr, channels)
        events = detector.push(arr, channels)
        for k, ev in enumerate(events):
            report = check_imu_skew(ev.window) if ev.kind == "window" else None
            if report is not None:
                self.report = report
            if report is None or report["within"]:
                self._seen([ev])
                continue
            # the skewed window and everything after it come again from a detector without a1
            detector, again = self._again(detector, ev.window, report)
            return detector, events[:k] + again
        return detector, events

    def _seen(self, events: list) -> list:
        for ev in events:
            if ev.kind == "window":
                w = ev.window
                self._last_end_t = float(w.column("t")[-1])
                self._last_entry_t = float(w.entry_time_s)
            elif ev.reason != "empty":      # continuity lost: the detector restarted, so does the history
                self.reset()
        return events

    def _keep(self, arr, channels) -> None:
        if self.keep_rows <= 0:
            return
        self._kept.append((arr, tuple(channels)))
        self._kept_rows += arr.shape[0]
        while self._kept and self._kept_rows - self._kept[0][0].shape[0] >= self.keep_rows:
            self._kept_rows -= self._kept.pop(0)[0].shape[0]

    def _again(self, old, win, report) -> tuple:
        self.skews += 1
        self.adapter.drop_a1()
        kept, self._kept, self._kept_rows = self._kept, [], 0
        rows = [self.strip(a, c) for a, c in kept]
        chans = tuple(c for c in old.channels if c != "a1")
        new = self.remake(rows[0][1] if rows else chans)
        t = win.column("t")
        ts = float(win.sample_period_s)
        # from the margin before the skewed window, even inside the window given out before it (a traversal back
        # lies inside the window of the traversal before it: started after that window's end, the vector drive's
        # speed steps lost 3 of them); a window found again at or before that window's entry is a duplicate, dropped
        start = float(t[0]) - rate.samples(SKEW_REFEED_MARGIN_SAMPLES, ts) * ts
        ids = old.windows_captured - 1          # the window comes out again under its own id
        samples, batches, counts = old.samples_seen, old.batches_seen, dict(getattr(old, "counts", {}))
        new.windows_captured = ids
        if self._last_end_t > start:
            new.inside_window_until_s = self._last_end_t     # its entries there are traversals back
        events = []
        for a, c in rows:
            tcol = a[:, list(c).index("t")]
            a = a[tcol >= start]
            if a.shape[0]:
                events += new.push(a, c)
        events = [ev for ev in events if not (ev.kind == "window" and ev.window is not None
                                              and ev.window.entry_time_s <= self._last_entry_t + 0.5 * ts)]
        self._seen(events)
        for r, n in counts.items():          # the old detector's counts go on (the second pass adds its own)
            if r in new.counts:
                new.counts[r] += n
        for r, n in getattr(old, "windows_lost", {}).items():
            new.windows_lost[r] = new.windows_lost.get(r, 0) + n
        new.samples_seen, new.batches_seen = samples, batches
        again = any(ev.kind == "window" for ev in events)
        self.last_lost = not again and not getattr(new, "capturing", False)
        self.dropped += int(self.last_lost)
        self.log(skew_line(report, win.window_id, "lost" if self.last_lost else "again" if again else "capturing"))
        return new, events
