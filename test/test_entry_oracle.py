"""entry_oracle: how many traversals the encoders' angles resolve within ±2 samples (research report, docs/results.md)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from jident_ros.research.evaluation import entry_oracle as E
from jident_ros.research.evaluation import zoo


def _crossing(speed_rad_per_sample: float, accel_rad_per_sample2: float = 0.0, entry: int = 50, n: int = 120,
              half_zone: float = 0.05):
    """A relative angle untwisting from the + flank at ``speed`` per sample, crossing the zone's edge between samples
    entry - 1 and entry, then accelerating into the zone."""
    k = np.arange(n, dtype=float) - (entry - 0.5)
    return half_zone - speed_rad_per_sample * k - 0.5 * accel_rad_per_sample2 * np.clip(k, 0.0, None) ** 2


def test_the_reading_quantum_counts_both_encoders():
    assert E.reading_quantum_rad(65536, 1.0) == pytest.approx(2 * 2 * math.pi / 65536)
    assert E.reading_quantum_rad(8192, -3.0) == pytest.approx(4 * 2 * math.pi / 8192)


@pytest.mark.parametrize(("speed", "accel", "after"), [
    (1e-3, 0.0, 0),          # a fast crossing: a quantum inside in its first sample
    (1e-4, 0.0, 2),          # 0.2 mrad a quantum: 2.5 samples
    (1e-5, 0.0, 20),         # a slow one
    (1e-7, 4e-6, 10),        # a gap opened by acceleration alone (a light reversal): sqrt(2 q / a)
])
def test_shown_after_is_the_time_the_angle_takes_to_lie_a_quantum_inside(speed, accel, after):
    q = 2e-4
    delta = _crossing(speed, accel)
    assert np.abs(delta[49]) > 0.05 >= np.abs(delta[50])                # the truth's entry is row 50
    assert E.shown_after(delta, 0.05, 50, 120, q) == after


def test_a_gap_never_a_quantum_deep_is_never_shown():
    delta = np.full(100, 0.0501)                                        # on the flank, then half a quantum in
    delta[50:60] = 0.05 - 5e-5
    assert E.shown_after(delta, 0.05, 50, 60, 1e-4) is None
    assert E.shown_after(-delta, 0.05, 50, 60, 1e-4) is None            # either flank


def test_the_detector_entries_are_read_per_traversal_and_other_models_skipped(tmp_path):
    f = tmp_path / "dol_1.json"
    f.write_text(json.dumps({"model": "dol", "entries": [["JointState 2^16 clean", "d1-01", "slip drop", 1200, 1203],
                                                         ["JointState 2^16 clean", "d1-01", "slip reversal", 1210, None]]}))
    g = tmp_path / "vector_1.json"
    g.write_text(json.dumps({"model": "vector", "entries": [["JointState 2^16 clean", "s1-01", "speed reversal", 5, 6]]}))
    old = tmp_path / "dol_2.json"
    old.write_text(json.dumps({"model": "dol"}))                       # written before entries were recorded
    got = E.detector_entries([f, g, old], "dol")
    assert got == {("JointState 2^16 clean", "d1-01", "slip drop", 1200): 3,
                   ("JointState 2^16 clean", "d1-01", "slip reversal", 1210): None}


def test_the_table_splits_the_detector_by_what_the_angles_show():
    rows = [("slip drop", "d1-01", 100, 0), ("slip drop", "d1-02", 100, 5), ("slip drop", "d1-03", 100, None),
            ("light", "d1-01", 300, 1)]
    lab = E.LABELS[0]
    entries = {(lab, "d1-01", "slip drop", 100): 1, (lab, "d1-02", "slip drop", 100): 4,
               (lab, "d1-03", "slip drop", 100): None, (lab, "d1-01", "light", 300): -3}
    md = E.markdown(rows, "dol", [1], entries, "cmd", "abc", 1.0)
    line = {ln.split(" | ")[0].lstrip("| "): ln for ln in md.splitlines() if ln.startswith("| ")}
    assert line["slip drop"].startswith("| slip drop | 3 | 1/3 (33 %) | 2 | 0 / 1 | 1/1 (100 %) | 0/1 (0 %) | – | – | 1 / 0 |")
    assert "| all | 4 | 2/4 (50 %) |" in line["all"] and "| 1/2 (50 %) | 0/1 (0 %) |" in line["all"]
    heads = {E.markdown([], m, [1], {}, "cmd", "abc", 1.0).splitlines()[0].split("(")[0] for m in ("vector", "dol")}
    assert len(heads) == 2


def test_first_entries_take_the_first_window_of_each_gap_and_cut_off_ones():
    res = {"windows": [{"index": 7, "gap": 0}, {"index": 9, "gap": 0}, {"index": 30, "gap": None}],
           "cut_off": [{"index": 50, "gap": 1}]}
    assert zoo.first_entries(res) == {0: 7, 1: 50}


def test_a_bad_seed_list_gets_one_line(capsys):
    assert E.main(["--seeds", "1-x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "entry_oracle: error: argument --seeds" in err
