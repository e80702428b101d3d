"""The free angle fit's change-point scan (issue 20 item 1): the candidate intervals of a gap in which the motor
angle is a free mass's, grown from quiet cores of the detector's coarse gap by a χ² test of the whole interval and
Chow's forecast test of its end rows.

gap_free.free_angle_fit calls :meth:`IntervalScan.intervals` and fits J1 over each candidate (the most precise one is
the gap); its module docstring and docs/method.md ("The free angle fit") say what the scan decides and why.  Moved
out of free_angle_fit in stop 41, its closures as this class's methods (test_sizes named that function's length and
nesting as a debt; the numbers are the same: the draws' sections, the goldens and bench_gap's windows are identical).
The rules are gap_free's module constants, handed over as :class:`ScanRules` at each call, so a test that changes one
of them there is followed here (and this module never imports gap_free: no cycle).  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jident_ros.identify import lapack
from jident_ros.identify.gap_numerics import _einsum, _scan_sums, _sym3_inverse, chi2_bounds


@dataclass(frozen=True)
class ScanRules:
    """gap_free's constants the scan follows (their docstrings there): FREE_MIN_SAMPLES,
    CHANGEPOINT_FORECAST_SAMPLES, the forecast test's χ² bound, the normal quantile of CHANGEPOINT_P, CORE_VAR_RATIO,
    OTHER_CORES_BELOW and FITTED_CONSTANT_SCAN."""

    free_min_samples: int
    forecast_samples: int
    chi2_forecast: float
    z: float
    core_var_ratio: float
    other_cores_below: float
    fitted_constant_scan: bool


class IntervalScan:
    """The scan over the rows [L, R) of a window (row 0 here is the window's row L).

    ``y``: the motor angle from the coarse gap's first row, rad; ``Xs``: the scan's design [1, u, Φ_mid/scale] (the
    physics with the friction band's middle); ``q``: the encoder's quantum, rad (the noise floor); [lo_c, hi_c): the
    detector's coarse gap; ``W``: the change-point search span, rows; ``rules``: :class:`ScanRules`."""

    def __init__(self, y: np.ndarray, Xs: np.ndarray, q: float, lo_c: int, hi_c: int, W: int, rules: ScanRules):
        self.y, self.Xs, self.q, self.lo_c, self.hi_c, self.W, self.rules = y, Xs, q, lo_c, hi_c, W, rules
        self.n = y.size
        self.forecast_rows = np.arange(rules.forecast_samples)

    def cores(self) -> tuple:
        """(core, cores): the coarse gap's core (its ends moved in by up to half the search span), and the cores grown
        from: its quiet thirds (a long coarse interval may hold contact, a later flank's re-contact row: a third whose
        residual variance is within CORE_VAR_RATIO of the quietest), else the core itself."""
        lo_c, hi_c, W, fmin, y, Xs = self.lo_c, self.hi_c, self.W, self.rules.free_min_samples, self.y, self.Xs
        k_in = min(W // 2, max((hi_c - lo_c) // 4, 0))
        core = (lo_c + k_in, hi_c - k_in) if hi_c - lo_c - 2 * k_in >= fmin else (lo_c, hi_c)
        if core[1] - core[0] < fmin:
            core = (max(0, min(lo_c, self.n - fmin)), max(0, min(lo_c, self.n - fmin)) + fmin)
        third = (core[1] - core[0]) // 3
        if third < 2 * fmin:
            return core, [core]
        subs, var = [(core[0] + k * third, core[0] + (k + 1) * third) for k in range(3)], []
        for a0, b0 in subs:
            rs = y[a0:b0] - Xs[a0:b0] @ lapack.lstsq(Xs[a0:b0], y[a0:b0])
            var.append(float(rs @ rs) / (third - Xs.shape[1]))
        return core, [subs[k] for k in range(3) if var[k] <= self.rules.core_var_ratio * min(var)]

    def grown(self, cr: tuple, Xs: np.ndarray | None = None) -> tuple:
        """The interval grown from the core rows ``cr`` (e, s, e again; the noise from the core's fit) with the design
        ``Xs`` (the scan's, by default)."""
        Xs = self.Xs if Xs is None else Xs
        y = self.y
        c0 = lapack.lstsq(Xs[cr[0]:cr[1]], y[cr[0]:cr[1]])
        r = y - Xs @ c0
        rc = r[cr[0]:cr[1]]
        s2 = max(float(rc @ rc) / max(rc.size - Xs.shape[1], 1), self.q * self.q / 12.0, 1e-30)
        # the cumulative sums shared by every candidate below, and the χ² test's bound s2 · χ²(1 - CHANGEPOINT_P; n - p)
        # for every interval length n (at least 1 dof)
        test = (Xs, r, s2, _scan_sums(Xs, r), s2 * chi2_bounds(self.n, Xs.shape[1], self.rules.z))
        e_row = self._grow_end(test, cr[0], cr[1])
        s_row = self._grow_start(test, e_row, cr[0])
        e_row = self._grow_end(test, s_row, cr[1] if cr[1] <= e_row else e_row)
        return s_row, e_row

    def _first_failure(self, test: tuple, lo_rows: np.ndarray, hi_rows: np.ndarray, side: str):
        """Index of the first candidate interval [lo, hi) that is not accepted (None: all are).  Accepted: the whole
        interval's residual is noise (χ² test) and its k_f end rows on ``side`` are predicted by the fit without them
        (Chow's forecast test: a contaminated end shows in the extrapolation first).  Every candidate's two fits (over
        [lo, hi) and over the interval without the k_f rows) in one batch: normal matrices from the cumulative sums,
        inverted in closed form (a decision, not a published number: the inverse's product where the earlier code
        solved, the same test to rounding)."""
        Xs, r, s2, sums, chi_bound = test
        k_f, p = self.rules.forecast_samples, Xs.shape[1]
        if side == "end":
            ilo, ihi, rows = lo_rows, hi_rows - k_f, hi_rows[:, None] - k_f + self.forecast_rows
        else:
            ilo, ihi, rows = lo_rows + k_f, hi_rows, lo_rows[:, None] + self.forecast_rows
        c = lo_rows.size
        D = sums[np.concatenate([hi_rows, ihi])] - sums[np.concatenate([lo_rows, ilo])]
        Ainv = _sym3_inverse(D[:, :6])
        sol = _einsum("kij,kj->ki", Ainv, D[:, 6:9])
        rss = D[:c, 9] - _einsum("ki,ki->k", D[:c, 6:9], sol[:c])
        ok = rss <= chi_bound[hi_rows - lo_rows]
        xt = Xs[rows]                                             # (cand, k_f, p)
        pred = _einsum("ckp,cp->ck", xt, sol[c:])
        lev = _einsum("ckq,ckq->ck", xt @ Ainv[c:], xt)          # x A⁻¹ xᵀ of each test row
        stat = ((r[rows] - pred) ** 2 / (s2 * (1.0 + lev))).sum(axis=1)
        bad = np.flatnonzero(~(ok & ((ihi - ilo < p + 2) | (stat <= self.rules.chi2_forecast))))
        return int(bad[0]) if bad.size else None

    def _grow_end(self, test: tuple, s_row: int, e_from: int) -> int:
        cand = np.arange(max(s_row + self.rules.free_min_samples, e_from), min(self.hi_c + self.W, self.n) + 1)
        if cand.size == 0:
            return e_from
        k = self._first_failure(test, np.full(cand.size, s_row), cand, "end")
        return int(cand[-1]) if k is None else int(cand[max(k - 1, 0)])

    def _grow_start(self, test: tuple, e_row: int, s_from: int) -> int:
        cand = np.arange(min(e_row - self.rules.free_min_samples, s_from), max(self.lo_c - self.W, 0) - 1, -1)
        if cand.size == 0:
            return s_from
        k = self._first_failure(test, cand, np.full(cand.size, e_row), "start")
        return int(cand[-1]) if k is None else int(cand[max(k - 1, 0)])

    def intervals(self, L: int, Phi: np.ndarray, Cc: np.ndarray, phi_scale: float, coulomb_max_nm: float,
                  offset_nm: float) -> tuple:
        """The candidate intervals (window rows: ``L`` added), the first core's first.

        Every quiet third grows its own interval (one inside an interval grown already is not grown again); of the
        intervals the one whose J1 is the most precise is the gap (gap_free.free_angle_fit).  A core in a rest where
        the coupling still carries a small torque (a soft coupling that touched zero and sprang back before the gap
        opened) grows into a short interval whose J1 takes that torque; the gap's own core grows over the gap.
        ``Phi``, ``Cc``: the double integrals of the torque and of the motion's sign over the rows; ``phi_scale``: Φ's
        scale; the friction band [0, ``coulomb_max_nm``] and the offset band ± ``offset_nm``, N m."""
        rules, lo_c, hi_c = self.rules, self.lo_c, self.hi_c
        core, cores = self.cores()
        s_row, e_row = self.grown(cores[0])
        intervals = [(L + s_row, L + e_row)]
        covered = min(e_row, hi_c) - max(s_row, lo_c)
        short = covered < rules.other_cores_below * (hi_c - lo_c)
        for other in cores[1:] if short else ():
            if any(a0 <= L + other[0] and L + other[1] <= b0 for a0, b0 in intervals):
                continue
            s_o, e_o = self.grown(other)
            if e_o - s_o >= rules.free_min_samples and (L + s_o, L + e_o) not in intervals:
                intervals.append((L + s_o, L + e_o))
        if rules.fitted_constant_scan and short and (coulomb_max_nm or offset_nm):
            self._constant_again(intervals, L, core, cores, (Phi, Cc, phi_scale), (coulomb_max_nm, offset_nm))
        return tuple(intervals)

    def _constant_again(self, intervals: list, L: int, core: tuple, cores: list, integrals: tuple, bands: tuple) -> None:
        """The scan's assumed friction (the band's middle) is not the gap's constant torque (the friction and the
        estimate's offset): the intervals stop where that difference has curved the angle.  The constant fitted over
        the coarse gap's core, kept within its bands, and the quiet cores grown again with it; an interval longer than
        every one before by the fit's minimum joins ``intervals`` (the rows the assumed friction cut off, not the same
        gap moved by a few rows: DOL d16-12's 94 rows beside the 98 grown before).  ``integrals``: (Φ, C, Φ's scale) of
        :meth:`intervals`; ``bands``: (the friction band's top, the offset band), N m."""
        (Phi, Cc, phi_scale), (coulomb_max_nm, offset_nm) = integrals, bands
        Xs, y = self.Xs, self.y
        cc_core = Cc[core[0]:core[1]]
        c_core = max(float(np.abs(cc_core).max()), 1e-300)
        X4 = np.column_stack([Xs[core[0]:core[1], :2], Phi[core[0]:core[1]] / phi_scale, cc_core / c_core])
        c4 = lapack.lstsq(X4, y[core[0]:core[1]])
        if not c4[2] > 0:
            return
        f_hat = -float(c4[3]) / c_core / (c4[2] / phi_scale)
        f_hat = min(max(f_hat, -float(offset_nm)), float(coulomb_max_nm) + float(offset_nm))
        phi_hat = Phi - f_hat * Cc
        X3 = np.column_stack([Xs[:, :2], phi_hat / max(float(np.abs(phi_hat).max()), 1e-300)])
        # (a core inside one grown already is not grown again, as above)
        longest, again = max(b0 - a0 for a0, b0 in intervals), []
        for cr in cores:
            if any(a0 <= cr[0] and cr[1] <= b0 for a0, b0 in again):
                continue
            s_o, e_o = self.grown(cr, X3)
            again.append((s_o, e_o))
            if e_o - s_o >= longest + self.rules.free_min_samples and (L + s_o, L + e_o) not in intervals:
                intervals.append((L + s_o, L + e_o))


__all__ = ["IntervalScan", "ScanRules"]
