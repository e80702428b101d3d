"""The load side's free interval: the rows where the load encoder shows no coupling torque (issue 20).

Inside the gap the load is a free mass under its own torque (the process, its friction): its angle α2 is smooth,
a cubic in time over the gap for a constant or linearly ramping load torque.  At the entry and at the re-contact
the coupling torque appears on the load, and its acceleration jumps by the coupling torque over J2.  On a drive
whose load is light after the event (a line slipping off its wheel leaves the wheel, 0.12 kg m² against J1 =
1.16) the re-contact changes the *motor's* acceleration by about 10 % only: the motor's own change-point test
(gap_free.free_angle_fit) took 46 contact samples for free motion there and J1 was published +32.8 % off, and the
spring's release before the entry (8 samples) for free motion, +13 % (the DOL zoo, motulator's induction machine on
line: docs/vector_drive.md).  The load's acceleration jumps from about 0 to m_el/(J1 + J_w) at that re-contact:
it shows the change point where the motor does not.

:func:`load_free_bounds` grows the interval from the detector's coarse gap as the motor's test does (the tightest
third of it as the core, then the end, the start and the end again; a candidate is accepted when its cubic fit's
residual is noise by a χ² test and its last CHANGEPOINT_FORECAST_SAMPLES rows are predicted by the fit without them,
Chow's forecast test), and the angle fits stay inside it.  A cubic absorbs part of a kink, so the bound can come a
few samples after the true change point: it is a bound (the motor's own test decides inside it), never a location.
The load angle's scale and offset (gear ratio, encoder offset) do not matter: the test is on the angle's own
noise and quantum.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import numpy as np

from jident_ros.identify import lapack
from jident_ros.identify.distributions import normal_isf
from jident_ros.identify.gap_free import _FORECAST_ROWS, CHANGEPOINT_FORECAST_SAMPLES, FREE_MIN_SAMPLES
from jident_ros.identify.gap_numerics import _einsum, _quantum, _robust_noise, chi2_bounds, chi2_upper, memo_get, memo_put

#: The window key of the load angle the gap stage reads for the bound (the detector windows' raw alpha2: the gap
#: stage must not read it as inequality 1's zone-centred angle).
LOAD_ANGLE_KEY = "load_angle"
#: Degree of the load angle's polynomial in a free interval (3: a linearly ramping load torque).
LOAD_POLY_DEGREE = 3
#: The test's noise is never below a quantum of this (rad), a 2^16-count encoder's: a finer one shows the load's
#: own departures from a cubic (our simulator's process load at 2^18 and 2^20 counts/rev without a floor: the bound
#: 2-8 rows inside 18-28-row gaps, the interval coverage of `jident evaluate --full`'s encoder sweep 97.6 -> 93.5 %
#: at 2^18); the bound was chosen at 2^13 and 2^16 (the DOL and second drives).  At 2^15's quantum a light wheel's
#: re-contact (test_gap_load's slip window) went unseen for 20 rows.
LOAD_NOISE_FLOOR_RAD = 2.0 * np.pi / 2 ** 16
#: Growing an end tests the first SCAN_DENSE candidates each, then every SCAN_STRIDE-th (then the ones before the first
#: failure).
SCAN_DENSE, SCAN_STRIDE = 24, 4
#: Cores tried in the coarse gap after the first's interval, each joined to it where they share a core's rows.
MORE_CORES = 2
#: Rows of the core the interval grows from.
CORE_SAMPLES = 2 * FREE_MIN_SAMPLES
#: A core that starts before the detector's entry row (none after it fits) must reach this many rows past it.
CORE_LATE_OVERLAP = 4
#: A candidate interval is consistent when its residual sum of squares (and its end rows' forecast error) is below
#: the (1 - this) χ² quantile: stricter than the motor's test (gap_free.CHANGEPOINT_P, 1e-3), as the load angle's
#: quantisation error is correlated when the load turns by near a whole number of counts per sample (the second
#: drive's 2^13 encoder: at 1e-3 the bound fell 25 samples inside a 62-sample gap), and a contact's jump on the load
#: side is large (the DOL slip: the bound 1 sample after the re-contact at 1e-6 too)
LOAD_CHANGEPOINT_P = 1e-6
_Z_LOAD = float(normal_isf(LOAD_CHANGEPOINT_P))


def _chi2_upper(dof) -> np.ndarray:
    """The (1 - LOAD_CHANGEPOINT_P) quantile of χ² with ``dof`` degrees of freedom (gap_free's Wilson-Hilferty)."""
    return chi2_upper(dof, _Z_LOAD)


_CHI2_FORECAST = float(_chi2_upper(np.array([CHANGEPOINT_FORECAST_SAMPLES]))[0])


def _design(n: int, origin: int, scale: float) -> np.ndarray:
    u = (np.arange(n) - origin) / scale
    return np.vander(u, LOAD_POLY_DEGREE + 1, increasing=True)


def _first_free_core(X: np.ndarray, y: np.ndarray, starts, s2: float) -> tuple | None:
    """The core: the first CORE_SAMPLES rows, starting at one of ``starts`` in order (the detector's entry row on),
    that a cubic fits to the noise (the detector's re-contact row may be late, the DOL slip's by 21 samples; its entry
    a few samples early, into the spring's release); None: no bound (the motor's own test decides alone)."""
    bound = s2 * float(_chi2_upper(np.array([CORE_SAMPLES - X.shape[1]]))[0])
    for k in starts:
        c = lapack.lstsq(X[k:k + CORE_SAMPLES], y[k:k + CORE_SAMPLES])
        rs = y[k:k + CORE_SAMPLES] - X[k:k + CORE_SAMPLES] @ c
        if float(rs @ rs) <= bound:
            return k, k + CORE_SAMPLES
    return None


class _Scan:
    """The χ² and forecast tests of candidate intervals [lo, hi) of the load angle's cubic, from cumulative normal
    equations on the residual of the core's fit (small numbers: the differences lose nothing)."""

    def __init__(self, X: np.ndarray, y: np.ndarray, core: tuple, s2: float):
        n, p = X.shape
        c0 = lapack.lstsq(X[core[0]:core[1]], y[core[0]:core[1]])
        self.X, self.r, self.s2, self.p, self.n = X, y - X @ c0, s2, p, n
        self.chi_bound = s2 * chi2_bounds(n, p, _Z_LOAD)
        Z = np.zeros((n + 1, p * p + p + 1))       # cumulative x xᵀ, x r and r² (a zero row in front)
        Z[1:, :p * p] = _einsum("ki,kj->kij", X, X).reshape(n, p * p)
        Z[1:, p * p:p * p + p] = X * self.r[:, None]
        Z[1:, -1] = self.r * self.r
        np.cumsum(Z, axis=0, out=Z)
        self.Z = Z

    def first_failure(self, lo_rows: np.ndarray, hi_rows: np.ndarray, side: str):
        """Index of the first candidate not accepted (None: all are).  The SCAN_DENSE candidates next to the core
        each (a contact or a spring's release there may fail one row and pass the next: every 4th alone put the DOL
        slip's 2^13 window back at +13 %), then every SCAN_STRIDE-th and those before the first that fails: the
        batched inverses of every candidate cost 0.7 ms on a 200-row gap (bench/bench_gap.py's load reversal)."""
        n = lo_rows.size
        tested = np.concatenate([np.arange(min(SCAN_DENSE, n)), np.arange(SCAN_DENSE, n, SCAN_STRIDE)])
        k = self._failure(lo_rows[tested], hi_rows[tested], side)
        if k is None or tested[k] < SCAN_DENSE:
            return None if k is None else int(tested[k])
        fine = np.arange(tested[k - 1] + 1, tested[k])
        j = self._failure(lo_rows[fine], hi_rows[fine], side) if fine.size else None
        return int(tested[k]) if j is None else int(fine[j])

    def _failure(self, lo_rows: np.ndarray, hi_rows: np.ndarray, side: str):
        p, k_f = self.p, CHANGEPOINT_FORECAST_SAMPLES
        if side == "end":
            ilo, ihi, test = lo_rows, hi_rows - k_f, hi_rows[:, None] - k_f + _FORECAST_ROWS
        else:
            ilo, ihi, test = lo_rows + k_f, hi_rows, lo_rows[:, None] + _FORECAST_ROWS
        c = lo_rows.size
        D = self.Z[np.concatenate([hi_rows, ihi])] - self.Z[np.concatenate([lo_rows, ilo])]
        Ainv = lapack.inv(D[:, :p * p].reshape(-1, p, p))
        sol = _einsum("kij,kj->ki", Ainv, D[:, p * p:p * p + p])
        rss = D[:c, -1] - _einsum("ki,ki->k", D[:c, p * p:p * p + p], sol[:c])
        ok = rss <= self.chi_bound[hi_rows - lo_rows]
        xt = self.X[test]
        pred = _einsum("ckp,cp->ck", xt, sol[c:])
        lev = _einsum("ckq,ckq->ck", xt @ Ainv[c:], xt)
        stat = ((self.r[test] - pred) ** 2 / (self.s2 * (1.0 + lev))).sum(axis=1)
        bad = np.flatnonzero(~(ok & ((ihi - ilo < p + 2) | (stat <= _CHI2_FORECAST))))
        return int(bad[0]) if bad.size else None

    def grow_end(self, s_row: int, e_from: int) -> int:
        cand = np.arange(max(s_row + FREE_MIN_SAMPLES, e_from), self.n + 1)
        if cand.size == 0:
            return e_from
        k = self.first_failure(np.full(cand.size, s_row), cand, "end")
        return int(cand[-1]) if k is None else int(cand[max(k - 1, 0)])

    def grow_start(self, e_row: int, s_from: int) -> int:
        cand = np.arange(min(e_row - FREE_MIN_SAMPLES, s_from), -1, -1)
        if cand.size == 0:
            return s_from
        k = self.first_failure(cand, np.full(cand.size, e_row), "start")
        return int(cand[-1]) if k is None else int(cand[max(k - 1, 0)])


def load_free_bounds(alpha2, start: int, end: int, search: int) -> tuple | None:
    """(lo, hi): the window rows around the coarse gap [start, end) (± ``search``) in which the load angle is a
    free mass's (module docstring); None when the window has no usable load angle (too few rows, constant)."""
    if alpha2 is None:
        return None
    a = np.asarray(alpha2, float)
    n_all = a.size
    L, R = max(0, start - search), min(n_all, end + search)
    # the same rows give the same bound: kept while the window is estimated (its lag check fits it again)
    key = ("load_free_bounds", a[L:R].tobytes(), L, R, start, end, search)
    kept = memo_get(key)
    if kept is None:
        kept = memo_put(key, (_free_bounds(a, L, R, start, end, search),))
    return kept[0]


def _free_bounds(a: np.ndarray, L: int, R: int, start: int, end: int, search: int) -> tuple | None:
    """:func:`load_free_bounds` over the rows [L, R) of the load angle ``a``."""
    if R - L < CORE_SAMPLES + FREE_MIN_SAMPLES or not np.all(np.isfinite(a[L:R])):
        return None
    y = a[L:R] - a[start]
    X = _design(R - L, start - L, max(end - start, 1))
    lo_c, hi_c = start - L, end - L
    q = _quantum(a[L:R])
    # the noise: the encoder's quantum (uniform, q²/12; the robust estimate from second differences overstates it
    # 4-fold on a quantised angle that accelerates), else the angle's own (robust, second differences)
    s2 = max(q * q / 12.0 if q > 0 else _robust_noise(a[L:R]) ** 2, LOAD_NOISE_FLOOR_RAD ** 2 / 12.0)
    if not float(np.ptp(y)) > 10.0 * np.sqrt(s2):
        return None                                       # the load does not move: nothing to read
    # (the core starts at most `search` rows after the detector's entry: its cost stays bounded on a long coarse gap)
    core = _first_free_core(X, y, range(lo_c, min(max(lo_c, hi_c - CORE_SAMPLES), R - L - CORE_SAMPLES,
                                                  lo_c + search) + 1), s2)
    if core is None:
        # the detector's entry late (the DOL slip's, 12 samples, 4 before the re-contact): a core that starts before
        # it and still reaches into the coarse gap by CORE_LATE_OVERLAP rows, nearest the entry first
        core = _first_free_core(X, y, range(lo_c - 1, max(lo_c - CORE_SAMPLES + CORE_LATE_OVERLAP, 0) - 1, -1), s2)
    if core is None:
        return None
    grown = _grown(X, y, core, s2)
    if grown is None:
        return None
    # a load torque that changes over a long gap (a slip's) is no cubic over all of it, and the first core may lie in
    # a contact whose torque fades smoothly (a soft damped coupling letting go: a cubic follows it over 16 rows): the
    # interval grown from the first core then ends inside the gap (blind DOL draws d4-01, d4-05, d4-12: 103, 64 and
    # 62 rows before the re-contact; on d4-05 and d4-12 the motor's fit, kept to the fading contact, published J1
    # +6 %, +9 % outside its interval).  The coarse gap's rows after it get a core of their own, and where its
    # interval shares at least a core's rows with the one before, the load is free over both (a contact between them
    # would be a kink no cubic over the shared rows passes): the bound is their hull.  Sharing fewer rows they may be
    # the two sides of a re-contact's kink, each absorbing part of it (test_gap_load's light wheel: 8 rows)
    for _ in range(MORE_CORES):
        after = _first_free_core(X, y, range(grown[1], hi_c - CORE_SAMPLES + 1), s2)
        other = None if after is None else _grown(X, y, after, s2)
        if other is None or other[1] <= grown[1] or grown[1] - other[0] < CORE_SAMPLES:
            break
        grown = (min(grown[0], other[0]), other[1])
    return L + grown[0], L + grown[1]


def _grown(X: np.ndarray, y: np.ndarray, core: tuple, s2: float) -> tuple | None:
    """(start, end) rows of X grown from ``core``, each end from the core alone (a bound on each side, not the best
    interval: a heavy load's entry barely shows on its side, and a start grown past it would pull the end in); None
    when the scan's matrices are singular."""
    scan = _Scan(X, y, core, s2)
    with np.errstate(all="ignore"):
        try:
            return scan.grow_start(core[1], core[0]), scan.grow_end(core[0], core[1])
        except np.linalg.LinAlgError:
            return None


__all__ = ["LOAD_ANGLE_KEY", "LOAD_POLY_DEGREE", "load_free_bounds"]
