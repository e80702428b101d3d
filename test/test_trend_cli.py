"""`jident trend`, `jident simulate --scenario wear` (jident_ros/cli/trend.py, sim/scenarios.py), the offline
replay across clock jumps and joined batches (bag/drive_replay.py), and the node's pure trend pieces
(identify/trend_status.py, TrendConfig.from_parameters)."""
from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest

from jident_ros.cli.main import main as jident
from jident_ros.config import load_system_config


@pytest.fixture(scope="module")
def system():
    return load_system_config()


@pytest.fixture(scope="module")
def wear40(tmp_path_factory):
    """40 entries an hour apart, 30 dB, K2 2.5 -> 3.5 mm, J1 +2.5 % from entry 20 (about 2 s)."""
    out = tmp_path_factory.mktemp("wear") / "wear40"
    assert jident(["simulate", "--scenario", "wear", "--windows", "40", "--snr-db", "30", "--out", str(out),
                   "--quiet"]) == 0
    return out


# --------------------------------------------------------------------------- scenario

def test_wear_scenario_times_widths_and_step(system):
    from jident_ros.sim.scenarios import wear_scenario
    sc = wear_scenario(system, 11, 3600.0, 0.0025, 0.0035, j1_kgm2=1.16, j1_step_at_window=4, j1_step_pct=2.5)
    assert len(sc) == 11
    assert np.allclose(np.diff(sc.entry_times_s), 3600.0) and sc.entry_times_s[0] == 3600.0
    assert np.allclose(sc.true_width_m, np.linspace(0.0025, 0.0035, 11))
    assert np.allclose(sc.true_inertia_kgm2[:4], 1.16) and np.allclose(sc.true_inertia_kgm2[4:], 1.16 * 1.025)
    assert sc.j1_step_time_s == sc.entry_times_s[4]
    assert sc.wear_rate_m_per_day == pytest.approx(0.001 / 10 / 3600 * 86400)
    by_rate = wear_scenario(system, 5, 86400.0, 0.003, width_growth_m_per_day=1e-4)
    assert np.allclose(np.diff(by_rate.true_width_m), 1e-4)


@pytest.mark.parametrize("kw, field", [({"n_windows": 0}, "n_windows"), ({"interval_s": -1.0}, "interval_s"),
                                       ({"j1_step_at_window": 10}, "j1_step_at_window"),
                                       ({"width_end_m": 0.004, "width_growth_m_per_day": 1e-4}, "width_end_m"),
                                       ({"width_growth_m_per_day": -1.0}, "the width reaches")])
def test_wear_scenario_refuses_bad_arguments(system, kw, field):
    from jident_ros.sim.scenarios import wear_scenario
    args = dict(n_windows=10, interval_s=3600.0)
    args.update(kw)
    with pytest.raises(ValueError, match=field):
        wear_scenario(system, **args)


# --------------------------------------------------------------------------- offline replay

def test_one_entry_an_hour_loses_nothing(system, tmp_path):
    """Each entry's stream starts 48 samples before it (the first 50-sample batch holds the entry):
    without the clock-jump handling the detector dropped that batch as a 'gap' and lost the window."""
    from jident_ros.cli.offline import diagnose_recording
    from jident_ros.cli.scenario import write_scenario_recording
    from jident_ros.sim.scenarios import wear_scenario
    sc = wear_scenario(system, 6, 3600.0, 0.0025, 0.003, j1_step_at_window=3)
    rec = write_scenario_recording(tmp_path / "rec", system, sc, gap_samples=0)
    res = diagnose_recording(rec, system=system, image_method=False)
    assert res.dropped == {}
    assert res.clock_jumps == 5
    assert [w.entry_time_s for w in res.windows] == pytest.approx(list(sc.entry_times_s), abs=1e-6)
    assert [w.true_inertia_kgm2 for w in res.windows] == pytest.approx(list(sc.true_inertia_kgm2))
    for w, c in zip(res.windows, sc.cases):
        assert w.inertia_kgm2 == pytest.approx(c.inertia_kgm2, rel=0.01)


def test_joined_batches_give_the_same_windows_and_drops(system, tmp_path, monkeypatch):
    """A NaN batch in the steady stretch is dropped ('nonfinite', counted once) whether the clean batches
    around it go to the detector joined or one by one; the windows are the same."""
    from jident_ros.bag.drive_replay import DriveReplay
    from jident_ros.bag.writer import BagWriter
    from jident_ros.cli.offline import diagnose_recording, multiarray_message
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    ws = simulate_grid(system, [Case(1.16, 0.005, 0.025), Case(1.073, 0.005, 0.025), Case(1.218, 0.005, 0.025)])
    stream, _ = embed_windows(ws, 400, 1.0, DEFAULT_CHANNELS)
    per = 400 + len(ws.t)
    s0 = (per // 50 + 1) * 50                                        # one whole batch in case 1's steady stretch
    stream[s0:s0 + 50, DEFAULT_CHANNELS.index("m_el")] = np.nan
    with BagWriter(tmp_path / "rec") as bag:
        bag.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray")
        for s in range(0, stream.shape[0], 50):
            b = stream[s:s + 50]
            bag.write("/drive/signals", multiarray_message(b, DEFAULT_CHANNELS), int(b[-1, 0] * 1e9))
    # the paper detector (K2 given): 'auto' would take the flank detector for a recording without drive/backlash_width
    joined = diagnose_recording(tmp_path / "rec", system=system, image_method=False, detector="paper")
    flank_joined = diagnose_recording(tmp_path / "rec", system=system, image_method=False)
    monkeypatch.setattr(DriveReplay, "MAX_RUN_SAMPLES", 1)       # every batch alone
    single = diagnose_recording(tmp_path / "rec", system=system, image_method=False, detector="paper")
    flank_single = diagnose_recording(tmp_path / "rec", system=system, image_method=False)
    assert joined.dropped == single.dropped == {"nonfinite": 1}
    assert flank_joined.detector == "flank" and flank_joined.dropped == flank_single.dropped
    assert flank_joined.dropped["nonfinite"] == 1
    assert [(w.entry_time_s, w.inertia_kgm2) for w in flank_joined.windows] == \
        [(w.entry_time_s, w.inertia_kgm2) for w in flank_single.windows]
    assert joined.batches == single.batches == math.ceil(stream.shape[0] / 50)
    assert len(joined.windows) == 3
    assert [(w.entry_time_s, w.inertia_kgm2) for w in joined.windows] == \
        [(w.entry_time_s, w.inertia_kgm2) for w in single.windows]


# --------------------------------------------------------------------------- jident trend

def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_jident_trend_end_to_end(wear40, tmp_path, capsys):
    out = tmp_path / "trend"
    assert jident(["trend", str(wear40), "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    rows = _rows(out / "trend.csv")
    assert len(rows) == 40
    for col in ("time_s", "inertia_kgm2", "inertia_ci_low_kgm2", "inertia_ci_high_kgm2", "backlash_width_m",
                "change", "inertia_smoothed_kgm2", "backlash_width_smoothed_m", "level", "skip_reason"):
        assert col in rows[0]
    times = [float(r["time_s"]) for r in rows]
    assert times == sorted(times) and times[0] == 3600.0
    changed = [i for i, r in enumerate(rows) if r["change"] == "1" and "inertia" in r["change_quantity"]]
    assert len(changed) == 1 and 20 <= changed[0] <= 24           # the J1 step is at entry 20
    assert all(r["change"] == "0" for i, r in enumerate(rows) if i < 20)
    assert (out / "trend.png").stat().st_size > 10_000
    # summary: the step, the wear rate near the truth (1 mm over 39 h = 0.615 mm/day)
    assert "inertia: +" in text and "health: WARN" in text
    rate = float(text.split("wear rate ")[1].split(" ")[0])
    assert rate == pytest.approx(1.0 / 39 * 24, rel=0.2)


def test_trend_state_resumes_where_it_stopped(system, tmp_path, capsys):
    from jident_ros.cli.scenario import write_scenario_recording
    from jident_ros.identify.trend import TrendTracker
    from jident_ros.sim.scenarios import wear_scenario
    sc = wear_scenario(system, 16, 3600.0, j1_step_at_window=12)
    half = [dataclasses.replace(sc, cases=sc.cases[s], entry_times_s=sc.entry_times_s[s])
            for s in (slice(0, 8), slice(8, 16))]
    recs = [write_scenario_recording(tmp_path / f"r{k}", system, h, snr_db=30.0, seed=k)
            for k, h in enumerate(half)]
    state = tmp_path / "trend.json"
    common = ["--quiet", "--commissioning-windows", "5"]
    assert jident(["trend", str(recs[0]), "--out", str(tmp_path / "a"), "--state", str(state), *common]) == 0
    assert TrendTracker.load(state).n_windows == 8
    # both recordings, given in reverse order: the first 8 windows are already in the state
    assert jident(["trend", str(recs[1]), str(recs[0]), "--out", str(tmp_path / "b"), "--state", str(state),
                   *common]) == 0
    assert "8 already in the state" in capsys.readouterr().out
    resumed = TrendTracker.load(state)
    assert jident(["trend", str(recs[1]), str(recs[0]), "--out", str(tmp_path / "c"), *common]) == 0
    one_pass = _rows(tmp_path / "c" / "trend.csv")
    assert resumed.n_windows == 16 and len(one_pass) == 16
    assert resumed.config.commissioning_windows == 5
    assert resumed.to_dict()["inertia"]["x"] == pytest.approx(float(one_pass[-1]["inertia_smoothed_kgm2"]), rel=1e-12)
    assert len(_rows(tmp_path / "b" / "trend.csv")) == 8


def test_trend_bad_input_is_one_line(wear40, tmp_path, capsys):
    def err(argv):
        assert jident(argv) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("jident: error:")
        return lines[0]
    assert "nope" in err(["trend", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    bad_state = tmp_path / "s.json"
    bad_state.write_text("{not json")
    assert "--state" in err(["trend", str(wear40), "--out", str(tmp_path / "o"), "--state", str(bad_state), "--quiet"])
    bad_state.write_text(json.dumps({"kind": "other"}))
    assert "kind" in err(["trend", str(wear40), "--out", str(tmp_path / "o"), "--state", str(bad_state), "--quiet"])
    assert "--commissioning-windows" in err(["trend", str(wear40), "--out", str(tmp_path / "o"),
                                             "--commissioning-windows", "1"])
    assert "--j1-step-at" in err(["simulate", "--scenario", "wear", "--windows", "5", "--j1-step-at", "5",
                                  "--out", str(tmp_path / "w")])
    assert "not an empty directory" in err(["simulate", "--scenario", "wear", "--out", str(wear40)])


# --------------------------------------------------------------------------- node pieces

def test_trend_parameters_map_to_the_config():
    from jident_ros.identify.trend import PARAMETER_FIELDS, TrendConfig
    from jident_ros.identify.trend_config import NOT_PARAMETERS
    from jident_ros.parameters import DIAGNOSTIC, TREND
    assert TrendConfig.from_parameters(TREND) == TrendConfig()       # the defaults agree
    assert set(PARAMETER_FIELDS.values()) == {f.name for f in dataclasses.fields(TrendConfig)} - NOT_PARAMETERS
    assert set(TREND) - set(PARAMETER_FIELDS) == {"trend_enabled", "trend_state_file"}
    assert all(DIAGNOSTIC[k] == v for k, v in TREND.items())
    cfg = TrendConfig.from_parameters({"trend_commissioning_windows": 10, "trend_width_warn_m": 0.01,
                                       "trend_inertia_baseline_kgm2": 1.2, "trend_cusum_threshold_sd": 0.0})
    assert (cfg.commissioning_windows, cfg.width_warn_m, cfg.inertia_baseline_kgm2, cfg.cusum_threshold_sd) == \
        (10, 0.01, 1.2, None)
    with pytest.raises(ValueError, match="trend_commissioning_windows"):
        TrendConfig.from_parameters({"trend_commissioning_windows": 2.5})
    with pytest.raises(ValueError, match="trend_drift_alarm_pct"):
        TrendConfig.from_parameters({"trend_drift_alarm_pct": 1.0})
    with pytest.raises(ValueError, match="trend_width_change_detection"):
        TrendConfig.from_parameters({"trend_width_change_detection": 1})


def test_trend_status_levels_messages_and_values():
    from jident_ros.identify.trend import TrendConfig, TrendTracker
    from jident_ros.identify.trend_status import TREND_STATUS_NAME, trend_status
    from jident_ros.research.evaluation.trend_simulation import simulate_series
    assert TREND_STATUS_NAME == "jident_diagnostic: trend"
    s = simulate_series(60, step_at=40, step_pct=6.0, seed=3, width_growth_m_per_window=2e-6)
    tr = TrendTracker(TrendConfig(commissioning_windows=20))
    ups = tr.batch(s.time_s, s.inertia_kgm2, s.inertia_se_kgm2, s.width_m, s.width_se_m)
    level, msg, vals = trend_status(ups[5])
    assert level == 0 and "learning the baseline" in msg and dict(vals)["commissioning"] is True
    level, msg, vals = trend_status(ups[30])
    d = dict(vals)
    assert level == 0 and d["inertia_drift_pct"] != "" and d["wear_rate_m_per_day"] > 0
    assert d["changes_detected"] == 0 and "last_change_quantity" not in d
    fired = next(u for u in ups if u.changes)
    level, msg, vals = trend_status(fired)
    d = dict(vals)
    assert level == 2 and "change +" in msg              # +6 % > the 5 % alarm
    assert d["last_change_quantity"] == "inertia" and d["last_change_size_pct"] == pytest.approx(6.0, abs=1.5)
    skipped = tr.update(float(s.time_s[-1]) + 1.0, float("nan"), 0.01)
    level, msg, vals = trend_status(skipped)
    assert dict(vals)["skipped"] is True and "inertia_kgm2" in dict(vals)["skip_reason"] and "skipped" in msg
    assert level == 2                                    # a skip is at least WARN (here the held change's ERROR)
    tr.count_refused("outside_band")
    u = tr.update(float(s.time_s[-1]) + 2.0, None, None, float(s.width_m[-1]), float(s.width_se_m[-1]),
                  inertia_refused="no_gap")
    d = dict(trend_status(u)[2])
    assert d["inertia_windows_fed"] == 60 and d["inertia_windows_refused"] in ("outside_band 1, no_gap 1",
                                                                               "no_gap 1, outside_band 1")
    assert d["windows_skipped"] == "inertia_kgm2 1" and d["time_segment"] == 0
    assert d["inertia_drift_ci95_low_pct"] < d["inertia_drift_pct"] < d["inertia_drift_ci95_high_pct"]


@pytest.mark.slow
def test_trend_targets_quick_run():
    """python -m jident_ros.research.evaluation.trend_targets --quick (about 20 s)."""
    from jident_ros.research.evaluation.trend_targets import format_table, measure
    r = measure(seed=0, quick=True)
    assert r["detection"]["missed"] == 0 and r["detection"]["median"] <= 3
    assert r["false"]["per_10k"] <= 1.0
    assert 0.9 <= r["steady"]["coverage95"] <= 0.99
    assert "| tracker update" in format_table(r)


# --------------------------------------------------------------------------- what the trend takes of a window

def _diagnosis(status, source, width_method="contact"):
    from types import SimpleNamespace

    from jident_ros.identify.gap import WidthEstimate
    gap = SimpleNamespace(inertia_kgm2=1.3, std_error_kgm2=0.01, ci95_kgm2=(1.28, 1.32))
    return SimpleNamespace(gap=gap, source=source, inertia_kgm2=1.3 if source == "gap" else None, status=status,
                           refused_reason=None if source else "J1 1.3 outside the plausible band", problems=[],
                           message=status, width=WidthEstimate(0.0051, 1e-4, 1500, width_method))


def _offline_window(d, detector="paper", estimate=None):
    from types import SimpleNamespace
    return SimpleNamespace(diagnosis=d, entry_time_s=7.0, window_id=3, true_inertia_kgm2=None, detector=detector,
                           backlash_width_estimate_m=estimate, backlash_width_se_m=None if estimate is None else 3e-6)


def test_an_ambiguous_gap_j1_is_fed_a_refused_one_is_not_and_the_width_source_is_named():
    """Issue 21: the class verdict (one window) does not decide what the trend sees; physics does."""
    from jident_ros.cli.trend import trend_window
    from jident_ros.identify.trend_status import refusal_kind, trend_inputs
    tw = trend_window(_offline_window(_diagnosis("ambiguous", None)), "rec")
    assert (tw.inertia_kgm2, tw.inertia_se_kgm2, tw.skip_reason, tw.refused_kind) == (1.3, 0.01, None, None)
    assert (tw.width_m, tw.width_source) == (0.0051, "gap")
    # refused as implausible: neither its J1 nor its width (likely a false entry), the reason kept and counted
    tw = trend_window(_offline_window(_diagnosis("refused", None)), "rec")
    assert tw.inertia_kgm2 is None and tw.inertia_se_kgm2 is None and tw.width_m is None, tw
    assert tw.skip_reason.startswith("gap J1 1.3 kg m^2 refused (refused") and "plausible" in tw.skip_reason
    assert tw.refused_kind == "outside_band"
    d = _diagnosis("refused", None)
    d.refused_reason = "backlash_width_m: the window's K2 = 0.005 m disagrees with the re-contact"
    assert refusal_kind(d) == "inconsistent"
    d.gap = None
    assert refusal_kind(d) == "input"
    d.status = "undiagnosed"
    assert refusal_kind(d) == "no_gap" and trend_inputs(d).width_m == 0.0051   # no gap: the width still counts
    tw = trend_window(_offline_window(_diagnosis("deviating", "gap")), "rec")
    assert (tw.inertia_kgm2, tw.inertia_se_kgm2, tw.inertia_ci_low_kgm2, tw.skip_reason) == (1.3, 0.01, 1.28, None)
    # a flank-detector window: its flank-to-flank K2 wins over the gap estimator's width, with its se (floored)
    tw = trend_window(_offline_window(_diagnosis("deviating", "gap"), "flank", 0.00482), "rec", width_se_floor_m=5e-6)
    assert (tw.width_m, tw.width_se_m, tw.width_source) == (0.00482, 5e-6, "flank")
    # no flank estimate in a flank window (NaN): the gap width, said so
    from types import SimpleNamespace
    win = SimpleNamespace(detector="flank", backlash_width_estimate_m=math.nan, backlash_width_se_m=math.nan)
    assert trend_inputs(_diagnosis("deviating", "gap"), 0.0, win).width_source == "gap"
    # the diagnosis' own flank width (diagnose_window with the detector's estimate) counts as flank
    assert trend_inputs(_diagnosis("deviating", "gap", "flank")).width_source == "flank"


def test_jident_trend_flank_and_paper_detectors_and_parallel_jobs(wear40, system):
    from jident_ros.cli.trend import run_trend
    one = run_trend([wear40, wear40], system=system, jobs=1)
    two = run_trend([wear40, wear40], system=system, jobs=2)
    assert [(w.time_s, w.inertia_kgm2, w.width_m) for w in one.windows] == \
        [(w.time_s, w.inertia_kgm2, w.width_m) for w in two.windows]
    assert len(one.windows) == 80 and one.recordings == two.recordings
    flank = run_trend([wear40], system=system)
    truth = 0.0025 + 0.001 * np.arange(40) / 39
    w = np.array([x.width_m for x in flank.windows])
    assert {x.width_source for x in flank.windows} == {"flank"}
    assert np.max(np.abs(w / truth - 1)) < 0.005                     # the flank estimate: < 0.5 % off
    paper = run_trend([wear40], system=system, detector="paper")
    wp = np.array([x.width_m for x in paper.windows])
    assert {x.width_source for x in paper.windows} == {"gap"} and np.max(np.abs(wp / truth - 1)) > 0.01
    # the wear rate (1 mm in 39 h) from the flank estimates within 2 %
    assert flank.updates[-1].wear_rate_m_per_s == pytest.approx(0.001 / 39 / 3600, rel=0.02)


# --------------------------------------------------------------------------- fleet (issue 21)

def test_fleet_groups_by_namespace_and_by_mapping_one_trend_per_drive(tmp_path, system, capsys):
    """Three recordings of two drives (namespaces /press1 and /press2; press1's split in two recordings, the
    second one's J1 stepped): one trend per drive, one row each, the grouping by a --drive-id file equal to it."""
    from jident_ros.cli.fleet import FLEET_COLUMNS, group_by_drive, recording_namespaces
    from jident_ros.cli.scenario import write_scenario_recording
    from jident_ros.sim.scenarios import wear_scenario
    sc = wear_scenario(system, 16, 3600.0, 0.0025, 0.0030, None, None, 10, -5.0, None)
    first = dataclasses.replace(sc, cases=sc.cases[:8], entry_times_s=sc.entry_times_s[:8])
    second = dataclasses.replace(sc, cases=sc.cases[8:], entry_times_s=sc.entry_times_s[8:])
    steady = wear_scenario(system, 8, 3600.0, 0.0025, 0.0030, None, None, None, 0.0, None)
    fleet = tmp_path / "fleet"
    write_scenario_recording(fleet / "a" / "r1", system, first, snr_db=30.0, namespace="/press1")
    write_scenario_recording(fleet / "b" / "r2", system, second, snr_db=30.0, seed=1, namespace="/press1")
    write_scenario_recording(fleet / "a" / "r3", system, steady, snr_db=30.0, seed=2, namespace="/press2")
    assert recording_namespaces(fleet / "a" / "r3") == {"press2": "/press2/drive/signals"}
    out = tmp_path / "out"
    assert jident(["trend", str(fleet), "--fleet", "--out", str(out), "--jobs", "2", "--quiet"]) == 0
    rows = list(csv.DictReader(open(out / "fleet.csv")))
    assert list(rows[0]) == list(FLEET_COLUMNS)
    by = {r["drive"]: r for r in rows}
    assert set(by) == {"press1", "press2"}
    assert (by["press1"]["recordings"], by["press1"]["windows"], by["press2"]["windows"]) == ("2", "16", "8")
    assert int(by["press1"]["changes"]) >= 1 and by["press1"]["last_change"].startswith("-")   # the -5 % step
    assert by["press2"]["changes"] == "0" and "change" not in by["press2"]["message"]   # (WARN: the wear)
    assert float(by["press1"]["inertia_drift_pct"]) < -3.0 < float(by["press2"]["inertia_drift_pct"])
    assert (out / "fleet.png").stat().st_size > 0 and (out / "drives" / "press2" / "trend.csv").exists()
    assert "press1" in capsys.readouterr().out
    # the same grouping from a mapping file; a recording it does not name is one clear line
    mapping = tmp_path / "drives.csv"
    mapping.write_text("# recording,drive\nfleet/a/r1,press1\nfleet/b/r2,press1\nfleet/a/r3,press2\n")
    recs = [fleet / "a" / "r1", fleet / "b" / "r2", fleet / "a" / "r3"]
    assert {k: [r for r, _ in v] for k, v in group_by_drive(recs, str(mapping)).items()} == \
        {k: [r for r, _ in v] for k, v in group_by_drive(recs).items()}
    mapping.write_text("fleet/a/r1,press1\n")
    assert jident(["trend", str(fleet), "--fleet", "--drive-id", str(mapping), "--out", str(out), "--quiet"]) == 2
    assert "no drive for recording" in capsys.readouterr().err


@pytest.mark.slow
def test_hidden_scenario_rebuilt_step_flagged_within_5_recordings_none_before(tmp_path, system):
    """Issue 21's scenario rebuilt with our writers: one drive recorded hourly for 40 h (one bag each), raw 2^16
    encoder angles, the drive/signals topic only (no truth topics), 30 dB, K2 2.5 -> 5 mm, J1 -2.5 % from
    recording 25 (index 24).  ~3 min."""
    from jident_ros.cli.trend_run import run_trend
    from jident_ros.research.evaluation.raw_scenario import write_raw_scenario
    from jident_ros.sim.scenarios import wear_scenario
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    sc = wear_scenario(system, 40, 3600.0, 0.0025, 0.005, None, None, 24, -2.5, None)
    paths = write_raw_scenario(tmp_path / "rec", system, sc, snr_db=30.0, channels=DEFAULT_CHANNELS)
    run = run_trend(paths, system=system, jobs=2)
    changes = [c for c in run.tracker.changes if c.quantity == "inertia"]
    step_t = sc.entry_times_s[24]
    assert changes and all(c.time_s >= step_t for c in changes), changes               # none before the step
    first = changes[0]
    assert first.sign == -1 and first.class_pct == -2.5
    assert sum(1 for w in run.windows if step_t <= w.time_s <= first.time_s) <= 5       # within 5 recordings
    widths = [u.width_m for u in run.updates if u.width_m is not None]
    assert widths[-1] / widths[0] == pytest.approx(2.0, rel=0.1)                        # the width trend as before


def test_the_drive_monitor_feeds_an_ambiguous_j1_and_counts_a_refused_one():
    """The nodes' path (identify.monitor.DriveMonitor): an ambiguous window's J1 reaches the tracker; a window
    refused as implausible gives no update and is counted by its reason."""
    from types import SimpleNamespace

    from jident_ros.identify.monitor import DriveMonitor
    from jident_ros.identify.trend import TrendConfig, TrendTracker
    diagnoses = iter([_diagnosis("ambiguous", None), _diagnosis("refused", None)])
    diagnoser = SimpleNamespace(diagnose=lambda win, **kw: next(diagnoses))
    mon = DriveMonitor(None, diagnoser, TrendTracker(TrendConfig(commissioning_windows=3)))
    win = SimpleNamespace(entry_time_s=10.0, detector="paper", backlash_width_estimate_m=None,
                          backlash_width_se_m=None)
    r = mon.window(win)
    assert r.trend is not None and r.trend.inertia_kgm2 == 1.3 and r.trend.inertia_windows_fed == 1
    r = mon.window(SimpleNamespace(**{**vars(win), "entry_time_s": 20.0}))
    assert r.trend is None and mon.tracker.inertia_refused == {"outside_band": 1}


def test_a_second_window_of_one_traversal_goes_to_the_trend_once():
    """An early entry whose gap fit found the traversal's rows, then the traversal's own window over the same rows
    (DOL draw d16-12): the trend takes the traversal once and counts the second window as 'same_traversal'; a window
    whose gap fit reads later rows goes in again, and a window without gap fit rows is not compared."""
    from types import SimpleNamespace

    import numpy as np

    from jident_ros.identify.monitor import DriveMonitor
    from jident_ros.identify.trend import TrendConfig, TrendTracker
    from jident_ros.identify.trend_status import REFUSAL_KINDS, SAME_TRAVERSAL
    from jident_ros.stream.layout import Window
    assert SAME_TRAVERSAL in REFUSAL_KINDS

    def window(wid, t0, fit):
        d = _diagnosis("ambiguous", None)
        d.gap.fit_start, d.gap.fit_end = fit
        t = t0 + np.arange(200) * 5e-4
        win = Window(np.column_stack([t, np.zeros(200)]), ("t", "alpha1"), 48, float(t[48]), float("nan"), 0.1, 5e-4,
                     window_id=wid)
        return win, d

    wins = [window(1, 0.0, (92, 190)), window(2, 0.025, (42, 140)), window(3, 0.2, (48, 150)),
            window(4, 0.23, (-1, -1))]
    diagnoses = iter([d for _, d in wins])
    mon = DriveMonitor(None, SimpleNamespace(diagnose=lambda win, **kw: next(diagnoses)),
                       TrendTracker(TrendConfig(commissioning_windows=3)))
    r = [mon.window(w) for w, _ in wins]
    assert [x.same_traversal_as for x in r] == [None, 1, None, None]
    assert r[1].trend is None and mon.tracker.inertia_refused == {SAME_TRAVERSAL: 1}
    assert r[0].trend.inertia_windows_fed == 1 and r[2].trend.inertia_windows_fed == 2
    assert r[3].trend.inertia_windows_fed == 3       # no fit rows: nothing to compare, fed


def test_jident_trend_takes_a_second_window_of_one_traversal_once_as_the_node_does():
    """cli.trend_run.trend_window (jident trend, replay): a window that offline's DriveMonitor marked as reading the
    traversal of the window before gives the tracker no J1 and no width, counted as 'same_traversal' (replay = live)."""
    from dataclasses import replace

    from jident_ros.cli.offline import OfflineWindow
    from jident_ros.cli.trend_run import trend_window
    from jident_ros.identify.trend_status import SAME_TRAVERSAL
    ow = OfflineWindow(4, 7.0, 0.005, None, _diagnosis("ambiguous", None), 0.0051, 3e-6, "flank")
    assert trend_window(ow, "rec").inertia_kgm2 == 1.3
    tw = trend_window(replace(ow, same_traversal_as=3), "rec")
    assert tw.inertia_kgm2 is None and tw.width_m is None and tw.refused_kind == SAME_TRAVERSAL
    assert "window 3" in tw.skip_reason


def test_the_torque_accuracy_term_is_left_out_of_the_relative_test_and_given_to_the_absolute_j1():
    """A scale error of the drive's torque estimate moves every J1 alike: the gap's 'torque_accuracy' term is
    taken out of the se the trend tests the drift with; the drive's declared torque_accuracy (a uniform bound)
    becomes the absolute J1's term."""
    import math as m

    from jident_ros.identify.trend import TrendConfig
    from jident_ros.identify.trend_status import trend_inputs
    d = _diagnosis("ambiguous", None)
    d.gap.std_error_terms = (("fit", 0.006), ("torque_accuracy", 0.008))
    d.gap.std_error_kgm2 = 0.01
    assert trend_inputs(d).inertia_se_kgm2 == pytest.approx(0.006)
    d.gap.std_error_terms = ()
    assert trend_inputs(d).inertia_se_kgm2 == pytest.approx(0.01)
    # the other constants of the drive (the torque estimate's bounded offset and lag, the Coulomb band) go out too;
    # the window's own terms (statistical, torque noise, change points) stay
    d.gap.std_error_terms = (("statistical", 0.003), ("torque_noise", 0.004), ("torque_offset", 0.005),
                             ("torque_lag", 0.002), ("coulomb_band", 0.001), ("torque_accuracy", 0.002))
    d.gap.std_error_kgm2 = m.sqrt(0.003 ** 2 + 0.004 ** 2 + 0.005 ** 2 + 0.002 ** 2 + 0.001 ** 2 + 0.002 ** 2)
    assert trend_inputs(d).inertia_se_kgm2 == pytest.approx(0.005)
    cfg = TrendConfig.from_parameters({"torque_accuracy": 0.02})
    assert cfg.torque_accuracy_pct == pytest.approx(2.0 / m.sqrt(3.0))
    assert TrendConfig.from_parameters({"torque_accuracy": 0.02, "trend_torque_accuracy_pct": 1.5}).torque_accuracy_pct \
        == 1.5


def test_a_trend_fit_s_own_interval_is_written_beside_its_j1():
    """Where the trend reads another fit than the published one (GapEstimate.trend_fit), trend.csv's interval is that
    fit's (J1 ± 1.96 se), not the published one, which belongs to another J1."""
    from jident_ros.cli.trend import trend_window
    d = _diagnosis("deviating", "gap")
    d.gap.trend_fit = (1.25, 0.02, ())
    tw = trend_window(_offline_window(d), "rec")
    assert tw.inertia_kgm2 == pytest.approx(1.25)
    assert (tw.inertia_ci_low_kgm2, tw.inertia_ci_high_kgm2) == (pytest.approx(1.2108), pytest.approx(1.2892))
