"""Golden outputs of the product's chain (issue 19: a move must not change them).

Regenerate (one command, from the repository root, after a change that is meant to change the outputs):

    .venv/bin/python scripts/golden.py            # rewrites test/data/golden/
    .venv/bin/python scripts/golden.py --check    # compares instead (what test/test_golden.py runs)

The recordings are made deterministically here (never stored; only the outputs are, a few KB each):

* ``demo``: the demo's five default cases (jident_ros/cli/demo.py ``DEFAULT_CASES``) written as the diagnostic
  node records the simulator's topics (drive/signals batches of 50, drive/true_inertia, drive/backlash_width,
  drive/case; K2 followed from drive/backlash_width): the demo recording without the DDS timing variance;
  ``jident diagnose --json`` (the JSON and the printed table) with the image method (the default pattern library, built when missing);
* ``raw_csv_flank``: raw encoder angles (random offsets, slip, 65536 counts, 30 dB) of our simulator as a CSV file,
  ``jident diagnose --detector flank``; ``raw_csv_dynamics``: the same without alpha2, ``--detector dynamics``;
* ``second_drive_jointstate_fwd`` / ``_rev``: two JointState bags of the independent second drive model (30 dB),
  ``jident diagnose`` with the flank detector;
* ``second_drive_signals``: one drive/signals bag of the second drive, ``--detector flank``;
* ``trend``: ``jident simulate --scenario wear --windows 12 --snr-db 30`` then ``jident trend``: trend.csv and the
  printed summary.

What varies from run to run is taken out before storing/comparing: the timing values ``estimate_latency_ms`` and
``processing_ms``, the wall time in the trend summary, and file paths (the work directory is ``<work>``; a JSON
``recording``/``library`` path is replaced by its last component).  Everything else is compared exactly, but for
the last digits of numbers: two numbers are equal within ``NUMBER_REL_TOL`` (1e-6) relative plus ``NUMBER_ABS_TOL``
(1e-9) absolute.  Bit for bit was the rule until stop 40, when a fresh machine (numpy 2.4.6) gave the committed code's
outputs to 1e-15 (J1) … 1e-8 (the image method's distances) relative, and the model error, a difference of two J1
near 1 kg m^2, to 2e-11 kg m^2: the rounding of the machine's BLAS, not a change of behaviour, which moves these
numbers far more (test_golden checks that a number moved by 1e-5 is seen).
"""
from __future__ import annotations

import argparse
import contextlib
import difflib
import io
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
GOLDEN = REPO / "test" / "data" / "golden"
TIMING_KEYS = ("estimate_latency_ms", "processing_ms")


def _jident(argv) -> str:
    """Run ``jident argv`` in this process; its stdout (stderr discarded); raises on a non-zero status."""
    from jident_ros.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    if code != 0:
        raise RuntimeError(f"jident {' '.join(map(str, argv))}: exit {code}: {err.getvalue().strip()}")
    return out.getvalue()


def write_demo_recording(bag_dir: Path, system) -> Path:
    """The demo's default cases as the diagnostic node records the simulator's topics (the offline test's writer)."""
    sys.path.insert(0, str(REPO / "test"))
    from test_offline import write_recording

    from jident_ros.cli.demo import DEFAULT_CASES
    from jident_ros.sim import Case
    return write_recording(bag_dir, system, namespace="/demo", cases=[Case(*c) for c in DEFAULT_CASES])


def _write_csv(path: Path, data, channels) -> Path:
    np.savetxt(path, data, delimiter=",", header=",".join(channels), comments="", fmt="%.17g")
    return path


def _raw_csvs(work: Path, system) -> tuple:
    from jident_ros.research.evaluation.raw_inputs import raw_recordings
    (rec,) = raw_recordings(system, (1.073,), (0.0075,), snr_db=30.0, steady_s=0.5, seed=9)
    flank = _write_csv(work / "raw_flank.csv", rec.data, rec.channels)
    keep = [i for i, c in enumerate(rec.channels) if c != "alpha2"]
    dyn = _write_csv(work / "raw_dynamics.csv", rec.data[:, keep], [rec.channels[i] for i in keep])
    return flank, dyn


def _second_drive(work: Path, fmt: str, directions=("forward", "reverse")) -> list:
    """One recording per direction of the second drive (J1 1.16, K2 5 mm, 30 dB) in ``fmt``."""
    from jident_ros.research.second_drive.model import DriveParams
    from jident_ros.research.second_drive.record import SensorConfig, build_grid, grid_cases, write_recording
    recs = build_grid(DriveParams(), grid_cases(directions, (1.16,), (0.005,)), SensorConfig(snr_db=30.0),
                      steady_s=0.5, post_s=1.3, seed=3)
    out = work / f"second_{fmt}"
    out.mkdir()
    return [out / write_recording(out, r, fmt) for r in recs]


def _clean(obj):
    """The JSON without what varies between runs: timing values, directories."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if k in TIMING_KEYS:
                continue
            if k in ("recording", "library", "signals_topic") and isinstance(v, str) and ("/" in v or "\\" in v):
                v = Path(v).name if k != "signals_topic" or v.endswith((".csv", ".mcap")) else v
            out[k] = _clean(v)
        return out
    if isinstance(obj, list):
        return [_clean(x) for x in obj]
    return obj


def _diagnose(name: str, rec: Path, work: Path, extra=()) -> tuple:
    """(the --json document cleaned, the printed table and summary line with the work directory as <work>)."""
    out = work / f"{name}.json"
    text = _jident(["diagnose", rec, "--json", out, "--quiet", *extra])
    return _clean(json.loads(out.read_text())), text.replace(str(work), "<work>")


def generate(work: Path) -> dict:
    """{file name: text} of every golden output, made in ``work``."""
    from jident_ros.config import load_system_config
    system = load_system_config()
    files: dict = {}

    def dump(name, doc_and_text):
        doc, text = doc_and_text
        files[f"diagnose_{name}.json"] = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n"
        files[f"diagnose_{name}.txt"] = text

    demo = write_demo_recording(work / "demo_recording", system)
    dump("demo", _diagnose("demo", demo, work))
    flank, dyn = _raw_csvs(work, system)
    dump("raw_csv_flank", _diagnose("raw_csv_flank", flank, work, ["--no-image"]))
    dump("raw_csv_dynamics", _diagnose("raw_csv_dynamics", dyn, work, ["--no-image", "--detector", "dynamics"]))
    fwd, rev = _second_drive(work, "jointstate")
    dump("second_drive_jointstate_fwd", _diagnose("js_fwd", fwd, work, ["--no-image"]))
    dump("second_drive_jointstate_rev", _diagnose("js_rev", rev, work, ["--no-image"]))
    (sig,) = _second_drive(work, "signals", ("forward",))
    dump("second_drive_signals", _diagnose("sig", sig, work, ["--no-image", "--detector", "flank"]))
    wear = work / "wear12"
    _jident(["simulate", "--scenario", "wear", "--windows", "12", "--snr-db", "30", "--out", wear, "--quiet"])
    trend_dir = work / "trend"
    summary = _jident(["trend", wear, "--out", trend_dir, "--quiet"])
    files["trend.csv"] = (trend_dir / "trend.csv").read_text().replace(str(work), "<work>")
    # the wall time it took is not an output
    files["trend_summary.txt"] = re.sub(r"\(\d+(\.\d+)? s\)", "(<wall> s)", summary.replace(str(work), "<work>"))
    return files


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="compare with test/data/golden/ instead of writing it")
    ap.add_argument("--golden", default=str(GOLDEN), help="the golden directory (default test/data/golden)")
    args = ap.parse_args(argv)
    golden = Path(args.golden)
    work = Path(tempfile.mkdtemp(prefix="jident_golden_"))
    try:
        files = generate(work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if not args.check:
        golden.mkdir(parents=True, exist_ok=True)
        for old in golden.iterdir():
            if old.name not in files:
                old.unlink()
        for name, text in files.items():
            (golden / name).write_text(text)
        print(f"{len(files)} golden files written to {golden}: " + ", ".join(
            f"{n} ({len(t.encode()) // 1024 + 1} KB)" for n, t in sorted(files.items())))
        return 0
    bad = compare(files, golden)
    for line in bad:
        print(line)
    print(f"golden: {len(files) - len({b.split(':')[0] for b in bad})}/{len(files)} identical")
    return 1 if bad else 0


#: Two numbers of a golden output are the same within this relative difference plus NUMBER_ABS_TOL: the rounding of
#: another machine's BLAS and libm, not a change of behaviour (module docstring).
NUMBER_REL_TOL = 1e-6
NUMBER_ABS_TOL = 1e-9
_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def same_text(a: str, b: str, rel_tol: float = NUMBER_REL_TOL, abs_tol: float = NUMBER_ABS_TOL) -> bool:
    """``a`` and ``b`` equal but for numbers within ``rel_tol`` relative plus ``abs_tol`` of each other (the rest
    character for character)."""
    if a == b:
        return True
    if _NUMBER.sub("#", a) != _NUMBER.sub("#", b):
        return False
    for x, y in zip(_NUMBER.findall(a), _NUMBER.findall(b)):
        if x == y:
            continue
        fx, fy = float(x), float(y)
        if abs(fx - fy) > rel_tol * max(abs(fx), abs(fy)) + abs_tol:
            return False
    return True


def compare(files: dict, golden: Path) -> list:
    """One line per differing/missing file (:func:`same_text`), with the first differing lines."""
    bad = []
    for name, text in sorted(files.items()):
        path = golden / name
        if not path.exists():
            bad.append(f"{name}: missing in {golden} (regenerate: .venv/bin/python scripts/golden.py)")
            continue
        want = path.read_text()
        if not same_text(want, text):
            diff = list(difflib.unified_diff(want.splitlines(), text.splitlines(), "golden", "now", n=0, lineterm=""))
            bad.append(f"{name}: differs:\n  " + "\n  ".join(diff[:12]))
    return bad


if __name__ == "__main__":
    sys.exit(main())
