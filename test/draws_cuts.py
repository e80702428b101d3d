"""Cuts of the blind draws' recordings kept under test/data (test_flank.py, test_short_bounce.py): rows of a
JointState recording with 2^20-count encoders, stored as counts from the first row."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data"


def draws_cut(name: str, key: str) -> tuple:
    """(samples, channels, the npz) of input ``key`` ("js", "imu") in test/data/``name``: t, alpha1, alpha2, m_el and,
    where the cut has it, a1."""
    d = np.load(DATA / name)
    q = 2.0 * math.pi / 2 ** 20
    cols = [float(d[f"{key}_alpha10"]) + q * d[f"{key}_alpha1_counts"],
            float(d[f"{key}_alpha20"]) + q * d[f"{key}_alpha2_counts"], d[f"{key}_m_el"].astype(float)]
    ch = ("t", "alpha1", "alpha2", "m_el") + (("a1",) if f"{key}_a1" in d else ())
    if "a1" in ch:
        cols.append(d[f"{key}_a1"].astype(float))
    return np.column_stack([np.arange(cols[0].size) * 5e-4] + cols), ch, d
