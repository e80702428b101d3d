"""`jident trend` across a restarted drive clock (recordings in recording order, never interleaved; a resumed
state leaves out what it holds by recording) and `jident trend --fleet --state` (one state per drive) -- issue 21
(jident_ros/cli/trend_run.py, cli/fleet.py)."""
from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import pytest

from jident_ros.cli.main import main as jident
from jident_ros.config import load_system_config

#: Drive-clock entry times of six one-entry recordings: the drive restarts (t back near 0) after the third.
ENTRY_T = (3600.0, 7200.0, 10800.0, 100.0, 3700.0, 7300.0)
#: The recorder's clock (log time) at each recording's start: always later than the previous recording's.
RECORDED_AT = (1.0e9, 1.0e9 + 3600.0, 1.0e9 + 7200.0, 1.0e9 + 20000.0, 1.0e9 + 23600.0, 1.0e9 + 27200.0)


@pytest.fixture(scope="module")
def restarted(tmp_path_factory):
    """Six bags of one drive, one entry each (raw 2^16 angles, 30 dB), the drive clock restarted after the
    third; the recorder's log time increasing throughout (``RECORDED_AT``)."""
    from jident_ros.cli.scenario import write_signals_bag
    from jident_ros.research.evaluation.raw_inputs import raw_recordings
    system = load_system_config()
    root = tmp_path_factory.mktemp("restart")
    paths = []
    for k, (t_entry, at) in enumerate(zip(ENTRY_T, RECORDED_AT)):
        rec = raw_recordings(system, [1.16], [0.003], snr_db=30.0, steady_s=0.3, seed=k)[0]
        data = rec.data.copy()
        ti = rec.channels.index("t")
        data[:, ti] += t_entry - data[rec.entry_row, ti]
        paths.append(write_signals_bag(root / f"rec{k}", data, rec.channels, log_offset_s=at - data[0, ti]))
    return paths


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_restarted_clock_is_ordered_by_recording_not_interleaved(restarted, tmp_path, capsys):
    """Given shuffled, the recordings go through the tracker by their start (the recorder's clock): rec0..rec5,
    with one time segment where the drive clock went back.  Sorting the windows by drive time (the former rule)
    would interleave rec3 (t = 100) before rec0 and rec4 between rec0 and rec1."""
    from jident_ros.cli.trend_run import recording_start_ns
    assert [recording_start_ns(p) for p in restarted] == sorted(recording_start_ns(p) for p in restarted)
    assert recording_start_ns(restarted[3]) == pytest.approx(RECORDED_AT[3] * 1e9, abs=1e8)   # its first batch, logged at its end
    shuffled = [restarted[i] for i in (4, 0, 5, 2, 3, 1)]
    out = tmp_path / "out"
    assert jident(["trend", *map(str, shuffled), "--out", str(out), "--quiet", "--jobs", "1"]) == 0
    rows = _rows(out / "trend.csv")
    assert [r["recording"].rsplit("rec", 1)[1] for r in rows] == ["0", "1", "2", "3", "4", "5"]
    assert [float(r["time_s"]) for r in rows] == pytest.approx(ENTRY_T, abs=0.01)
    text = capsys.readouterr().out
    assert "in recording order (each recording's start)" in text
    # --order given: as listed
    assert jident(["trend", *map(str, shuffled), "--out", str(tmp_path / "given"), "--quiet", "--jobs", "1",
                   "--order", "given"]) == 0
    assert [r["recording"].rsplit("rec", 1)[1] for r in _rows(tmp_path / "given" / "trend.csv")] == \
        ["4", "0", "5", "2", "3", "1"]


def test_order_recordings_keeps_each_recording_together():
    """The pure rule: by start when every recording has one; else by first entry on the drive clock (CSV files
    of one clock); a recording without a window keeps its place among equals; 'given' keeps the order."""
    from jident_ros.cli.trend_run import order_recordings
    w = lambda *ts: [SimpleNamespace(time_s=t) for t in ts]  # noqa: E731
    a, b, c = (30, w(5.0, 6.0)), (10, w(100.0, 200.0)), (20, w(1.0))
    got, how = order_recordings([a, b, c])
    assert [x[0] for x in got] == [10, 20, 30] and "start" in how
    got, how = order_recordings([(None, a[1]), (None, b[1]), (None, c[1])])
    assert [x[1][0].time_s for x in got] == [1.0, 5.0, 100.0] and "drive clock" in how
    got, _ = order_recordings([(None, b[1]), (5, c[1])])         # one start missing: drive clock for all
    assert [x[1][0].time_s for x in got] == [1.0, 100.0]
    got, how = order_recordings([a, b, c], "given")
    assert [x[0] for x in got] == [30, 10, 20] and how == "in the order given"
    with pytest.raises(ValueError, match="order"):
        order_recordings([a], "time")


def test_state_resumes_by_recording_across_a_restart(restarted, tmp_path, capsys):
    """rec0..rec3 with a state, then all six with it: the state's cursor (rec3's start, its last window) leaves
    out rec0..rec3 only, although rec4/rec5's drive times (3700, 7300) are below rec2's (10800) and above
    rec3's (100): a time rule would feed rec0..rec2 again or drop rec4/rec5.  Equal to one pass over all six."""
    from jident_ros.identify.trend import TrendTracker
    state = tmp_path / "trend.json"
    common = ["--quiet", "--jobs", "1", "--commissioning-windows", "3"]
    assert jident(["trend", *map(str, restarted[:4]), "--out", str(tmp_path / "a"), "--state", str(state), *common]) == 0
    saved = json.loads(state.read_text())
    assert saved["recording_cursor"][1] == pytest.approx(100.0, abs=0.01)
    capsys.readouterr()
    assert jident(["trend", *map(str, restarted), "--out", str(tmp_path / "b"), "--state", str(state), *common]) == 0
    assert "4 already in the state" in capsys.readouterr().out
    assert [r["recording"].rsplit("rec", 1)[1] for r in _rows(tmp_path / "b" / "trend.csv")] == ["4", "5"]
    resumed = TrendTracker.load(state)
    assert jident(["trend", *map(str, restarted), "--out", str(tmp_path / "c"), *common]) == 0
    one = _rows(tmp_path / "c" / "trend.csv")
    assert resumed.n_windows == 6 == len(one) and resumed.time_segment == 1
    assert resumed.to_dict()["inertia"]["x"] == pytest.approx(float(one[-1]["inertia_smoothed_kgm2"]), rel=1e-12)


@pytest.mark.parametrize("cursor, field", [(["x", 1.0], "recording_cursor[0]"), ([-5, 1.0], "recording_cursor[0]"),
                                           ([1, float("nan")], "recording_cursor[1]"), ([1], "recording_cursor")])
def test_a_bad_recording_cursor_is_refused_naming_it(tmp_path, cursor, field):
    from jident_ros.identify.trend import TrendStateError, TrendTracker
    tr = TrendTracker()
    tr.update(1.0, 1.16, 0.01, 0.003, 1e-5)
    d = tr.to_dict()
    assert d["recording_cursor"] is None and TrendTracker.from_dict(d).recording_cursor is None
    d["recording_cursor"] = cursor
    with pytest.raises(TrendStateError, match=field.replace("[", r"\[").replace("]", r"\]")):
        TrendTracker.from_dict(d)


def test_fleet_keeps_one_state_per_drive(restarted, tmp_path, capsys):
    """Two drives (folders a and b, --drive-id parent): the first run over part of each drive's recordings, the
    second over all of them resumes each drive from its own state (a/..json, b/..json) and equals one pass; a
    drive whose state is unusable gets an error row naming the file while the other carries on; --state a file
    is one line."""
    import os

    from jident_ros.cli.fleet import state_file
    fleet = tmp_path / "fleet"
    for drive, idx in (("a", (0, 1, 2)), ("b/x", (3, 4, 5))):
        (fleet / drive).mkdir(parents=True)
        for i in idx:
            os.symlink(restarted[i], fleet / drive / f"rec{i}")
    # drive 'x' (the parent folder of b/x); a drive id with a separator stays inside the state directory
    assert state_file(tmp_path / "s", "../up/x").parent == tmp_path / "s"
    states = tmp_path / "states"
    common = ["--fleet", "--drive-id", "parent", "--quiet", "--jobs", "1", "--commissioning-windows", "2"]
    part = [str(fleet / "a" / "rec0"), str(fleet / "a" / "rec1"), str(fleet / "b" / "x" / "rec3")]
    # (drive x has one window: still commissioning, its row has no drift -- a fleet run used to fail on it)
    assert jident(["trend", *part, "--out", str(tmp_path / "o1"), "--state", str(states), *common]) == 0
    assert sorted(p.name for p in states.iterdir()) == ["a.json", "x.json"]
    assert jident(["trend", str(fleet), "--out", str(tmp_path / "o2"), "--state", str(states), *common]) == 0
    assert jident(["trend", str(fleet), "--out", str(tmp_path / "o3"), *common]) == 0
    resumed = {r["drive"]: r for r in _rows(tmp_path / "o2" / "fleet.csv")}
    one = {r["drive"]: r for r in _rows(tmp_path / "o3" / "fleet.csv")}
    for d in ("a", "x"):
        assert resumed[d]["inertia_kgm2"] == one[d]["inertia_kgm2"] and resumed[d]["error"] == ""
        assert json.loads(state_file(states, d).read_text())["n_windows"] == 3
    assert [len(_rows(tmp_path / "o2" / "drives" / d / "trend.csv")) for d in ("a", "x")] == [1, 2]
    # an unusable state: that drive's row names the file, the other drive is fine, exit status 1
    bad = json.loads(state_file(states, "a").read_text())
    bad["n_windows"] = "many"
    state_file(states, "a").write_text(json.dumps(bad))
    assert jident(["trend", str(fleet), "--out", str(tmp_path / "o4"), "--state", str(states), *common]) == 1
    rows = {r["drive"]: r for r in _rows(tmp_path / "o4" / "fleet.csv")}
    assert "a.json" in rows["a"]["error"] and "n_windows" in rows["a"]["error"] and rows["x"]["error"] == ""
    capsys.readouterr()
    assert jident(["trend", str(fleet), "--out", str(tmp_path / "o5"), "--state", str(state_file(states, "x")),
                   *common]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a directory for one state per drive" in err[0]


def test_trend_relative_diagnoses_each_drive_with_its_own_radius(monkeypatch, tmp_path):
    """trend_relative's pools: the second drive's windows with its truth file's r = 0.08 m and N (the run of the
    former section used our 0.1 m: every absolute J1 +25 %); ours with the system's r."""
    from jident_ros.research.evaluation import trend_relative as tr
    seen = []

    def fake(path, system=None, gear_ratio=1.0, **kw):
        seen.append((str(path), system.load.wheel_radius_m, gear_ratio))
        raise tr.OfflineError("not diagnosed here")
    monkeypatch.setattr(tr, "diagnose_samples", fake)
    system = load_system_config()
    recs = [(tmp_path / "a.csv", tr.J1_BASE, 0.08, 2.0), (tmp_path / "b.csv", tr.J1_STEP, system.load.wheel_radius_m, 1.0)]
    assert tr.pools(recs, system)["counts"]["errors"] == 2
    assert seen == [(str(tmp_path / "a.csv"), 0.08, 2.0), (str(tmp_path / "b.csv"), system.load.wheel_radius_m, 1.0)]
    # the truth record of a recording: its own .truth.json, else its row of the folder's truth.json
    (tmp_path / "truth.json").write_text(json.dumps({"recordings": [{"file": "x/a.csv", "inertia_kgm2": 1.131,
                                                                     "reference_radius_m": 0.08, "gear_ratio": 1.0}]}))
    assert tr._truth(tmp_path / "a.csv")["reference_radius_m"] == 0.08


def test_entry_refinement_experiment_is_undone():
    from jident_ros.research.evaluation.raw_scenario import entry_refinement
    from jident_ros.stream.flank import FlankDetector
    shipped = FlankDetector._refine
    with entry_refinement(False):
        assert FlankDetector._refine is not shipped and FlankDetector._refine(None, None, 7) == (0, None)
    assert FlankDetector._refine is shipped
    with pytest.raises(RuntimeError), entry_refinement(False):
        raise RuntimeError
    assert FlankDetector._refine is shipped


def test_a_step_inside_the_baseline_refinement_is_measured_from_the_windows_before_it():
    """Noise-free J1 1.16 for 5 windows, then +2.5 %: with a 3-window commissioning the baseline is still being
    refined (towards 20 windows) when the step arrives and takes the first stepped window in (winsorised) before
    the CUSUM fires; the change's size is measured from the baseline's windows before the onset: +2.50 %, not
    the +2.42 % of the half-absorbed baseline (the demo's wear scenario).  A change after the refinement is
    measured from the baseline as before; the state round-trips base_start and refuses a wrong one."""
    from jident_ros.identify.trend import TrendConfig, TrendStateError, TrendTracker
    tr = TrendTracker(TrendConfig(commissioning_windows=3))
    ys = [1.16] * 5 + [1.16 * 1.025] * 5
    ups = [tr.update(3600.0 * (i + 1), y, 0.0004 * y) for i, y in enumerate(ys)]
    ev = [c for u in ups for c in u.changes if c.quantity == "inertia"]
    assert len(ev) == 1 and ev[0].onset_window_index == 5 and ev[0].sign == 1
    assert ev[0].size_pct == pytest.approx(2.5, abs=1e-6) and ev[0].class_pct == 2.5
    d = tr.to_dict()
    assert d["inertia"]["base_start"] == 5 and TrendTracker.from_dict(d)._inertia.base_start == 5
    d["inertia"]["base_start"] = 99
    with pytest.raises(TrendStateError, match="inertia.base_start"):
        TrendTracker.from_dict(d)
    # after the refinement (20 windows) the baseline holds no later window: the same size either way
    late = TrendTracker(TrendConfig(commissioning_windows=3))
    ys = [1.16] * 25 + [1.16 * 0.975] * 5
    ev = [c for i, y in enumerate(ys) for c in late.update(3600.0 * (i + 1), y, 0.0004 * y).changes]
    assert len(ev) == 1 and ev[0].size_pct == pytest.approx(-2.5, abs=1e-6)
