"""The detectors at any sample rate: the vector drive recorded at 1, 2, 4 and 8 kHz, diagnosed at its own rate.

``python -m jident_ros.research.evaluation.zoo_rates --report`` (``--results -`` prints instead of writing
docs/results.md; ``--rates 4,8`` a subset; ``--out`` the recordings' folder, default out/zoo_variants: the 1, 2 and
4 kHz recordings are zoo_variants' "recorded at 1 kHz", "base" and "recorded at 4 kHz", shared with it)

Issue 20: users record at 1, 2, 4 or 8 kHz.  The detectors' sample counts that are durations were chosen at 2 kHz
and are converted to the configured sample period (jident_ros.stream.rate).  This runs the vector drive
(docs/vector_drive.md's base drive, the zoo_variants events and sensors) at each rate, diagnosed with that sample
period and a window of the same length in time (1 s from the entry; 2 kHz: config/system.yaml's, as the base
variant), and counts what zoo_variants counts plus the entry within ±1 ms of the contact loss (±2 samples at 2 kHz:
the same time at every rate) and the largest entry offset in ms.  At 8 kHz the drive's control period is 125 µs
(motulator's drive records a multiple of its control period; the others keep 250 µs): a drive of the same physics
with a faster loop.  The second drive (jident_ros/research/second_drive, the zoo's speed steps down at J1 1.16, K2 2.5
and 7.5 mm, both directions, JointState 2^16 and 2^13, clean and 30 dB) the same way, recorded under out/zoo_rates.
Nothing is chosen here.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from jident_ros.config import load_system_config
from jident_ros.research.evaluation import zoo
from jident_ros.research.evaluation.zoo_variants import EVENTS, SENSORS
from jident_ros.research.second_drive import record as sd_record
from jident_ros.research.second_drive.model import DriveParams as SecondParams
from jident_ros.research.vector_drive import record as vd_record
from jident_ros.research.vector_drive.model import DriveParams, motulator_available

#: (rate label, folder (zoo_variants' variant folder where it has the rate), sample period s)
RATES = (("1 kHz", "recorded_at_1_kHz", 1e-3), ("2 kHz", "base", 5e-4), ("4 kHz", "recorded_at_4_kHz", 2.5e-4),
         ("8 kHz", "recorded_at_8_kHz", 1.25e-4))


def drive_at(sample_period_s: float) -> DriveParams:
    """The base vector drive recorded every ``sample_period_s`` (its control period halved to 125 µs below 250 µs)."""
    b = DriveParams()
    if sample_period_s < b.controller.control_period_s:
        b = replace(b, controller=replace(b.controller, control_period_s=sample_period_s))
    return replace(b, sample_period_s=sample_period_s) if sample_period_s != b.sample_period_s else b


def system_at(sample_period_s: float):
    """config/system.yaml at ``sample_period_s`` with a 1 s window (2 kHz: unchanged, as zoo_variants' base)."""
    system = load_system_config(None)
    if sample_period_s == system.sampling.sample_period_s:
        return system
    return replace(system, sampling=replace(system.sampling, sample_period_s=sample_period_s,
                                            samples_from_entry=int(round(1.0 / sample_period_s))))


def second_items(ts: float, system, out: Path) -> list:
    """(ZooRecording, diagnose_one result) of the second drive recorded every ``ts`` (the zoo's gen_second at
    J1 1.16, JointState only)."""
    params = replace(SecondParams(), sample_period_s=ts)
    cases = sd_record.grid_cases(("forward", "reverse"), (1.16,), zoo.WIDTHS)
    items = []
    for counts in (65536, 8192):
        for noise, snr in zoo.NOISE:
            sensors = sd_record.SensorConfig(encoder_counts=counts, snr_db=snr)
            for r in sd_record.build_grid(params, cases, sensors, steady_s=1.0, post_s=1.3, seed=7):
                zr = zoo.second_recording(r.truth, counts, noise, snr)
                zr.files = {"jointstate": zoo._write(out, zr.name, r.signals, "jointstate")}
                items.append((zr, zoo.diagnose_one(zr, "jointstate", system, declare=True)))
    return items


def run(out: Path, rates=None, log=print, models=("vector", "second")) -> dict:
    """{(model, rate label): zoo.summarise counts} (simulations cached under ``out``/cache)."""
    t0 = time.perf_counter()
    rows = {}
    for label, folder, ts in RATES:
        if rates and label not in rates:
            continue
        if "second" in models:
            system = system_at(ts)
            items = second_items(ts, system, Path("out/zoo_rates") / folder)
            rows[("second drive", label)] = dict(zoo.summarise(items, nominal_kgm2=system.motor.nominal_inertia_kgm2),
                                                 sample_period_s=ts)
            log(f"second drive {label}: diagnosed {len(items)} files ({time.perf_counter() - t0:.0f} s)")
        if "vector" not in models:
            continue
        p, system = drive_at(ts), system_at(ts)
        items = []
        for ev in EVENTS:
            for sensor, fmt, counts, snr in SENSORS:
                t1 = time.perf_counter()
                r = vd_record.build(p, ev, "forward", vd_record.Sensors(encoder_counts=counts, snr_db=snr), seed=23,
                                    cache_dir=Path(out) / "cache")
                zr = zoo.vector_recording(r, ev, "forward", p.mechanics.motor_inertia_kgm2, counts, snr,
                                          Path(out) / folder, (fmt,))
                if time.perf_counter() - t1 > 2:
                    log(f"{label}: simulated {r.name} ({time.perf_counter() - t1:.0f} s)")
                items.append((zr, zoo.diagnose_one(zr, fmt, system, declare=True, extra={})))
        rows[("vector drive", label)] = dict(zoo.summarise(items, nominal_kgm2=system.motor.nominal_inertia_kgm2),
                                             sample_period_s=ts)
        log(f"{label}: diagnosed {len(items)} files ({time.perf_counter() - t0:.0f} s)")
    return {"rows": rows, "elapsed_s": time.perf_counter() - t0}


def markdown(res: dict, command: str, commit: str) -> str:
    lines = [f"### The vector drive and the second drive at 1, 2, 4 and 8 kHz (`{command}`)", "",
             f"Measured on commit {commit} ({res['elapsed_s']:.0f} s). jident_ros/research/evaluation/zoo_rates.py: "
             "docs/vector_drive.md's drive recorded every T_s (8 kHz: control period 125 µs), events "
             + ", ".join(e.replace("_", " ") for e in EVENTS) + " (forward), each as " + ", ".join(s[0] for s in SENSORS)
             + "; the second drive: the zoo's speed steps down at J1 1.16, K2 2.5 and 7.5 mm, both directions, JointState "
             "2^16 and 2^13, clean and 30 dB; each diagnosed at its own T_s, declared as the zoo declares it. "
             "'within ±1 ms': the entry "
             "within 1 ms of the true first sample in the zone (±2 samples at 2 kHz).", "",
             "| model | rate | T_s | traversals found | entry within ±2 samples | entry within ±1 ms | entry offsets (ms) | "
             "published (traversal windows) | published > 10 % off | median / max abs error | 95 % CI covers | "
             "false entries |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (model, label), s in sorted(res["rows"].items(), key=lambda kv: (kv[0][0] != "vector drive", kv[0][1])):
        ts, off = s["sample_period_s"], s.get("offsets", [])
        ms = [o * ts * 1e3 for o in off]
        err = "–" if s.get("err_median") is None else f"{100 * s['err_median']:.1f} % / {100 * s['err_max']:.1f} %"
        false = s.get("false_steady", 0) + s.get("false_same_flank", 0) + s.get("false_other", 0)
        lines.append(f"| {model} | {label} | {ts * 1e3:g} ms | {s.get('found', 0)}/{s.get('traversals', 0)} | "
                     f"{zoo._pct(sum(1 for o in off if abs(o) <= 2), len(off))} | "
                     f"{zoo._pct(sum(1 for m in ms if abs(m) <= 1.0 + 1e-9), len(ms))} | "
                     f"{'–' if not ms else f'{min(ms):+.2f} … {max(ms):+.2f}'} | "
                     f"{s.get('trav_published', 0)}/{s.get('trav_windows', 0)} | {s.get('published_off', 0)} | {err} | "
                     f"{s.get('covered', 0)}/{s.get('with_interval', 0)} | {false} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.zoo_rates",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--report", action="store_true", help="simulate (or reuse), diagnose, print the table")
    p.add_argument("--out", default="out/zoo_variants", help="recordings and the simulation cache")
    p.add_argument("--results", default="-", help="'-' prints (the only choice: the table goes into a section "
                                                  "by hand)")
    p.add_argument("--rates", default="", help="comma-separated rates (1 kHz, 2 kHz, 4 kHz, 8 kHz; default: all)")
    p.add_argument("--models", default="vector,second", help="comma-separated: vector, second (default: both)")
    a = p.parse_args(argv)
    if not a.report:
        p.print_help()
        return 0
    if a.results != "-":
        sys.stderr.write("zoo_rates: error: argument --results: only '-' (print)\n")
        return 2
    reason = motulator_available()
    if reason:
        sys.stderr.write(f"zoo_rates: error: the vector drive needs motulator: {reason}\n")
        return 2
    rates = [r.strip() for r in a.rates.split(",") if r.strip()]
    rates = [r if r.endswith("kHz") else f"{r} kHz" for r in rates]
    unknown = [r for r in rates if r not in [x[0] for x in RATES]]
    if unknown:
        sys.stderr.write(f"zoo_rates: error: argument --rates: unknown {unknown[0]!r} (one of "
                         f"{', '.join(x[0] for x in RATES)})\n")
        return 2
    models = tuple(m.strip() for m in a.models.split(",") if m.strip())
    if not models or any(m not in ("vector", "second") for m in models):
        sys.stderr.write(f"zoo_rates: error: argument --models: expected vector and/or second, got {a.models!r}\n")
        return 2
    commit = zoo._commit()
    res = run(Path(a.out), rates or None, log=lambda t: print(t, file=sys.stderr, flush=True), models=models)
    print(markdown(res, "python -m jident_ros.research.evaluation.zoo_rates --report"
                   + (f" --rates {a.rates}" if rates else "") + (f" --models {a.models}" if a.models != "vector,second"
                                                                 else ""), commit))
    return 0


if __name__ == "__main__":
    sys.exit(main())
