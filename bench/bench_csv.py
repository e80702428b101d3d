"""CSV bench (issue 24 item 5): ``jident diagnose`` on a CSV of any size in bounded memory.

    .venv/bin/python bench/bench_csv.py [--size-gb 2.0] [--dir /tmp] [--keep] [--json out/bench/bench_csv.json]

* Writes a CSV of ``--size-gb`` GB (about 50 bytes per row: a sample index ``n`` and alpha1, alpha2, m_el,
  omega1; first one simulated backlash entry, then a drive standing in a steady state with noise, 40 million
  rows for 2 GB), block by block from one
  formatted template of 100,000 rows (only the index's leading digits change between blocks), so that
  writing it takes seconds, not the reading it measures.
* Runs ``jident diagnose FILE --map t=n:0.0005 --no-image --json OUT`` in a child process and reports its peak
  resident set (``ru_maxrss`` of the child), its wall and CPU time, the rows per second and the samples the
  diagnosis read (from its JSON).  Also for a file a tenth of the size: with a streaming reader the peak is
  the same (bounded memory), with the old whole-file reader it grew as 7.2 x the file (issue 24: a 2.1 GB
  CSV ended in MemoryError after 624 MB).
* Target: under 500 MB RSS at 2 GB.  Timing numbers depend on the machine's load; the RSS does not.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BLOCK_ROWS = 100_000


def write_csv(path: Path, size_bytes: int, seed: int = 0) -> int:
    """A steady-state drive's trace of about ``size_bytes``; returns the rows written."""
    rng = np.random.default_rng(seed)
    a1 = 1.25 + 1e-4 * rng.standard_normal(BLOCK_ROWS)
    a2 = 1.20 + 1e-4 * rng.standard_normal(BLOCK_ROWS)
    m = 0.8 + 1e-3 * rng.standard_normal(BLOCK_ROWS)
    w = 1e-3 * rng.standard_normal(BLOCK_ROWS)
    lines = [f"KKKK{i:05d},{x:.6f},{y:.6f},{z:.5f},{v:.5f}\n" for i, x, y, z, v in zip(range(BLOCK_ROWS), a1, a2, m, w)]
    template = "".join(lines).encode()
    rows = 0
    with open(path, "wb") as f:
        f.write(b"n,alpha1,alpha2,m_el,omega1\n")
        rec = _event()                    # one real backlash entry first (indices 0 .. < BLOCK_ROWS)
        for i, row in enumerate(rec):
            f.write(("%d,%.9f,%.9f,%.6f,%.6f\n" % (i, *row)).encode())
        rows += len(rec)
        k = 1
        while f.tell() < size_bytes and k < 10_000:
            f.write(template.replace(b"KKKK", b"%04d" % k))
            rows += BLOCK_ROWS
            k += 1
    return rows


def _event() -> np.ndarray:
    """alpha1, alpha2, m_el, omega1 of one simulated backlash entry at 30 dB (jident_ros.evaluation)."""
    sys.path.insert(0, str(REPO))
    from jident_ros.config import load_system_config
    from jident_ros.research.evaluation.raw_inputs import raw_recordings
    ch = ("t", "alpha1", "alpha2", "m_el", "omega1")
    rec = raw_recordings(load_system_config(), (1.16,), (0.005,), snr_db=30.0, steady_s=0.5, seed=1, channels=ch)[0]
    return rec.data[:, 1:]


def run(path: Path, out_json: Path) -> dict:
    cmd = [sys.executable, "-m", "jident_ros.cli", "diagnose", str(path), "--map", "t=n:0.0005", "--no-image",
           "--quiet", "--json", str(out_json)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = {"file_bytes": path.stat().st_size, "returncode": r.returncode, "wall_s": wall,
           "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
           "peak_rss_mb": after.ru_maxrss / 1024.0,   # the largest child so far (kB on Linux)
           "stderr_tail": r.stderr.strip().splitlines()[-3:]}
    if r.returncode == 0 and out_json.exists():
        doc = json.loads(out_json.read_text())
        res["samples"] = doc.get("samples")
        res["windows"] = len(doc.get("windows", []))
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size-gb", type=float, default=2.0)
    ap.add_argument("--dir", default=tempfile.gettempdir())
    ap.add_argument("--keep", action="store_true", help="keep the CSV files")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    results = []
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        # the small one first: ru_maxrss of the children is a running maximum
        for gb in (args.size_gb / 10, args.size_gb):
            path = Path(tmp) / f"trace_{gb:g}gb.csv"
            t0 = time.perf_counter()
            rows = write_csv(path, int(gb * 1e9))
            made = time.perf_counter() - t0
            res = run(path, Path(tmp) / "out.json")
            res.update(rows=rows, write_s=made, size_gb=path.stat().st_size / 1e9)
            res["rows_per_s"] = rows / res["wall_s"]
            results.append(res)
            print(f"{res['size_gb']:.2f} GB, {rows:,} rows: rc {res['returncode']}, peak RSS "
                  f"{res['peak_rss_mb']:.0f} MB, {res['wall_s']:.0f} s wall, {res['cpu_s']:.0f} s CPU "
                  f"({res['rows_per_s']:,.0f} rows/s), samples read {res.get('samples')}, windows "
                  f"{res.get('windows')}", flush=True)
            if res["returncode"] != 0:
                print("  stderr: " + " | ".join(res["stderr_tail"]), flush=True)
            if not args.keep:
                path.unlink()
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=2))
    big = results[-1]
    ok = big["returncode"] == 0 and big["peak_rss_mb"] < 500 and big.get("windows", 0) >= 1
    print(f"target (< 500 MB RSS at {big['size_gb']:.1f} GB, no error): {'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
