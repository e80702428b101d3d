"""A scenario recorded as a real drive records it (issue 21's hidden scenario, rebuilt with our writers).

    python -m jident_ros.research.evaluation.raw_scenario --out DIR [--windows 40] [--interval-s 3600]
        [--width-start-m 0.0025 --width-end-m 0.005] [--j1-step-at 24 --j1-step-pct -2.5] [--snr-db 30]
        [--encoder-counts 65536] [--channels t,alpha1,...] [--namespace /press1] [--seed 0] [--study]
    jident trend DIR/rec_* --out OUT

One bag per entry (``DIR/rec_000``, ...) holding the ``drive/signals`` topic only (no truth topics), raw encoder
angles (arbitrary offsets, a slip at the entry, ``--encoder-counts`` per revolution:
:func:`jident_ros.research.evaluation.raw_inputs.raw_recordings`), white noise at ``--snr-db`` on the other
channels, 1 s of steady drive before the event, the drive clock at the entry equal to the scenario's entry time
(:func:`jident_ros.sim.scenarios.wear_scenario`: K2 growing linearly, J1 stepped once).  ``--channels``: every
channel our simulator publishes (default), or e.g. :data:`DRIVE_CHANNELS` (what a drive itself measures: no
accelerometer, no load-side torque).  ``truth.json`` beside the bags (read by nothing in the product).

``--study`` then runs ``jident trend``'s engine on the recordings twice -- as the product runs, and with the flank
detector's entry refinement off (:func:`entry_refinement`: the entry sample = the departure sample, an
experiment, not a product setting) -- and prints, per run, where each window's entry fell against the truth
(samples), the K2 and J1 it gave, what the trend was fed and when it flagged the J1 step (:func:`study`).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
from pathlib import Path
from typing import Optional

from jident_ros.cli.scenario import write_signals_bag
from jident_ros.cli.trend_run import run_trend
from jident_ros.config import load_system_config
from jident_ros.research.evaluation.raw_inputs import flank_refine, raw_recordings
from jident_ros.sim.scenarios import Scenario, wear_scenario
from jident_ros.stream.layout import DEFAULT_CHANNELS, KNOWN_CHANNELS

#: What a drive itself measures (the JointState of a motor and a load joint: positions, velocities, the motor's
#: torque estimate); no accelerometer, no load-side torque or line speed.
DRIVE_CHANNELS = ("t", "alpha1", "omega1", "m_el", "alpha2", "omega2")
#: Steady drive recorded before each event, s.
RAW_STEADY_S = 1.0


def write_raw_scenario(out, system, scenario: Scenario, *, snr_db: Optional[float] = None, seed: int = 0,
                       encoder_counts: int = 2 ** 16, namespace: str = "", channels=DEFAULT_CHANNELS) -> list:
    """``scenario`` as a real drive records it (module docstring).  Returns the bag directories."""
    out = Path(out)
    paths = []
    for i, c in enumerate(scenario.cases):
        rec = raw_recordings(system, [c.inertia_kgm2], [c.backlash_width_m], c.consistency_pa_sn, snr_db=snr_db,
                             counts=int(encoder_counts), steady_s=RAW_STEADY_S, seed=int(seed) * 100003 + i,
                             channels=tuple(channels))[0]
        data = rec.data.copy()
        ti = rec.channels.index("t")
        data[:, ti] += float(scenario.entry_times_s[i]) - data[rec.entry_row, ti]
        paths.append(write_signals_bag(out / f"rec_{i:03d}", data, rec.channels, namespace))
    return paths


def entry_refinement(on: bool):
    """The flank detector's entry refinement (``FlankDetector._refine``: the entry moved past the departure while
    the load torque m_el - J1_nom dω1/dt has not vanished) as it is (``on``) or off (the entry sample is the
    departure sample, no re-contact row from the dynamics) inside the block: an experiment on the detector lane's
    code, in this process only (:func:`~jident_ros.research.evaluation.raw_inputs.flank_refine`)."""
    if on:
        return contextlib.nullcontext()
    return flank_refine(lambda saved: lambda self, data, dep: (0, None))


def study(paths, truth: dict, system, refine: bool = True) -> dict:
    """``jident trend``'s engine (:func:`jident_ros.cli.trend_run.run_trend`, in this process) over ``paths`` with
    the entry refinement on or off: per window its entry offset from the truth (samples), K2, J1 (or why none);
    the J1 fed/refused counts, the first J1 change (recording index, its delay in recordings from the step, any
    before it) and the width's last/first ratio."""
    ts = system.sampling.sample_period_s
    with entry_refinement(refine):
        run = run_trend(paths, system=system, jobs=1)
    entries = truth["entry_times_s"]
    rec_index = {str(p): i for i, p in enumerate(paths)}
    rows = []
    for w in run.windows:
        i = rec_index[w.recording]
        rows.append({"recording": i, "offset_samples": int(round((w.time_s - entries[i]) / ts)),
                     "width_mm": None if w.width_m is None else 1e3 * w.width_m,
                     "j1": w.inertia_kgm2, "why_none": w.refused_kind or (w.skip_reason or "")[:60] or None})
    step = truth["j1_step_at"]
    changes = [(rec_index[w.recording], c) for w, u in zip(run.windows, run.updates) for c in u.changes
               if c.quantity == "inertia"]
    after = [(i, c) for i, c in changes if i >= step]
    widths = [u.width_m for u in run.updates if u.width_m is not None]
    last = run.updates[-1] if run.updates else None
    return {"refine": refine, "windows": rows, "exact": sum(r["offset_samples"] == 0 for r in rows),
            "late": sorted(r["offset_samples"] for r in rows if r["offset_samples"] > 0),
            "fed": run.tracker.inertia_fed, "refused": dict(run.tracker.inertia_refused),
            "before_step": [i for i, _ in changes if i < step],
            "first_after": None if not after else {"recording": after[0][0], "delay": after[0][0] - step,
                                                   "size_pct": after[0][1].size_pct},
            "width_ratio": widths[-1] / widths[0] if len(widths) > 1 else math.nan,
            "commissioned_kgm2": None if last is None else last.inertia_reference_kgm2,
            "baseline_kgm2": None if last is None else last.inertia_baseline_kgm2}


def format_study(results: list) -> str:
    """The markdown table of :func:`study`'s results (one row per run)."""
    lines = ["| entry refinement | entries exact / late (offsets, samples) | J1 fed / refused | first J1 change "
             "(recording, delay) | changes before the step | width last/first | J1 commissioned / baseline |",
             "|---|---|---|---|---|---|---|"]
    for r in results:
        f = r["first_after"]
        first = "none" if f is None else f"{f['recording']} (+{f['delay']}), {f['size_pct']:+.2f} %"
        lines.append(f"| {'on (as shipped)' if r['refine'] else 'off (experiment)'} | {r['exact']} / "
                     f"{len(r['late'])} {r['late']} | {r['fed']} / {sum(r['refused'].values())} {r['refused']} | "
                     f"{first} | {len(r['before_step'])} | {r['width_ratio']:.3f} | "
                     f"{r['commissioned_kgm2']:.4f} / {r['baseline_kgm2']:.4f} |")
    return "\n".join(lines)


def _channels(text: str) -> tuple:
    names = tuple(c.strip() for c in text.split(",") if c.strip())
    bad = [c for c in names if c not in KNOWN_CHANNELS]
    if bad or "t" not in names or "alpha1" not in names:
        raise SystemExit(f"--channels: {bad[0] if bad else text!r} is not a channel list with t and alpha1 "
                         f"(known: {','.join(KNOWN_CHANNELS)})")
    return names


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.raw_scenario",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--windows", type=int, default=40)
    ap.add_argument("--interval-s", type=float, default=3600.0)
    ap.add_argument("--width-start-m", type=float, default=0.0025)
    ap.add_argument("--width-end-m", type=float, default=0.005)
    ap.add_argument("--j1-step-at", type=int, default=24, help="first recording (0-based) with the stepped J1")
    ap.add_argument("--j1-step-pct", type=float, default=-2.5)
    ap.add_argument("--snr-db", type=float, default=30.0)
    ap.add_argument("--encoder-counts", type=int, default=2 ** 16)
    ap.add_argument("--channels", default=",".join(DEFAULT_CHANNELS),
                    help=f"recorded channels (default: all; a drive's own: {','.join(DRIVE_CHANNELS)})")
    ap.add_argument("--namespace", default="")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--study", action="store_true",
                    help="then run the trend with the flank detector's entry refinement on and off (module docstring)")
    a = ap.parse_args(argv)
    system = load_system_config()
    out = Path(a.out)
    if out.exists() and any(out.glob("rec_*")):
        ap.error(f"--out {a.out}: already holds recordings (rec_*); give a new or empty directory")
    try:
        sc = wear_scenario(system, a.windows, a.interval_s, a.width_start_m, a.width_end_m, None, None,
                           a.j1_step_at, a.j1_step_pct, None)
    except ValueError as exc:
        ap.error(str(exc))
    paths = write_raw_scenario(out, system, sc, snr_db=a.snr_db, seed=a.seed, encoder_counts=a.encoder_counts,
                               namespace=a.namespace, channels=_channels(a.channels))
    truth = {"entry_times_s": [float(t) for t in sc.entry_times_s],
             "inertia_kgm2": [c.inertia_kgm2 for c in sc.cases], "backlash_width_m": [c.backlash_width_m for c in sc.cases],
             "j1_step_at": sc.j1_step_at_window, "snr_db": a.snr_db, "encoder_counts": a.encoder_counts,
             "channels": list(_channels(a.channels))}
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    print(f"{len(paths)} recordings in {out} (rec_000 .. rec_{len(paths) - 1:03d}), truth.json beside them")
    if a.study:
        results = [study(paths, truth, system, refine) for refine in (True, False)]
        (out / "study.json").write_text(json.dumps(results, indent=1))
        print(format_study(results))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
