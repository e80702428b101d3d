"""The gap fit's model choice on both drives (docs/method.md, "Gap-only fit and the model choice").

``python -m jident_ros.research.evaluation.gap_choice [--second-drive DIR ...]`` prints

* on our simulator's 168 grid windows, noise-free and at 60/40/30/20 dB (the seeds of ``jident evaluate``'s
  robustness sweep (a), 5 per level): how often the steadiness test (:func:`gap.pre_entry_steady`) keeps the
  joint fit, and the class, 95 % interval coverage, 'ambiguous' share and |J1 error| of the default (the model
  choice), the joint fit and the gap-only fit on the same windows;
* on the second drive's CSV recordings (``python -m jident_ros.research.second_drive --format csv``; the flank detector's
  event windows, as ``raw_inputs --report``): the steadiness test's largest p and smallest F, and the gap-only fit
  with the candidate interval moved (entry ``--early`` samples early, re-contact ``--late`` samples late) with and
  without the trimming of the in-zone set by the dynamics.

Plain numpy/scipy; the truth (truth.json) is read only here.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy import stats

from jident_ros.config import load_system_config
from jident_ros.identify.gap import (
    GAP_ONLY_TRIM_REL,
    GAP_ONLY_TRIM_SIGMA,
    NoGapError,
    estimate_inertia,
    gap_only_fit,
    nearest_class,
    pre_entry_steady,
)
from jident_ros.identify.monitor import DetectorConfig, make_detector
from jident_ros.identify.verdict import classes_in_interval
from jident_ros.research.evaluation.raw_inputs import RawRecording, event_window, run_detector
from jident_ros.research.evaluation.robustness import SNR_LEVELS_DB, noise_seed
from jident_ros.sim import SystemConfig, add_measurement_noise, paper_grid_cases, simulate_grid
from jident_ros.stream.inputs import read_csv

#: The fits compared on our simulator: label -> estimate_inertia's method.
FITS = {"default (model choice)": None, "joint fit": "acceleration", "gap-only fit": "gap_only"}
#: Base seeds of robustness sweep (a): the first one and its extra seeds.
SEEDS = (1, 2, 3, 4, 5)


def _judge(j1, lo, hi, truth, classes) -> dict:
    return {"class": classes[nearest_class(j1, classes)] == truth, "covered": lo <= truth <= hi,
            "ambiguous": len(classes_in_interval((lo, hi), classes)) >= 2, "error": abs(j1 / truth - 1.0)}


def _summary(rows: list) -> dict:
    n = len(rows)
    err = np.array([r["error"] for r in rows])
    return {"n": n, "class": sum(r["class"] for r in rows) / n, "covered": sum(r["covered"] for r in rows) / n,
            "ambiguous": sum(r["ambiguous"] for r in rows) / n, "median": float(np.median(err)),
            "max": float(err.max())}


def our_simulator(system: SystemConfig, log=print) -> dict:
    ws = simulate_grid(system, paper_grid_cases(system))
    classes = tuple(system.grid.inertia_classes_kgm2)
    r = system.load.wheel_radius_m
    out = {}
    for snr in (None,) + tuple(SNR_LEVELS_DB):
        seeds = [None] if snr is None else [noise_seed(b, snr) for b in SEEDS]
        rows = {k: [] for k in FITS}
        chosen, pmin = {}, 1.0
        for sd in seeds:
            w = ws if snr is None else add_measurement_noise(ws, snr, sd)
            for i, c in enumerate(w.cases):
                win = {k: w.signals[k][i] for k in ("alpha1", "alpha2", "a1", "m_el")}
                pmin = min(pmin, pre_entry_steady(win["m_el"][:w.entry_index]).p_value)
                for label, m in FITS.items():
                    g = estimate_inertia(win, w.entry_index, c.backlash_width_m, r, w.sample_period_s, m,
                                         system.motor.bearing_friction_nms_per_rad)
                    if m is None:
                        chosen[g.method] = chosen.get(g.method, 0) + 1
                    rows[label].append(_judge(g.inertia_kgm2, *g.ci95_kgm2, c.inertia_kgm2, classes))
        key = "noise-free" if snr is None else f"{snr:g} dB"
        out[key] = {"chosen": chosen, "min_p": pmin, "fits": {k: _summary(v) for k, v in rows.items()}}
        log(f"our simulator, {key} ({len(rows['joint fit'])} windows): fit chosen {chosen}, smallest p {pmin:.2g}")
        for label, s in out[key]["fits"].items():
            log(f"    {label:>22}: class {100 * s['class']:.1f} %, CI covers {100 * s['covered']:.1f} %, ambiguous "
                f"{100 * s['ambiguous']:.1f} %, |J1 error| median {100 * s['median']:.3f} % max {100 * s['max']:.3f} %")
    return out


def _moved(torque, acc, e, g, truth, classes, trim: bool) -> dict:
    kw = {} if trim else {"max_trim": (0, 0)}
    f = gap_only_fit(torque, acc, e, g, GAP_ONLY_TRIM_SIGMA, GAP_ONLY_TRIM_REL, **kw)
    half = float(stats.t.ppf(0.975, f["dof"])) * f["se"]
    return _judge(f["j1"], f["j1"] - half, f["j1"] + half, truth, classes)


def second_drive(system: SystemConfig, directory, early: int = 3, late: int = 2, log=print) -> dict:
    directory = Path(directory)
    truth = json.loads((directory / "truth.json").read_text())
    classes = tuple(system.grid.inertia_classes_kgm2)
    tests, moved = [], {"trimmed": [], "not trimmed": []}
    for tr in truth["recordings"]:
        data, channels, _ = read_csv(directory / tr["file"])
        ts = float(tr["sample_period_s"])
        det = make_detector(system, DetectorConfig("flank", channels=channels, gear_ratio=float(tr["gear_ratio"]),
                                                   encoder_counts_per_rev=int(tr["encoder"]["counts_per_rev"] or 0)),
                            float(tr["reference_radius_m"]), ts)
        rec = RawRecording(data, channels, int(tr["entry_index"]), float(tr["inertia_kgm2"]),
                           float(tr["backlash_width_m"]), tr["direction"], int(tr["event"]["index"]))
        wins = [e.window for e in run_detector(det, rec) if e.kind == "window"]
        ev = event_window(wins, float(data[rec.entry_row, 0]), float(data[int(tr["recontact_index"]), 0]), ts)
        if ev is None:
            continue
        d = ev.as_dict()
        tests.append(pre_entry_steady(d["m_el"][:ev.entry_index]))
        # the true interval inside the window, then moved
        e = ev.entry_index + int(round((float(data[rec.entry_row, 0]) - ev.entry_time_s) / ts))
        g = e + int(tr["recontact_index"]) - rec.entry_row
        torque = d["m_el"] - float(tr.get("bearing_friction_nms", 0.0)) * d["omega1"]
        acc = d["a1"] / ev.wheel_radius_m
        for label, trim in (("trimmed", True), ("not trimmed", False)):
            try:
                moved[label].append(_moved(torque, acc, e - early, g + late, rec.inertia_kgm2, classes, trim))
            except NoGapError:
                moved[label].append({"class": False, "covered": False, "ambiguous": False, "error": np.inf})
    out = {"windows": len(tests), "not_steady": sum(not t.steady for t in tests),
           "max_p": max(t.p_value for t in tests), "min_f": min(t.f_statistic for t in tests),
           "moved": {k: _summary(v) for k, v in moved.items()}, "early": early, "late": late}
    log(f"second drive {directory}: {out['windows']} event windows, pre-entry m_el not steady in {out['not_steady']} "
        f"(largest p {out['max_p']:.2g}, smallest F {out['min_f']:.3g})")
    for label, s in out["moved"].items():
        log(f"    gap-only fit, entry {early} early and re-contact {late} late, {label}: class "
            f"{round(s['class'] * s['n'])}/{s['n']}, CI covers {round(s['covered'] * s['n'])}, ambiguous "
            f"{round(s['ambiguous'] * s['n'])}, |J1 error| median {100 * s['median']:.3f} % max {100 * s['max']:.2f} %")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.gap_choice", description=__doc__.split("\n\n")[0])
    p.add_argument("--second-drive", nargs="*", default=(), metavar="DIR")
    p.add_argument("--no-simulator", action="store_true", help="skip our simulator's grid")
    p.add_argument("--early", type=int, default=3, help="entry moved this many samples early (second drive)")
    p.add_argument("--late", type=int, default=2, help="re-contact moved this many samples late (second drive)")
    p.add_argument("--json", default="")
    a = p.parse_args(argv)
    system = load_system_config()
    res = {}
    if not a.no_simulator:
        res["our_simulator"] = our_simulator(system)
    for d in a.second_drive:
        res.setdefault("second_drive", {})[str(d)] = second_drive(system, d, a.early, a.late)
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
