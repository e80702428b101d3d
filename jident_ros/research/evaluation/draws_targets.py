"""The blind draws against issue 20's targets, one row per set.

``python -m jident_ros.research.evaluation.draws_targets out/draws_json/*.json`` (``--results -`` prints instead of
writing docs/results.md's section "Blind draws against issue 20's targets"), reading the counts that
``python -m jident_ros.research.evaluation.zoo_draws --report --json FILE`` writes per set.

Each row is one set of twelve drawn drives (vector or DOL), counted as the zoo counts (:func:`zoo.summarise`); the
columns are issue 20's targets:

* every traversal found (a traversal: a gap from flank to flank, and a DOL slip drop's own gap, which returns to the
  flank it left: zoo_dol.SAME_FLANK_EVENT_GAPS); 0 false entries in steady running and at same-flank torque changes
  (the other false entries: windows whose entry matches no gap, mostly entries more than 20 samples before a
  traversal's);
* the entry within ±2 samples of the true contact loss (the zone entry) in >= 90 % of the traversals found;
* JointState without an accelerometer at the drawn encoder (the "2^16" inputs): J1 published for >= 80 % of the
  speed-event traversals clean, >= 50 % at 30 dB, >= 50 % of all its traversals; the speed events are the speed step
  and the speed reversal on a vector drive, the slip drop and the slip reversal on a DOL drive (whose line has no
  speed step);
* 0 published J1 more than 10 % off, on every input (a J1 published on a false entry whose fit lies in no true gap
  counts as off: the truth has no gap there; one published by a second window of a gap, or on an early entry whose
  fit lies in a true gap (zoo.fit_gap), counts by its error);
* the 95 % interval covers the truth in >= 85 % of the published windows (stop 48: every published window judged by
  its error, the traversals' first windows, the second windows of a gap and the early entries whose fit lies in a
  true gap; until stop 47 the first windows alone);
* the K2 median error <= 5 % clean (the traversal windows' own K2, every clean input: no Imu there);
* no 'between classes' WARN, nor another class named, for a drive on its class (every drawn J1 is a class).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from jident_ros.research.evaluation import zoo
from jident_ros.research.evaluation.zoo_draws import PROTOCOL_NOTE

#: The section's title (docs/results.md)
TITLE = "## Blind draws against issue 20's targets"

#: The events whose traversals the "speed event" targets count, per model
SPEED_EVENTS = {"vector": ("speed step down", "speed reversal"), "dol": ("slip drop", "slip reversal")}


def _groups(res: dict, label_ok, events=None) -> dict:
    """The merged counts of ``res``'s input x event groups whose sensor label passes ``label_ok`` (and whose event is
    one of ``events``)."""
    picked = [s for key, s in res["groups"].items()
              if label_ok(key.split("|")[0]) and (events is None or key.split("|")[1] in events)]
    return zoo._merge(picked)


def _js(label: str) -> bool:
    """A JointState input without an accelerometer at the drawn encoder (not the 2^13 one)."""
    return label.startswith("JointState 2^16")


def _frac(a: int, b: int, target: float | None = None) -> str:
    """'a/b (p %)', bold where ``target`` (a share) is missed."""
    text = f"{a}/{b} ({zoo._pct(a, b)})"
    return f"**{text}**" if target is not None and b and a < target * b else text


def row(res: dict) -> dict:
    """Issue 20's targets for one set of draws (``res``: zoo_draws' --json file): the cells of its row, and whether
    each target is met."""
    model = res["model"]
    alls = zoo._merge(res["rows"].values())
    speed = SPEED_EVENTS[model]
    clean = _groups(res, lambda lab: _js(lab) and lab.endswith("clean"), speed)
    noisy = _groups(res, lambda lab: _js(lab) and lab.endswith("30 dB"), speed)
    js_all = _groups(res, _js)
    k2 = _groups(res, lambda lab: lab.endswith("clean"))["k2_errors"]
    false_target = alls.get("false_steady", 0) + alls.get("false_same_flank", 0)
    in_gap = alls.get("false_in_gap_errors", [])
    off = (alls.get("published_off", 0) + alls.get("published_on_false", 0) + alls.get("repeat_off", 0)
           + sum(1 for e in in_gap if abs(e) > zoo.OFF))
    covered = alls.get("covered", 0) + alls.get("repeat_covered", 0) + alls.get("false_in_gap_covered", 0)
    judged = alls.get("with_interval", 0) + alls.get("repeat_published", 0) + len(in_gap)
    offsets = alls.get("offsets", [])
    within = sum(1 for o in offsets if abs(o) <= 2)
    k2_median = float(np.median(k2)) if k2 else None
    cells = {
        "set": f"{'vector' if model == 'vector' else 'DOL'} {res['seed']} ({len(res['rows'])})",
        "found": _frac(alls.get("found", 0), alls.get("traversals", 0), 1.0),
        "false": (f"{false_target}" if not false_target else f"**{false_target}**")
        + f" ({alls.get('false_other', 0)}"
        + (f"; {alls['repeat_windows']} second window{'s' if alls['repeat_windows'] != 1 else ''} of a gap"
           if alls.get("repeat_windows") else "") + ")",
        "entry": _frac(within, len(offsets), 0.9),
        "clean": _frac(clean.get("trav_published", 0), clean.get("traversals", 0), 0.8),
        "noisy": _frac(noisy.get("trav_published", 0), noisy.get("traversals", 0), 0.5),
        "all": _frac(js_all.get("trav_published", 0), js_all.get("traversals", 0), 0.5),
        "off": f"{off}" if not off else f"**{off}**",
        "covers": _frac(covered, judged, 0.85),
        "k2": "–" if k2_median is None else (f"{100 * k2_median:.1f} %" if k2_median <= 0.05
                                            else f"**{100 * k2_median:.1f} %**"),
        "classes": f"{alls.get('between_on_class', 0)} / {alls.get('wrong_class', 0)}",
        "commit": res.get("commit", "?"),
    }
    return cells


COLUMNS = (("set", "set (drives)"), ("found", "traversals found (all)"),
           ("false", "false entries in steady running / at same-flank changes (0) (other; second windows of a gap)"),
           ("entry", "entry within ±2 (≥ 90 %)"), ("clean", "JointState clean, speed events: published (≥ 80 %)"),
           ("noisy", "JointState 30 dB, speed events (≥ 50 %)"), ("all", "JointState, all traversals (≥ 50 %)"),
           ("off", "published > 10 % off (0)"), ("covers", "95 % interval covers (≥ 85 %)"),
           ("k2", "K2 median, clean (≤ 5 %)"), ("classes", "'between classes' / another class, on its class (0 / 0)"),
           ("commit", "measured on"))


#: A traversal missed whose true gap is at most this many samples long counts as a short one in the per-event table
#: (2.5 ms at the draws' 2 kHz: a few samples of free motion, at the detector's resolution)
SHORT_GAP_SAMPLES = 5
#: An entry this many samples or more after the true contact loss counts as late in the per-event table
LATE_SAMPLES = 8


def _reason_text(reasons: dict) -> str:
    """The most common refusal (its share), the '#' placeholders of the zoo's reason keys left as they are."""
    if not reasons:
        return "–"
    top, n = max(reasons.items(), key=lambda kv: kv[1])
    return f"{n}/{sum(reasons.values())}: {top.removeprefix('gap: ')[:90]}"


def event_rows(results: list) -> list:
    """One row per model x event over every set in ``results``: where the targets are missed (the traversals missed
    and how long their gaps were, the entries within ±2 without and with an Imu and the late ones, JointState's
    publication without an Imu and its most common refusal)."""
    by: dict = {}
    for res in results:
        for key, s in res["groups"].items():
            label, event = key.split("|")
            by.setdefault((res["model"], event), []).append((label, s))
    lines = []
    for (model, event), items in sorted(by.items(), key=lambda kv: (kv[0][0] != "vector", kv[0][1])):
        a = zoo._merge([s for _, s in items])
        if not a.get("traversals"):
            continue
        missed = a.get("traversals", 0) - a.get("found", 0)
        gaps = a.get("missed_gap_rows")
        short = "–" if gaps is None or len(gaps) != missed else \
            f"{sum(1 for n in gaps if 0 <= n <= SHORT_GAP_SAMPLES)}/{missed}"
        kinds = a.get("missed_kinds")
        where = "–" if kinds is None or len(kinds) != missed else \
            f"{kinds.count('located')} / {kinds.count('spanned')}"
        js = zoo._merge([s for lab, s in items if not lab.startswith("JointState+Imu")])
        imu = zoo._merge([s for lab, s in items if lab.startswith("JointState+Imu")])
        off_js, off_imu = js.get("offsets", []), imu.get("offsets", [])
        offsets = off_js + off_imu
        reasons: dict = {}
        for lab, s in items:
            if not lab.startswith("JointState+Imu"):
                for r, n in s.get("reasons", {}).items():
                    reasons[r] = reasons.get(r, 0) + n
        lines.append(f"| {'vector' if model == 'vector' else 'DOL'} | {event} | "
                     f"{a.get('found', 0)}/{a['traversals']} ({zoo._pct(a.get('found', 0), a['traversals'])}) | {short} | {where} | "
                     f"{zoo._pct(sum(1 for o in off_js if abs(o) <= 2), len(off_js))} / "
                     f"{zoo._pct(sum(1 for o in off_imu if abs(o) <= 2), len(off_imu))} | "
                     f"{zoo._pct(sum(1 for o in offsets if o >= LATE_SAMPLES), len(offsets))} | "
                     f"{js.get('trav_published', 0)}/{js.get('traversals', 0)} "
                     f"({zoo._pct(js.get('trav_published', 0), js.get('traversals', 0))}) | {_reason_text(reasons)} |")
    return lines


def _files_text(files: list) -> str:
    """The files as the command line gave them, or ``DIR/*.json`` when they are every .json file of one folder."""
    paths = [Path(f) for f in files]
    folders = {p.parent for p in paths}
    if len(paths) > 2 and len(folders) == 1:
        folder = folders.pop()
        if sorted(folder.glob("*.json")) == sorted(paths):
            return f"{folder}/*.json"
    return " ".join(str(f) for f in files)


def markdown(results: list, files: list) -> str:
    """The section: one row per set (``results``: the --json files' contents, read from ``files``)."""
    cmd = "python -m jident_ros.research.evaluation.draws_targets " + _files_text(files)
    lines = [f"{TITLE} (`{cmd}`)", "",
             "Each set's counts from `python -m jident_ros.research.evaluation.zoo_draws --report --model M --seed S "
             "--draws 12 --json FILE` (its own section, 'Blind draws, set S', has the drives); this table reads those "
             "files (jident_ros/research/evaluation/draws_targets.py says what each column counts). Bold: the target "
             "missed. " + PROTOCOL_NOTE, "",
             "| " + " | ".join(title for _, title in COLUMNS) + " |",
             "|" + "---|" * len(COLUMNS)]
    order = sorted(results, key=lambda r: (r["model"] != "vector", int(r["seed"])))
    for res in order:
        cells = row(res)
        lines.append("| " + " | ".join(cells[key] for key, _ in COLUMNS) + " |")
    lines += ["", "### Where the targets are missed, per event (every set above, every input)", "",
              f"Traversals missed, and of them those whose true gap is at most {SHORT_GAP_SAMPLES} samples long "
              "(entry to re-contact; '–': a file written before zoo_draws counted them), and those whose rows a window "
              "entered elsewhere still reached (zoo.missed_kind: its gap fit starts in the traversal, 'located'; its "
              "re-contact lies at the traversal's end or later, the contact before it unresolved, 'spanned'); the entry "
              "within ±2 samples "
              f"of the true contact loss on the inputs without and with an Imu, and {LATE_SAMPLES} or more samples "
              "late on all; J1 published on the traversals of the inputs without an Imu, and their most common "
              "refusal (its count over all their refusals, the zoo's reason with its numbers as #).", "",
              "| model | event | traversals found | missed: gap ≤ "
              f"{SHORT_GAP_SAMPLES} samples | missed: located / spanned by a window entered elsewhere | entry within "
              f"±2: without / with Imu | entry ≥ {LATE_SAMPLES} late | JointState without Imu: published | its most "
              "common refusal |",
              "|---|---|---|---|---|---|---|---|---|"]
    lines += event_rows(order)
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.draws_targets",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="+", help="zoo_draws --report --json files, one per set")
    p.add_argument("--results", default="docs/results.md", help="results file to update ('-' prints)")
    a = p.parse_args(argv)
    results = []
    for f in a.files:
        try:
            results.append(json.loads(Path(f).read_text()))
        except (OSError, ValueError) as exc:
            sys.stderr.write(f"draws_targets: error: {f}: {exc}\n")
            return 2
        if "groups" not in results[-1]:
            sys.stderr.write(f"draws_targets: error: {f}: no 'groups' (written by an older zoo_draws)\n")
            return 2
    zoo.write_section(markdown(results, a.files), a.results, f"{len(results)} sets")
    return 0


if __name__ == "__main__":
    sys.exit(main())
