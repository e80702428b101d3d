"""The time base of a stream: the sample index, or the stamps as the sampling instants.

The detectors, the gap fit and the image method take the rows as sampled every T_s.  A drive that samples on its
own clock (a fieldbus with distributed clocks, a drive node that stamps its own samples) gives exactly that, and
any jitter of its stamps is only the stamping's.  A loop that reads the drive when it runs and stamps each reading
with its own clock (ros2_control's controller manager on a kernel without real-time scheduling) samples at
jittered instants and says so in its stamps: at 100 rad/s a 25 µs jitter moves the angle by 2.5 mrad, 26 counts
of a 2^16 encoder, noise that a fit over the sample index takes for the drive's.

:class:`StampGrid` tells the two apart from the data: the motor angle is smooth in the time base its samples were
taken on.  On a block of :data:`DECIDE_ROWS` rows whose stamps scatter around their grid by more than
:data:`GRID_TOLERANCE` T_s, it compares the median absolute second difference of alpha1 over the index with that
of alpha1 interpolated from the stamps onto the grid.  Clearly smoother on the stamps (below
:data:`SMOOTHER_RATIO`): from then on every row is interpolated (linearly, between the two stamps around each grid
instant) onto the uniform grid t_0 + k T_s, and the stamps' jitter no longer reaches the detector (nor do steps
between jittered stamps beyond ``gap_tolerance`` T_s that lose no sample: up to 2 T_s are bridged).  Clearly
smoother on the index (above 1 / SMOOTHER_RATIO), or stamps on their grid: the rows go through as they are, for
good.  Undecided (the drive at rest: no motion tells the two apart): the block goes through as it is and the next
one is tested (the rows of a block under test go through as they are: no delay).  A
longer step, or a clock set back by more, is not bridged (the grid starts again after it, and the detector counts
the gap or the jump); a stamp a little out of order or repeated goes through no later than the row before it (the
detector counts it).

A recording faster than T_s by an integer factor k (stamps stepping by T_s/k, 2 <= k <= :data:`MAX_DECIMATION`,
decided from the first two rows) is decimated first: every k-th row is taken, the rest dropped, and it is said
(the detectors' and the gap stage's sample counts were chosen at 2 kHz; a user who sets T_s to the stamps' period
gets every row).

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math

import numpy as np

#: Rows per decision block (0.2 s at 2 kHz).
DECIDE_ROWS = 400
#: Stamps within this share of T_s of their fitted grid are the grid (the usual case; CSV stamps rounded to
#: microseconds included): the rows go through as they are.
GRID_TOLERANCE = 0.02
#: alpha1's second differences on the stamps below this share of the index's: the stamps are the instants.
#: Chosen on the vector drive sampled with a 25 µs rms jitter (zoo_variants "sampling jitter 25 µs": 0.010-0.011),
#: tested with 50 µs (0.004-0.005) and with uniform samples under jittered stamps ("stamping jitter 50 µs": 75-76);
#: docs/results.md.
SMOOTHER_RATIO = 0.5

MODES = ("undecided", "index", "stamps")
#: The largest integer ratio of T_s to the stamps' step that is decimated (a faster recording than T_s).
MAX_DECIMATION = 16


def _ordinal(k: int) -> str:
    return f"{k}{'nd' if k % 10 == 2 and k != 12 else 'rd' if k % 10 == 3 and k != 13 else 'th'}"


def _roughness(x: np.ndarray) -> float:
    return float(np.median(np.abs(np.diff(x, 2)))) if x.size > 2 else 0.0


def grid_deviation(t: np.ndarray) -> np.ndarray:
    """Each stamp's deviation from the stamps' least-squares grid t_0 + k T (T fitted), s."""
    k = np.arange(t.size, dtype=float)
    slope, t0 = np.polyfit(k, t, 1)
    return t - (t0 + slope * k)


class StampGrid:
    """Rows (n, c) with the stamps in column 0 -> rows on the time base the samples were taken on (module
    docstring).  ``alpha_col``: the column of alpha1 (None: no angle, the rows always go through).

    Attributes: ``mode`` (one of :data:`MODES`), ``jitter_rms_s`` (the stamps' rms deviation from their grid in
    the deciding block), ``ratio`` (alpha1's roughness on the stamps over that on the index there), ``resampled``
    (rows written on the grid)."""

    def __init__(self, sample_period_s: float, alpha_col: int | None, gap_tolerance: float = 1.5,
                 decide_rows: int = DECIDE_ROWS):
        self.sample_period_s = float(sample_period_s)
        self.alpha_col = alpha_col
        self.gap_tolerance = float(gap_tolerance)
        self.decide_rows = int(decide_rows)
        self.mode = "undecided" if alpha_col is not None else "index"
        self.jitter_rms_s = math.nan
        self.ratio = math.nan
        self.resampled = 0
        self._block: list = []
        self._held = 0
        self._prev: np.ndarray | None = None
        self._next_t = math.nan
        self.decimation = 0                       # 0: not decided yet (the first two rows decide), else k
        self._rows_in = 0
        self._first: np.ndarray | None = None

    def said(self) -> str:
        """One line when the rows were decimated or put on the grid ('' otherwise)."""
        out = []
        if self.decimation > 1:
            out.append(f"the stamps step by T_s/{self.decimation} ({self.decimation / self.sample_period_s:g} Hz): "
                       f"every {_ordinal(self.decimation)} sample taken (the detectors' and the gap stage's sample counts "
                       f"were chosen at sampling.sample_period_s; set it to the stamps' period to take them all)")
        if self.mode == "stamps":
            out.append(f"the stamps scatter {1e6 * self.jitter_rms_s:.3g} µs rms around their grid and alpha1 is "
                       f"smoother on them ({self.ratio:.2g} x the sample index's roughness): they are the sampling "
                       f"instants, {self.resampled} rows interpolated onto the T_s grid")
        return "; ".join(out)

    def summary(self) -> dict:
        return {"time_base": self.mode, "jitter_rms_s": self.jitter_rms_s, "angle_roughness_ratio": self.ratio,
                "rows_resampled": self.resampled, "decimated_by": max(self.decimation, 1)}

    def _decimate(self, x: np.ndarray) -> np.ndarray:
        """Every k-th row (k = :attr:`decimation`, decided from the first two rows' step: the stamps step by
        T_s/k within 10 % for an integer k in 2..:data:`MAX_DECIMATION`), counted from the stream's first row."""
        if self.decimation == 0:
            if self._first is not None:
                x = np.vstack([self._first, x])
                self._first = None
            if x.shape[0] < 2:
                self._first = x
                return x[:0]
            step = float(np.median(np.diff(x[:, 0])))
            k = round(self.sample_period_s / step) if step > 0 else 1
            ok = 2 <= k <= MAX_DECIMATION and abs(k * step - self.sample_period_s) <= 0.1 * self.sample_period_s
            self.decimation = k if ok else 1
        if self.decimation == 1:
            return x
        keep = (self._rows_in + np.arange(x.shape[0])) % self.decimation == 0
        self._rows_in += x.shape[0]
        return x[keep]

    def feed(self, x: np.ndarray) -> np.ndarray:
        """One block of rows in stream order; returns the rows to hand on (possibly a different number)."""
        x = self._decimate(np.asarray(x, dtype=np.float64))
        if self.mode == "index" or x.shape[0] == 0:
            return x
        if self.mode == "stamps":
            return self._regrid(x)
        self._block.append(x)                     # undecided: the rows go through, a copy decides
        self._held += x.shape[0]
        if self._held >= self.decide_rows:
            block = np.concatenate(self._block)
            self._block, self._held = [], 0
            self._decide(block)
            if self.mode == "stamps":             # the grid goes on from the last row handed on
                self._prev, self._next_t = x[-1], x[-1, 0] + self.sample_period_s
        return x

    def drop_last_column(self) -> None:
        """The input loses its last channel (a1 left out): the grid goes on without it."""
        self._block, self._held = [], 0
        if self._prev is not None:
            self._prev = self._prev[:-1]

    def _decide(self, block: np.ndarray) -> None:
        t = block[:, 0]
        if not np.all(np.diff(t) > 0):            # out of order / repeated: the detector's to count
            return
        dev = grid_deviation(t)
        if float(np.max(np.abs(dev))) <= GRID_TOLERANCE * self.sample_period_s:
            self.mode = "index"
            return
        a = block[:, self.alpha_col]
        grid = t[0] + self.sample_period_s * np.arange(int((t[-1] - t[0]) / self.sample_period_s) + 1)
        by_index, by_stamps = _roughness(a), _roughness(np.interp(grid, t, a))
        if by_index <= 0.0 and by_stamps <= 0.0:
            return                                # at rest: nothing tells the two apart
        self.jitter_rms_s = float(np.sqrt(np.mean(dev * dev)))
        self.ratio = by_stamps / by_index if by_index > 0 else math.inf
        if self.ratio < SMOOTHER_RATIO:
            self.mode = "stamps"
        elif self.ratio > 1.0 / SMOOTHER_RATIO:
            self.mode = "index"

    @property
    def _bridge_s(self) -> float:
        """The longest step between two stamps interpolated across: gap_tolerance T_s widened by the jitter (6 rms,
        two stamps' 3) up to 2 T_s (one missing sample may then be bridged)."""
        ts = self.sample_period_s
        return max(self.gap_tolerance * ts, min(self.gap_tolerance * ts + 6.0 * self.jitter_rms_s, 2.0 * ts))

    def _regrid(self, x: np.ndarray) -> np.ndarray:
        """Rows on the grid: one interpolation per column where every step is forward and bridged (the usual
        batch), else row by row (:meth:`_regrid_rows`)."""
        prev, ts = self._prev, self.sample_period_s
        if prev is not None and x.shape[0]:
            t = np.concatenate([[prev[0]], x[:, 0]])
            d = np.diff(t)
            if d.min() > 0 and d.max() <= self._bridge_s:
                n = int(math.floor((t[-1] - self._next_t) / ts)) + 1 if t[-1] >= self._next_t else 0
                g = self._next_t + ts * np.arange(n)
                rows = np.vstack([prev, x])
                out = np.column_stack([g] + [np.interp(g, t, rows[:, j]) for j in range(1, x.shape[1])])
                self._prev, self._next_t = x[-1], self._next_t + n * ts
                self.resampled += n
                return out
        return self._regrid_rows(x)

    def _regrid_rows(self, x: np.ndarray) -> np.ndarray:
        out = []
        ts = self.sample_period_s
        for row in x:
            t = row[0]
            prev = self._prev
            if prev is None or abs(t - prev[0]) > self._bridge_s:          # a start, a gap, a clock set back
                out.append(row)
                self._prev, self._next_t = row, t + ts
                continue
            if t <= prev[0]:                       # out of order / repeated: no later than the last row out, for
                r = row.copy()                     # the detector to count
                r[0] = min(t, out[-1][0] if out else self._next_t - ts)
                out.append(r)
                continue
            while self._next_t <= t:
                w = (self._next_t - prev[0]) / (t - prev[0])
                r = prev + w * (row - prev)
                r[0] = self._next_t
                out.append(r)
                self.resampled += 1
                self._next_t += ts
            self._prev = row
        return np.array(out).reshape(-1, x.shape[1])


__all__ = ["DECIDE_ROWS", "GRID_TOLERANCE", "MAX_DECIMATION", "MODES", "SMOOTHER_RATIO", "StampGrid", "grid_deviation"]
