"""Raw-encoder inputs of the entry detectors (issue 20 item 4, issue 24's spike): wrapped positions, encoder
spikes, same-flank torque changes, a missing K2, the default detector on drive/signals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.research.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector
from jident_ros.stream.detector import BacklashDetector, stream_batches
from jident_ros.stream.flank import FlankDetector


@pytest.fixture(scope="module")
def system():
    return load_system_config()


def wrap(x):
    """A continuous joint's position as ROS reports it, in [-pi, pi)."""
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi


def _wrapped(rec):
    data = rec.data.copy()
    for c in ("alpha1", "alpha2"):
        j = rec.channels.index(c)
        data[:, j] = wrap(data[:, j])
    return data


@pytest.mark.parametrize("batch_size", [50, 1, 7])
def test_wrapped_positions_give_the_windows_of_the_unwrapped_ones(system, batch_size):
    """Every entry found on wrapped positions, at the same sample, with the same K2 (batch size 1: a wrap at
    every batch boundary); the windows carry the unwrapped angles (whole turns apart from the raw ones)."""
    recs = raw_recordings(system, (1.16, 0.957), (0.0025, 0.01), steady_s=0.5, seed=3)
    for rec in recs:
        ref = [e.window for e in run_detector(flank_detector(system), rec, batch_size) if e.kind == "window"]
        det = flank_detector(system)
        evs = []
        for b in stream_batches(_wrapped(rec), batch_size):
            evs += det.push(b, rec.channels)
        got = [e.window for e in evs + det.finish() if e.kind == "window"]
        assert det.wraps_undone > 10
        assert len(got) == len(ref) == 1
        assert got[0].entry_time_s == ref[0].entry_time_s == rec.data[rec.entry_row, 0]
        assert got[0].backlash_width_estimate_m == pytest.approx(ref[0].backlash_width_estimate_m, rel=1e-9)
        for c in ("alpha1", "alpha2"):
            turns = (got[0].column(c) - ref[0].column(c)) / (2 * math.pi)
            np.testing.assert_allclose(turns, np.round(turns[0]), atol=1e-9)   # one whole-turn shift, no jump


@pytest.mark.parametrize("gear", [1.0, 3.0])
def test_a_load_encoder_counting_the_other_way_takes_a_negative_gear_ratio(system, gear):
    """A reversing gear or an encoder mounted facing the motor's: alpha2 counts the other way.  With N < 0 every
    window is the one of the encoder counting the same way with |N| (same entry, same K2); with |N| the flank
    detector finds nothing and says what to set.  Parameters, CLI and the detector accept any non-zero N."""
    from jident_ros.nodes.params import ParameterError, coerce
    from jident_ros.parameters import WINDOWING_PARAMS
    (rec,) = raw_recordings(system, (1.16,), (0.005,), steady_s=0.5, seed=3)
    same = rec.data.copy()
    same[:, rec.channels.index("alpha2")] /= gear
    flipped = same.copy()
    flipped[:, rec.channels.index("alpha2")] *= -1.0

    def windows(data, n):
        det = flank_detector(system, gear_ratio=n)
        evs = []
        for b in stream_batches(data, 50):
            evs += det.push(b, rec.channels)
        return det, [e.window for e in evs + det.finish() if e.kind == "window"]
    _, ref = windows(same, gear)
    _, got = windows(flipped, -gear)
    assert len(ref) == len(got) == 1 and got[0].entry_time_s == ref[0].entry_time_s
    assert got[0].backlash_width_estimate_m == pytest.approx(ref[0].backlash_width_estimate_m, rel=1e-9)
    det, none = windows(flipped, gear)
    assert not none and "negative when the load encoder counts the other way" in det.no_entry_reason()
    p = WINDOWING_PARAMS["gear_ratio"]
    assert coerce("gear_ratio", -gear, p) == -gear and "!= 0" in p.range_text()
    with pytest.raises(ParameterError, match="gear_ratio: must be .* != 0, got 0"):
        coerce("gear_ratio", 0.0, p)


def test_without_unwrapping_wrapped_positions_are_not_found(system):
    """The test above depends on the unwrapping (wrapped positions and unwrap_angles off: not every entry)."""
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.5, seed=3)[0]
    s = system.sampling
    det = FlankDetector(system.load.wheel_radius_m, s.sample_period_s, unwrap_angles=False,
                        nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2, encoder_counts_per_rev=65536)
    evs = []
    for b in stream_batches(_wrapped(rec), 50):
        evs += det.push(b, rec.channels)
    wins = [e.window for e in evs if e.kind == "window"]
    assert [w.entry_time_s for w in wins] != [rec.data[rec.entry_row, 0]]


def test_unwrap_continues_across_batches_and_restarts_after_a_reset():
    ts, w = 5e-4, 400.0
    t = 1.0 + np.arange(3000) * ts
    a = 0.3 + w * (t - 1.0)
    data = np.column_stack([t, wrap(a), wrap(0.2 * a)])
    det = BacklashDetector(0.005, 0.1, ts, channels=("t", "alpha1", "alpha2"))
    x, problem = det._validate(data[:1000], ("t", "alpha1", "alpha2"))
    y, _ = det._validate(data[1000:1001], ("t", "alpha1", "alpha2"))     # the next sample alone
    assert problem is None
    np.testing.assert_allclose(x[:, 1], a[:1000], atol=1e-9)
    np.testing.assert_allclose(y[:, 1], a[1000:1001], atol=1e-9)
    np.testing.assert_allclose(x[:, 2], 0.2 * a[:1000], atol=1e-9)
    det.reset()                                                         # continuity lost: start again
    z, _ = det._validate(data[2000:2010], ("t", "alpha1", "alpha2"))
    np.testing.assert_allclose(z[0, 1], wrap(a[2000]), atol=1e-9)


def _steady_then_entry(spikes=(), n=3000, ts=5e-4, w=150.0, entry=1500, jump=0.03):
    """t, alpha1, alpha2 turning steadily on a flank, the load encoder jumping by ``jump`` at ``entry`` (a
    slip: the clutch leaves its flank), spikes {(row, length): rad} added to alpha1."""
    t = 1.0 + np.arange(n) * ts
    a1 = 3.0 + w * (t - 1.0)
    a2 = 1.0 + w * (t - 1.0)
    a2[entry:] += jump
    for (row, length), size in dict(spikes).items():
        a1[row:row + length] += size
    return np.column_stack([t, a1, a2]), ("t", "alpha1", "alpha2")


@pytest.mark.parametrize("batch_size", [50, 1, 2, 7])
@pytest.mark.parametrize("length", [1, 2])
def test_an_encoder_spike_is_not_an_entry_and_does_not_swallow_the_real_one(batch_size, length):
    """issue 24: a spike 0.25 s before the real entry opened a window that swallowed it.  A spike of 1 or 2
    samples (either sign) is counted, no window; the real entry gets its window on its own sample."""
    for size in (0.2, -0.05):
        data, ch = _steady_then_entry({(1000, length): size})
        det = FlankDetector(0.1, 5e-4, channels=ch)
        evs = [e for b in stream_batches(data, batch_size) for e in det.push(b, ch)] + det.finish()
        starts = [e.window.entry_time_s for e in evs if e.window is not None]
        assert starts == [data[1500, 0]], (size, starts)
        assert det.spikes == 1 and det.flank_shifts == 0


def test_three_samples_beyond_the_threshold_are_a_departure():
    """The spike rule's bound: confirm_samples (3) samples in a row off the flank are an entry."""
    data, ch = _steady_then_entry({(1000, 3): 0.2})
    det = FlankDetector(0.1, 5e-4, channels=ch, min_travel_rad=0.0)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert [e.window.entry_time_s for e in evs if e.window is not None][0] == data[1000, 0]
    assert det.spikes == 0


def _twist_change(size, n=3000, ts=5e-4, w=150.0, at=1000, tau_samples=6.0):
    """The coupling twisting by ``size`` rad more (a torque step on the same flank: a speed step up, a load
    change), exponentially over ``tau_samples``."""
    t = 1.0 + np.arange(n) * ts
    a1 = 3.0 + w * (t - 1.0)
    a2 = 1.0 + w * (t - 1.0)
    k = np.arange(n) - at
    a1 += np.where(k >= 0, size * (1.0 - np.exp(-np.maximum(k, 0) / tau_samples)), 0.0)
    return np.column_stack([t, a1, a2]), ("t", "alpha1", "alpha2")


@pytest.mark.parametrize("size", [0.0035, -0.0035, 0.0045])
def test_a_same_flank_torque_change_is_not_an_entry(size):
    """More (or less) torque on the same flank moves delta by the coupling's twist change (3.4 mrad on the second
    drive's speed step up 100 -> 120 rad/s): no window, counted as a flank shift; the detector then follows the
    new flank level and still finds the next real entry."""
    data, ch = _twist_change(size)
    data[2000:, 2] += 0.03                        # a real entry later
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    starts = [e.window.entry_time_s for e in evs if e.window is not None]
    assert starts == [data[2000, 0]] and det.flank_shifts == 1


def test_a_twist_change_beyond_min_travel_is_an_entry():
    """The bound of the rule: an excursion of more than min_travel_rad (5 mrad) is a backlash entry."""
    data, ch = _twist_change(0.006)
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert len([e for e in evs if e.window is not None]) == 1 and det.flank_shifts == 0


def test_speed_step_up_on_the_second_drive_is_not_an_entry():
    """The second drive model (docs/second_drive.md) under a speed step up, 100 -> 120 rad/s: the PI drives the
    torque to its limit on the same flank; raw 2^16 encoders with offsets: no window."""
    from jident_ros.research.second_drive.model import Drive, DriveParams, simulate
    p = DriveParams()
    r = simulate(Drive(p, [1.16], 100.0, [0.0625], steps=[(0.25, 20.0)]), 1.2)
    q = 2 * math.pi / 65536
    a1 = np.floor((r.alpha1[:, 0] + 1.3) / q) * q
    a2 = np.floor((r.alpha2[:, 0] + 0.4) / q) * q
    ts = 5e-4
    data = np.column_stack([1.0 + np.arange(a1.size) * ts, a1, a2, r.m_el[:, 0]])
    ch = ("t", "alpha1", "alpha2", "m_el")
    det = FlankDetector(0.08, ts, channels=ch, nominal_inertia_kgm2=1.16, encoder_counts_per_rev=65536)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert evs == [] and det.flank_shifts >= 1


def test_a_glitch_that_swallows_a_real_entry_is_counted():
    """A glitch longer than confirm_samples (5 samples) is taken for an entry; the real entry 100 samples later
    lies inside its window: the window goes out flagged, and the lost entry is counted (swallowed_entry)."""
    data, ch = _steady_then_entry({(1400, 5): 0.2}, n=4000)
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    wins = [e for e in evs if e.kind == "window"]
    assert len(wins) == 1 and wins[0].window.entry_time_s == data[1400, 0]
    assert det.counts["swallowed_entry"] == 1 and "swallowed" in wins[0].detail
    data, ch = _steady_then_entry({})                          # a real entry alone: nothing counted
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert det.counts["swallowed_entry"] == 0


def _diagnose(system, w):
    from jident_ros.config import load_method_config
    from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig
    return Diagnoser(system, load_method_config(), DiagnosisConfig(image_method=False)).diagnose(w)


def test_a_missing_k2_never_blocks_the_gap_j1(system, monkeypatch):
    """With FLANK_WINDOWS_WITHOUT_K2 on (the default since the gap fit's intervals are honest without a1), a flank
    window without a K2 estimate (a one-sided excursion: the motor left its flank and came back) is diagnosed from
    its gap like any other: not refused 'backlash_width_m: ... got nan'.  Off it is refused."""
    import dataclasses

    from jident_ros.identify import window_args as diagnosis  # detector_arguments' home (stop 34)
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=4)[0]
    w = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"][0]
    ref = _diagnose(system, w)
    assert ref.diagnosed and ref.inertia_kgm2 == pytest.approx(1.16, rel=0.02)
    no_k2 = dataclasses.replace(w, backlash_width_m=math.nan, backlash_width_estimate_m=math.nan,
                                backlash_width_se_m=math.nan)
    assert diagnosis.FLANK_WINDOWS_WITHOUT_K2 is True
    monkeypatch.setattr(diagnosis, "FLANK_WINDOWS_WITHOUT_K2", False)
    assert not _diagnose(system, no_k2).diagnosed
    monkeypatch.setattr(diagnosis, "FLANK_WINDOWS_WITHOUT_K2", True)
    d = _diagnose(system, no_k2)
    assert d.diagnosed and d.inertia_kgm2 == ref.inertia_kgm2, d.message
    assert "backlash_width_estimate_m" not in d.value_dict()          # no K2 read off raw angles instead


def test_a_shallow_gap_window_gets_its_entry_and_k2_but_no_j1(system):
    """A window the flank detector flags as a shallow gap (layout.FLAG_SHALLOW_GAP: a slip drop's few samples past the
    coupling's zero twist, round 18) is diagnosed without a gap fit: no J1, the reason says why (DOL
    draws set 6's d6-12, a 4-sample gap, published J1 +19 % outside its intervals when it was fitted)."""
    import dataclasses

    from jident_ros.identify.diagnosis import SHALLOW_GAP_REASON, WindowInput
    from jident_ros.identify.gap import resolution_limited
    from jident_ros.stream.layout import FLAG_SHALLOW_GAP, flag_names
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=4)[0]
    w = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"][0]
    assert _diagnose(system, w).inertia_kgm2 == pytest.approx(1.16, rel=0.02)
    flagged = dataclasses.replace(w, flags=w.flags | FLAG_SHALLOW_GAP)
    assert "shallow_gap" in flag_names(flagged.flags) and WindowInput.from_window(flagged).shallow_gap
    d = _diagnose(system, flagged)
    assert d.inertia_kgm2 is None and d.gap is None
    assert SHALLOW_GAP_REASON in d.message or SHALLOW_GAP_REASON in (d.refused_reason or ""), d.message
    assert resolution_limited(SHALLOW_GAP_REASON) and d.level_name == "OK", d.message   # this window's limit: no WARN
    assert math.isfinite(flagged.backlash_width_estimate_m)              # the window's K2 (its detector's) stays


def test_raw_angles_are_never_read_as_zone_centred(system):
    """A flank window's K2 is its detector's (offset-free relative angle with N); the diagnosis does not read
    r|alpha1 - alpha2| off raw encoder angles (issue 20: 'r|alpha1 - alpha2| = 25.15 m', 133 of 210 windows)."""
    import dataclasses
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=4)[0]
    w = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"][0]
    for win in (w, dataclasses.replace(w, recontact_index=-1)):      # also when the gap fit cannot start
        d = _diagnose(system, win)
        vals = d.value_dict()
        assert "recontact_width_m" not in vals and "width_consistent" not in vals
        assert "alpha1 - alpha2|" not in d.message + "; ".join(d.problems)


def _signals_bag(tmp_path, rec, name="raw"):
    from jident_ros.research.second_drive.record import write_signals
    sig = {c: rec.data[:, j] for j, c in enumerate(rec.channels)}
    path = tmp_path / name
    write_signals(path, sig, channels=rec.channels)
    return path


def test_the_default_detector_finds_entries_in_drive_signals_with_raw_angles(system, tmp_path):
    """issue 20: on drive/signals bags with raw encoder angles (no K2 topic) the default detector found nothing,
    'no backlash entry found' with no hint.  Now auto runs the flank detector there; the paper detector, when
    asked for, says why it finds nothing and what to set; a wrong gear ratio is named."""
    from jident_ros.cli.offline import diagnose_recording
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.5, seed=6)[0]
    bag = _signals_bag(tmp_path, rec)
    res = diagnose_recording(bag, system=system, image_method=False)
    assert res.detector == "flank" and len(res.windows) == 1 and res.backlash_width_source == "estimated"
    assert res.windows[0].entry_time_s == rec.data[rec.entry_row, 0]
    paper = diagnose_recording(bag, system=system, image_method=False, detector="paper")
    assert not paper.windows and "never inside the zone" in paper.no_entry_hint
    assert "--detector flank" in paper.no_entry_hint
    wrong = diagnose_recording(bag, system=system, image_method=False, gear_ratio=2.0)
    assert not wrong.windows and "gear_ratio" in wrong.no_entry_hint and "N = 2" in wrong.no_entry_hint


def test_the_flank_detector_says_why_it_found_nothing():
    data, ch = _steady_then_entry({}, entry=10**6)                  # steady running only
    det = FlankDetector(0.1, 5e-4, channels=ch)
    for b in stream_batches(data, 50):
        det.push(b, ch)
    assert "never left it" in det.no_entry_reason()
    data, ch = _twist_change(0.0035)
    det = FlankDetector(0.1, 5e-4, channels=ch)
    for b in stream_batches(data, 50):
        det.push(b, ch)
    assert "1 same-flank torque change" in det.no_entry_reason()


def test_more_torque_on_the_same_flank_and_back_is_not_an_entry_with_m_el():
    """The vector drive's speed step up: the torque limit twists the coupling 5.8 mrad deeper (more than
    min_travel_rad), then back.  With m_el the detector knows which way is deeper into the flank (with the torque
    it carries): that move needs 4 x min_travel_rad, and the move back counts its travel beyond the level before
    the step: no window, 2 flank shifts; a real entry later is still found, and so is a real entry in the
    'deeper' direction (a traversal is far longer than 20 mrad)."""
    data, ch = _twist_change(0.008, n=6000, at=1000)
    data[3000:, 1] -= 0.008 * (1.0 - np.exp(-np.arange(3000) / 6.0))     # back to the first level
    m_el = np.where((np.arange(6000) >= 1000) & (np.arange(6000) < 3000), 300.0, 100.0)
    data = np.column_stack([data, m_el])
    ch = ch + ("m_el",)
    data[5000:, 2] += 0.05                                                  # a real entry (delta decreases)
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert [e.window.entry_time_s for e in evs if e.window is not None] == [data[5000, 0]]
    assert det.flank_shifts == 2
    data[5000:, 2] -= 0.1                                                   # the entry the other way instead
    det = FlankDetector(0.1, 5e-4, channels=ch)
    evs = [e for b in stream_batches(data, 50) for e in det.push(b, ch)] + det.finish()
    assert [e.window.entry_time_s for e in evs if e.window is not None] == [data[5000, 0]]
    without = FlankDetector(0.1, 5e-4, channels=ch[:3])                   # without m_el: 8 mrad is an entry
    evs = [e for b in stream_batches(data[:, :3], 50) for e in without.push(b, ch[:3])] + without.finish()
    assert len([e for e in evs if e.window is not None or e.reason == "cut_off"]) >= 2


def test_one_count_of_a_coarse_encoder_at_the_entry_is_not_a_slip():
    """2^13 counts: around a slow departure the steps of delta are 0 and the entry's is one count; that is not
    the slip scenario's jump (the vector drive's K2 was 96 % off): the traversal's K2 is measured."""
    from jident_ros.stream.flank_delta import estimate_width
    q = 2 * math.pi / 8192
    n, e, g, theta, r = 400, 48, 148, 0.05, 0.1
    k = np.arange(n) - e
    delta = np.where(k < 0, theta, theta - 2 * theta * np.clip(k / (g - e), 0, 1) ** 2)
    a2 = np.full(n, 1.0)                                             # the load at rest: delta moves by counts
    a1 = np.floor((a2 + delta + 0.3) / q) * q
    a2q = np.floor(a2 / q) * q
    d = a1 - a2q
    first = e + int(np.argmax(np.abs(d[e:] - d[e - 1]) > 0.5 * q))        # the first sample a count off the flank
    assert abs(abs(d[first] - d[first - 1]) - q) < 1e-9 and abs(d[first + 1] - d[first]) < 1e-12  # 1 count, still
    res = estimate_width({"alpha1": a1, "alpha2": a2q}, first, r, 5e-4, recontact=g, angle_quantum_rad=q)
    assert res.how == "traversal" and res.width_m == pytest.approx(theta * r, rel=0.05)


def test_jident_info_and_diagnose_on_a_drive_of_another_size(system, tmp_path, capsys):
    """issue 20 item 5: `jident info` with another nominal J1 failed ('load torque of case 0 exceeds the motor's
    pull-out torque'); every window repeated 'pattern library could not be built'.  Now info works (rc 0, says
    why the simulator cannot run the drive), and a drive without a library says once that the image method is
    off and how to build one; the windows carry no library error."""
    from pathlib import Path

    from jident_ros.cli.main import main
    from jident_ros.cli.offline import diagnose_samples
    from jident_ros.config import load_system_config
    from jident_ros.research.second_drive.record import write_csv
    profile = Path(__file__).resolve().parents[1] / "docs" / "examples" / "profiles" / "small_drive.yaml"
    assert main(["info", "--config", str(profile)]) == 0
    out = capsys.readouterr().out
    assert "nominal_inertia_kgm2 = 0.03" in out and "image method is off" in out and "cannot run this drive" in out
    small = load_system_config(profile)
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=7)[0]
    path = tmp_path / "small.csv"
    write_csv(path, {c: rec.data[:, j] for j, c in enumerate(rec.channels)})
    lines = []
    res = diagnose_samples(path, system=small, log=lines.append, library_path=str(tmp_path / "none.npz"))
    assert len(res.windows) == 1
    assert sum("image method off" in t for t in lines) == 1 and sum("image method off" in t for t in res.notes) == 1
    d = res.windows[0].diagnosis
    assert "pattern library" not in d.message and d.value_dict()["image_method"].startswith("off")
