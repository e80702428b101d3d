"""The Imu and the JointState clocks matched by their data (issue 24): an Imu whose stamps agree with the
JointState's while its data do not (a stamp taken late) gives a J1 off by percents (a 2 ms skew: -2.5 %).

* :func:`imu_skew` estimates how far a1 lags the motor encoder's acceleration (the first difference of omega1 and
  the second difference of alpha1, smoothed alike; the better correlated wins), to a fraction of a sample;
* :func:`check_imu_skew` says whether a captured window's skew is within :data:`IMU_SKEW_TOLERANCE_SAMPLES`
  (half a sample: 0.25 ms at 2 kHz, the stamp matching's own tolerance);
* beyond it the window is not diagnosed (the detector placed its entry and re-contact with the skewed a1) and
  the input goes on without a1 (:meth:`jident_ros.stream.inputs.JointStateAdapter.drop_a1`), the detector
  replaced by one on the encoder's acceleration (:func:`carry_counts`, :class:`ImuSkewGuard`).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

__all__ = ["IMU_SKEW_MIN_CORRELATION", "IMU_SKEW_TOLERANCE_SAMPLES", "ImuSkewGuard", "carry_counts",
           "check_imu_skew", "imu_skew", "skew_line"]

#: Imu a1 may be this many sample periods out of step with the encoder before a1 is left out of a window.
IMU_SKEW_TOLERANCE_SAMPLES = 0.5
#: The smallest correlation of a1 with the encoder's acceleration at which a skew estimate is trusted.
IMU_SKEW_MIN_CORRELATION = 0.5


def imu_skew(a1, sample_period_s: float, alpha1=None, omega1=None, max_lag_samples: int = 40,
             smooth_samples: int = 15) -> Optional[dict]:
    """How far a1 lags the motor encoder, estimated from the data (the stamps may agree while the data do
    not): the lag maximising the correlation of a1 with the encoder's acceleration (the first difference of
    omega1 and the second difference of alpha1, each tried, both signals smoothed alike by a
    ``smooth_samples`` moving average; the better correlated reference wins), refined by a parabola through
    the peak.  Returns ``{"skew_s", "skew_samples", "correlation", "reference": "omega1"|"alpha1"}`` (skew > 0:
    a1 comes late) or None when no encoder channel is given, the data are too short or flat, or the peak
    correlation is below :data:`IMU_SKEW_MIN_CORRELATION` (no estimate)."""
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
    best = max(found, key=lambda f: f[1])
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
    give a J1: its a1 is out of step, and the detector placed the entry and the re-contact with it -- drop it
    and go on without a1 (:meth:`JointStateAdapter.drop_a1`).  Without an estimate a1 is kept (the stamps
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


def carry_counts(old, new):
    """``new`` detector goes on where ``old`` stopped: window ids, samples, batches and drop counts carried
    over (a detector replaced mid-stream, e.g. without a1).  Returns ``new``."""
    for name in ("windows_captured", "samples_seen", "batches_seen"):
        if hasattr(old, name) and hasattr(new, name):
            setattr(new, name, getattr(old, name))
    for r, n in getattr(old, "counts", {}).items():
        if r in getattr(new, "counts", {}):
            new.counts[r] += n
    return new


def skew_line(report: dict, window_id) -> str:
    """One line for a window whose Imu skew is beyond the tolerance (:func:`check_imu_skew`)."""
    late = "late" if report["skew_s"] > 0 else "early"
    return (f"window {window_id} not diagnosed: Imu a1 is {1e3 * abs(report['skew_s']):.2f} ms {late} against the "
            f"encoder (a1 against the derivative of {report['reference']}, correlation {report['correlation']:.2f}); "
            f"beyond the tolerance {1e3 * report['tolerance_s']:.2f} ms: no J1 from a1, a1 left out from now on "
            "(the encoder gives the acceleration)")


class ImuSkewGuard:
    """An offline reader's side of :func:`check_imu_skew` (``jident diagnose`` on a JointState + Imu bag): a
    window whose a1 is out of step is not diagnosed (counted in :attr:`dropped`, one line to ``log``), the
    adapter goes on without a1 and the owner's detector is replaced (:meth:`carried` carries ids and counts)."""

    def __init__(self, adapter, log):
        self.adapter, self.log = adapter, log
        self.dropped = 0
        self.retired = None

    def strip(self, arr, channels):
        """A batch made before a1 was left out, without its a1 column."""
        if self.adapter is not None and self.adapter.a1_dropped and "a1" in channels:
            keep = [j for j, c in enumerate(channels) if c != "a1"]
            return arr[:, keep], tuple(channels[j] for j in keep)
        return arr, channels

    def carried(self, detector):
        return detector if self.retired is None else carry_counts(self.retired, detector)

    def in_step(self, win, owner) -> bool:
        """True when ``win`` may be diagnosed; else ``owner.detector`` is retired (set to None)."""
        if self.adapter is None or not self.adapter.use_imu:
            return True
        report = check_imu_skew(win)
        if report is None or report["within"]:
            return True
        self.dropped += 1
        self.log(skew_line(report, win.window_id))
        self.adapter.drop_a1()
        self.retired, owner.detector = owner.detector, None
        return False
