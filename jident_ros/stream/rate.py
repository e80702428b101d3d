"""Durations counted in samples, at any sample rate (issue 20; pure Python, never imports rclpy).

The detectors' sample counts that are durations (fit lengths, search spans, hold counts, the history kept) were
chosen on recordings at 2 kHz, ``sampling.sample_period_s`` = 0.5 ms, and are written as samples at that rate
(the module constants keep their values, so the reasons given beside them still read in samples).  A detector
configured with another sample period T_s converts each of them once through :func:`samples`: the same duration in
its own samples, max(1, round(n x 0.5 ms / T_s)), halves rounded up.  At 0.5 ms every count is returned unchanged
(the outputs at 2 kHz are identical, bit for bit: ``scripts/golden.py --check``).

Counts that are not durations stay counts: noise quanta, shares, rms factors, numbers of rounds or candidates, and
the confirmation of a departure by ``confirm_samples`` samples (an encoder spike is one or two *reads*, whatever the
rate).
"""
from __future__ import annotations

import math

#: The sample period the detectors' sample counts were chosen at (2 kHz), s.
REFERENCE_SAMPLE_PERIOD_S = 5e-4


def rate_factor(sample_period_s: float) -> float:
    """Samples at ``sample_period_s`` per sample at the reference 0.5 ms (2.0 at 4 kHz, 0.5 at 1 kHz); exactly 1.0 at
    0.5 ms."""
    ts = float(sample_period_s)
    if ts == REFERENCE_SAMPLE_PERIOD_S:
        return 1.0
    if not (math.isfinite(ts) and ts > 0):
        raise ValueError(f"sample_period_s: must be a finite number > 0, got {sample_period_s!r}")
    return REFERENCE_SAMPLE_PERIOD_S / ts


def samples(n_ref, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S, minimum: int = 1):
    """``n_ref`` samples at 2 kHz as the same duration in samples at ``sample_period_s``: max(``minimum``,
    round(n_ref x 0.5 ms / T_s)), a half rounded up (4.5 -> 5, not Python's 4); ``n_ref`` itself (an int) at 0.5 ms.
    A tuple is converted element by element."""
    if isinstance(n_ref, tuple):
        return tuple(samples(n, sample_period_s, minimum) for n in n_ref)
    f = rate_factor(sample_period_s)
    if f == 1.0:
        return int(n_ref)
    return max(int(minimum), int(math.floor(float(n_ref) * f + 0.5 + 1e-9)))


def samples_float(n_ref: float, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S) -> float:
    """A duration of ``n_ref`` samples at 2 kHz (not rounded: a lag or a bound) in samples at ``sample_period_s``."""
    return float(n_ref) * rate_factor(sample_period_s)


def odd_samples(n_ref: int, sample_period_s: float = REFERENCE_SAMPLE_PERIOD_S, minimum: int = 5) -> int:
    """A filter window of ``n_ref`` samples at 2 kHz (odd) as the odd number of samples nearest above the same
    duration at ``sample_period_s``, at least ``minimum`` (7 -> 15 at 4 kHz, 5 at 1 kHz); ``n_ref`` at 0.5 ms."""
    n = samples(n_ref, sample_period_s)
    if rate_factor(sample_period_s) == 1.0:
        return n
    return max(int(minimum), 2 * (n // 2) + 1)
