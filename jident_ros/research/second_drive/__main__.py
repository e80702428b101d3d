"""python -m jident_ros.research.second_drive --out DIR [options]: write the grid of
single-event recordings of the second drive and their truth.json.

Bad input: one line naming the argument and its value on stderr, exit status 2.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

from .model import PAPER_INERTIAS_KGM2, PAPER_WIDTHS_M, DriveParams
from .record import FORMATS, WEAR_WIDTHS_M, SensorConfig, build_grid, build_wear, grid_cases, truth_document, write_recording, write_truth

PROG = "python -m jident_ros.research.second_drive"


class _Parser(argparse.ArgumentParser):
    def error(self, message):                      # one line, exit 2, no usage block
        sys.stderr.write(f"{PROG}: error: {message}\n")
        sys.exit(2)


def _bad(name, value, why):
    sys.stderr.write(f"{PROG}: error: argument {name}: {why}: {value!r}\n")
    sys.exit(2)


def comma_list(kind):
    """Argparse type: a comma-separated list of ``kind`` values (one line naming the value when it is not)."""
    def parse(text):
        try:
            vals = [kind(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a comma-separated list of {kind.__name__}: {text!r}") from None
        if not vals:
            raise argparse.ArgumentTypeError(f"empty list: {text!r}")
        return vals
    return parse


def parser():
    p = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory (created; must be new or empty)")
    p.add_argument("--format", default="jointstate", choices=FORMATS)
    p.add_argument("--scenario", default="grid", choices=("grid", "wear"),
                   help="grid: one event per recording (direction x J1 x K2); wear: one long recording per "
                        "direction and J1, one event per width, the zone widening between events")
    p.add_argument("--snr-db", type=float, default=None, help="white noise, 'measured' SNR in dB (default: none)")
    p.add_argument("--encoder-counts", type=int, default=65536, help="counts per revolution (0: no quantisation)")
    p.add_argument("--wrap-encoders", action="store_true", help="single-turn encoders: angles mod 2 pi")
    p.add_argument("--speed-noise-rad-s", type=float, default=0.0, help="white noise std on omega1, omega2")
    p.add_argument("--torque-noise-pct", type=float, default=0.0, help="white noise std on m_el, %% of rated")
    p.add_argument("--steady-s", type=float, default=1.0, help="steady stretch before the event, s")
    p.add_argument("--post-s", type=float, default=1.3, help="simulated time after the event, s (>= 1.25)")
    p.add_argument("--direction", default="both", choices=("forward", "reverse", "both"))
    p.add_argument("--gear-ratio", type=float, default=1.0, help="gearbox ratio N (1 or 4)")
    p.add_argument("--inertias", type=comma_list(float), default=None,
                   help="J1 values, kg m^2 (default: grid the 7 classes, wear 1.16)")
    p.add_argument("--widths", type=comma_list(float), default=None,
                   help="K2 values, m (default: grid the paper's 6; wear 10 increasing widths, on and off the grid)")
    p.add_argument("--namespace", default="", help="topic namespace, e.g. press3")
    p.add_argument("--imu", action="store_true", help="jointstate: also sensor_msgs/Imu on <ns>/imu (x = a1)")
    p.add_argument("--ros-distro", default="humble", choices=("humble", "jazzy"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="2 J1 x 2 K2 per direction (smoke run)")
    return p


def _validate(a):
    finite = lambda x: x is not None and math.isfinite(x)   # noqa: E731
    if a.snr_db is not None and not finite(a.snr_db):
        _bad("--snr-db", a.snr_db, "must be finite")
    if a.encoder_counts < 0 or a.encoder_counts > 2 ** 32:
        _bad("--encoder-counts", a.encoder_counts, "must be 0 (none) or 1..2^32")
    if not finite(a.speed_noise_rad_s) or a.speed_noise_rad_s < 0:
        _bad("--speed-noise-rad-s", a.speed_noise_rad_s, "must be >= 0")
    if not finite(a.torque_noise_pct) or a.torque_noise_pct < 0:
        _bad("--torque-noise-pct", a.torque_noise_pct, "must be >= 0")
    if not finite(a.steady_s) or not 0.05 <= a.steady_s <= 600:
        _bad("--steady-s", a.steady_s, "must be in [0.05, 600] s")
    if not finite(a.post_s) or not 1.25 <= a.post_s <= 60:
        _bad("--post-s", a.post_s, "must be in [1.25, 60] s (>= 1.2 s after the entry)")
    if a.gear_ratio not in (1.0, 4.0):
        _bad("--gear-ratio", a.gear_ratio, "supported: 1 or 4")
    for name, vals, lo, hi in (("--inertias", a.inertias, 0.5, 3.0), ("--widths", a.widths, 5e-4, 0.02)):
        for v in vals or ():
            if not finite(v) or not lo <= v <= hi:
                _bad(name, v, f"must be in [{lo}, {hi}]")
    if a.namespace and not all(part.isidentifier() for part in a.namespace.strip("/").split("/")):
        _bad("--namespace", a.namespace, "not a valid ROS namespace")
    if a.imu and a.format != "jointstate":
        _bad("--imu", a.format, "only with --format jointstate")
    out = Path(a.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        _bad("--out", a.out, "exists and is not an empty directory")


def main(argv=None):
    a = parser().parse_args(argv)
    _validate(a)
    params = replace(DriveParams(), gear_ratio=float(a.gear_ratio))
    directions = ("forward", "reverse") if a.direction == "both" else (a.direction,)
    sensors = SensorConfig(encoder_counts=a.encoder_counts, wrap_encoders=a.wrap_encoders, snr_db=a.snr_db,
                           speed_noise_rad_s=a.speed_noise_rad_s, torque_noise_pct=a.torque_noise_pct)
    t_start = time.perf_counter()
    if a.scenario == "grid":
        inertias = a.inertias or (PAPER_INERTIAS_KGM2[:1] + PAPER_INERTIAS_KGM2[4:5] if a.quick
                                  else PAPER_INERTIAS_KGM2)
        widths = a.widths or ((PAPER_WIDTHS_M[0], PAPER_WIDTHS_M[-1]) if a.quick else PAPER_WIDTHS_M)
        recs = build_grid(params, grid_cases(directions, inertias, widths), sensors, steady_s=a.steady_s,
                          post_s=a.post_s, seed=a.seed)
    else:
        inertias = a.inertias or PAPER_INERTIAS_KGM2[:1]
        widths = a.widths or ((0.0025, 0.0044, 0.01) if a.quick else WEAR_WIDTHS_M)
        recs = build_wear(params, directions, inertias, sensors, widths=widths, steady_s=a.steady_s, seed=a.seed)
    t_sim = time.perf_counter() - t_start
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for rec in recs:
        rel = write_recording(out, rec, a.format, a.namespace, a.imu, a.ros_distro)
        files.append(rel)
        tr = rec.truth
        if a.scenario == "grid":
            print(f"{rel}: {tr['direction']} J1={tr['inertia_kgm2']:.3f} kg m^2 K2={tr['backlash_width_m']:.5f} m "
                  f"entry t={tr['entry_time_s']:.4f} s, first gap {tr['gaps'][0]['samples']} samples, "
                  f"{len(tr['gaps'])} gaps, {tr['n_samples']} samples", flush=True)
        else:
            ev = tr["events"]
            print(f"{rel}: {tr['direction']} J1={tr['inertia_kgm2']:.3f} kg m^2, {len(ev)} events, K2 "
                  f"{ev[0]['backlash_width_m']:.5f} .. {ev[-1]['backlash_width_m']:.5f} m, entries at "
                  + " ".join(f"{e['entry_time_s']:.3f}" if e["entry_time_s"] is not None else "none" for e in ev)
                  + f" s, {tr['n_samples']} samples", flush=True)
    write_truth(out / "truth.json", truth_document(params, sensors, recs, a.format, files,
                                                   command=[PROG] + list(sys.argv[1:] if argv is None else argv),
                                                   namespace=a.namespace, scenario=a.scenario))
    print(f"{len(recs)} recordings ({a.format}) + truth.json in {out}: simulated in {t_sim:.1f} s, "
          f"total {time.perf_counter() - t_start:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
