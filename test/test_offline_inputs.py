"""jident diagnose on CSV files (raw encoder angles, no K2): windows on the entry sample, the width estimate and
flags in the JSON, a window cut off by the end of the data reported."""
from __future__ import annotations

import json

import numpy as np
import pytest

from jident_ros.cli.main import main as jident
from jident_ros.cli.offline import OfflineError, diagnose_samples
from jident_ros.config import load_system_config
from jident_ros.research.evaluation.raw_inputs import raw_recordings


@pytest.fixture(scope="module")
def rec():
    return raw_recordings(load_system_config(), (1.073,), (0.0075,), snr_db=30.0, steady_s=0.5, seed=9)[0]


def write(path, rec, rows=None):
    data = rec.data if rows is None else rec.data[:rows]
    np.savetxt(path, data, delimiter=",", header=",".join(rec.channels), comments="", fmt="%.17g")
    return path


def test_csv_without_k2_gives_the_window_and_its_width(tmp_path, rec, capsys):
    p = write(tmp_path / "trace.csv", rec)
    out = tmp_path / "r.json"
    assert jident(["diagnose", str(p), "--no-image", "--json", str(out), "--quiet"]) == 0
    res = json.loads(out.read_text())
    (w,) = res["windows"]
    assert w["entry_time_s"] == pytest.approx(rec.data[rec.entry_row, 0], abs=1e-9)
    assert w["detector"] == "flank" and w["flags"] == []
    assert w["backlash_width_estimate_m"] == pytest.approx(0.0075, rel=0.05)
    assert w["inertia_estimate_kgm2"] == pytest.approx(1.073, rel=0.01) and w["level"] in ("OK", "WARN")
    assert res["cut_off"] == []


def test_a_window_cut_off_by_the_end_of_a_csv_is_reported(tmp_path, rec, capsys):
    p = write(tmp_path / "short.csv", rec, rec.entry_row + 500)
    res = diagnose_samples(p, image_method=False)
    assert res.windows == [] and len(res.cut_off) == 1 and res.dropped == {"cut_off": 1}
    assert res.cut_off[0]["samples_from_entry"] == 500
    assert jident(["diagnose", str(p), "--no-image", "--quiet"]) == 1
    assert "cut off by the end of the data: entry at" in capsys.readouterr().out


def test_paper_mode_needs_k2_and_flank_mode_refuses_it(tmp_path, rec):
    p = write(tmp_path / "t.csv", rec, 100)
    with pytest.raises(OfflineError, match="needs K2"):
        diagnose_samples(p, image_method=False, detector="paper")
    with pytest.raises(OfflineError, match="only for --detector paper"):
        diagnose_samples(p, image_method=False, backlash_width_m=0.005)


def test_csv_without_alpha2_gives_a_dynamics_window_only_with_detector_dynamics(tmp_path, rec, capsys):
    """A drive without a load encoder (no alpha2, omega2, a2, v2 columns): ``--detector dynamics`` finds the entry
    from m_el and a1 on the true sample and the gap fit gives J1; the default flank detector refuses it in one line
    naming alpha2."""
    from jident_ros.research.evaluation.raw_inputs import without
    p = write(tmp_path / "motor_only.csv", without(rec, ("alpha2", "omega2", "a2", "v2")))
    assert "alpha2" not in p.read_text().splitlines()[0].split(",")
    out = tmp_path / "d.json"
    assert jident(["diagnose", str(p), "--detector", "dynamics", "--no-image", "--json", str(out), "--quiet"]) == 0
    (w,) = json.loads(out.read_text())["windows"]
    assert w["detector"] == "dynamics"
    assert w["entry_time_s"] == pytest.approx(rec.data[rec.entry_row, 0], abs=1e-9)
    assert w["inertia_estimate_kgm2"] == pytest.approx(1.073, rel=0.01), w["message"]
    capsys.readouterr()
    assert jident(["diagnose", str(p), "--no-image", "--quiet"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'alpha2' missing" in err[0], err
