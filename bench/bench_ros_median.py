"""Medians of several ``bench_ros.py --out`` runs (issue 25's targets are medians of 3 runs on the idle machine).

    python bench/bench_ros_median.py out/bench/bench_ros_1.json out/bench/bench_ros_2.json out/bench/bench_ros_3.json

Prints one Markdown table: per run and the median, the highest lossless rate factor (``--bisect``), the
back-pressured (rate 0) end-to-end rate, the latency median at 20x, and each node's peak resident memory
(VmHWM, the largest over the run's levels), with the commit and load each run names.
"""
from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_ros import targets  # noqa: E402  (the bench's own reading of its targets, not a second one)


def row(run: dict) -> dict:
    t = targets(run["levels"], run.get("limit"))
    peak = {}
    for lv in run["levels"]:
        for node, mem in lv.get("memory_mib", {}).items():
            hwm = mem.get("VmHWM") if isinstance(mem, dict) else None
            if hwm is not None:
                peak[node] = max(peak.get(node, 0.0), float(hwm))
    return {"commit": run["machine"].get("commit", "?"),
            "load": run["machine"].get("load_average_start", [float("nan")])[0],
            "lossless": t["sustained_rtf"]["value"],
            "rate0": t["backpressured_rate"]["value"],          # None unless rate 0 was lossless and right
            "rate0_lossless": t["backpressured_rate"]["value"] is not None,
            "lat20": t["latency_median_ms"]["value"],
            "peak_ok": t["diagnostic_peak_rss_mib"]["value"],
            "peak": peak}


def _fmt(x, unit=""):
    return "–" if x is None else f"{x:.1f}{unit}"


def main(paths: list[str]) -> int:
    rows = [row(json.load(open(p))) for p in paths]
    nodes = sorted({n for r in rows for n in r["peak"]})
    head = ["run", "commit", "load at start", "highest lossless ×", "rate 0 end-to-end ×", "rate 0 lossless",
            "latency median at 20× [ms]", "diagnostic peak RSS, sustained levels [MiB]"] + [
                f"{n} peak RSS, every level [MiB]" for n in nodes]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for i, r in enumerate(rows, 1):
        print("| " + " | ".join([str(i), r["commit"], f"{r['load']:.2f}", _fmt(r["lossless"], "×"),
                                 _fmt(r["rate0"], "×"), "yes" if r["rate0_lossless"] else "no",
                                 _fmt(r["lat20"]), _fmt(r["peak_ok"])] + [_fmt(r["peak"].get(n)) for n in nodes])
              + " |")

    def med(key):
        vals = [r[key] for r in rows if r[key] is not None]
        return statistics.median(vals) if vals else None
    print("| " + " | ".join(["median", "", "", _fmt(med("lossless"), "×"), _fmt(med("rate0"), "×"),
                             f"{sum(r['rate0_lossless'] for r in rows)}/{len(rows)}", _fmt(med("lat20")),
                             _fmt(med("peak_ok"))]
                            + [_fmt(statistics.median([r["peak"][n] for r in rows if n in r["peak"]]))
                               for n in nodes]) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
