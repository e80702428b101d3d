"""What the encoders show of the contact loss: how many traversals their angles resolve within ±2 samples.

``python -m jident_ros.research.evaluation.entry_oracle --model M --seeds 1-28 [--json FILES]`` (``--results -``
prints instead of writing docs/results.md; ``--out`` the recordings, default out/zoo_draws)

Issue 20 asks for the entry within ±2 samples of the true contact loss (the first sample in the zone) in >= 90 % of
traversals.  A detector reading JointState has the two encoders' angles, the drive's speed feedback and its torque
estimate; the first is what shows the gap directly: the relative angle delta = alpha1 - N alpha2 leaves the flank it
was twisted against and crosses the zone.  An encoder of ``counts`` per revolution reads each angle to a quantum
q = 2 pi / counts (floor), so the relative angle's reading is uncertain by q (1 + |N|): until the true relative angle is
that far inside the zone, the readings of a sample in contact and of a sample in the gap can be the same, even for
a detector told where the flank is (the truth's offsets and half-width) and the encoders' disc errors.  At a slow
crossing -- a light load reversal, whose coupling torque fades to zero with the load's slow ramp and whose gap opens
with the motor and the load nearly at one speed -- that takes many samples.

For every traversal of the blind draws (zoo_draws' drives and cached simulations, nothing simulated here unless a
set was never run; the traversals zoo_draws counts), this module reads the TRUE relative angle at the recorded
instants (:attr:`jident_ros.research.vector_drive.record.Recording.delta_rad`, jitter included) and counts the
samples from the true entry to the first sample at least one reading quantum inside the zone: 'shown after'.  Where
it is more than 2, the encoders cannot place the entry within ±2 samples from the angle's crossing alone (a detector
can still be right there: by chance, or from the motor's own acceleration, an Imu's).  With zoo_draws' ``--json``
files (their per-traversal ``entries``) it sets the flank detector's entries beside it, on the traversals the angles
show within 2 samples and on the others: how much of the ±2 target's shortfall is the encoders' and how much the
detector's.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from jident_ros.research.evaluation import zoo, zoo_dol, zoo_draws, zoo_variants
from jident_ros.research.evaluation.draws_oracle import draws_arguments
from jident_ros.research.vector_drive import record as vd_record

#: The ±2 samples of issue 20's entry target.
WITHIN = 2
#: 'late': shown this many samples after the entry or later (zoo_draws' LATE_SAMPLES count).
LATE = 8
#: The detector's inputs set beside the angles (zoo_draws' sensor labels: without an Imu, clean; with one, 30 dB).
LABELS = ("JointState 2^16 clean", "JointState+Imu 2^16 30 dB")


def reading_quantum_rad(counts: int, gear_ratio: float) -> float:
    """The relative angle's reading quantum, rad: q (1 + |N|), q = 2 pi / ``counts`` (two floor-quantised encoders,
    the load's scaled by the gear ratio N)."""
    return 2.0 * math.pi / counts * (1.0 + abs(gear_ratio))


def shown_after(delta_rad: np.ndarray, half_zone_rad: float, entry: int, recontact: int, quantum_rad: float):
    """Samples from the true ``entry`` to the first sample before ``recontact`` whose true relative angle lies at least
    ``quantum_rad`` inside the zone (|delta| <= half-zone - quantum); None where none does (the gap is never a reading
    quantum deep: the angles never show it)."""
    inside = np.flatnonzero(np.abs(np.asarray(delta_rad[entry:recontact], float)) <= half_zone_rad - quantum_rad)
    return int(inside[0]) if inside.size else None


def clean_recordings(d, out: Path) -> list:
    """[(event, Recording)] of drawn drive ``d``: its recordings with the draws' first (clean) sensors, from the
    simulations zoo_draws cached under ``out``/cache (the encoders are the drive's in every sensor label; only the
    other channels' noise differs)."""
    if d.model == "vector":
        _, _, counts, snr = zoo_variants.SENSORS[0]
        sens = vd_record.Sensors(**{"encoder_counts": counts, "snr_db": snr, **d.sensor_fields})
        return [(ev, vd_record.build(d.params, ev, d.direction, sens, seed=zoo_variants.SEED, cache_dir=out / "cache"))
                for ev in zoo_variants.EVENTS]
    _, _, counts, snr = zoo_dol.SWEEP_SENSORS[0]
    sens = vd_record.Sensors(**{"encoder_counts": counts, "snr_db": snr, **d.sensor_fields})
    return [(ev, vd_record.build_dol(d.params, ev, d.direction, sens, seed=zoo_dol.SEED, cache_dir=out / "cache"))
            for ev in zoo_draws.DOL_EVENTS]


def _traversal(g: dict, event: str, model: str) -> bool:
    return zoo_dol.traversal(g, event) if model == "dol" else bool(g["traversal"])


def resolution_of_drive(d, out: Path) -> list:
    """[(event with spaces, drive name, true entry row, shown_after or None)] over drawn drive ``d``'s traversals
    (those with a re-contact in the recording)."""
    rows = []
    for ev, r in clean_recordings(d, Path(out)):
        tr = r.truth
        q = reading_quantum_rad(int(tr["encoder"]["counts_per_rev"]), float(tr["gear_ratio"]))
        for g in tr["gaps"]:
            if not _traversal(g, ev, d.model) or g["recontact_index"] is None:
                continue
            rows.append((ev.replace("_", " "), d.name, int(g["entry_index"]),
                         shown_after(r.delta_rad, float(tr["half_zone_rad"]), int(g["entry_index"]),
                                     int(g["recontact_index"]), q)))
    return rows


def detector_entries(json_files, model: str) -> dict:
    """(sensor label, drive, event, true entry row) -> the first matching window's entry row minus it (None: the
    traversal was not found), from zoo_draws --json files (their ``entries``; files without them are skipped)."""
    out = {}
    for f in json_files:
        d = json.loads(Path(f).read_text())
        if d.get("model") != model:
            continue
        for label, drive, event, entry, found in d.get("entries", []):
            out[(label, drive, event, int(entry))] = None if found is None else int(found) - int(entry)
    return out


def _pct(k: int, n: int) -> str:
    return "–" if not n else f"{k}/{n} ({100 * k / n:.0f} %)"


def _detector_cells(sel: list, entries: dict, label: str) -> str:
    """'within ±2 where shown within 2 / where not' of the detector's entries on ``label`` over the rows ``sel``."""
    cells = []
    for shown in (True, False):
        offs = [entries.get((label, drive, ev, b)) for ev, drive, b, s in sel
                if (s is not None and s <= WITHIN) == shown and (label, drive, ev, b) in entries]
        found = [o for o in offs if o is not None]
        cells.append(_pct(sum(1 for o in found if abs(o) <= WITHIN), len(found)))
    return " | ".join(cells)


def _missed_cell(sel: list, entries: dict, label: str) -> str:
    """'never a quantum deep / shown' over the traversals of ``sel`` the detector missed on ``label``."""
    missed = [s for ev, drive, b, s in sel if (label, drive, ev, b) in entries and entries[(label, drive, ev, b)] is None]
    return "–" if not any((label, d, e, b) in entries for e, d, b, _ in sel) else \
        f"{sum(1 for s in missed if s is None)} / {sum(1 for s in missed if s is not None)}"


def markdown(rows: list, model: str, seeds: list, entries: dict, command: str, commit: str, elapsed: float) -> str:
    name = "vector" if model == "vector" else "DOL"
    events = sorted({r[0] for r in rows})
    lines = [f"## What the encoders show of the contact loss, {name} drives (`{command}`)", "",
             f"Measured on commit {commit} ({elapsed:.0f} s; sets {seeds[0]}–{seeds[-1]}, the drives and simulations "
             "zoo_draws cached). jident_ros/research/evaluation/entry_oracle.py: on each traversal, the samples from "
             "the true contact loss (the first sample in the zone) to the first sample whose TRUE relative angle "
             "θ1 − N θ2 lies one reading quantum of the two encoders, 2π/counts · (1 + |N|), inside the zone: until "
             "then a sample in the gap and one in contact can read the same, even to a detector told the flank's "
             "position and the encoders' disc errors ('never': the gap is never a quantum deep). Where it is more "
             f"than {WITHIN}, the angles cannot place the entry within ±{WITHIN} samples; a detector may still do so "
             "by chance or from the motor's acceleration (an Imu's). Beside it, the flank detector's entries "
             "(zoo_draws --json files' per-traversal entries: the first matching window, as 'entry within ±2' counts "
             "them) within ±2 on the traversals found, where the angles show the gap within 2 samples and where "
             "they do not; and the traversals it missed, by whether the angles ever show their gap.", "",
             f"| event | traversals | shown within {WITHIN} samples | shown after, median | shown {LATE} or more late / "
             f"never | detector within ±{WITHIN}, {LABELS[0]}: where shown within {WITHIN} | ... where not | "
             f"{LABELS[1]}: where shown within {WITHIN} | ... where not | missed by the detector, {LABELS[0]}: never a "
             "quantum deep / shown |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for ev in events + ["all"]:
        sel = [r for r in rows if ev in ("all", r[0])]
        shown = [r[3] for r in sel]
        ok = sum(1 for s in shown if s is not None and s <= WITHIN)
        finite = [s for s in shown if s is not None]
        late = sum(1 for s in finite if s >= LATE)
        never = sum(1 for s in shown if s is None)
        med = "–" if not finite else f"{float(np.median(finite)):.0f}"
        lines.append(f"| {ev} | {len(sel)} | {_pct(ok, len(sel))} | {med} | {late} / {never} | "
                     f"{_detector_cells(sel, entries, LABELS[0])} | {_detector_cells(sel, entries, LABELS[1])} | "
                     f"{_missed_cell(sel, entries, LABELS[0])} |")
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    a, seeds = draws_arguments("entry_oracle", __doc__.split("\n\n")[0], "1-28",
                               "zoo_draws --json files: the detector's entries", argv)
    if seeds is None:
        return 2
    t0 = time.perf_counter()
    rows = []
    for seed in seeds:
        for i in range(1, a.draws + 1):
            rows += resolution_of_drive(zoo_draws.draw(seed, i, a.model), Path(a.out))
    cmd = (f"python -m jident_ros.research.evaluation.entry_oracle --model {a.model} --seeds {a.seeds}"
           + (" --json FILES" if a.json else ""))
    md = markdown(rows, a.model, seeds, detector_entries(a.json, a.model), cmd, zoo._commit(),
                  time.perf_counter() - t0)
    zoo.write_section(md, a.results, f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
