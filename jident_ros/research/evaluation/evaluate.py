"""Evaluation of the identification over the paper's full grid (`jident evaluate`).

Everything published in docs/results.md's method section comes from
:func:`run_evaluation` + :func:`render_markdown`.  Honesty rules:

* patterns come only from the eta_k = 0.025 runs; testing on exactly those
  runs is trivially right (distance zero), so those 42 cases are reported
  apart and never counted in the headline accuracy (the other 126 cases);
* noisy windows are tested against the noise-free pattern library.
"""
from __future__ import annotations

import dataclasses
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from jident_ros.identify.gap import NoGapError, estimate_backlash_width, estimate_inertia, nearest_class
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.method.patterns import (
    PatternLibrary,
    fuse,
    matched_seeds,
    rounded_width,
    take_windows,
    with_widths,
)
from jident_ros.method.pipeline import SIGNALS, MethodConfig, batch_features, margin, pre_entry_reference
from jident_ros.sim import Case, SystemConfig, WindowSet, add_measurement_noise, paper_grid_cases, simulate_grid
from jident_ros.sim.model import Model
from jident_ros.sim.profiles import film_share, with_film_share
from jident_ros.sim.sensors import DEFAULT_SENSORS, SensorSpec, apply_sensors

#: Film shares of the validity map (share of the load the film carries at the pattern eta_k); the default
#: profile's share and the heavy-film profile are evaluated beside them.
VALIDITY_FILM_SHARES = (0.0001, 0.001, 0.003, 0.01, 0.03, 0.1)
#: Seed of the default sensor set's noise on the evaluation grid.
SENSOR_SEED = 3

#: The paper's 16 example cases (tables 1-4): signal, J1, width, eta_k, p, the paper's H vector.
PAPER_EXAMPLES = [
    ("a1", 0.957, 0.00375, 0.0375, 2, [9.5409, 8.4485, 7.3105, 6.0374, 0.0671, 10.5406, 11.4658]),
    ("a1", 0.957, 0.00375, 0.0375, 3, [9.4615, 8.3730, 7.2421, 5.9764, 0.0675, 10.4579, 11.3810]),
    ("a1", 1.131, 0.01, 0.0375, 3, [0.0115, 0.0001, 0.0128, 0.0276, 0.1080, 0.0212, 0.0297]),
    ("a1", 1.131, 0.01, 0.0375, 9, [0.0150, 0.0002, 0.0166, 0.0357, 0.1333, 0.0276, 0.0380]),
    ("m_el", 1.102, 0.0075, 0.0125, 2, [0.7347, 0.3730, 0.0012, 0.4137, 2.4923, 1.0490, 1.3497]),
    ("m_el", 1.102, 0.0075, 0.0125, 3, [1.0650, 0.5381, 0.0023, 0.5904, 3.4786, 1.5264, 1.9718]),
    ("m_el", 1.189, 0.01, 0.05, 3, [0.4008, 0.8187, 1.3102, 1.7962, 4.2535, 0.0050, 0.3993]),
    ("m_el", 1.189, 0.01, 0.05, 9, [0.3424, 0.7000, 1.1203, 1.5364, 3.6411, 0.0046, 0.3415]),
    ("omega1", 1.218, 0.005, 0.0125, 2, [0.8648, 1.3365, 1.8056, 2.3249, 4.8432, 0.4357, 0.0604]),
    ("omega1", 1.218, 0.005, 0.0125, 3, [0.8659, 1.3383, 1.8080, 2.3280, 4.8496, 0.4363, 0.0604]),
    ("omega1", 1.218, 0.0025, 0.05, 3, [0.9500, 1.6000, 2.2706, 2.9889, 6.4174, 0.3959, 0.1762]),
    ("omega1", 1.218, 0.0025, 0.05, 6, [0.9391, 1.5815, 2.2445, 2.9548, 6.3460, 0.3913, 0.1741]),
    ("v2", 1.218, 0.01, 0.0125, 2, [1.7737, 2.7766, 3.8581, 5.0250, 10.7233, 0.8414, 0.0263]),
    ("v2", 1.218, 0.01, 0.0125, 3, [1.8340, 2.8699, 3.9862, 5.1898, 11.0535, 0.8704, 0.0272]),
    ("v2", 1.073, 0.009, 0.0375, 3, [3.3018, 2.2717, 1.1624, 0.0330, 5.8461, 4.2600, 5.1521]),
    ("v2", 1.073, 0.009, 0.0375, 6, [1.8634, 1.2977, 0.6724, 0.0195, 3.6275, 2.3761, 2.8415]),
]


@dataclass
class GridResult:
    """H vectors of every case, signal and p for one (method, data) setting.

    h : ndarray (n_p, n_cases, n_signals, n_classes)
    """

    label: str
    method: MethodConfig
    p_values: tuple
    cases: list
    true_class: np.ndarray
    h: np.ndarray
    pattern_mask: np.ndarray       # cases at the pattern eta_k (reported apart)
    seconds: float
    library_seconds: float = 0.0
    notes: dict = field(default_factory=dict)

    def predicted(self) -> np.ndarray:
        """(n_p, n_cases, n_signals) class indices."""
        return np.argmin(self.h, axis=-1)

    def fused_predicted(self) -> np.ndarray:
        """(n_p, n_cases) fused class indices over the five signals (the paper's :func:`fuse`; variant
        'sensor_matched': the plain sum, as :meth:`PatternLibrary.fuse` with a scatter)."""
        if self.method.variant == "sensor_matched":
            return np.argmin(self.h.sum(axis=2), axis=-1)
        out = np.zeros(self.h.shape[:2], dtype=int)
        for k in range(self.h.shape[0]):
            for i in range(self.h.shape[1]):
                out[k, i] = fuse(list(self.h[k, i]))[0]
        return out

    def accuracy(self, headline: bool = True) -> dict:
        """{'per_signal': (n_p, n_signals), 'fused': (n_p,)} over headline or pattern cases."""
        mask = ~self.pattern_mask if headline else self.pattern_mask
        ok = self.predicted()[:, mask] == self.true_class[mask][None, :, None]
        fok = self.fused_predicted()[:, mask] == self.true_class[mask][None, :]
        return {"per_signal": ok.mean(axis=1), "fused": fok.mean(axis=1), "n": int(mask.sum())}

    def margins(self) -> np.ndarray:
        """(n_p, n_cases, n_signals) second-smallest / smallest H."""
        s = np.sort(self.h, axis=-1)
        with np.errstate(divide="ignore"):
            return np.where(s[..., 0] > 0, s[..., 1] / np.where(s[..., 0] > 0, s[..., 0], 1), np.inf)


def window_features(windows: WindowSet, method: MethodConfig, p_values, progress=None):
    """centres[p, case, signal] -> (n_clusters,), all windows of a signal in one batch."""
    ps = tuple(float(p) for p in p_values)
    n = len(windows.cases)
    out = np.zeros((len(ps), n, len(SIGNALS), method.n_clusters))
    refs = np.array([pre_entry_reference(windows.case(i), windows.entry_index) for i in range(n)])
    for s, name in enumerate(SIGNALS):
        out[:, :, s], _, _ = batch_features(windows.signals[name], name, method, ps, refs, windows.entry_index)
        if progress:
            progress(s + 1, len(SIGNALS))
    return out


def evaluate_grid(system: SystemConfig, method: MethodConfig, clean: WindowSet, tested: WindowSet,
                  label: str, library: PatternLibrary | None = None, progress=None) -> GridResult:
    """H vectors of every tested window against the library built from ``clean``."""
    t0 = time.perf_counter()
    if library is None:
        library = PatternLibrary.build(system, method, windows=clean)
    t_lib = time.perf_counter() - t0
    feats = window_features(tested, method, library.p_values, progress)
    return grid_result(system, method, library, tested, feats, label, time.perf_counter() - t0, t_lib)


def grid_result(system: SystemConfig, method: MethodConfig, library: PatternLibrary, tested: WindowSet,
                feats: np.ndarray, label: str, seconds: float = 0.0, library_seconds: float = 0.0, *,
                widths_m=None, width_mode: str = "nearest") -> GridResult:
    """GridResult of tested windows whose features are known.

    ``feats`` has shape (n_p, n_cases, n_signals, n_clusters) (p in ``library.p_values``
    order); H (eq. 33) of each case is taken against the library's patterns at the case's width
    (or at ``widths_m[i]``, e.g. the gap estimator's width estimate) picked by ``width_mode``
    (:meth:`PatternLibrary.patterns_at`: the nearest library width, or interpolated).
    """
    ps = library.p_values
    classes = list(system.grid.inertia_classes_kgm2)
    n = len(tested.cases)
    h = np.zeros((len(ps), n, len(SIGNALS), len(classes)))
    for i, c in enumerate(tested.cases):
        w = c.backlash_width_m if widths_m is None else float(widths_m[i])
        for k in range(len(ps)):
            for s in range(len(SIGNALS)):
                h[k, i, s] = library.h_vector(k, s, w, feats[k, i, s], width_mode)
    true = np.array([classes.index(c.inertia_kgm2) for c in tested.cases])
    pmask = np.array([c.consistency_pa_sn == system.grid.pattern_consistency_pa_sn for c in tested.cases])
    res = GridResult(label, method, ps, list(tested.cases), true, h, pmask, seconds, library_seconds)
    res.notes["centres"] = feats
    return res


@dataclass
class Evaluation:
    results: list
    examples: list
    system: SystemConfig
    seconds: float
    simulate_seconds: float
    gap: list = field(default_factory=list)
    best: list = field(default_factory=list)
    command: str = "jident evaluate"
    ablation_examples: list = field(default_factory=list)   # paper examples on equal_load_grid
    validity: list = field(default_factory=list)             # one dict per film share (validity map)
    width_mismatch: dict = field(default_factory=dict)       # accuracy vs window/library width mismatch
    halfway: dict = field(default_factory=dict)              # nearest vs width_interp at halfway widths
    sensors: str = ""                                        # the default sensor set, in words
    film_share: float = float("nan")                         # the evaluated profile's share
    ablation_share: float = float("nan")                     # the profile the ablation ran on


def paper_examples(system: SystemConfig, method: MethodConfig, clean: WindowSet, result: GridResult) -> list:
    """Our H vectors for the paper's 16 example cases beside the paper's.

    Examples at a p that ``result`` was not evaluated at (``jident evaluate --p ...``) are left out."""
    rows = []
    index = {(c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn): i for i, c in enumerate(clean.cases)}
    classes = list(system.grid.inertia_classes_kgm2)
    for sig, j1, w, eta, p, paper_h in PAPER_EXAMPLES:
        if float(p) not in result.p_values:
            continue
        i = index[(j1, w, eta)]
        k = result.p_values.index(float(p))
        ours = result.h[k, i, SIGNALS.index(sig)]
        rows.append({"signal": sig, "j1": j1, "width": w, "eta": eta, "p": p, "paper_h": paper_h,
                     "ours": ours, "true": classes.index(j1), "ours_class": int(np.argmin(ours)),
                     "paper_class": int(np.argmin(paper_h)), "margin": margin(ours)})
    return rows


def gap_evaluation(system: SystemConfig, windows: WindowSet, label: str,
                   channels=("alpha1", "alpha2", "a1", "m_el"), method=None) -> dict:
    """The gap estimator (gap.py) on every window: errors, class accuracy, CI coverage."""
    classes = list(system.grid.inertia_classes_kgm2)
    est = np.full(len(windows.cases), np.nan)
    lo, hi = est.copy(), est.copy()
    reasons = {}
    for i, c in enumerate(windows.cases):
        win = {k: windows.signals[k][i] for k in channels}
        try:
            g = estimate_inertia(win, windows.entry_index, c.backlash_width_m, system.load.wheel_radius_m,
                                 windows.sample_period_s, method)
        except NoGapError as exc:
            reasons[i] = str(exc)
            continue
        est[i], (lo[i], hi[i]) = g.inertia_kgm2, g.ci95_kgm2
    true = np.array([c.inertia_kgm2 for c in windows.cases])
    ok = ~np.isnan(est)
    cls = np.array([nearest_class(e, classes) if np.isfinite(e) else -1 for e in est])
    return {"label": label, "channels": channels, "estimate": est, "true": true,
            "rel_error": (est - true) / true, "class": cls,
            "class_ok": cls == np.array([classes.index(t) for t in true]),
            "covered": ok & (lo <= true) & (true <= hi), "failed": reasons}


def best_verdict(gap: dict, paper: GridResult, p_index: int = 0) -> dict:
    """The 'gap' variant's class: the gap estimate's nearest class, the paper method's
    fused class where the window has no usable gap."""
    fused = paper.fused_predicted()[p_index]
    cls = np.where(gap["class"] >= 0, gap["class"], fused)
    ok = cls == paper.true_class
    return {"label": gap["label"], "class": cls, "ok": ok, "headline": float(ok[~paper.pattern_mask].mean()),
            "all": float(ok.mean()), "fallbacks": int((gap["class"] < 0).sum())}


def equal_load_grid(system: SystemConfig, clean: WindowSet) -> WindowSet:
    """The cases of ``clean`` re-simulated with every eta_k group at the pattern group's load (an ablation).

    Not a model change: a diagnostic experiment for docs/method.md ("How well it works").  For each
    eta_k group the process force F_p is set so that F_p + F_film(v_2, eta_k) equals the pattern
    group's F_p + F_film(v_2, 0.025) at the pattern group's steady line speed v_2 (the mean pre-entry
    v_2 of the pattern runs in ``clean``).  The steady-state load torque, slip and speed are then the
    same in every group (to ~1e-5); what eta_k still changes is the film's damping of the line-mass
    motion (dF_film/dv_2 = n_1 F_film / v_2).  Returns a WindowSet in ``clean``'s case order.
    """
    g = system.grid
    pattern = [i for i, c in enumerate(clean.cases) if c.consistency_pa_sn == g.pattern_consistency_pa_sn]
    if not pattern:
        raise ValueError(f"equal_load_grid: clean holds no pattern run (eta_k = {g.pattern_consistency_pa_sn})")
    v2 = float(np.mean(clean.signals["v2"][pattern, :clean.entry_index]))
    model = Model(system)
    load = system.load.process_force_n + float(model.film_force(v2, g.pattern_consistency_pa_sn))
    parts = {}
    for eta in sorted({c.consistency_pa_sn for c in clean.cases}):
        force = load - float(model.film_force(v2, eta))
        group = [i for i, c in enumerate(clean.cases) if c.consistency_pa_sn == eta]
        sysx = dataclasses.replace(system, load=dataclasses.replace(system.load, process_force_n=force))
        parts[eta] = (group, simulate_grid(sysx, [clean.cases[i] for i in group],
                                           sample_period_s=clean.sample_period_s), force)
    signals = {k: np.empty_like(v) for k, v in clean.signals.items()}
    slip = np.empty_like(clean.initial_slip)
    for group, ws, _ in parts.values():
        for k in signals:
            signals[k][group] = ws.signals[k]
        slip[group] = ws.initial_slip
    forces = {eta: force for eta, (_, _, force) in parts.items()}
    return WindowSet(clean.t, signals, list(clean.cases), clean.entry_index, clean.sample_period_s, slip,
                     dict(clean.metadata, equal_load_process_force_n=forces, pattern_line_speed_m_s=v2))


def _feature_task(args):
    """Features of one signal of one data set under one method configuration.

    A top-level function so that a process pool can run it.  ``args`` =
    (windows (n, n_samples), signal name, MethodConfig, references (n,), entry index).
    Returns centres (n_p, n, n_clusters), ranges (n, 2) as (h3, k3), and the seconds taken.
    """
    x, name, m, refs, entry = args
    t = time.perf_counter()
    centres, ranges, _ = batch_features(x, name, m, m.p_values, refs, entry)
    return centres, np.array([(r.h3, r.k3) for r in ranges]), time.perf_counter() - t


def _pattern_order(system: SystemConfig, windows: WindowSet) -> list:
    """Indices of the pattern runs (eta_k = 0.025) in ``windows``, class-major, width-minor."""
    g = system.grid
    index = {c: i for i, c in enumerate(windows.cases)}
    return [index[Case(j, w, g.pattern_consistency_pa_sn)] for j in g.inertia_classes_kgm2
            for w in g.backlash_widths_m]


def run_evaluation(system: SystemConfig, method: MethodConfig, *, snr_db=(40.0, 30.0), seeds=(1, 2),
                   readings=("dyadic", "linear", "swt"), variants=("paper", "load_scaled", "sensor_matched"),
                   progress=None,
                   log=print, jobs: int | None = None, ablation: bool = True,
                   sensors: SensorSpec | None = DEFAULT_SENSORS, film_shares=VALIDITY_FILM_SHARES,
                   stress_system: SystemConfig | None = None, full_map: bool = False,
                   halfway: bool = True, matched_noise_free: bool = True,
                   library_cache: bool = False) -> Evaluation:
    """The whole evaluation: every variant noise-free and noisy, the gap estimator, the level-10 readings.

    The work is split into one task per (method configuration, data set, signal):
    batch_features of the 168 windows of that signal, run in ``jobs`` processes
    (default: the number of CPUs), the slowest tasks (linear reading) first.  Each
    configuration's pattern library is assembled from its noise-free features (the
    pattern runs are windows of the noise-free grid), so no window is transformed
    twice.  The numbers do not depend on ``jobs`` or on the task order.  A result's
    ``seconds`` is the worker time of its tasks.  With ``ablation`` the paper-faithful
    mode also runs on :func:`equal_load_grid` (every eta_k group at the pattern load),
    against the same library; its paper examples go to ``Evaluation.ablation_examples``.

    Issue 13 additions: ``sensors`` adds a data set recorded by that sensor set (:mod:`jident_ros.sim.sensors`)
    beside the awgn ones; the validity map runs the paper-faithful mode noise-free on the grid of every
    ``film_shares`` profile (:func:`sim.profiles.with_film_share`, own library each) and of ``stress_system``
    (the heavy-film profile), where the equal-load ablation runs (``full_map``: at every share, and the
    sensor set at every share too); ``halfway`` simulates windows at widths halfway between the library's
    and identifies them with the nearest width's patterns, with ``width_interp`` and ``width_simulated`` at
    the gap estimator's width estimate (``full_map``: also the width-error sweep, :func:`width_error_sweep`);
    the width mismatch map reuses the noise-free features against every library width.  The variant
    'sensor_matched' (in ``variants``, with ``sensors``) runs on the sensor data set and, with
    ``matched_noise_free``, on the noise-free grid; with ``library_cache`` its library is taken from the pattern
    library cache (:func:`identify.library.default_library_path`, as the diagnostic node does; refused unless
    built for this system and method configuration) and saved there when it is built (the same library either
    way: it is a deterministic function of the two configurations).
    """
    t0 = time.perf_counter()
    cases = paper_grid_cases(system)
    clean = simulate_grid(system, cases)
    t_sim = time.perf_counter() - t0
    log(f"simulated {len(cases)} cases in {t_sim:.1f} s")
    datasets = [("noise-free", clean)] + [(f"SNR {snr:g} dB (seed {seed})", add_measurement_noise(clean, snr, seed))
                                           for snr, seed in zip(snr_db, seeds)]
    if sensors is not None:
        datasets.append((sensor_label(sensors), apply_sensors(clean, sensors, SENSOR_SEED,
                                                              system.motor.base.torque_nm)))
    # (method, [(result label, data name, windows, notes)]) in the order of the results;
    # every configuration's first data set is the noise-free grid
    configs = []
    for variant in variants:
        if variant == "sensor_matched":
            continue   # below: its library comes from the pattern runs recorded through the sensors
        m = dataclasses.replace(method, variant=variant)
        data_sets = datasets if variant == "paper" else datasets[:1]   # load_scaled: noise-free only
        configs.append((m, [(f"{variant}, {name}", name, data, {"variant": variant, "data": name})
                            for name, data in data_sets], system))
        if ablation and variant == "paper" and stress_system is None:
            t1 = time.perf_counter()
            equal = equal_load_grid(system, clean)
            log(f"equal-load ablation grid simulated in {time.perf_counter() - t1:.1f} s")
            configs[-1][1].append(("paper, equal-load ablation, noise-free", "equal-load ablation", equal,
                                   {"ablation": "equal load", "data": "equal-load ablation",
                                    "process_force_n": equal.metadata["equal_load_process_force_n"]}))
    cached = None   # the sensor_matched library, when the cache holds it
    if "sensor_matched" in variants and sensors is not None:
        mm = dataclasses.replace(method, variant="sensor_matched")
        cached, _ = (load_pattern_library(default_library_path(system, mm), system, mm, build_if_missing=False)
                     if library_cache else (None, None))
        configs.append(sensor_matched_config(system, method, clean, datasets[-1], matched_noise_free,
                                             with_library_runs=cached is None))
        if cached is not None:
            log(f"sensor_matched library from the cache {default_library_path(system, mm)}")
    paper_config = next((i for i, (m, _, _) in enumerate(configs) if m.variant == "paper"), None)
    if halfway and paper_config is not None:
        half = simulate_grid(system, halfway_width_cases(system))
        configs[paper_config][1].append(("paper, halfway widths, noise-free, nearest width", "halfway", half,
                                         {"halfway": True, "data": "halfway widths", "windows": half}))
    # the validity map: the paper-faithful mode on other film shares (own library each)
    pm = dataclasses.replace(method, variant="paper")
    if not full_map:   # the budget of the default run: the validity map at the p = 2 and 3
        pm = dataclasses.replace(pm, p_values=tuple(p for p in method.p_values if p in (2.0, 3.0)) or method.p_values)
    profiles = [(f"film share {100 * sh:g} %", with_film_share(system, sh), sh) for sh in film_shares]
    if stress_system is not None:
        profiles.append(("heavy-film profile", stress_system, film_share(stress_system)))
    for name, sysx, sh in profiles:
        t1 = time.perf_counter()
        cl = simulate_grid(sysx, cases)
        runs = [(f"paper, {name}, noise-free", "noise-free", cl, {"validity": sh, "data": "noise-free"})]
        if ablation and (full_map or sysx is stress_system):
            eq = equal_load_grid(sysx, cl)
            runs.append((f"paper, {name}, equal-load ablation", "equal-load ablation", eq,
                         {"validity": sh, "ablation": "equal load", "data": "equal-load ablation",
                          "process_force_n": eq.metadata["equal_load_process_force_n"]}))
        if full_map and sensors is not None:
            runs.append((f"paper, {name}, {sensor_label(sensors)}", "sensors",
                         apply_sensors(cl, sensors, SENSOR_SEED, sysx.motor.base.torque_nm),
                         {"validity": sh, "data": "sensors"}))
        configs.append((pm, runs, sysx))
        log(f"validity map: {name} simulated in {time.perf_counter() - t1:.1f} s")
    for reading in readings:
        if reading != method.scale_reading:
            m = dataclasses.replace(method, scale_reading=reading, p_values=(2.0,), variant="paper")
            configs.append((m, [(f"paper, reading '{reading}', noise-free", "noise-free", clean,
                                 {"reading": reading})], system))
    tasks, keys = [], []
    for c, (m, runs, _) in enumerate(configs):
        for d, (_, _, data, _) in enumerate(runs):
            refs = np.array([pre_entry_reference(data.case(i), data.entry_index) for i in range(len(data.cases))])
            for s, name in enumerate(SIGNALS):
                tasks.append((data.signals[name], name, m, refs, data.entry_index))
                keys.append((c, d, s))
    cost = {"linear": 0, "swt": 2}  # slowest first (the 1024-scale reading), for load balance
    order = sorted(range(len(tasks)), key=lambda t: (cost.get(tasks[t][2].scale_reading, 1), t))
    jobs = jobs or os.cpu_count() or 1
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            done = list(pool.map(_feature_task, [tasks[t] for t in order]))
    else:
        done = [_feature_task(tasks[t]) for t in order]
    outputs = dict(zip([keys[t] for t in order], done))

    results, libraries = [], {}
    pattern = _pattern_order(system, clean)
    for c, (m, runs, sysx) in enumerate(configs):
        library = None
        if m.variant == "sensor_matched" and cached is not None:
            library = libraries[c] = cached
        elif m.variant == "sensor_matched":
            library = libraries[c] = _seed_library(sysx, m, runs, [[outputs[(c, d, s)] for s in range(len(SIGNALS))]
                                                                   for d in range(len(runs))])
            if library_cache:
                try:
                    library.save(default_library_path(sysx, m))
                except OSError as exc:
                    log(f"sensor_matched library not saved to the cache: {exc}")
        for d, (label, _, data, note) in enumerate(runs):
            if "library_seed" in note:
                continue
            parts = [outputs[(c, d, s)] for s in range(len(SIGNALS))]
            feats = np.stack([centres for centres, _, _ in parts], axis=2)   # (n_p, n_cases, n_signals, K)
            if library is None:   # runs[0] is the noise-free grid, which holds the pattern runs
                ranges = np.stack([r for _, r, _ in parts], axis=1)         # (n_cases, n_signals, 2)
                library = PatternLibrary.from_features(feats, ranges, pattern, sysx, m)
                libraries[c] = library
            res = grid_result(sysx, m, library, data, feats, label, sum(t for _, _, t in parts))
            res.notes.update(note)
            if note.get("halfway"):
                res.pattern_mask[:] = False   # no halfway window is a pattern run
            results.append(res)
    for res in results:
        log(_summary(res))
    gaps, best, examples, ablation_examples = [], [], [], []
    validity = []
    for c, (m, runs, sysx) in enumerate(configs):
        rs = [r for r in results if r.notes.get("validity") is not None and r.label in {x[0] for x in runs}]
        if not rs:
            continue
        base = next(r for r in rs if r.notes["data"] == "noise-free")
        entry = {"share": base.notes["validity"], "label": base.label, "result": base,
                 "examples": paper_examples(sysx, base.method, runs[0][2], base),
                 "stress": sysx is stress_system}
        for r in rs:
            if r.notes["data"] == "equal-load ablation":
                entry["ablation"] = r
                entry["ablation_examples"] = paper_examples(sysx, r.method, runs[0][2], r)
            elif r.notes["data"] == "sensors":
                entry["sensors"] = r
        validity.append(entry)
    for res in results:
        if res.notes.get("ablation") and res.notes.get("validity") is None:
            ablation_examples = paper_examples(system, res.method, clean, res)
    stress = next((v for v in validity if v["stress"] and "ablation" in v), None)
    if stress is not None:
        ablation_examples = stress["ablation_examples"]
    paper_results = {r.notes.get("data"): r for r in results if r.notes.get("variant") == "paper"}
    for name, data in datasets:
        res = paper_results.get(name)
        if res is None:
            continue
        if data is clean:
            examples = paper_examples(system, res.method, clean, res)
        g = gap_evaluation(system, data, name)
        gaps.append(g)
        best.append(best_verdict(g, res))
        log(f"gap estimator, {name}: class accuracy {g['class_ok'].mean() * 100:.1f} %, "
            f"max |error| {np.nanmax(np.abs(g['rel_error'])) * 100:.2f} %")
    paper_clean = paper_results.get("noise-free")
    mismatch = width_mismatch_map(system, paper_clean, libraries[paper_config]) if paper_clean is not None else {}
    half = {}
    hres = next((r for r in results if r.notes.get("halfway")), None)
    if hres is not None:
        half = halfway_comparison(system, hres, libraries[paper_config], error_sweep=full_map, sensors=sensors)
    ev = Evaluation(results, examples, system, time.perf_counter() - t0, t_sim, gaps, best,
                    ablation_examples=ablation_examples, validity=validity, width_mismatch=mismatch,
                    halfway=half, sensors="" if sensors is None else sensors.describe(
                        system.sampling.sample_period_s, system.motor.base.torque_nm),
                    film_share=film_share(system))
    ev.ablation_share = stress["share"] if stress is not None else ev.film_share
    return ev


def sensor_matched_config(system: SystemConfig, method: MethodConfig, clean: WindowSet, sensor_data,
                          noise_free: bool = True, with_library_runs: bool = True) -> tuple:
    """Configuration (method, runs, system) of variant 'sensor_matched' in :func:`run_evaluation`: the
    library runs (the 42 noise-free pattern runs recorded through ``method.sensor_spec()`` with each of
    ``method.matched_seeds`` seeds, as :meth:`PatternLibrary.sensor_matched` builds them), then the tested
    data: the noise-free grid (with ``noise_free``) and ``sensor_data`` = (name, windows) (the default sensor
    set at SENSOR_SEED).  Without ``with_library_runs`` only the tested data (the library comes from a cache)."""
    m = dataclasses.replace(method, variant="sensor_matched")
    runs_42 = take_windows(clean, _pattern_order(system, clean))
    spec = m.sensor_spec()
    runs = [(f"sensor_matched library, seed {seed}", "library", apply_sensors(runs_42, spec, seed,
                                                                               system.motor.base.torque_nm),
             {"library_seed": seed}) for seed in (matched_seeds(m) if with_library_runs else ())]
    name, data = sensor_data
    runs += [(f"sensor_matched, {n}", n, d, {"variant": "sensor_matched", "data": n})
             for n, d in ((("noise-free", clean),) if noise_free else ()) + ((name, data),)]
    return m, runs, system


def _seed_library(system: SystemConfig, method: MethodConfig, runs: list, parts: list) -> PatternLibrary:
    """The 'sensor_matched' library from the per-seed features of ``runs`` (``parts[d][s]`` = the
    :func:`_feature_task` output of run d, signal s); equal to :meth:`PatternLibrary.sensor_matched`."""
    cen, rng = [], []
    for d, (_, _, data, note) in enumerate(runs):
        if "library_seed" not in note:
            continue
        feats = np.stack([c for c, _, _ in parts[d]], axis=2)
        ranges = np.stack([r for _, r, _ in parts[d]], axis=1)
        lib = PatternLibrary.from_features(feats, ranges, range(len(data.cases)), system, method)
        cen.append(lib.centres)
        rng.append(lib.ranges)
    return PatternLibrary.from_seed_libraries(np.array(cen), np.array(rng), system, method)


def sensor_label(spec: SensorSpec) -> str:
    """Data-set label of a sensor set: 'sensors (default set, seed 3)' or 'sensors (custom, seed 3)'."""
    return f"sensors ({'default set' if spec == DEFAULT_SENSORS else 'custom'}, seed {SENSOR_SEED})"


def halfway_width_cases(system: SystemConfig) -> list[Case]:
    """Every J1 class and eta_k at the widths halfway between neighbouring library widths."""
    g = system.grid
    w = sorted(g.backlash_widths_m)
    half = [0.5 * (a + b) for a, b in zip(w[:-1], w[1:])]
    return [Case(float(j), float(x), float(e)) for e in g.consistency_indices_pa_sn
            for j in g.inertia_classes_kgm2 for x in half]


def estimated_widths(system: SystemConfig, windows: WindowSet) -> np.ndarray:
    """The gap estimator's backlash-width estimate of every window (gap.estimate_backlash_width; NaN where
    there is no gap), as the diagnostic node would give it to a width-aware library."""
    r = system.load.wheel_radius_m
    out = np.full(len(windows.cases), np.nan)
    for i, c in enumerate(windows.cases):
        win = {k: windows.signals[k][i] for k in ("alpha1", "alpha2", "a1", "m_el")}
        try:
            g = estimate_inertia(win, windows.entry_index, c.backlash_width_m, r, windows.sample_period_s)
            out[i] = estimate_backlash_width(win, g.gap_end, r, windows.sample_period_s, g.inertia_kgm2).width_m
        except NoGapError:
            continue
    return out


def halfway_comparison(system: SystemConfig, nearest: GridResult, library: PatternLibrary,
                       error_sweep: bool = False, sensors: SensorSpec | None = None) -> dict:
    """Windows at halfway widths: the paper's nearest-width patterns against ``width_interp`` patterns at
    the gap estimator's width estimate and ``width_simulated`` patterns (the pattern runs simulated at that
    estimate, :func:`patterns.simulated_width_library`); the nominal width where there is no estimate."""
    cases = nearest.cases
    sim = nearest.notes["windows"]
    est = estimated_widths(system, sim)
    true_w = np.array([c.backlash_width_m for c in cases])
    used = np.where(np.isfinite(est), est, [c.backlash_width_m for c in cases])
    interp = grid_result(system, nearest.method, library, sim, nearest.notes["centres"],
                         "paper, halfway widths, noise-free, width_interp", widths_m=used, width_mode="width_interp")
    interp.pattern_mask[:] = False
    # width_simulated: the pattern runs simulated at every (rounded) estimated width, one library holding them all
    rounded = np.array([rounded_width(w) for w in used])
    simulated_system = with_widths(system, sorted(set(rounded)))
    t = time.perf_counter()
    simulated_library = PatternLibrary.build(simulated_system, nearest.method)
    simulated = grid_result(simulated_system, nearest.method, simulated_library, sim, nearest.notes["centres"],
                            "paper, halfway widths, noise-free, width_simulated", time.perf_counter() - t,
                            widths_m=rounded)
    simulated.pattern_mask[:] = False
    out = {"width_error": width_error_sweep(system, nearest)} if error_sweep else {}
    if sensors is not None:   # how well the width is known when the same windows come from real sensors
        noisy = apply_sensors(sim, sensors, SENSOR_SEED, system.motor.base.torque_nm)
        rel = np.abs(estimated_widths(system, noisy) / true_w - 1.0)
        out["sensor_width_error"] = {"median": float(np.nanmedian(rel)), "max": float(np.nanmax(rel)),
                                     "within_0.1%": float(np.mean(rel <= 0.001)), "label": sensor_label(sensors)}
    return out | {"nearest": nearest, "width_interp": interp, "width_simulated": simulated,
            "simulated_widths": len(simulated_system.grid.backlash_widths_m),
            "width_error_max": float(np.nanmax(np.abs(est - true_w) / true_w)) if np.isfinite(est).any() else np.nan,
            "no_estimate": int((~np.isfinite(est)).sum())}


#: Relative width errors of :func:`width_error_sweep`.
WIDTH_ERRORS = (0.0, 0.001, 0.005, 0.01, 0.02)


def width_error_sweep(system: SystemConfig, nearest: GridResult, errors=WIDTH_ERRORS) -> dict:
    """How exactly ``width_simulated`` needs the window's width: the halfway windows of ``nearest`` against
    pattern runs simulated at their true width times (1 + error).  Returns {error: fused accuracy per p}."""
    true_w = np.array([c.backlash_width_m for c in nearest.cases])
    out = {}
    for err in errors:
        widths = np.array([rounded_width(w * (1.0 + err)) for w in true_w])
        sysx = with_widths(system, sorted(set(widths)))
        lib = PatternLibrary.build(sysx, nearest.method)
        res = grid_result(sysx, nearest.method, lib, nearest.notes["windows"], nearest.notes["centres"],
                          f"halfway, patterns at width x {1 + err:g}", widths_m=widths)
        res.pattern_mask[:] = False
        out[err] = res.accuracy()["fused"]
    return out


def width_mismatch_map(system: SystemConfig, result: GridResult, library: PatternLibrary) -> dict:
    """Fused accuracy (per p) of the headline windows identified with the patterns of every library width:
    mismatch = library width / window width - 1 (0: the paper's case).  Reuses the windows' features."""
    feats = result.notes["centres"]
    mask = ~result.pattern_mask
    widths = np.array(library.widths_m)
    rows = {}
    for i, c in enumerate(result.cases):
        if not mask[i]:
            continue
        for e, w in enumerate(widths):
            mis = round(float(w / c.backlash_width_m - 1.0), 4)
            for k in range(len(result.p_values)):
                hs = [library.h_vector(k, s, float(w), feats[k, i, s]) for s in range(len(SIGNALS))]
                ok = library.fuse(hs)[0] == result.true_class[i]
                rows.setdefault(mis, np.zeros((len(result.p_values), 2), int))
                rows[mis][k] += (int(ok), 1)
    mis = np.array(sorted(rows))
    acc = np.array([rows[m][:, 0] / rows[m][:, 1] for m in mis])            # (n_mismatch, n_p)
    n = np.array([rows[m][0, 1] for m in mis])
    return {"mismatch": mis, "accuracy": acc, "n": n, "p_values": result.p_values}


def _summary(res: GridResult) -> str:
    acc = res.accuracy()
    fused = " ".join(f"p={p:g}:{a * 100:.1f}%" for p, a in zip(res.p_values, acc["fused"]))
    return f"{res.label}: fused accuracy {fused} ({acc['n']} headline cases, {res.seconds:.1f} s)"
