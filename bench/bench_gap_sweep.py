#!/usr/bin/env python3
"""CPU seconds of the gap estimator as the robustness sweeps run it (issue 23, item 3), and a digest of its output.

    .venv/bin/python bench/bench_gap_sweep.py
    # another commit's code, the same script: git archive REF jident_ros | tar -x -C /tmp/ref &&
    #   (cd /tmp && PYTHONPATH=/tmp/ref /path/to/.venv/bin/python /path/to/bench/bench_gap_sweep.py)

``robustness.gap_on_windows`` (all 7 channel sets) on 4 data sets of the 168 grid windows: noise-free, 30 dB
(seed 1), 20 dB (seed 2), encoders quantised to 2^16 counts/rev.  Prints which package it ran, the CPU seconds
(process time: the machine is shared) and a digest of every estimate, interval, gap end and refusal reason: equal
digests = the same numbers bit for bit.
"""
from __future__ import annotations

import hashlib
import pickle
import time

import numpy as np

import jident_ros
from jident_ros.config import load_system_config
from jident_ros.research.evaluation.robustness import gap_on_windows, paper_grid_cases
from jident_ros.sim import add_measurement_noise, quantise_encoders, simulate_grid


def main() -> int:
    print(f"package: {jident_ros.__file__}")
    system = load_system_config()
    clean = simulate_grid(system, list(paper_grid_cases(system)))
    sets = [clean, add_measurement_noise(clean, 30.0, 1), add_measurement_noise(clean, 20.0, 2),
            quantise_encoders(clean, 2 ** 16)]
    t0 = time.process_time()
    outs = [gap_on_windows(system, w) for w in sets]
    cpu = time.process_time() - t0
    blob = pickle.dumps([{k: {kk: (vv.tobytes() if isinstance(vv, np.ndarray) else vv) for kk, vv in v.items()}
                          for k, v in o.items()} for o in outs])
    print(f"gap_on_windows, 7 channel sets x {len(sets)} data sets of {len(clean.cases)} windows: {cpu:.2f} CPU-s; "
          f"digest {hashlib.sha256(blob).hexdigest()[:16]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
