"""The detector evaluation over the validation drives (jident_ros/research/evaluation/detector_zoo.py): matching
and counting on a small second-drive directory (speed step down, raw 2^16 encoders, wrapped and with a spike)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from jident_ros.research.evaluation.detector_zoo import evaluate_dir, summarise


@pytest.fixture(scope="module")
def second_drive_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sd") / "csv"
    subprocess.run([sys.executable, "-m", "jident_ros.research.second_drive", "--out", str(out), "--format", "csv",
                    "--encoder-counts", "65536", "--inertias", "1.16", "--widths", "0.0025,0.01", "--gear-ratio", "4",
                    "--direction", "both", "--steady-s", "0.5"], check=True, capture_output=True, timeout=300)
    return out


def test_every_entry_found_on_wrapped_geared_encoders_and_a_spike_swallows_nothing(second_drive_dir):
    for kw in ({}, {"wrap": True}, {"wrap": True, "spike_s": 0.25}):
        s = summarise(evaluate_dir(second_drive_dir, **kw))
        assert s["found"] == s["with_gap"] == 4 and s["false"] == 0, (kw, s)
        # with return-traversal windows on, the K2 = 10 mm recordings. return traversal (resting at the flank) gets one
        # once delta moves: inside the true gap, late (the gap estimator's change points refine it), not false
        assert s["late"] <= 2 and all(o > 0 for o in s["late_offsets"]), (kw, s)
        assert s["within_2"] >= s["matched"] - 1 and s["k2_median"] < 0.05 and s["swallowed"] == 0   # gear 4: one at -4
    assert summarise(evaluate_dir(second_drive_dir, wrap=True, spike_s=0.25))["spikes"] == 4
