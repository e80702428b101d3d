"""python -m jident_ros.research.vector_drive --out DIR [options]: simulate the vector drive's events and write
their recordings (JointState MCAP bags with and without Imu, CSV), one truth file per recording
(<name>.truth.json) and an index truth.json.

Bad input: one line naming the argument and its value on stderr, exit status 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from jident_ros.research.second_drive.__main__ import comma_list  # the same argparse list type

from .dol import DOL_EVENTS, DolParams
from .model import EVENTS, DriveParams, motulator_available, small_drive
from .record import INPUTS, Sensors, build, build_dol, with_inertia, with_width, write

PROG = "python -m jident_ros.research.vector_drive"


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        sys.stderr.write(f"{PROG}: error: {message}\n")
        sys.exit(2)


def parser():
    p = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--mode", choices=("vector", "dol"), default="vector",
                   help="vector: motulator's vector control and speed PI (default); dol: the machine direct on a stiff "
                        "50 Hz grid, its torque estimated from stator voltages and currents (docs/vector_drive.md)")
    p.add_argument("--events", type=comma_list(str), default=None,
                   help=f"comma-separated, of {', '.join(EVENTS)} (vector) or {', '.join(DOL_EVENTS)} (dol); "
                        "default: all of the mode's")
    p.add_argument("--directions", type=comma_list(str), default=["forward", "reverse"])
    p.add_argument("--inertias", type=comma_list(float), default=[1.16], help="J1 values, kg m^2")
    p.add_argument("--widths", type=comma_list(float), default=[0.005], help="K2 values, m (at r)")
    p.add_argument("--counts", type=comma_list(int), default=[65536], help="encoder counts per revolution")
    p.add_argument("--snr-db", type=comma_list(float), default=None, help="noise levels in dB (default: clean only)")
    p.add_argument("--formats", type=comma_list(str), default=list(INPUTS), help=f"of {', '.join(INPUTS)}")
    p.add_argument("--size", choices=("default", "small"), default="default",
                   help="default: 37 kW, J1 1.16 kg m^2; small: motulator's 2.2 kW machine, 3:1 gear")
    p.add_argument("--duration-s", type=float, default=2.2)
    p.add_argument("--event-time-s", type=float, default=0.6)
    p.add_argument("--cache", default="", help="simulation cache directory (default: none)")
    p.add_argument("--seed", type=int, default=0)
    return p


def _bad(name, value, why):
    sys.stderr.write(f"{PROG}: error: argument {name}: {why}: {value!r}\n")
    sys.exit(2)


def main(argv=None) -> int:
    a = parser().parse_args(argv)
    known = EVENTS if a.mode == "vector" else DOL_EVENTS
    a.events = list(known) if a.events is None else a.events
    for e in a.events:
        if e not in known:
            _bad("--events", e, f"not one of {', '.join(known)} (--mode {a.mode})")
    for d in a.directions:
        if d not in ("forward", "reverse"):
            _bad("--directions", d, "not forward or reverse")
    for f in a.formats:
        if f not in INPUTS:
            _bad("--formats", f, f"not one of {', '.join(INPUTS)}")
    for name, vals, lo, hi in (("--inertias", a.inertias, 1e-3, 100.0), ("--widths", a.widths, 1e-4, 0.05)):
        for v in vals:
            if not (math.isfinite(v) and lo <= v <= hi):
                _bad(name, v, f"must be in [{lo}, {hi}]")
    for c in a.counts:
        if not 0 <= c <= 2 ** 32:
            _bad("--counts", c, "must be 0 (no quantisation) or 1..2^32")
    if not (math.isfinite(a.duration_s) and a.event_time_s + 1.2 <= a.duration_s <= 60):
        _bad("--duration-s", a.duration_s, "must leave >= 1.2 s after the event and be <= 60 s")
    if not (math.isfinite(a.event_time_s) and 0.2 <= a.event_time_s):
        _bad("--event-time-s", a.event_time_s, "must be >= 0.2 s")
    reason = motulator_available()
    if reason:
        sys.stderr.write(f"{PROG}: error: {reason}\n")
        return 2
    if a.mode == "dol" and a.size != "default":
        _bad("--size", a.size, "the dol mode has the default size only")
    base = (DriveParams() if a.size == "default" else small_drive()) if a.mode == "vector" else DolParams()
    out = Path(a.out)
    cache = Path(a.cache) if a.cache else None
    index = []
    t0 = time.perf_counter()
    for j1 in a.inertias:
        for k2 in a.widths:
            p = with_width(with_inertia(base, j1), k2)
            for ev in a.events:
                for d in a.directions:
                    for counts in a.counts:
                        for snr in (a.snr_db or [None]):
                            make = build if a.mode == "vector" else build_dol
                            rec = make(p, ev, d, Sensors(counts, snr), seed=a.seed, duration_s=a.duration_s,
                                       event_time_s=a.event_time_s, cache_dir=cache)
                            files = [write(out, rec, f) for f in a.formats]
                            index.append(dict(rec.truth, files=files))
                            tr = rec.truth
                            print(f"{rec.name}: {len(tr['gaps'])} gaps, first entry "
                                  f"{tr['entry_time_s'] if tr['entry_time_s'] is not None else 'none'} s, "
                                  f"torque estimate {100 * (tr['torque_estimate_error']['steady_relative'] or 0):+.2f} "
                                  f"% (steady)", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    schema = "jident_ros.research.vector_drive/truth/1" if a.mode == "vector" else \
        "jident_ros.research.vector_drive.dol/truth/1"
    (out / "truth.json").write_text(json.dumps({"schema": schema,
                                                "command": [PROG] + list(sys.argv[1:] if argv is None else argv),
                                                "recordings": index}, indent=1, allow_nan=False) + "\n")
    print(f"{len(index)} recordings + truth files in {out} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
