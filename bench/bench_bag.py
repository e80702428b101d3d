"""Recording bench: the rosbags/mcap path of jident_ros.bag against the hand-written one it replaced,
and the disk budget of a day of drive/signals at 2 kHz.

    .venv/bin/python bench/bench_bag.py [--rounds 7] [--batches 400] [--json out/bench/bench_bag.json]

* **Old**: ``jident_ros/recording.py`` at commit cd6a2ee (the hand-written CDR codec and BagWriter),
  checked out with ``git show`` into a temporary directory and imported from there.
* **New**: :mod:`jident_ros.bag.messages` (rosbags' typestore) and :class:`jident_ros.bag.writer.BagWriter`.
* Per round (interleaved old/new, ``--rounds`` rounds, medians reported): serialise and deserialise a
  1000 x 9 ``std_msgs/Float64MultiArray`` (best of 200 calls, per call); write ``--batches`` drive/signals
  batches (50 samples x 9 channels, from an already decoded message as the node's dict path does, and as
  CDR bytes as the node's raw subscription does) to a new bag, zstd: open + writes + close, and the writes
  alone (close writes the summary and metadata.yaml once per file; the new one also frees its reserve).
* **Disk budget**: ``--budget-s`` drive seconds of a simulated drive (the simulator's cases between
  steady-state gaps, the node's batch of 50 samples, the default 8 channels + t) written by the
  :class:`~jident_ros.bag.rotating_recorder.Recorder` with its defaults, a chunk every 0.5 s of drive time (what
  flush_age_s gives at real time); bytes per sample and per day at 2 kHz.  Also for white-noise samples
  (incompressible: the upper bound for a real drive's noisy signals).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from jident_ros.bag import messages as M  # noqa: E402
from jident_ros.bag.rotating_recorder import Recorder  # noqa: E402
from jident_ros.bag.writer import BagWriter  # noqa: E402

SIGNALS = "std_msgs/msg/Float64MultiArray"
CHANNELS = "t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2"
OLD_COMMIT = "cd6a2ee"


def old_module(tmp: Path):
    """jident_ros/recording.py as of cd6a2ee, imported from a temporary file."""
    src = subprocess.run(["git", "-C", str(REPO), "show", f"{OLD_COMMIT}:jident_ros/recording.py"],
                         capture_output=True, text=True, check=True).stdout
    path = tmp / "old_recording.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("old_recording", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def message(n: int, seed: int = 0) -> dict:
    data = np.random.default_rng(seed).random((n, 9))
    return {"layout": {"dim": [{"label": "sample", "size": n, "stride": n * 9},
                               {"label": CHANNELS, "size": 9, "stride": 9}], "data_offset": 0},
            "data": data.reshape(-1)}


def best_per_call(fn, calls: int = 200) -> float:
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(calls // 5):
            fn()
        best = min(best, (time.perf_counter() - t0) / (calls // 5))
    return best


def time_write(writer_cls, tmp: Path, tag: str, msgs, raw: bool) -> tuple[float, float]:
    """(open + writes + close, the writes alone) in s."""
    bag = tmp / f"{tag}-{time.monotonic_ns()}"
    t0 = time.perf_counter()
    w = writer_cls(bag)
    w.add_topic("/drive/signals", SIGNALS)
    t1 = time.perf_counter()
    for i, m in enumerate(msgs):
        w.write("/drive/signals", m, 10**18 + i * 25_000_000)
    t2 = time.perf_counter()
    w.close()
    return time.perf_counter() - t0, t2 - t1


def compare(rounds: int, batches: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        old = old_module(tmp)
        big = message(1000)
        old_big = old.deserialize(SIGNALS, old.serialize(SIGNALS, big))
        new_big = M.deserialize(SIGNALS, M.serialize(SIGNALS, big))
        cdr = M.serialize(SIGNALS, big)
        assert old.serialize(SIGNALS, old_big) == cdr, "old and new bytes differ"
        small = [message(50, seed=i) for i in range(batches)]
        old_small = [old.deserialize(SIGNALS, old.serialize(SIGNALS, m)) for m in small]
        new_small = [M.deserialize(SIGNALS, M.serialize(SIGNALS, m)) for m in small]
        small_cdr = [M.serialize(SIGNALS, m) for m in small]
        rows = {k: [] for k in ("ser_old", "ser_new", "de_old", "de_new", "write_old", "write_new",
                                "write_raw_old", "write_raw_new", "loop_old", "loop_new", "loop_raw_old",
                                "loop_raw_new")}
        for _ in range(rounds):
            rows["ser_old"].append(best_per_call(lambda: old.serialize(SIGNALS, old_big)))
            rows["ser_new"].append(best_per_call(lambda: M.serialize(SIGNALS, new_big)))
            rows["de_old"].append(best_per_call(lambda: old.deserialize(SIGNALS, cdr)))
            rows["de_new"].append(best_per_call(lambda: M.deserialize(SIGNALS, cdr)))
            for key, cls, msgs in (("old", old.BagWriter, old_small), ("new", BagWriter, new_small),
                                   ("raw_old", old.BagWriter, small_cdr), ("raw_new", BagWriter, small_cdr)):
                total, loop = time_write(cls, tmp, key, msgs, "raw" in key)
                rows[f"write_{key}"].append(total)
                rows[f"loop_{key}"].append(loop)
    med = {k: statistics.median(v) for k, v in rows.items()}
    return {"rounds": rounds, "batches": batches, "median_s": med,
            "ratio_old_over_new": {k: med[f"{k}_old"] / med[f"{k}_new"]
                                   for k in ("ser", "de", "write", "write_raw", "loop", "loop_raw")}}


def simulated_stream(seconds: float):
    """(n, 9) samples of a simulated drive: the simulator's cases between 400-sample steady gaps."""
    from jident_ros.config import load_system_config
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    system = load_system_config()
    ws = simulate_grid(system, [Case(j, 0.005, 0.025) for j in (1.16, 1.073, 1.218, 1.131, 1.102, 1.189)])
    stream, _ = embed_windows(ws, 400, 1.0, DEFAULT_CHANNELS)
    ts = ws.sample_period_s
    n = int(seconds / ts)
    reps = -(-n // len(stream))
    out = np.concatenate([stream] * reps)[:n].copy()
    out[:, 0] = 1.0 + np.arange(n) * ts
    return out, list(DEFAULT_CHANNELS), ts


def budget(seconds: float) -> dict:
    from jident_ros.cli.offline import multiarray_message
    stream, channels, ts = simulated_stream(seconds)
    per_chunk = int(round(0.5 / ts))   # samples per 0.5 s: the open chunk's age limit at real time
    out = {}
    for kind in ("simulated", "white_noise"):
        data = stream if kind == "simulated" else np.random.default_rng(0).standard_normal(stream.shape)
        with tempfile.TemporaryDirectory() as d:
            rec = Recorder(d, flush_age_s=None)
            for s in range(0, len(data), 50):
                b = data[s:s + 50]
                rec.write("/drive/signals", SIGNALS, M.serialize(SIGNALS, multiarray_message(b, channels)))
                if (s + 50) % per_chunk == 0:
                    rec.flush()
            rec.close()
            size = sum(p.stat().st_size for p in rec.bag_dir.iterdir())
        n = len(data)
        out[kind] = {"samples": n, "bytes": size, "bytes_per_sample": size / n,
                     "gb_per_day_at_2khz": size / n * 2000 * 86400 / 1e9}
    out["raw_float64_bytes_per_sample"] = 8 * stream.shape[1]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--batches", type=int, default=400)
    ap.add_argument("--budget-s", type=float, default=120.0, help="drive seconds for the disk budget")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    res = {"compare": compare(args.rounds, args.batches), "budget": budget(args.budget_s)}
    c = res["compare"]
    med, ratio = c["median_s"], c["ratio_old_over_new"]
    print(f"recording bench: medians of {c['rounds']} interleaved rounds (old = {OLD_COMMIT} hand-written, "
          f"new = rosbags + mcap); ratio = old / new (> 1: new faster)")
    print(f"  serialise 1000x9 Float64MultiArray : old {med['ser_old'] * 1e6:8.1f} us  new {med['ser_new'] * 1e6:8.1f} us"
          f"  ratio {ratio['ser']:.2f}")
    print(f"  deserialise 1000x9                 : old {med['de_old'] * 1e6:8.1f} us  new {med['de_new'] * 1e6:8.1f} us"
          f"  ratio {ratio['de']:.2f}")
    print(f"  write {c['batches']} batches (50x9), messages : old {med['write_old'] * 1e3:8.1f} ms  "
          f"new {med['write_new'] * 1e3:8.1f} ms  ratio {ratio['write']:.2f}")
    print(f"  write {c['batches']} batches (50x9), CDR bytes: old {med['write_raw_old'] * 1e3:8.1f} ms  "
          f"new {med['write_raw_new'] * 1e3:8.1f} ms  ratio {ratio['write_raw']:.2f}")
    print(f"  ... the {c['batches']} writes alone, messages : old {med['loop_old'] * 1e3:8.1f} ms  "
          f"new {med['loop_new'] * 1e3:8.1f} ms  ratio {ratio['loop']:.2f}")
    print(f"  ... the {c['batches']} writes alone, CDR bytes: old {med['loop_raw_old'] * 1e3:8.1f} ms  "
          f"new {med['loop_raw_new'] * 1e3:8.1f} ms  ratio {ratio['loop_raw']:.2f}")
    b = res["budget"]
    for kind in ("simulated", "white_noise"):
        r = b[kind]
        print(f"  disk budget ({kind:11s}): {r['bytes_per_sample']:.2f} bytes/sample "
              f"(raw float64 {b['raw_float64_bytes_per_sample']}) -> {r['gb_per_day_at_2khz']:.2f} GB per day at 2 kHz "
              f"({r['samples']} samples, {r['bytes']} bytes)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
