"""Recordings as a real drive makes them, from our simulator, and the issue-12 targets of the flank detector.

A real drive has no zone-centred angles and no K2: :func:`raw_recordings` turns simulated windows
(docs/model.md section 3: the line slips by K2 at the entry) into single-event recordings of raw encoder
signals:

* a steady stretch of ``steady_s`` seconds in front of the event (the first sample held, the angles
  advancing at the steady speeds — the steady state is exact in the model), the 48 + 2000 samples of the
  window, ``tail_samples`` more (held) after it, the drive clock running on;
* arbitrary encoder offsets (uniform in [0, 2 pi) each, the zone centre at least 0.5 rad from delta = 0),
  and at the entry a slip that moves the load encoder's offset by a further uniform +-0.5 rad;
* encoder quantisation (``counts`` per revolution, floor) and white noise on the other channels at
  ``snr_db`` (MATLAB awgn 'measured', the noise power from the window's samples, as
  :func:`jident_ros.sim.add_measurement_noise`; the angles get quantisation only);
* reverse rotation: our simulator's steady-state solver starts from forward motoring only, so a reverse
  recording **mirrors the signs** of every channel but t (the model is odd in every state: the motor's
  torque under the swapped phase sequence, the film friction sign(v2) |v2|^n, the clutch law).

``python -m jident_ros.research.evaluation.raw_inputs --report`` runs the targets of issue 12 on the grid (7 J1 x 6
K2, eta_k of the pattern group) with the flank detector (no K2 given), clean and at 30 dB, both directions,
2^16-count encoders, 10 s steady stretches: entries found and false, the entry sample against the truth
(and against inequality 1 with zone-centred angles and the true K2), K2 error, and the default gap fit (the
model choice of :func:`jident_ros.identify.gap.estimate_inertia`) on every event window: class, 95 % interval
coverage, 'ambiguous' (two classes in the interval), J1 published by the verdict policy
(:func:`jident_ros.identify.verdict.decide_gap`) and how many of those are more than 10 % off.  With
``--second-drive DIR...`` the same on the second drive's CSV recordings (docs/second_drive.md).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.identify.diagnosis import detector_arguments
from jident_ros.identify.gap import NoGapError, estimate_inertia, nearest_class
from jident_ros.identify.monitor import DetectorConfig, make_detector
from jident_ros.identify.verdict import VerdictPolicy, decide_gap
from jident_ros.sim import Case, SystemConfig, simulate_grid
from jident_ros.stream.detector import stream_batches
from jident_ros.stream.flank import FlankDetector
from jident_ros.stream.inputs import read_csv
from jident_ros.stream.layout import DEFAULT_CHANNELS

#: Channels that get white noise (as jident_ros.sim.add_measurement_noise, plus omega1).
NOISY = ("a1", "m_el", "omega1", "a2", "v2", "omega2")

#: The event's window for the gap fit: the first window whose entry lies from this many samples before the
#: true entry up to the true re-contact (the detector's 'found' counts only |offset| <= 1).
EVENT_WINDOW_EARLY_SAMPLES = 4
#: A published J1 this far from the truth is counted as misleading (issue 12: none may be).
PUBLISHED_TOLERANCE = 0.10


@contextlib.contextmanager
def flank_refine(replacement):
    """Inside the block, ``FlankDetector._refine`` (the entry sample from the departure, and the re-contact row) is
    ``replacement(saved)``, a function of the saved one; restored after, also on an exception. The experiments on
    the detector lane's code (raw_scenario.entry_refinement, zoo.entry_shift), in this process only."""
    saved = FlankDetector._refine
    FlankDetector._refine = replacement(saved)
    try:
        yield
    finally:
        FlankDetector._refine = saved


def gap_row(w, true_j1: float, classes, nominal_kgm2: float, bearing_friction: float = 0.0,
            method: Optional[str] = None, policy: Optional[VerdictPolicy] = None) -> dict:
    """The gap fit (``method`` None: the default model choice) on one detector window, judged against the
    truth: j1, rel_error, class_ok, covered (95 % interval), ambiguous (two or more classes in it),
    published (the verdict policy accepts it; a flank window carries no K2 to check it against), fit (the
    fit used), gap_problem (why there is none)."""
    policy = VerdictPolicy() if policy is None else policy
    try:
        g = estimate_inertia(w.as_dict(), w.entry_index, w.backlash_width_m, w.wheel_radius_m, w.sample_period_s,
                             method=method, bearing_friction_nms_per_rad=bearing_friction,
                             recontact_index=w.recontact_index,
                             entry_uncertainty_samples=detector_arguments(w).get("entry_uncertainty_samples", 0))
    except NoGapError as exc:
        return {"j1": None, "rel_error": None, "class_ok": False, "covered": False, "ambiguous": False,
                "published": False, "fit": "", "gap_problem": str(exc)}
    dec = decide_gap(g, classes, nominal_kgm2, policy, None, w.backlash_width_m)
    return {"j1": g.inertia_kgm2, "rel_error": g.inertia_kgm2 / true_j1 - 1.0,
            "class_ok": classes[nearest_class(g.inertia_kgm2, classes)] == true_j1,
            "covered": bool(g.ci95_kgm2[0] <= true_j1 <= g.ci95_kgm2[1]), "ambiguous": dec.status == "ambiguous",
            "published": dec.publish, "fit": g.method, "gap_problem": ""}


def gap_summary(rows: list) -> dict:
    """Counts over the rows of :func:`gap_row` (rows without a fit included as failures)."""
    fitted = [r for r in rows if r.get("j1") is not None]
    err = np.array([abs(r["rel_error"]) for r in fitted])
    fits: dict = {}
    for r in fitted:
        fits[r["fit"]] = fits.get(r["fit"], 0) + 1
    return {"gap_windows": len(rows), "gap_fitted": len(fitted),
            "class_correct": sum(bool(r.get("class_ok")) for r in rows),
            "ci_covers": sum(bool(r.get("covered")) for r in rows),
            "ambiguous": sum(bool(r.get("ambiguous")) for r in rows),
            "published": sum(bool(r.get("published")) for r in rows),
            "published_off": sum(bool(r.get("published")) and abs(r["rel_error"]) > PUBLISHED_TOLERANCE
                                 for r in rows),
            "j1_median_abs_error": float(np.median(err)) if err.size else None,
            "j1_max_abs_error": float(err.max()) if err.size else None, "fits": fits}


def event_window(wins: list, entry_t: float, recontact_t: float, ts: float):
    for w in wins:
        if entry_t - (EVENT_WINDOW_EARLY_SAMPLES + 0.5) * ts <= w.entry_time_s < recontact_t:
            return w
    return None


@dataclass
class RawRecording:
    """One single-event recording.

    data : (n, c) samples, columns ``channels`` (t first)
    channels : tuple of names
    entry_row : row of the entry sample (the first in the zone: the truth)
    inertia_kgm2, backlash_width_m : the case's J1 and K2
    direction : "forward" | "reverse"
    steady_rows : the rows of the steady stretch before the event (false entries are counted there)
    """

    data: np.ndarray
    channels: tuple
    entry_row: int
    inertia_kgm2: float
    backlash_width_m: float
    direction: str
    steady_rows: int

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.channels.index(name)]


def raw_recordings(system: SystemConfig, inertias: Optional[Sequence[float]] = None,
                   widths: Optional[Sequence[float]] = None, consistency_pa_sn: float = 0.025, *,
                   snr_db: Optional[float] = None, counts: int = 65536, steady_s: float = 10.0,
                   tail_samples: int = 100, direction: str = "forward", seed: int = 0,
                   slip_offset_rad: float = 0.5, raw_angles: bool = True,
                   channels: Sequence[str] = DEFAULT_CHANNELS) -> list:
    """Single-event recordings of every (J1, K2) of the grid (module docstring).

    ``raw_angles`` False keeps the simulator's zone-centred angles (no offsets, no slip offset, no
    quantisation when ``counts`` is 0): the comparison with inequality 1.
    """
    if direction not in ("forward", "reverse"):
        raise ValueError(f"direction: expected 'forward' or 'reverse', got {direction!r}")
    g = system.grid
    inertias = tuple(g.inertia_classes_kgm2 if inertias is None else inertias)
    widths = tuple(g.backlash_widths_m if widths is None else widths)
    cases = [Case(float(j), float(w), float(consistency_pa_sn)) for j in inertias for w in widths]
    ws = simulate_grid(system, cases)
    ts = ws.sample_period_s
    rng = np.random.default_rng(seed)
    n_steady = int(round(steady_s / ts))
    nw = len(ws.t)
    out = []
    sgn = 1.0 if direction == "forward" else -1.0
    for i, case in enumerate(cases):
        n = n_steady + nw + tail_samples
        cols = {}
        back = (np.arange(n_steady) - n_steady) * ts
        fwd = (np.arange(1, tail_samples + 1)) * ts
        for c in channels:
            if c == "t":
                continue
            x = ws.signals[c][i]
            col = np.empty(n)
            col[n_steady:n_steady + nw] = x
            if c in ("alpha1", "alpha2"):
                w = ws.signals["omega1" if c == "alpha1" else "omega2"][i]
                col[:n_steady] = x[0] + w[0] * back
                col[n_steady + nw:] = x[-1] + w[-1] * fwd
            else:
                col[:n_steady] = x[0]
                col[n_steady + nw:] = x[-1]
            if snr_db is not None and c in NOISY:
                p = float(np.mean(x * x)) / 10.0 ** (snr_db / 10.0)
                col = col + rng.standard_normal(n) * math.sqrt(p)
            cols[c] = sgn * col
        entry = n_steady + int(ws.entry_index)
        if raw_angles:
            while True:
                o1, o2 = rng.uniform(0.0, 2 * math.pi, 2)
                if abs((o1 - o2 + math.pi) % (2 * math.pi) - math.pi) >= 0.5:
                    break
            cols["alpha1"] = cols["alpha1"] + o1
            cols["alpha2"] = cols["alpha2"] + o2
            cols["alpha2"][entry:] += rng.uniform(-slip_offset_rad, slip_offset_rad)
        if counts:
            q = 2 * math.pi / counts
            for c in ("alpha1", "alpha2"):
                cols[c] = np.floor(cols[c] / q) * q
        t = 1.0 + np.arange(n) * ts
        data = np.column_stack([t if c == "t" else cols[c] for c in channels])
        out.append(RawRecording(data, tuple(channels), entry, case.inertia_kgm2, case.backlash_width_m,
                                direction, n_steady))
    return out


def run_detector(det, rec: RawRecording, batch_size: int = 50) -> list:
    """Windows the detector captures on a recording (then finish(): a cut-off window is an event too)."""
    events = []
    for b in stream_batches(rec.data, batch_size):
        events += det.push(b, rec.channels)
    events += det.finish()
    return events


def flank_detector(system: SystemConfig, counts: int = 65536, **kw) -> FlankDetector:
    """The flank detector of our simulator's recordings (``kw``: :class:`DetectorConfig` fields)."""
    return make_detector(system, DetectorConfig("flank", encoder_counts_per_rev=counts, **kw))


#: The inputs the dynamics detector is measured on: the channels a drive without them lacks.
DYNAMICS_INPUTS = {"no load encoder": ("alpha2", "omega2", "a2", "v2"),
                   "no load encoder, no accelerometer": ("alpha2", "omega2", "a2", "v2", "a1")}


def without(rec: RawRecording, absent: Sequence[str]) -> RawRecording:
    """The recording without the channels ``absent`` (a drive that lacks those sensors)."""
    keep = [c for c in rec.channels if c not in absent]
    idx = [rec.channels.index(c) for c in keep]
    return RawRecording(rec.data[:, idx], tuple(keep), rec.entry_row, rec.inertia_kgm2, rec.backlash_width_m,
                        rec.direction, rec.steady_rows)


def evaluate_condition(system: SystemConfig, recs: list, counts: int, detector: str = "flank") -> dict:
    """Per recording: windows, entry offset (samples), K2 relative error, gap J1 and its class."""
    classes = tuple(system.grid.inertia_classes_kgm2)
    ts = system.sampling.sample_period_s
    rows = []
    for rec in recs:
        det = make_detector(system, DetectorConfig(detector, channels=rec.channels, encoder_counts_per_rev=counts))
        evs = run_detector(det, rec)
        wins = [e.window for e in evs if e.kind == "window"]
        t_entry = float(rec.data[rec.entry_row, 0])
        offsets = [int(round((w.entry_time_s - t_entry) / ts)) for w in wins]
        hit = [k for k, o in enumerate(offsets) if abs(o) <= 1]
        row = {"inertia_kgm2": rec.inertia_kgm2, "backlash_width_m": rec.backlash_width_m,
               "windows": len(wins), "found": bool(hit), "false_entries": len(wins) - len(hit),
               "false_in_steady": sum(1 for w in wins if w.entry_time_s < float(rec.data[rec.steady_rows, 0])),
               "drops": {k: v for k, v in det.counts.items() if v}, "entry_offset": None,
               "width_m": None, "width_se_m": None, "width_error": None, "j1": None, "class_ok": False,
               "gap_problem": ""}
        if hit:
            w = wins[hit[0]]
            row["entry_offset"] = offsets[hit[0]]
            row["width_m"], row["width_se_m"] = w.backlash_width_estimate_m, w.backlash_width_se_m
            row["width_error"] = w.backlash_width_estimate_m / rec.backlash_width_m - 1.0
            row["flags"] = w.flags
        ev = event_window(wins, t_entry, t_entry + 1.5 * ts, ts)   # the simulator's truth has no re-contact row
        if ev is not None:
            row.update(gap_row(ev, rec.inertia_kgm2, classes, system.motor.nominal_inertia_kgm2,
                               system.motor.bearing_friction_nms_per_rad))
        rows.append(row)
    n = len(rows)
    werr = np.array([abs(r["width_error"]) for r in rows if r["width_error"] is not None and
                     math.isfinite(r["width_error"])])
    offs = [r["entry_offset"] for r in rows if r["entry_offset"] is not None]
    return {"recordings": n, "entries_found": sum(r["found"] for r in rows),
            "false_entries": sum(r["false_entries"] for r in rows),
            "false_in_steady": sum(r["false_in_steady"] for r in rows),
            "steady_s_total": sum(rec.steady_rows for rec in recs) * ts,
            "entry_offset_counts": {str(k): offs.count(k) for k in sorted(set(offs))},
            "width_max_abs_error": float(werr.max()) if werr.size else None,
            "width_median_abs_error": float(np.median(werr)) if werr.size else None,
            "width_estimates": int(werr.size), **gap_summary(rows), "rows": rows}


def paper_consistency(system: SystemConfig, counts: int = 0) -> dict:
    """Entry sample of the flank detector against inequality 1 (zone-centred angles, the true K2) on
    the grid: the distribution of (flank entry row - inequality-1 entry row)."""
    recs = raw_recordings(system, raw_angles=False, counts=counts, steady_s=1.0)
    s = system.sampling
    diffs = []
    for rec in recs:
        paper = make_detector(system, DetectorConfig("paper", rec.backlash_width_m))
        pw = [e.window for e in run_detector(paper, rec) if e.kind == "window"]
        fw = [e.window for e in run_detector(flank_detector(system, counts), rec) if e.kind == "window"]
        if not pw or not fw:
            diffs.append(None)
            continue
        diffs.append(int(round((fw[0].entry_time_s - pw[0].entry_time_s) / s.sample_period_s)))
    vals = [d for d in diffs if d is not None]
    return {"cases": len(recs), "compared": len(vals),
            "difference_counts": {str(k): vals.count(k) for k in sorted(set(vals))}}


def evaluate_second_drive(system: SystemConfig, directory, batch_size: int = 50, detector: str = "flank",
                          absent: Sequence[str] = ()) -> dict:
    """The flank detector and the gap estimator on a directory of the second drive's CSV recordings
    (``python -m jident_ros.research.second_drive --format csv``, ground truth in its truth.json, read only here):
    r = the truth's reference radius and N its gear ratio (what a user configures), no K2.  ``absent``: channels
    taken out (a drive without those sensors)."""
    directory = Path(directory)
    truth = json.loads((directory / "truth.json").read_text())
    classes = tuple(system.grid.inertia_classes_kgm2)
    nominal = system.motor.nominal_inertia_kgm2
    rows = []
    for tr in truth["recordings"]:
        data, channels, _ = read_csv(directory / tr["file"])
        ts = float(tr["sample_period_s"])
        rec = without(RawRecording(data, channels, int(tr["entry_index"]), float(tr["inertia_kgm2"]),
                                   float(tr["backlash_width_m"]), tr["direction"], int(tr["event"]["index"])), absent)
        data, channels = rec.data, rec.channels
        det = make_detector(system, DetectorConfig(detector, channels=channels, gear_ratio=float(tr["gear_ratio"]),
                                                   encoder_counts_per_rev=int(tr["encoder"]["counts_per_rev"] or 0)),
                            float(tr["reference_radius_m"]), ts)
        evs = run_detector(det, rec, batch_size)
        wins = [e.window for e in evs if e.kind == "window"]
        t_entry = float(data[rec.entry_row, 0])
        offsets = [int(round((w.entry_time_s - t_entry) / ts)) for w in wins]
        hit = [k for k, o in enumerate(offsets) if abs(o) <= 1]
        row = {"name": tr["name"], "direction": tr["direction"], "inertia_kgm2": rec.inertia_kgm2,
               "backlash_width_m": rec.backlash_width_m, "windows": len(wins), "offsets": offsets,
               "found": bool(hit), "false_entries": len(wins) - len(hit),
               "false_in_steady": sum(1 for w in wins if w.entry_time_s < float(data[rec.steady_rows, 0])),
               "drops": {k: v for k, v in det.counts.items() if v}, "width_error": None, "j1": None,
               "class_ok": False, "gap_problem": "", "recontact_true": int(tr["recontact_index"]) - rec.entry_row}
        if hit:
            w = wins[hit[0]]
            row["width_error"] = w.backlash_width_estimate_m / rec.backlash_width_m - 1.0
            row["width_how"] = det.last_width.how if det.last_width else ""
            row["flags"] = w.flags
        # the gap fits on the event's window, also when its entry sample is a few samples early
        ev = event_window(wins, t_entry, float(data[int(tr["recontact_index"]), 0]), ts)
        if ev is not None:
            row["recontact"] = ev.recontact_index - ev.entry_index
            b1 = float(tr.get("bearing_friction_nms", 0.0))
            row.update(gap_row(ev, rec.inertia_kgm2, classes, nominal, b1))
            row["alternatives"] = {m: gap_row(ev, rec.inertia_kgm2, classes, nominal, b1, method=m)
                                   for m in SECOND_DRIVE_ALTERNATIVES}
        rows.append(row)
    werr = np.array([abs(r["width_error"]) for r in rows if r["width_error"] is not None and
                     math.isfinite(r["width_error"])])
    offs = [o for r in rows for o in r["offsets"][:1]]
    return {"recordings": len(rows), "entries_found": sum(r["found"] for r in rows),
            "false_entries": sum(r["false_entries"] for r in rows),
            "false_in_steady": sum(r["false_in_steady"] for r in rows),
            "entry_offset_counts": {str(k): offs.count(k) for k in sorted(set(offs))},
            "width_max_abs_error": float(werr.max()) if werr.size else None,
            "width_median_abs_error": float(np.median(werr)) if werr.size else None,
            "width_estimates": int(werr.size), **gap_summary(rows),
            "alternatives": {m: gap_summary([r["alternatives"][m] for r in rows if "alternatives" in r])
                             for m in SECOND_DRIVE_ALTERNATIVES}, "rows": rows}


CONDITIONS = (("clean", None), ("30 dB", 30.0))

#: The single fits run beside the default on the second drive's event windows.
SECOND_DRIVE_ALTERNATIVES = ("acceleration", "gap_only", "speed")


def gap_line(res: dict) -> str:
    """The gap part of a report line."""
    n = res["gap_windows"]
    return (f"gap fit on {n} event windows: class {res['class_correct']}/{n}, 95 % CI covers "
            f"{res['ci_covers']}/{n}, ambiguous {res['ambiguous']}/{n}, published {res['published']} "
            f"({res['published_off']} > {PUBLISHED_TOLERANCE:.0%} off), |J1 error| median "
            f"{_pct(res['j1_median_abs_error'])} max {_pct(res['j1_max_abs_error'])}, fits {res['fits']}")


def report(system: SystemConfig, steady_s: float = 10.0, counts: int = 65536, seed: int = 12,
           log=print, detector: str = "flank") -> dict:
    """The flank detector (``detector`` "flank") on our simulator's recordings, or the dynamics detector
    ("dynamics") on the same recordings without the channels of each :data:`DYNAMICS_INPUTS` set."""
    out = {"counts_per_rev": counts, "steady_s": steady_s, "detector": detector, "conditions": {}}
    t0 = time.perf_counter()
    if detector == "flank":
        pc = paper_consistency(system)
        out["paper_consistency"] = pc
        log(f"entry sample vs inequality 1 (zone-centred angles, true K2, {pc['compared']}/{pc['cases']} cases): "
            f"flank - paper = {pc['difference_counts']}")
    inputs = {"": ()} if detector == "flank" else DYNAMICS_INPUTS
    for label, snr in CONDITIONS:
        for direction in ("forward", "reverse"):
            recs = raw_recordings(system, snr_db=snr, counts=counts, steady_s=steady_s, direction=direction,
                                  seed=seed + (0 if snr is None else 1) + (0 if direction == "forward" else 2))
            for name, absent in inputs.items():
                res = evaluate_condition(system, [without(r, absent) for r in recs], counts, detector)
                key = f"{label} {direction}" + (f", {name}" if name else "")
                out["conditions"][key] = res
                log(f"{key:>14}: entries {res['entries_found']}/{res['recordings']}, false {res['false_entries']} "
                    f"(in {res['steady_s_total']:.0f} s steady: {res['false_in_steady']}), entry offset "
                    f"{res['entry_offset_counts']}, K2 |error| median {_pct(res['width_median_abs_error'])} "
                    f"max {_pct(res['width_max_abs_error'])} ({res['width_estimates']} estimates); {gap_line(res)}")
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def _pct(x):
    return "n/a" if x is None else f"{100 * x:.2f} %"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.raw_inputs", description=__doc__.split("\n\n")[0])
    p.add_argument("--report", action="store_true", help="run the issue-12 detector targets on our simulator")
    p.add_argument("--steady-s", type=float, default=10.0)
    p.add_argument("--counts", type=int, default=65536)
    p.add_argument("--second-drive", nargs="*", default=(), metavar="DIR",
                   help="also evaluate these directories of the second drive's CSV recordings "
                        "(python -m jident_ros.research.second_drive --format csv --out DIR)")
    p.add_argument("--detector", choices=("flank", "dynamics"), default="flank",
                   help="flank (raw angles, no K2) or dynamics (the load-torque step; run without the load encoder, "
                        "and without it and a1)")
    p.add_argument("--json", default="", help="also write the full result here")
    a = p.parse_args(argv)
    if not a.report:
        p.print_help()
        return 0
    system = load_system_config()
    res = report(system, steady_s=a.steady_s, counts=a.counts, detector=a.detector)
    inputs = {"": ()} if a.detector == "flank" else DYNAMICS_INPUTS
    for d, (name, absent) in ((d, x) for d in a.second_drive for x in inputs.items()):
        r = evaluate_second_drive(system, d, detector=a.detector, absent=absent)
        res.setdefault("second_drive", {})[str(d) + (f", {name}" if name else "")] = r
        print(f"second drive {d}{', ' + name if name else ''}: entries {r['entries_found']}/{r['recordings']}, false {r['false_entries']} "
              f"(in the steady stretches: {r['false_in_steady']}), entry offset {r['entry_offset_counts']}, K2 |error| "
              f"median {_pct(r['width_median_abs_error'])} max {_pct(r['width_max_abs_error'])} "
              f"({r['width_estimates']} estimates); default {gap_line(r)}")
        for m, alt in r["alternatives"].items():
            print(f"    fit {m!r} alone: class {alt['class_correct']}/{alt['gap_windows']}, CI covers "
                  f"{alt['ci_covers']}, ambiguous {alt['ambiguous']}, published {alt['published']} "
                  f"({alt['published_off']} > {PUBLISHED_TOLERANCE:.0%} off), |J1 error| median "
                  f"{_pct(alt['j1_median_abs_error'])} max {_pct(alt['j1_max_abs_error'])}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
