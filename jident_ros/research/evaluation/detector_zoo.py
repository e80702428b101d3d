"""The entry detector on recordings of the validation drives (issue 20 item 4, issue 24's spike): per model x event
x noise, entries found, false entries, the coarse entry offset, the flank detector's K2 per traversal window.

``python -m jident_ros.research.evaluation.detector_zoo DIR [DIR ...] [--wrap] [--spike-s S]`` reads directories of
CSV recordings with a ``truth.json`` (the second drive's ``python -m jident_ros.research.second_drive --format csv``
or the vector drive's ``python -m jident_ros.research.vector_drive --formats csv``) and runs the flank detector as
``jident diagnose`` would (r and N from the truth, the nominal J1 of the configuration or ``--nominal-kgm2``, as a
user configures them; no K2).

* **found**: the first gap of the recording has a window whose entry lies within +-6 samples of its entry;
* **false**: a window whose entry lies more than 6 samples from every gap's entry (in steady running, at a
  same-flank torque change, a spike);
* **offset**: window entry row - true entry row (the coarse location; the gap estimator refines it);
* **K2**: the window's K2 against the truth, traversal windows only (a bounce measures nothing).

``--wrap`` reports every position in [-pi, pi) (a continuous joint); ``--spike-s S`` adds a one-sample spike of
0.2 rad to alpha1 S seconds before the first gap (issue 24: it opened a false window that swallowed the event).
Research code: the runtime never imports it.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Optional

import numpy as np

from jident_ros.config import load_system_config
from jident_ros.identify.monitor import DetectorConfig, make_detector
from jident_ros.research.evaluation.raw_inputs import RawRecording, run_detector
from jident_ros.stream.inputs import read_csv

#: A window this many samples or fewer from a gap's entry belongs to that gap.
MATCH_SAMPLES = 6


def _wrap(x):
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi


def evaluate_dir(directory, system=None, wrap: bool = False, spike_s: float = 0.0,
                 nominal_kgm2: Optional[float] = None) -> list:
    """One row per window and one per recording (``rec``: True) of a directory of CSV recordings."""
    system = load_system_config() if system is None else system
    directory = Path(directory)
    truth = json.loads((directory / "truth.json").read_text())
    rows = []
    for tr in truth["recordings"]:
        data, ch, _ = read_csv(directory / tr.get("file", tr["name"] + ".csv"))
        data = data.copy()
        ts = float(tr.get("sample_period_s", system.sampling.sample_period_s))
        gaps = tr.get("gaps", [])
        if spike_s and gaps:
            k = int(gaps[0]["entry_index"]) - int(round(spike_s / ts))
            data[k, ch.index("alpha1")] += 0.2
        if wrap:
            for c in ("alpha1", "alpha2"):
                data[:, ch.index(c)] = _wrap(data[:, ch.index(c)])
        counts = int((tr.get("encoder") or {}).get("counts_per_rev") or 0)
        # the user configures the drive's nominal J1 (the refinement's J1_nom), one value for the drive, not each
        # recording's true J1: ``nominal_kgm2`` (default the configuration's, 1.16)
        drive = system if nominal_kgm2 is None else dataclasses.replace(
            system, motor=dataclasses.replace(system.motor, nominal_inertia_kgm2=float(nominal_kgm2)))
        det = make_detector(drive, DetectorConfig("flank", channels=ch, gear_ratio=float(tr["gear_ratio"]),
                                                   encoder_counts_per_rev=counts), float(tr["reference_radius_m"]), ts)
        wins = [e.window for e in run_detector(det, RawRecording(data, ch, 0, 0.0, 0.0, tr["direction"], 0))
                if e.kind == "window"]
        event = (tr.get("event") or {}).get("type", "speed_step_down")
        noise = (tr.get("noise") or {}).get("snr_db")
        key = {"event": event, "noise": "clean" if noise is None else f"{noise:g} dB", "counts": counts}
        t0 = float(data[0, 0])
        for w in wins:
            row = int(round((w.entry_time_s - t0) / ts))
            best = min(gaps, key=lambda g: abs(g["entry_index"] - row)) if gaps else None
            off = None if best is None else row - int(best["entry_index"])
            inside = [g for g in gaps if g["entry_index"] + MATCH_SAMPLES < row < (g.get("end_index") or
                                                                              g.get("recontact_index") or -1)]
            if inside and (off is None or abs(off) > MATCH_SAMPLES):
                # an entry inside a true gap, more than MATCH_SAMPLES after its start (a return traversal that rests
                # at the flank with no relative speed: delta looks like a contact there): late, not false
                rows.append({**key, "name": tr["name"], "false": False, "late": True, "row": row,
                             "offset": row - int(inside[0]["entry_index"])})
                continue
            if off is None or abs(off) > MATCH_SAMPLES:
                rows.append({**key, "name": tr["name"], "false": True, "row": row})
                continue
            trav = bool(best.get("traversal", best.get("from_flank") != best.get("to_flank")))
            rows.append({**key, "name": tr["name"], "false": False, "offset": off, "first": best is gaps[0],
                         "traversal": trav, "k2_error": w.backlash_width_estimate_m / float(tr["backlash_width_m"]) - 1})
        rows.append({**key, "name": tr["name"], "rec": True, "gaps": len(gaps), "spikes": det.spikes,
                     "flank_shifts": det.flank_shifts, "swallowed": det.counts.get("swallowed_entry", 0),
                     "wraps": det.wraps_undone})
    return rows


def summarise(rows: list) -> dict:
    recs = [r for r in rows if r.get("rec")]
    wins = [r for r in rows if not r.get("rec")]
    with_gap = {r["name"] for r in recs if r["gaps"]}
    late = [r for r in wins if r.get("late")]
    wins = [r for r in wins if not r.get("late")]
    found = {r["name"] for r in wins if not r["false"] and r["first"]}
    offs = [r["offset"] for r in wins if not r["false"]]
    k2 = np.array([r["k2_error"] for r in wins if not r["false"] and r["traversal"]], float)
    fin = np.abs(k2[np.isfinite(k2)])
    return {"recordings": len(recs), "with_gap": len(with_gap), "found": len(found & with_gap),
            "false": sum(r["false"] for r in wins), "windows": len(wins) + len(late), "late": len(late),
            "late_offsets": sorted(r["offset"] for r in late),
            "offsets": {int(k): int(v) for k, v in zip(*np.unique(offs, return_counts=True))} if offs else {},
            "within_2": sum(abs(o) <= 2 for o in offs), "matched": len(offs),
            "k2_windows": int(k2.size), "k2_no_estimate": int(np.sum(~np.isfinite(k2))),
            "k2_median": float(np.median(fin)) if fin.size else None, "k2_max": float(fin.max()) if fin.size else None,
            "k2_over_5pct": int(np.sum(fin > 0.05)), "spikes": sum(r["spikes"] for r in recs),
            "flank_shifts": sum(r["flank_shifts"] for r in recs), "swallowed": sum(r["swallowed"] for r in recs)}


def _pct(x):
    return "-" if x is None else f"{100 * x:.2f} %"


def table(label: str, rows: list, by=("event", "noise", "counts")) -> list:
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    out = [f"| {label} | entries found | false | offset (samples) | within ±2 | K2 median | K2 max | K2 > 5 % |"
           f" spikes / same-flank / swallowed |", "|---|---|---|---|---|---|---|---|---|"]
    for key in sorted(groups, key=str):
        s = summarise(groups[key])
        out.append(f"| {' '.join(str(k) for k in key)} | {s['found']}/{s['with_gap']} | {s['false']} | "
                   f"{s['offsets']} | {s['within_2']}/{s['matched']} | {_pct(s['k2_median'])} | {_pct(s['k2_max'])} | "
                   f"{s['k2_over_5pct']}/{s['k2_windows']} | {s['spikes']} / {s['flank_shifts']} / {s['swallowed']} |")
    s = summarise(rows)
    out.append(f"| **all** | {s['found']}/{s['with_gap']} | {s['false']} | {s['offsets']} | "
               f"{s['within_2']}/{s['matched']} | {_pct(s['k2_median'])} | {_pct(s['k2_max'])} | "
               f"{s['k2_over_5pct']}/{s['k2_windows']} | {s['spikes']} / {s['flank_shifts']} / {s['swallowed']} |")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.detector_zoo",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("dirs", nargs="+", help="directories of CSV recordings with truth.json")
    p.add_argument("--wrap", action="store_true", help="positions reported in [-pi, pi)")
    p.add_argument("--spike-s", type=float, default=0.0, help="a one-sample 0.2 rad alpha1 spike this long before "
                   "the first gap (0: none)")
    p.add_argument("--nominal-kgm2", type=float, default=None, help="the drive's nominal J1 as configured "
                   "(motor.nominal_inertia_kgm2; default config/system.yaml's 1.16)")
    a = p.parse_args(argv)
    for d in a.dirs:
        rows = evaluate_dir(d, wrap=a.wrap, spike_s=a.spike_s, nominal_kgm2=a.nominal_kgm2)
        print(f"\n{d}{' (wrapped)' if a.wrap else ''}{f' (spike {a.spike_s:g} s before)' if a.spike_s else ''}:")
        print("\n".join(table("event noise counts", rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
