"""Backlash-zone entries from the dynamics, for drives whose angles are missing or too coarse (pure numpy, never
imports rclpy).

Paper section 2: while the clutch is on a flank the motor carries the load, inside the backlash zone it carries
none (the motor side is a single mass, J1 dω1/dt = m_el).  So the **load torque on the motor**

    T_L = m_el - J1_nom dω1/dt          (J1_nom = ``nominal_inertia_kgm2``, the motor's nominal J1)

is the steady load while in contact and falls to about zero when contact is lost: contact loss is a step of
T_L toward zero.  dω1/dt comes from ``a1`` (a1 / r, no delay) or, without an accelerometer, from the motor
encoder's smoothed second difference (Savitzky-Golay, quadratic, ``acceleration_window_samples`` = 15 samples:
a 2^16-count encoder's quantisation makes the 7-sample derivative's T_L noise about 22 % of the load on our
simulator, the 15-sample one's 5 %; the detector then runs (window - 1)/2 = 7 samples behind the stream, and
the rows without that many neighbours on each side, at the very start and end of the data, take dω1/dt = 0).
No α2, no K2 and no zone-centred angle is used.

:class:`DynamicsDetector` is the :class:`~jident_ros.stream.flank.FlankDetector` with T_L in place of the
relative angle δ:

* **contact** (a load carried): a run of ``contact_samples`` samples whose T_L has mean mu and standard deviation
  sigma with |mu| > ``k_sigma`` sigma; the **load level** F = mu then follows slow drifts (first-order filter,
  ``flank_time_constant_s``).  A drive that carries no load (|mu| within the noise) has no contact to lose:
  no entry can be seen from the dynamics then;
* **entry**: the first sample on which T_L has moved toward zero (or beyond it) from F by more than
  max(``k_sigma`` sigma, ``drop_fraction`` |F|); the load level is then forgotten and learnt again at the next
  contact;
* **entry sample, re-contact row**: as the flank detector's refinement (:func:`~jident_ros.stream.flank.
  single_mass_run`): the first sample from the departure on whose load torque has vanished, the re-contact row
  the first with load again;
* **window, drops, second entries, cut-off windows**: the flank detector's.  The width estimate needs both
  angles (``no angles`` otherwise: the window's K2 fields are NaN).

False entries over steady stretches and the entries found on both drives: docs/results.md ("Entries from the
dynamics"), ``python -m jident_ros.research.evaluation.raw_inputs --report --detector dynamics``.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np

from jident_ros.stream.detector import _positive
from jident_ros.stream.filters import savgol_coeffs
from jident_ros.stream.flank import FlankDetector
from jident_ros.stream.flank_delta import motor_acceleration
from jident_ros.stream.flank_free import single_mass_run
from jident_ros.stream.rate import odd_samples

#: Without a1 the entry row is searched from this many samples before the departure less the look-ahead on
#: (:func:`angle_entry`; a soft contact unloads before the flanks part).
ANGLE_ENTRY_EARLY = 4


class DynamicsDetector(FlankDetector):
    """Streaming detector of backlash-zone entries from the load-torque step (module docstring).

    Parameters
    ----------
    wheel_radius_m, sample_period_s, samples_before_entry, samples_from_entry, gap_tolerance, gear_ratio,
    encoder_counts_per_rev, refine_samples : as :class:`~jident_ros.stream.flank.FlankDetector`
    nominal_inertia_kgm2 : float   J1_nom in T_L = m_el - J1_nom dω1/dt (required, > 0)
    channels : must hold t, m_el and a1 or alpha1 (a1 is used when both are there); alpha2 is optional
    contact_samples : int          run length that makes a contact (default: 16 ms, 32 samples at 2 kHz)
    k_sigma : float                contact: |mu| > k_sigma sigma; entry: a drop of more than k_sigma sigma (8)
    drop_fraction : float          ... and of more than this share of the load level (0.5)
    flank_time_constant_s : float  drift tracking of the load level (0.05 s)
    acceleration_window_samples : int   Savitzky-Golay window of the encoder's second difference (odd, >= 5;
                                   default 7.5 ms: 15 samples at 2 kHz, the odd count of the same span at T_s, as
                                   the module's other sample counts, durations at 2 kHz: :mod:`jident_ros.stream.rate`)
    """

    detector_name = "dynamics"
    #: An entry inside a running window stays a second entry of it (its load-torque level says nothing of the flank).
    second_windows = False
    #: Its look-ahead history is needed (the smoothed derivative spreads the step over it).
    extra_optional = False
    required_channels = ("t", "m_el")
    required_reason = "the load torque m_el - J1 dω1/dt needs t and m_el"
    missing_channel_hint = ("; the dynamics detector captures every channel in `channels`: on a drive without a load "
                            "encoder leave alpha2 (and the other load-side channels) out of it")

    def __init__(self, wheel_radius_m: float, sample_period_s: float, channels: Sequence[str] = (),
                 nominal_inertia_kgm2: Optional[float] = None, samples_before_entry: int = 48,
                 samples_from_entry: int = 2000, gap_tolerance: float = 1.5, gear_ratio: float = 1.0,
                 contact_samples: Optional[int] = None, k_sigma: float = 8.0, drop_fraction: float = 0.5,
                 flank_time_constant_s: float = 0.05, encoder_counts_per_rev: int = 0,
                 refine_samples: Optional[int] = None, acceleration_window_samples: Optional[int] = None):
        if not _positive(nominal_inertia_kgm2):
            raise ValueError(f"nominal_inertia_kgm2: the dynamics detector needs J1_nom, a finite number > 0, got "
                             f"{nominal_inertia_kgm2!r}")
        if not _positive(drop_fraction) or drop_fraction >= 1.0:
            raise ValueError(f"drop_fraction: must be a number > 0 and < 1, got {drop_fraction!r}")
        if acceleration_window_samples is None and _positive(sample_period_s):
            acceleration_window_samples = odd_samples(15, sample_period_s)
        w = acceleration_window_samples
        if isinstance(w, bool) or int(w) != w or w < 5 or int(w) % 2 == 0:
            raise ValueError(f"acceleration_window_samples: must be an odd integer >= 5, got {w!r}")
        chans = tuple(channels)
        if "a1" not in chans and "alpha1" not in chans:
            raise ValueError(f"channels: need 'a1' or 'alpha1' for the motor acceleration, got {list(chans)}")
        super().__init__(wheel_radius_m, sample_period_s, channels=chans, samples_before_entry=samples_before_entry,
                         samples_from_entry=samples_from_entry, gap_tolerance=gap_tolerance, gear_ratio=gear_ratio,
                         nominal_inertia_kgm2=nominal_inertia_kgm2, contact_samples=contact_samples,
                         k_sigma=k_sigma, flank_time_constant_s=flank_time_constant_s,
                         encoder_counts_per_rev=encoder_counts_per_rev, refine_samples=refine_samples,
                         min_travel_rad=0.0)
        self.drop_fraction = float(drop_fraction)
        self.acceleration_source = "a1" if "a1" in self.channels else "alpha1"
        self.lookahead = 0 if self.acceleration_source == "a1" else int(w) // 2
        self._sg2 = savgol_coeffs(2 * self.lookahead + 1, 2, deriv=2, use="dot")[::-1] if self.lookahead else None
        self.history_extra = self.lookahead + self._n(ANGLE_ENTRY_EARLY) if self.lookahead else 0
        self._i_m = self.channels.index("m_el")
        self._i_acc = self.channels.index(self.acceleration_source)
        self.reset()

    # ------------------------------------------------------------- state
    @property
    def threshold_nm(self) -> float:
        """The drop of T_L toward zero that makes an entry (NaN while no load level is known)."""
        if self._flank is None:
            return math.nan
        return max(self.k_sigma * self._sigma, self.drop_fraction * abs(self._flank))

    @property
    def threshold_rad(self) -> float:   # the flank detector's name; here a torque, N m
        return self.threshold_nm

    @property
    def load_torque_nm(self) -> Optional[float]:
        """The current load level F of T_L, N m (None: no contact learnt)."""
        return self._flank

    def reset(self) -> None:
        super().reset()
        if hasattr(self, "lookahead"):
            n = len(self.channels)
            self._back = np.empty((0, n))      # the last `lookahead` rows handed on (context behind)
            self._held = np.empty((0, n))      # rows not yet handed on (waiting for their look-ahead)
            self._torque = np.empty(0)

    # ------------------------------------------------------------- load torque
    def load_torque(self, rows: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """T_L of ``rows`` with the rows ``before`` and ``after`` them as the derivative's context (a row
        without a full context takes dω1/dt = 0)."""
        m = rows[:, self._i_m]
        if self.lookahead == 0:
            return m - self.nominal_inertia_kgm2 * rows[:, self._i_acc] / self.wheel_radius_m
        h = self.lookahead
        a = np.concatenate([before[:, self._i_acc], rows[:, self._i_acc], after[:, self._i_acc]])
        acc = np.zeros(rows.shape[0])
        off = before.shape[0]
        k = np.arange(rows.shape[0]) + off
        full = (k >= h) & (k + h < a.size)
        if full.any():
            conv = np.convolve(a, self._sg2, mode="valid")        # conv[j] = derivative at row j + h
            acc[full] = conv[k[full] - h] / self.sample_period_s ** 2
        return m - self.nominal_inertia_kgm2 * acc

    def _delta(self, x: np.ndarray) -> np.ndarray:
        return self._torque

    # ------------------------------------------------------------- detection
    def _contact_runs(self, runs: np.ndarray) -> np.ndarray:
        """A load carried: |mean| above k_sigma standard deviations of the run."""
        return np.abs(runs.mean(axis=1)) > self.k_sigma * runs.std(axis=1, ddof=1)

    def _departed(self, seg: np.ndarray, prev: np.ndarray, thr: float) -> np.ndarray:
        """T_L moved toward zero (or beyond it) from the load level by more than the threshold."""
        s = 1.0 if self._flank > 0 else -1.0
        return s * (prev - seg) > thr

    def _consume(self, x: np.ndarray) -> list:
        """Hands the rows on to the flank detector's capture once their T_L is known (``lookahead`` rows later)."""
        last_t = float(x[-1, self._i_t])
        rows = np.concatenate([self._held, x])
        h = self.lookahead
        ready = rows.shape[0] - h
        events = []
        if ready > 0:
            events = self._hand_on(rows[:ready], rows[ready:])
            self._held = rows[ready:]
        else:
            self._held = rows
        self._last_t = last_t
        return events

    def _hand_on(self, rows: np.ndarray, after: np.ndarray) -> list:
        self._torque = self.load_torque(rows, self._back, after)
        back = np.concatenate([self._back, rows])[-self.lookahead:] if self.lookahead else self._back
        events = super()._consume(rows)
        self._back = back
        return events

    def finish(self) -> list:
        """The data ended: the rows still waiting for their look-ahead are handed on, then the flank
        detector's finish (a window in progress is reported as ``cut_off``)."""
        events = []
        if self._held.shape[0]:
            last_t = self._last_t
            held, self._held = self._held, self._held[:0]
            events = self._hand_on(held, held[:0])
            self._last_t = last_t
        return events + super().finish()

    def _refine(self, data: np.ndarray, dep: int):
        """(samples from the departure to the entry sample, re-contact row or None): the flank detector's
        refinement from the dynamics (the 7-sample acceleration of :func:`~jident_ros.stream.flank_delta.motor_acceleration`),
        starting ``lookahead`` samples before the departure (the smoothed derivative spreads the step over its
        window)."""
        wd = {c: data[:, j] for j, c in enumerate(self.channels)}
        acc, _ = motor_acceleration(wd, self.wheel_radius_m, self.sample_period_s)
        start = max(dep - self.lookahead, 1)
        if self.acceleration_source == "alpha1":
            entry = angle_entry(wd["alpha1"], wd["m_el"], self.sample_period_s,
                                dep - self.lookahead - self._n(ANGLE_ENTRY_EARLY), dep + self.lookahead + self._n(2),
                                self._n(40), self._n(12))
            if entry is None:
                return 0, None
            run = single_mass_run(wd["m_el"], acc, entry, self.nominal_inertia_kgm2, self.samples_before_entry,
                                  self._n(3), sample_period_s=self.sample_period_s)
            return entry - dep, (None if run is None else run[1])
        run = single_mass_run(wd["m_el"], acc, start, self.nominal_inertia_kgm2, self.samples_before_entry,
                              self.refine_samples + self.lookahead, sample_period_s=self.sample_period_s)
        if run is None:
            return 0, None
        return run[0] - dep, run[1]


def angle_entry(alpha1: np.ndarray, m_el: np.ndarray, sample_period_s: float, first: int, last: int,
                before: int = 40, after: int = 12) -> Optional[int]:
    """The entry row in [first, last] that best explains the motor angle, or None (rows out of range).

    Before the entry the motor turns steadily, from the entry on J1 d²α1/dt² = m_el, so
    α1(k) = α0 + ω0 k T_s + Z_e(k)/J1 with Z_e the discrete double integral of m_el from row e (0 before it):
    for every candidate e an ordinary least-squares fit of (α0, ω0, 1/J1) over the rows [first - before,
    last + after], and the e of the smallest residual.  Integrals, no differentiation: a coarse encoder's
    quantisation and the noise of m_el average out (the derivative detector's smoothing does not move it)."""
    lo, hi = first - before, last + after
    if first < 1 or lo < 0 or hi > alpha1.size or last < first:
        return None
    y = alpha1[lo:hi] - alpha1[lo]
    k = np.arange(hi - lo, dtype=float)
    best, best_rss = None, math.inf
    for e in range(first, last + 1):
        g = np.zeros(hi - lo)
        j0 = e - lo
        g[j0 + 1:] = np.cumsum(m_el[e:hi - 1]) * sample_period_s      # ω gain at the row, times J1
        z = np.concatenate([[0.0], np.cumsum(g[1:])]) * sample_period_s
        A = np.column_stack([np.ones_like(k), k, z])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        if not coef[2] > 0:
            continue
        r = y - A @ coef
        rss = float(r @ r)
        if rss < best_rss:
            best, best_rss = e, rss
    return best
