"""The dynamics detector (stream/dynamics.py): entries from the load-torque step, no load encoder, no K2."""
import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.identify.diagnosis import ENTRY_UNCERTAINTY_WITHOUT_A1, detector_arguments
from jident_ros.identify.gap import NoGapError, estimate_inertia, speed_fit
from jident_ros.research.evaluation.raw_inputs import raw_recordings, run_detector, without
from jident_ros.stream.dynamics import DynamicsDetector, angle_entry
from jident_ros.stream.layout import Window

SYSTEM = load_system_config()
R = SYSTEM.load.wheel_radius_m
TS = SYSTEM.sampling.sample_period_s
J_NOM = SYSTEM.motor.nominal_inertia_kgm2
LOAD_SENSORS = ("alpha2", "omega2", "a2", "v2")


@pytest.fixture(scope="module")
def recordings():
    out = {}
    for snr in (None, 30.0):
        for direction in ("forward", "reverse"):
            out[(snr, direction)] = raw_recordings(SYSTEM, inertias=[1.16, 0.957], widths=[0.0025, 0.01], snr_db=snr,
                                                   steady_s=2.0, direction=direction, seed=7)
    return out


def detector(channels, **kw):
    return DynamicsDetector(R, TS, channels=channels, nominal_inertia_kgm2=J_NOM, **kw)


def offsets(rec, batch_size=50):
    det = detector(rec.channels)
    wins = [e.window for e in run_detector(det, rec, batch_size) if e.kind == "window"]
    t_entry = rec.data[rec.entry_row, 0]
    return [int(round((w.entry_time_s - t_entry) / TS)) for w in wins], wins, det


@pytest.mark.parametrize("snr", [None, 30.0])
@pytest.mark.parametrize("direction", ["forward", "reverse"])
def test_entry_on_the_sample_from_a1_without_the_load_encoder(recordings, snr, direction):
    for rec in recordings[(snr, direction)]:
        rec = without(rec, LOAD_SENSORS)
        offs, wins, det = offsets(rec)
        assert offs == [0], (rec.inertia_kgm2, rec.backlash_width_m, offs)
        w = wins[0]
        assert w.detector == "dynamics" and "alpha2" not in w.channels
        assert w.recontact_index > w.entry_index            # the gap's end from the dynamics
        g = estimate_inertia(w.as_dict(), w.entry_index, w.backlash_width_m, R, TS,
                             recontact_index=w.recontact_index)
        assert abs(g.inertia_kgm2 / rec.inertia_kgm2 - 1) < 0.02
        assert not any(det.counts.values())


def test_no_entry_in_a_steady_stretch_at_30_db(recordings):
    rec = without(recordings[(30.0, "forward")][0], LOAD_SENSORS)
    steady = rec.data[:rec.steady_rows]
    det = detector(rec.channels)
    events = []
    for s in range(0, steady.shape[0], 50):
        events += det.push(steady[s:s + 50], rec.channels)
    assert events == [] and det.load_torque_nm is not None and det.load_torque_nm > 0


def test_batch_size_does_not_change_the_windows(recordings):
    rec = without(recordings[(30.0, "forward")][1], LOAD_SENSORS + ("a1",))     # the encoder path (look-ahead)
    _, a, _ = offsets(rec, 50)
    _, b, _ = offsets(rec, 7)
    _, c, _ = offsets(rec, 1000)
    assert len(a) == len(b) == len(c) >= 1
    for x, y, z in zip(a, b, c):
        assert np.array_equal(x.data, y.data) and np.array_equal(x.data, z.data)
        assert x.recontact_index == y.recontact_index == z.recontact_index


def test_encoder_only_entry_within_its_stated_uncertainty(recordings):
    for key in ((None, "forward"), (30.0, "reverse")):
        for rec in recordings[key]:
            offs, wins, _ = offsets(without(rec, LOAD_SENSORS + ("a1",)))
            assert len(offs) >= 1 and abs(offs[0]) <= ENTRY_UNCERTAINTY_WITHOUT_A1, offs
            assert detector_arguments(wins[0])["entry_uncertainty_samples"] == ENTRY_UNCERTAINTY_WITHOUT_A1


def test_window_travels_with_its_detector_code(recordings):
    rec = without(recordings[(None, "forward")][0], LOAD_SENSORS)
    _, wins, _ = offsets(rec)
    w = Window.unpack(*wins[0].pack())
    assert w.detector == "dynamics" and w.recontact_index == wins[0].recontact_index


@pytest.mark.parametrize("kw, field", [({"nominal_inertia_kgm2": None}, "nominal_inertia_kgm2"),
                                       ({"drop_fraction": 1.5}, "drop_fraction"),
                                       ({"acceleration_window_samples": 8}, "acceleration_window_samples")])
def test_bad_configuration_is_one_line_naming_the_field(kw, field):
    args = dict(channels=("t", "m_el", "a1"), nominal_inertia_kgm2=J_NOM)
    args.update(kw)
    with pytest.raises(ValueError, match=f"^{field}:"):
        DynamicsDetector(R, TS, **args)
    with pytest.raises(ValueError, match="^channels:"):
        DynamicsDetector(R, TS, channels=("t", "m_el", "omega1"), nominal_inertia_kgm2=J_NOM)
    with pytest.raises(ValueError, match="^channels: need 'm_el'"):
        DynamicsDetector(R, TS, channels=("t", "a1"), nominal_inertia_kgm2=J_NOM)


def test_angle_entry_finds_the_kink_of_a_quantised_angle():
    n, e, j = 120, 60, 1.1
    m = np.full(n, 150.0)
    w = np.full(n, 100.0)
    w[e + 1:] += np.cumsum(np.full(n - e - 1, m[0] / j * TS))
    alpha = np.concatenate([[0.0], np.cumsum(w[1:] * TS)])
    q = 2 * np.pi / 65536
    alpha = np.floor(alpha / q) * q
    assert abs(angle_entry(alpha, m, TS, e - 10, e + 8) - e) <= 1
    assert angle_entry(alpha, m, TS, 5, 10) is None          # not enough rows before the first candidate


def test_speed_fit_interval_covers_with_speed_noise():
    """ω1 regressed on ∫m_el: with speed noise as large as the gap's speed change the 95 % interval covers
    (the first release's fit, ∫m_el on ω1, was biased and far too narrow: 52 of 84 published > 10 % off)."""
    rng = np.random.default_rng(3)
    j, n = 1.0, 40
    m = np.full(n, 200.0)
    covered = refused = 0
    for _ in range(200):
        w = 100 + np.concatenate([[0.0], np.cumsum(np.full(n - 1, 200.0 / j * TS))]) + rng.normal(0, 0.5, n)
        try:
            jj, se, _, dof = speed_fit(w, m + rng.normal(0, 5, n), TS)
        except NoGapError:
            refused += 1
            continue
        covered += abs(jj - j) <= 2.05 * se
    assert covered >= 0.9 * (200 - refused)


def test_a_missing_load_channel_is_a_counted_drop_that_says_what_to_configure():
    """Default channels (with alpha2) on a drive without a load encoder: every batch is dropped, counted, and the
    reason names the channel and tells the user to leave it out of `channels`."""
    det = detector(("t", "alpha1", "alpha2", "a1", "m_el", "omega1"))
    t = np.arange(10) * TS
    batch = np.column_stack([t, np.zeros(10), np.zeros(10), np.full(10, 5.0), np.zeros(10)])
    events = det.push(batch, ("t", "alpha1", "a1", "m_el", "omega1"))
    assert [e.reason for e in events] == ["missing_channel"]
    assert "'alpha2' missing" in events[0].detail and "leave alpha2" in events[0].detail
    assert det.counts["missing_channel"] == 1
