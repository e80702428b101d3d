"""Robustness evaluation ("Beyond the paper", item 4): the gap estimator, the fused
verdict and the paper's image method side by side on the same simulated windows,
off the paper's grid and under measurement imperfections.

Sweeps (:func:`run_robustness`):

(a) the 168 grid cases noise-free and at SNR 60/40/30/20 dB (one seed per level; the
    gap estimator and the fused verdict's gap part also on ``extra_seeds``);
(b) off-grid J1: 1.16 x {0.99, 1.01, 0.88}, 1.10 and 1.00 kg m^2 at every grid width
    and eta_k, noise-free and at 30 dB;
(c) off-grid backlash widths {0.003, 0.0045, 0.006, 0.0085} m at the grid's J1 and
    eta_k, noise-free and at 30 dB (the image method uses the nearest library width);
(d) encoder quantisation of alpha1/alpha2 (2^12 ... 2^20 counts per revolution):
    gap interval, J1 and width estimate, and the motor-encoder-only 'angle' fit;
(e) other sample periods (0.25 ms, 1 ms): the gap estimator only (the pattern
    library is built for 0.5 ms).

Noise is :func:`jident_ros.sim.add_measurement_noise` (MATLAB's awgn 'measured'
SNR over the window, on a1, m_el, omega1, a2, v2, omega2; angles are not noised).
Plain numpy/scipy: no rclpy, no matplotlib (figures: ``jident_ros.research.evaluation.report_robustness``).
"""
from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from jident_ros.identify.fusion import fuse_verdict
from jident_ros.identify.gap import (
    GapEstimate,
    NoGapError,
    estimate_backlash_width,
    estimate_inertia,
    fit_cache,
    nearest_class,
)
from jident_ros.method.patterns import PatternLibrary, identify_windows
from jident_ros.sim import (
    Case,
    CaseTruths,
    SystemConfig,
    WindowSet,
    add_measurement_noise,
    paper_grid_cases,
    quantise_encoders,
    simulate_grid,
)
from jident_ros.sim.sensors import DEFAULT_SENSORS, apply_sensors

#: Gap-estimator channel sets: key -> (channels, fit method, description).
#: 'auto' is the default of the product (gap.estimate_inertia's model choice: the joint fit when the
#: pre-entry torque is steady, else 'gap_only'); 'gap_only' beside it shows what the fit without the
#: pre-entry anchor gives on the same windows.
CHANNEL_SETS = {
    "angles": (("alpha1", "alpha2", "a1", "m_el"), "auto", "α1+α2+a1+m_el"),
    "no_angles": (("a1", "m_el"), "auto", "a1+m_el (no angles)"),
    "gap_only": (("alpha1", "alpha2", "a1", "m_el"), "gap_only", "α1+α2+a1+m_el, gap-only fit (in-zone samples, no pre-entry anchor)"),
    "anchored": (("alpha1", "alpha2", "a1", "m_el"), "anchored", "α1+α2+a1+m_el, first-release fit (pre-entry anchor)"),
    "speed": (("omega1", "m_el"), "speed", "ω1+m_el (speed fit)"),
    "angle_eq1": (("alpha1", "alpha2", "m_el"), "angle", "α1+α2+m_el (no accelerometer)"),
    "angle": (("alpha1", "m_el"), "angle", "α1+m_el (motor encoder only)"),
}
#: The channel set whose estimate feeds the fused verdict and the width estimate.
PRIMARY = "angles"

SNR_LEVELS_DB = (60.0, 40.0, 30.0, 20.0)
#: Off-grid J1 values: (label, J1 in kg m^2).
OFFGRID_J1 = (("1.16 × 0.99", 1.16 * 0.99), ("1.16 × 1.01", 1.16 * 1.01), ("1.16 × 0.88", 1.16 * 0.88),
              ("1.10", 1.10), ("1.00", 1.00))
OFFGRID_WIDTHS_M = (0.003, 0.0045, 0.006, 0.0085)
ENCODER_COUNTS = (2 ** 12, 2 ** 14, 2 ** 16, 2 ** 18, 2 ** 20)
#: Channel sets run on the quantised windows: the primary one and the two without an accelerometer.
ENCODER_KEYS = (PRIMARY, "angle_eq1", "angle")
SAMPLE_PERIODS_S = (0.25e-3, 1e-3)
#: Noise level of the noisy off-grid sweeps and of the second target.
TARGET_SNR_DB = 30.0


@dataclass
class Sweep(CaseTruths):
    """Every method's answer on one set of windows (arrays indexed by case).

    gap[key] : dict with 'estimate', 'lo', 'hi' (kg m^2), 'rel_error', 'covered' (bool),
        'n_gap' (samples, 0 when failed), 'gap_end' (-1 when failed), 'failed' {case: reason}
    width : dict 'estimate' (m), 'rel_error' or None (needs the angles)
    verdict : dict 'class' (-1 when between classes), 'between' (bool), 'inertia', 'source' or None
    image : dict 'fused_class', 'vote_class' (-1 where not evaluated), 'width_used' (m), 'evaluated' (bool) or None
    """

    label: str
    kind: str
    cases: list
    snr_db: float | None
    seed: int | None
    sample_period_s: float
    counts_per_rev: int | None = None
    noised: tuple | None = None                  # channels that carry noise (None: add_measurement_noise's default)
    gap: dict = field(default_factory=dict)
    width: dict | None = None
    verdict: dict | None = None
    image: dict | None = None
    seconds: float = 0.0

    # ------------------------------------------------------------ truths (and CaseTruths')
    def true_class(self, classes) -> np.ndarray:
        """Index of the true J1 in ``classes``, -1 when J1 is off the classes."""
        cl = [float(c) for c in classes]
        return np.array([cl.index(j) if j in cl else -1 for j in self.true_inertia_kgm2])

    def nearest_true_class(self, classes) -> np.ndarray:
        return np.array([nearest_class(j, classes) for j in self.true_inertia_kgm2])

    def pattern_mask(self, pattern_eta: float) -> np.ndarray:
        return np.array([c.consistency_pa_sn == pattern_eta for c in self.cases])

    # ---------------------------------------------------------- summaries
    def gap_summary(self, key: str = PRIMARY, mask=None) -> dict:
        """median/max |relative error|, CI coverage, failures over the cases in ``mask``."""
        g = self.gap[key]
        m = np.ones(len(self.cases), bool) if mask is None else np.asarray(mask, bool)
        err = np.abs(g["rel_error"][m])
        ok = np.isfinite(err)
        n_gap = g["n_gap"][m][ok]
        half = (0.5 * (g["hi"] - g["lo"]) / self.true_inertia_kgm2)[m][ok]
        return {"n": int(m.sum()), "failed": int((~ok).sum()),
                "median": float(np.median(err[ok])) if ok.any() else np.nan,
                "max": float(np.max(err[ok])) if ok.any() else np.nan,
                "p95": float(np.percentile(err[ok], 95)) if ok.any() else np.nan,
                # coverage counts a failed estimate as not covering
                "coverage": float(g["covered"][m].mean()) if m.any() else np.nan,
                "ci_half": float(np.median(half)) if half.size else np.nan,
                "gap_samples": (int(n_gap.min()), int(n_gap.max())) if n_gap.size else (0, 0)}

    def width_summary(self, mask=None) -> dict:
        if self.width is None:
            return {}
        m = np.ones(len(self.cases), bool) if mask is None else np.asarray(mask, bool)
        err = np.abs(self.width["rel_error"][m])
        ok = np.isfinite(err)
        return {"n": int(m.sum()), "failed": int((~ok).sum()),
                "median": float(np.median(err[ok])) if ok.any() else np.nan,
                "max": float(np.max(err[ok])) if ok.any() else np.nan}

    def accuracy(self, classes, mask=None) -> dict:
        """Class accuracy of the gap's nearest class, the fused verdict and the image method
        over on-class cases (in ``mask``); 'between' = share of fused verdicts flagged between classes."""
        true = self.true_class(classes)
        m = (true >= 0) if mask is None else (np.asarray(mask, bool) & (true >= 0))
        out = {"n": int(m.sum())}
        g = self.gap[PRIMARY]
        gcls = np.array([nearest_class(e, classes) if np.isfinite(e) else -1 for e in g["estimate"]])
        out["gap"] = float((gcls[m] == true[m]).mean()) if m.any() else np.nan
        if self.verdict is not None:
            out["fused"] = float((self.verdict["class"][m] == true[m]).mean()) if m.any() else np.nan
            out["between"] = float(self.verdict["between"][m].mean()) if m.any() else np.nan
        if self.image is not None:
            mi = m & self.image["evaluated"]
            out["n_image"] = int(mi.sum())
            out["image"] = float((self.image["fused_class"][mi] == true[mi]).mean()) if mi.any() else np.nan
            out["image_vote"] = float((self.image["vote_class"][mi] == true[mi]).mean()) if mi.any() else np.nan
        return out

    def offclass_outcomes(self, classes, mask=None) -> dict:
        """For off-class J1: shares of fused verdicts 'between classes', 'nearest class', 'other class',
        and the image method's share answering the nearest class."""
        near = self.nearest_true_class(classes)
        m = np.ones(len(self.cases), bool) if mask is None else np.asarray(mask, bool)
        out = {"n": int(m.sum())}
        if self.verdict is not None and m.any():
            b = self.verdict["between"][m]
            c = self.verdict["class"][m]
            out["between"] = float(b.mean())
            out["nearest"] = float(((~b) & (c == near[m])).mean())
            out["other"] = float(((~b) & (c != near[m])).mean())
        if self.image is not None:
            mi = m & self.image["evaluated"]
            out["n_image"] = int(mi.sum())
            out["image_nearest"] = float((self.image["fused_class"][mi] == near[mi]).mean()) if mi.any() else np.nan
        return out


@dataclass
class RobustnessResult:
    """All sweeps of :func:`run_robustness` and the target checks."""

    classes_kgm2: tuple
    widths_m: tuple
    pattern_eta: float
    grid: list                       # Sweep per noise level (noise-free first), grid cases
    grid_extra: list                 # gap-estimator-only Sweeps at extra seeds (same SNR levels)
    offgrid_j1: list                 # Sweep per data (noise-free, 30 dB)
    offgrid_width: list              # Sweep per data (noise-free, 30 dB)
    quantisation: list               # Sweep per counts/rev (noise-free), reference = grid[0]
    sample_period: list              # Sweep per (Ts, data), gap estimator only
    library_widths_m: tuple
    seconds: float
    timings: dict = field(default_factory=dict)
    image_stride: int = 1
    wheel_radius_m: float = 0.1
    targets: list = field(default_factory=list)
    notes: dict = field(default_factory=dict)
    attribution: list = field(default_factory=list)   # gap estimator, target SNR on one channel only
    command: str = "jident evaluate"
    sensors: list = field(default_factory=list)       # Sweep per sensor-noise factor (default sensor set x k)
    sensor_set: str = ""                              # the default sensor set in words

    def sweep(self, group: str, label: str) -> Sweep:
        for s in getattr(self, group):
            if s.label == label:
                return s
        raise KeyError(f"{group}: no sweep labelled {label!r}")


# ---------------------------------------------------------------------------------------- core
def gap_on_windows(system: SystemConfig, windows: WindowSet, keys: Sequence[str] = tuple(CHANNEL_SETS)) -> dict:
    """The gap estimator with each channel set on every window (see :data:`CHANNEL_SETS`)."""
    r = system.load.wheel_radius_m
    n = len(windows.cases)
    true = np.array([c.inertia_kgm2 for c in windows.cases])
    out = {}
    with fit_cache():        # the channel sets share a window's angle fits ('angles' cross-checks, 'angle_eq1')
        for key in keys:
            chans, meth, _ = CHANNEL_SETS[key]
            est, lo, hi, se = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
            n_gap, end = np.zeros(n, int), np.full(n, -1)
            failed = {}
            for i, c in enumerate(windows.cases):
                win = {k: windows.signals[k][i] for k in chans}
                try:
                    g = estimate_inertia(win, windows.entry_index, c.backlash_width_m, r, windows.sample_period_s,
                                         meth, system.motor.bearing_friction_nms_per_rad)
                except NoGapError as exc:
                    failed[i] = str(exc)
                    continue
                est[i], (lo[i], hi[i]), se[i] = g.inertia_kgm2, g.ci95_kgm2, g.std_error_kgm2
                n_gap[i], end[i] = g.n_samples, g.gap_end
            out[key] = {"estimate": est, "lo": lo, "hi": hi, "se": se, "rel_error": (est - true) / true,
                        "covered": np.isfinite(est) & (lo <= true) & (true <= hi), "n_gap": n_gap, "gap_end": end,
                        "failed": failed}
    return out


def width_on_windows(system: SystemConfig, windows: WindowSet, gap_end: np.ndarray, inertia=None) -> dict:
    """Backlash width at re-contact (needs the angles-based gap end; with the gap's J1 in ``inertia``
    and a1, m_el in the windows, the contact-torque fit of :func:`gap.estimate_backlash_width`)."""
    r = system.load.wheel_radius_m
    n = len(windows.cases)
    est, std = np.full(n, np.nan), np.full(n, np.nan)
    how = np.full(n, "", dtype=object)
    chans = [k for k in ("alpha1", "alpha2", "a1", "m_el") if k in windows.signals]
    for i in range(n):
        if gap_end[i] < 0:
            continue
        win = {k: windows.signals[k][i] for k in chans}
        j1 = None if inertia is None or not np.isfinite(inertia[i]) else float(inertia[i])
        try:
            w = estimate_backlash_width(win, int(gap_end[i]), r, windows.sample_period_s, j1)
        except NoGapError:
            continue
        est[i], std[i], how[i] = w.width_m, w.std_m, w.method
    true = np.array([c.backlash_width_m for c in windows.cases])
    return {"estimate": est, "std": std, "method": how, "rel_error": (est - true) / true,
            "covered": np.isfinite(est) & (np.abs(est - true) <= 1.96 * std)}


def image_and_verdict(system: SystemConfig, windows: WindowSet, gap: dict, library: PatternLibrary,
                      method, p: float = 2.0, stride: int = 1) -> tuple[dict, dict]:
    """The image method (identify_window at p) on every ``stride``-th window, and the fused
    verdict on every window (image answers where evaluated, the primary gap estimate)."""
    classes = tuple(float(c) for c in system.grid.inertia_classes_kgm2)
    n = len(windows.cases)
    fused, vote = np.full(n, -1), np.full(n, -1)
    used = np.full(n, np.nan)
    evaluated = np.zeros(n, bool)
    v_cls, v_between, v_j1, v_src = np.full(n, -1), np.zeros(n, bool), np.full(n, np.nan), []
    g = gap[PRIMARY]
    # identify_window of every stride-th window, the features in one batch (patterns.identify_windows: the
    # same answers, bit for bit, at ~40 % of the per-window cost)
    image_rows = range(0, n, stride)
    idents = dict(zip(image_rows, identify_windows([windows.case(i) for i in image_rows], windows.entry_index,
                                                   [windows.cases[i].backlash_width_m for i in image_rows],
                                                   library, method, p)))
    for i, c in enumerate(windows.cases):
        answers, fci = None, None
        if i % stride == 0:
            ident = idents[i]
            answers, fci = ident.answers, ident.fused_class_index
            fused[i], evaluated[i] = fci, True
            used[i] = library.widths_m[ident.width_index]
        ge = None
        if np.isfinite(g["estimate"][i]):
            ge = GapEstimate(float(g["estimate"][i]), float(g["se"][i]), (float(g["lo"][i]), float(g["hi"][i])),
                             np.nan, windows.entry_index, int(g["gap_end"][i]), CHANNEL_SETS[PRIMARY][1], "angles")
        if ge is None and answers is None:
            v_src.append("none")
            continue
        v = fuse_verdict(classes, answers, fci, ge, g["failed"].get(i, ""))
        if answers is not None:
            vote[i] = -1 if v.image_class_index is None else v.image_class_index
        v_cls[i] = -1 if v.class_index is None else v.class_index
        v_between[i], v_j1[i] = v.between_classes, v.inertia_kgm2
        v_src.append(v.source)
    return ({"fused_class": fused, "vote_class": vote, "width_used": used, "evaluated": evaluated},
            {"class": v_cls, "between": v_between, "inertia": v_j1, "source": np.array(v_src)})


def gap_only_verdict(system: SystemConfig, gap: dict) -> dict:
    """fuse_verdict without image answers.  Where the gap estimate exists the verdict's class and
    'between classes' flag do not depend on the image answers (fusion.fuse_verdict), so this equals
    the full verdict there; windows without a gap estimate get class -1 and source 'none' (the full
    verdict would fall back to the image vote)."""
    classes = tuple(float(c) for c in system.grid.inertia_classes_kgm2)
    g = gap[PRIMARY]
    n = g["estimate"].size
    cls, between, j1, src = np.full(n, -1), np.zeros(n, bool), np.full(n, np.nan), []
    for i in range(n):
        if not np.isfinite(g["estimate"][i]):
            src.append("none")
            continue
        ge = GapEstimate(float(g["estimate"][i]), float(g["se"][i]), (float(g["lo"][i]), float(g["hi"][i])), np.nan,
                         0, int(g["gap_end"][i]), CHANNEL_SETS[PRIMARY][1], "angles")
        v = fuse_verdict(classes, None, None, ge)
        cls[i] = -1 if v.class_index is None else v.class_index
        between[i], j1[i] = v.between_classes, v.inertia_kgm2
        src.append(v.source)
    return {"class": cls, "between": between, "inertia": j1, "source": np.array(src)}


def evaluate_windows(system: SystemConfig, windows: WindowSet, label: str, kind: str, *,
                     library: PatternLibrary | None = None, method=None, p: float = 2.0, stride: int = 1,
                     keys: Sequence[str] = tuple(CHANNEL_SETS), snr_db=None, seed=None,
                     counts_per_rev=None, gap_verdict: bool = False) -> Sweep:
    """One :class:`Sweep`: the gap estimator (``keys``), the width, and, with a library, the
    image method and the fused verdict, all on the same ``windows``.  Without a library,
    ``gap_verdict`` still computes the fused verdict from the gap estimate alone (see
    :func:`gap_only_verdict`)."""
    t0 = time.perf_counter()
    sw = Sweep(label, kind, list(windows.cases), snr_db, seed, windows.sample_period_s, counts_per_rev)
    sw.gap = gap_on_windows(system, windows, keys)
    if PRIMARY in sw.gap:
        sw.width = width_on_windows(system, windows, sw.gap[PRIMARY]["gap_end"], sw.gap[PRIMARY]["estimate"])
    if library is None and gap_verdict and PRIMARY in sw.gap:
        sw.verdict = gap_only_verdict(system, sw.gap)
    if library is not None:
        if PRIMARY not in sw.gap:
            raise ValueError(f"keys: the fused verdict needs the {PRIMARY!r} gap estimate")
        sw.image, sw.verdict = image_and_verdict(system, windows, sw.gap, library, method, p, stride)
    sw.seconds = time.perf_counter() - t0
    return sw


def offgrid_j1_cases(system: SystemConfig, values=OFFGRID_J1) -> list[Case]:
    g = system.grid
    return [Case(float(j), float(w), float(e)) for e in g.consistency_indices_pa_sn for _, j in values
            for w in g.backlash_widths_m]


def offgrid_width_cases(system: SystemConfig, widths=OFFGRID_WIDTHS_M) -> list[Case]:
    g = system.grid
    return [Case(float(j), float(w), float(e)) for e in g.consistency_indices_pa_sn
            for j in g.inertia_classes_kgm2 for w in widths]


def _noisy(windows: WindowSet, snr, seed):
    return windows if snr is None else add_measurement_noise(windows, snr, seed)


def noise_seed(base: int, snr_db: float, salt: int = 0) -> int:
    """Seed of one noisy data set: fixed by (base seed, SNR, sweep), independent of which other
    levels are run (so --quick and the full run draw the same 30 dB noise)."""
    return int(base) * 1000 + int(round(10 * float(snr_db))) + int(salt)


def _data_label(snr, seed) -> str:
    return "noise-free" if snr is None else f"SNR {snr:g} dB (seed {seed})"


def run_robustness(system: SystemConfig, method, library: PatternLibrary | None = None, log=print, *,
                   snr_db: Sequence[float] = SNR_LEVELS_DB, seed: int = 1, extra_seeds: Sequence[int] = (2, 3, 4, 5),
                   offgrid_j1=OFFGRID_J1, offgrid_widths=OFFGRID_WIDTHS_M, encoder_counts=ENCODER_COUNTS,
                   sample_periods=SAMPLE_PERIODS_S, target_snr_db: float = TARGET_SNR_DB, p: float = 2.0,
                   image_stride: int = 1, grid_cases: Sequence[Case] | None = None,
                   quick: bool = False, sensor_factors: Sequence[float] = (1.0, 3.0, 10.0),
                   jobs: int = 1) -> RobustnessResult:
    """Every sweep (module docstring); ``image_stride`` > 1 runs the image method (and with it the
    image part of the fused verdict) on every k-th window only. ``grid_cases`` replaces the 168 grid
    cases (tests). The pattern library is built from the noise-free eta_k = 0.025 runs at p unless given.
    ``quick`` (smoke run, ~15 s): SNR 30 dB only, no extra seeds, the image method on every 4th window.
    ``jobs`` >= 2: the gap-only sweeps (extra noise seeds, attribution, quantisation, sample periods: :func:`_gap_only_sweeps`)
    run in a process of their own beside the others (the same function on the same inputs: the same numbers)."""
    if quick:
        snr_db, extra_seeds, image_stride = (target_snr_db,), (), max(image_stride, 4)
        sensor_factors = tuple(sensor_factors)[:1]
    t_all = time.perf_counter()
    log = log or (lambda *a: None)
    timings = {}
    g = system.grid
    classes = tuple(float(c) for c in g.inertia_classes_kgm2)
    mp = method.replace(p_values=(float(p),))
    if image_stride < 1:
        raise ValueError(f"image_stride must be >= 1, got {image_stride!r}")

    # (a) the grid ---------------------------------------------------------------------------
    t0 = time.perf_counter()
    cases = list(paper_grid_cases(system) if grid_cases is None else grid_cases)
    clean = simulate_grid(system, cases)
    timings["simulate grid"] = time.perf_counter() - t0
    if library is None:
        t0 = time.perf_counter()
        eta = g.pattern_consistency_pa_sn
        wanted = [Case(float(j), float(w), eta) for j in g.inertia_classes_kgm2 for w in g.backlash_widths_m]
        have = {c: i for i, c in enumerate(clean.cases)}
        if all(c in have for c in wanted):
            library = PatternLibrary.build(system, mp, windows=clean)
        else:
            library = PatternLibrary.build(system, mp)
        timings["pattern library (p = %g)" % p] = time.perf_counter() - t0
    else:
        library.p_index(p)  # refuse a library without this p
        mp = method
    kw = dict(library=library, method=mp, p=p, stride=image_stride)
    grid = []
    levels = [None] + [float(s) for s in snr_db]
    noisy_levels = [None] + ([target_snr_db] if target_snr_db is not None else [])
    gap_only_args = (system, clean, cases, levels, tuple(extra_seeds), seed, target_snr_db, noisy_levels,
                     tuple(sample_periods), tuple(encoder_counts))
    pool = None
    if jobs >= 2:
        pool = ProcessPoolExecutor(max_workers=1)
        gap_only_future = pool.submit(_gap_only_sweeps, *gap_only_args)
    for k, snr in enumerate(levels):
        sd = None if snr is None else noise_seed(seed, snr)
        sw = evaluate_windows(system, _noisy(clean, snr, sd), _data_label(snr, sd), "grid", snr_db=snr, seed=sd, **kw)
        grid.append(sw)
        s, a = sw.gap_summary(), sw.accuracy(classes)
        log(f"robustness, grid {sw.label}: gap max |error| {s['max'] * 100:.3f} %, CI coverage "
            f"{s['coverage'] * 100:.1f} %, fused {a['fused'] * 100:.1f} %, image {a['image'] * 100:.1f} % "
            f"({sw.seconds:.1f} s)")
    sensor_sweeps = []
    for k, factor in enumerate(sensor_factors):
        sd = noise_seed(seed, 0.0, 20 + k)
        sw = evaluate_windows(system, apply_sensors(clean, DEFAULT_SENSORS.scaled(factor), sd,
                                                   system.motor.base.torque_nm),
                              f"default sensor set × {factor:g} (seed {sd})", "sensors", seed=sd, **kw)
        sensor_sweeps.append(sw)
        a = sw.accuracy(classes)
        log(f"robustness, grid {sw.label}: gap class {a['gap'] * 100:.1f} %, fused {a['fused'] * 100:.1f} %, "
            f"image {a['image'] * 100:.1f} % ({sw.seconds:.1f} s)")
    timings["grid sweeps"] = np.nan       # with the extra seeds' sweeps, below
    # (b) off-grid J1 ------------------------------------------------------------------------

    def offgrid_sweeps(cases, kind: str, name: str, salt: int) -> list[Sweep]:
        """The off-grid cases simulated once, evaluated noise-free and at the target SNR (noise seed salt)."""
        t0 = time.perf_counter()
        w = simulate_grid(system, cases)
        sweeps = []
        for snr in noisy_levels:
            sd = None if snr is None else noise_seed(seed, snr, salt)
            sweeps.append(evaluate_windows(system, _noisy(w, snr, sd), _data_label(snr, sd), kind,
                                           snr_db=snr, seed=sd, **kw))
        timings[name] = time.perf_counter() - t0
        log(f"robustness, {name}: {len(w.cases)} cases x {len(sweeps)} data sets ({timings[name]:.1f} s)")
        return sweeps

    offj = offgrid_sweeps(offgrid_j1_cases(system, offgrid_j1), "offgrid_j1", "off-grid J1", 1) if offgrid_j1 else []

    # (c) off-grid widths --------------------------------------------------------------------
    offw = (offgrid_sweeps(offgrid_width_cases(system, offgrid_widths), "offgrid_width", "off-grid widths", 2)
            if offgrid_widths else [])

    # (d) encoder quantisation: with the gap-only sweeps below
    timings["encoder quantisation"] = np.nan

    # the gap-only sweeps: (a) extra noise seeds and the attribution, (e) sample periods
    if pool is not None:
        with pool:
            grid_extra, attribution, quant, per, gap_only_timings = gap_only_future.result()
    else:
        grid_extra, attribution, quant, per, gap_only_timings = _gap_only_sweeps(*gap_only_args)
    timings["grid sweeps"] = sum(s.seconds for s in grid + grid_extra)
    timings.update(gap_only_timings)

    res = RobustnessResult(classes, tuple(float(x) for x in g.backlash_widths_m), float(g.pattern_consistency_pa_sn),
                           grid, grid_extra, offj, offw, quant, per, tuple(library.widths_m),
                           time.perf_counter() - t_all, timings, int(image_stride),
                           float(system.load.wheel_radius_m))
    res.attribution = attribution
    res.sensors = sensor_sweeps
    res.sensor_set = DEFAULT_SENSORS.describe(clean.sample_period_s, system.motor.base.torque_nm)
    res.notes.update(speed_scale(clean, grid[0]))
    res.targets = check_targets(res, target_snr_db)
    for t in res.targets:
        log(f"robustness target {t['name']}: {t['measured']} -> {'met' if t['met'] else 'NOT met'}")
    log(f"robustness evaluation: {res.seconds:.1f} s")
    return res


def _gap_only_sweeps(system: SystemConfig, clean: WindowSet, cases, levels, extra_seeds, seed: int, target_snr_db,
                     noisy_levels, sample_periods, encoder_counts) -> tuple:
    """The sweeps of :func:`run_robustness` without the image method: the grid at the extra noise seeds (with the
    gap-only verdict), the attribution (noise on one channel only, at the target SNR), the encoder quantisation and
    the sample periods.  Returns (grid_extra, attribution, quantisation sweeps, sample-period sweeps, timings)."""
    grid_extra = []
    for es in extra_seeds:
        for k, snr in enumerate(levels[1:], start=1):
            sd = noise_seed(es, snr)
            grid_extra.append(evaluate_windows(system, add_measurement_noise(clean, snr, sd), _data_label(snr, sd),
                                               "grid", snr_db=snr, seed=sd, gap_verdict=True))
    attribution = []
    if target_snr_db is not None:  # which channel's noise limits the gap estimator (cheap: no image method)
        for chans in (("a1",), ("m_el",)):
            for es in (seed,) + tuple(extra_seeds):
                sd = noise_seed(es, target_snr_db, 9)
                sw = evaluate_windows(system, add_measurement_noise(clean, target_snr_db, sd, channels=chans),
                                      f"{target_snr_db:g} dB on {'+'.join(chans)} only (seed {sd})", "attribution",
                                      keys=(PRIMARY, "no_angles"), snr_db=target_snr_db, seed=sd)
                sw.noised = chans
                attribution.append(sw)
    # (d) encoder quantisation
    t0 = time.perf_counter()
    quant = [evaluate_windows(system, quantise_encoders(clean, int(n)), f"{int(n)} counts/rev", "quantisation",
                              keys=ENCODER_KEYS, counts_per_rev=int(n)) for n in encoder_counts]
    timings = {"encoder quantisation": time.perf_counter() - t0}
    # (e) sample periods: the gap estimator only
    t0 = time.perf_counter()
    per = []
    for j, ts in enumerate(sample_periods):
        w = simulate_grid(system, cases, sample_period_s=float(ts))
        for k, snr in enumerate(noisy_levels):
            sd = None if snr is None else noise_seed(seed, snr, 3 + j)
            per.append(evaluate_windows(system, _noisy(w, snr, sd), f"Ts = {ts * 1e3:g} ms, {_data_label(snr, sd)}",
                                        "sample_period", snr_db=snr, seed=sd))
    timings["sample periods"] = time.perf_counter() - t0
    return grid_extra, attribution, quant, per, timings


def speed_scale(clean: WindowSet, sweep: Sweep) -> dict:
    """Why the speed fit suffers from 'measured' noise: RMS of omega1 over the window, and the speed
    change across the gap (noise-free, from the primary gap interval)."""
    w1 = clean.signals["omega1"]
    rms = np.sqrt(np.mean(w1 * w1, axis=1))
    end = sweep.gap[PRIMARY]["gap_end"]
    ok = end > clean.entry_index
    idx = np.arange(len(end))[ok]
    dw = w1[idx, end[ok] - 1] - w1[idx, clean.entry_index]
    return {"omega1_rms_rad_s": (float(rms.min()), float(rms.max())),
            "gap_speed_change_rad_s": (float(dw.min()), float(dw.max())) if dw.size else (np.nan, np.nan)}


# ------------------------------------------------------------------------------------ targets
def _max_err(sweeps, key=PRIMARY) -> tuple[float, int, int]:
    """(max |rel error|, failures, cases) over sweeps (failures count as not meeting)."""
    errs = np.concatenate([np.abs(s.gap[key]["rel_error"]) for s in sweeps]) if sweeps else np.array([])
    ok = np.isfinite(errs)
    return (float(errs[ok].max()) if ok.any() else np.nan), int((~ok).sum()), int(errs.size)


def check_targets(res: RobustnessResult, target_snr_db: float | None = TARGET_SNR_DB) -> list[dict]:
    """The issue's targets with the measured numbers (primary channel set α1+α2+a1+m_el)."""
    out = []
    names = {"grid": "grid", "offgrid_j1": "off-grid J1", "offgrid_width": "off-grid widths"}
    clean = [s for s in [res.grid[0]] + res.offgrid_j1 + res.offgrid_width if s.snr_db is None]

    def add(name, target, value, met, measured):
        out.append({"name": name, "target": target, "value": value, "met": bool(met), "measured": measured})

    def per_group(sweeps):
        parts = []
        for s in sweeps:
            m, nf, n = _max_err([s])
            parts.append(f"{names[s.kind]} {m * 100:.3f} %" + (f" ({nf} of {n} without an estimate)" if nf else ""))
        return ", ".join(parts)

    m, nf, n = _max_err(clean)
    add("gap |J1 error|, noise-free", "≤ 0.5 % on the 168 grid cases and the off-grid values", m,
        nf == 0 and m <= 0.005, f"max {m * 100:.3f} % over {n} windows ({per_group(clean)})")
    if target_snr_db is not None:
        noisy = [s for s in res.grid + res.offgrid_j1 + res.offgrid_width if s.snr_db == target_snr_db]
        m, nf, n = _max_err(noisy)
        add(f"gap |J1 error|, {target_snr_db:g} dB", "≤ 2 % on the 168 grid cases and the off-grid values", m,
            nf == 0 and m <= 0.02, f"max {m * 100:.3f} % over {n} windows ({per_group(noisy)})")
        extra = [s for s in res.grid_extra if s.snr_db == target_snr_db]
        if extra:
            m2, nf2, n2 = _max_err(noisy + extra)
            ex = np.concatenate([np.abs(s.gap[PRIMARY]["rel_error"]) for s in noisy + extra])
            frac = float(np.mean(ex <= 0.02))
            add(f"gap |J1 error|, {target_snr_db:g} dB, {1 + len(extra)} noise seeds on the grid",
                "≤ 2 % (same target, more noise draws)", m2, nf2 == 0 and m2 <= 0.02,
                f"max {m2 * 100:.3f} % over {n2} windows (grid × {1 + len(extra)} seeds + off-grid); "
                f"≤ 2 % in {frac * 100:.1f} % of them")
    noisy_all = [s for s in res.grid + res.grid_extra + res.offgrid_j1 + res.offgrid_width if s.snr_db is not None]
    if noisy_all:
        cov = np.concatenate([s.gap[PRIMARY]["covered"] for s in noisy_all])
        lv = sorted({s.snr_db for s in noisy_all}, reverse=True)
        add("gap 95 % CI coverage, noisy cases", "≥ 95 %", float(cov.mean()), cov.mean() >= 0.95,
            f"{cov.mean() * 100:.1f} % of {cov.size} noisy windows (SNR {', '.join(f'{x:g}' for x in lv)} dB)")
    for group, label in (([s for s in clean if s.kind == "grid"], "168 grid cases"),
                         ([s for s in clean if s.kind != "grid"], "off-grid J1 and widths")):
        wsw = [s for s in group if s.width is not None]
        if not wsw:
            continue
        we = np.concatenate([np.abs(s.width["rel_error"]) for s in wsw])
        ok = np.isfinite(we)
        mw = float(we[ok].max()) if ok.any() else np.nan
        within = float(np.mean(we[ok] <= 0.05)) if ok.any() else np.nan
        add(f"backlash width error, noise-free, {label}", "≤ 5 %", mw, ok.all() and mw <= 0.05,
            f"max {mw * 100:.2f} % over {we.size} windows (≤ 5 % in {within * 100:.1f} %)"
            + (f", {int((~ok).sum())} failed" if (~ok).any() else ""))
    a0 = res.grid[0].accuracy(res.classes_kgm2)
    if "fused" in a0:
        add("fused class accuracy, noise-free grid", "100 %", a0["fused"], a0["fused"] >= 1.0,
            f"{a0['fused'] * 100:.1f} % of {a0['n']}")
    if target_snr_db is not None:
        for s in res.grid:
            if s.snr_db == target_snr_db and s.verdict is not None:
                a = s.accuracy(res.classes_kgm2)
                add(f"fused class accuracy, {target_snr_db:g} dB grid", "≥ 98 %", a["fused"], a["fused"] >= 0.98,
                    f"{a['fused'] * 100:.1f} % of {a['n']} ({a['between'] * 100:.1f} % flagged between classes)")
                extra = [x for x in res.grid_extra if x.snr_db == target_snr_db and x.verdict is not None]
                if extra:
                    accs = [x.accuracy(res.classes_kgm2) for x in [s] + extra]
                    n = sum(x["n"] for x in accs)
                    f = sum(x["fused"] * x["n"] for x in accs) / n
                    lo, hi = min(x["fused"] for x in accs), max(x["fused"] for x in accs)
                    add(f"fused class accuracy, {target_snr_db:g} dB grid, {len(accs)} noise seeds", "≥ 98 %", f,
                        f >= 0.98, f"{f * 100:.1f} % of {n} (per seed {lo * 100:.1f}–{hi * 100:.1f} %)")
    return out
