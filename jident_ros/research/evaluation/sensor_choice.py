"""Why the variant 'sensor_matched' (docs/method.md): the candidates measured side by side on the default sensor set.

``python -m jident_ros.research.evaluation.sensor_choice`` prints one markdown table: the fused accuracy of the image
method (126 headline cases, every p) on the 168 grid windows recorded by the default sensor set
(:data:`jident_ros.sim.sensors.DEFAULT_SENSORS`, seed 3 as in ``jident evaluate``; ``--seeds`` for more), for

* the paper-faithful mode (noise-free library);
* a zero-phase low-pass pre-filter (Butterworth, 4th order, ``scipy.signal.sosfiltfilt``) on every window and
  pattern run, at several cut-offs;
* libraries from the pattern runs recorded through the same sensors (``method.matched_seeds`` seeds):
  mean centres only; + distances in units of the seed-to-seed scatter; + fusion by the plain sum (= the
  variant 'sensor_matched'); the last also with the 20 Hz pre-filter.

Plus a diagnosis of one window: the range statistics (h3, k3) and the centres of each signal noise-free and
with the sensors, against the J1 effect of one class step.
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from scipy.signal import butter, sosfiltfilt

from jident_ros.config import load_method_config, load_system_config
from jident_ros.method import normalise as nz
from jident_ros.method.patterns import PatternLibrary, take_windows
from jident_ros.method.pipeline import SIGNALS, pre_entry_reference
from jident_ros.research.evaluation.evaluate import (
    SENSOR_SEED,
    _feature_task,
    _pattern_order,
    grid_result,
    sensor_matched_config,
    window_features,
)
from jident_ros.sim import WindowSet, paper_grid_cases, simulate_grid
from jident_ros.sim.sensors import DEFAULT_SENSORS, apply_sensors

#: Cut-offs of the low-pass candidates, Hz.
LOWPASS_HZ = (20.0, 100.0)


def lowpass(windows: WindowSet, cutoff_hz: float) -> WindowSet:
    """Every method signal of ``windows`` through a zero-phase 4th-order Butterworth low-pass."""
    sos = butter(4, cutoff_hz, fs=1.0 / windows.sample_period_s, output="sos")
    signals = dict(windows.signals)
    for name in SIGNALS:
        signals[name] = sosfiltfilt(sos, windows.signals[name], axis=-1)
    return dataclasses.replace(windows, signals=signals)


def _library(system, method, clean):
    feats, ranges = _features(clean, method)
    return PatternLibrary.from_features(feats, ranges, _pattern_order(system, clean), system, method)


def _features(windows, method):
    refs = np.array([pre_entry_reference(windows.case(i), windows.entry_index) for i in range(len(windows.cases))])
    parts = [_feature_task((windows.signals[s], s, method, refs, windows.entry_index)) for s in SIGNALS]
    return np.stack([c for c, _, _ in parts], axis=2), np.stack([r for _, r, _ in parts], axis=1)


def _matched_library(system, method, clean, cutoff_hz=None):
    """Per-seed pattern features -> (library with scatter, the same without it)."""
    m, runs, _ = sensor_matched_config(system, method, clean, ("sensors", clean))
    cen, rng = [], []
    for _, _, data, note in runs:
        if "library_seed" not in note:
            continue
        data = lowpass(data, cutoff_hz) if cutoff_hz else data
        feats, ranges = _features(data, m)
        lib = PatternLibrary.from_features(feats, ranges, range(len(data.cases)), system, m)
        cen.append(lib.centres)
        rng.append(lib.ranges)
    lib = PatternLibrary.from_seed_libraries(np.array(cen), np.array(rng), system, m)
    return lib, dataclasses.replace(lib, scatter=None)


def compare(system, method, test_seeds=(SENSOR_SEED,), log=print) -> list[tuple[str, int, np.ndarray]]:
    """(candidate, test seed, fused accuracy per p) for every candidate and test seed."""
    clean = simulate_grid(system, paper_grid_cases(system))
    paper = method.replace(variant="paper")
    matched = method.replace(variant="sensor_matched")
    torque = system.motor.base.torque_nm
    tests = {seed: apply_sensors(clean, DEFAULT_SENSORS, seed, torque) for seed in test_seeds}
    rows = []

    def score(name, lib, m, seed, data):
        res = grid_result(system, m, lib, data, window_features(data, m, m.p_values), name)
        rows.append((name, seed, res.accuracy()["fused"]))
        log(f"{name}, seed {seed}: fused " + " ".join(f"{100 * a:.1f}" for a in rows[-1][2]))

    lib = _library(system, paper, clean)
    for seed, data in tests.items():
        score("paper-faithful (noise-free library)", lib, paper, seed, data)
    for fc in LOWPASS_HZ:
        lib = _library(system, paper, lowpass(clean, fc))
        for seed, data in tests.items():
            score(f"low-pass {fc:g} Hz on windows and pattern runs", lib, paper, seed, lowpass(data, fc))
    scaled, mean_only = _matched_library(system, method, clean)
    n = matched.matched_seeds
    for seed, data in tests.items():
        score(f"library through the sensors ({n} seeds), mean centres, paper H and fusion", mean_only, paper, seed,
              data)
        score("+ H in units of the seed-to-seed scatter, paper fusion", scaled, paper, seed, data)
        score("+ fusion by the plain sum (= variant sensor_matched)", scaled, matched, seed, data)
    scaled20, _ = _matched_library(system, method, clean, 20.0)
    for seed, data in tests.items():
        score("variant sensor_matched + low-pass 20 Hz", scaled20, matched, seed, lowpass(data, 20.0))
    return rows


def diagnose(system, method, case_index: int = 5) -> list[str]:
    """One window (grid case ``case_index``) noise-free and through the default sensor set: each signal's range
    statistics (h3, k3) and mean centre (p = 2), and the J1 effect on the mean centre of one class step."""
    clean = simulate_grid(system, paper_grid_cases(system))
    noisy = apply_sensors(clean, DEFAULT_SENSORS, SENSOR_SEED, system.motor.base.torque_nm)
    m = method.replace(variant="paper", p_values=(2.0,))
    pattern = take_windows(clean, _pattern_order(system, clean))
    f_clean = window_features(take_windows(clean, [case_index]), m, (2.0,))[0, 0]
    f_noisy = window_features(take_windows(noisy, [case_index]), m, (2.0,))[0, 0]
    f_pat = window_features(pattern, m, (2.0,))[0]          # (42, ns, K), class-major, width-minor
    nw = len(system.grid.backlash_widths_m)
    order = np.argsort(system.grid.inertia_classes_kgm2)
    out = [f"Case {clean.cases[case_index]} (p = 2):", "",
           "| signal | (h3, k3) noise-free | (h3, k3) sensors | mean centre noise-free | sensors | "
           "J1 effect (smallest class step, pattern runs at this width) |", "|---|---|---|---|---|---|"]
    e = list(system.grid.backlash_widths_m).index(clean.cases[case_index].backlash_width_m)
    for s, name in enumerate(SIGNALS):
        rc = nz.range_params(clean.signals[name][case_index], name, m.eq12)
        rn = nz.range_params(noisy.signals[name][case_index], name, m.eq12)
        by_class = f_pat[[f * nw + e for f in order], s].mean(axis=-1)
        out.append(f"| {name} | ({rc.h3:.4g}, {rc.k3:.4g}) | ({rn.h3:.4g}, {rn.k3:.4g}) | "
                   f"{f_clean[s].mean():.4g} | {f_noisy[s].mean():.4g} | {np.min(np.abs(np.diff(by_class))):.3g} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.sensor_choice", description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[SENSOR_SEED], help="test seeds of the sensor noise")
    ap.add_argument("--config", help="system config or profile (default config/system.yaml)")
    ap.add_argument("--matched-seeds", type=int, help="noise seeds of the matched libraries (default: method.yaml)")
    args = ap.parse_args(argv)
    system, method = load_system_config(args.config), load_method_config()
    if args.matched_seeds:
        method = method.replace(matched_seeds=args.matched_seeds)
    print("\n".join(diagnose(system, method)) + "\n")
    rows = compare(system, method, tuple(args.seeds), log=lambda *a: None)
    ps = method.p_values
    print("| candidate | test seed | " + " | ".join(f"fused p = {p:g}" for p in ps) + " |")
    print("|---|---|" + "---|" * len(ps))
    for name, seed, acc in rows:
        print(f"| {name} | {seed} | " + " | ".join(f"{100 * a:.1f} %" for a in acc) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
