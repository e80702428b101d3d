"""The detectors at any sample rate (issue 20): their sample counts are durations at 2 kHz converted to the configured
sample period (jident_ros.stream.rate), so a drive recorded at 4 kHz is entered where the same drive at 2 kHz is."""
import math

import numpy as np
import pytest

from jident_ros.stream.flank import FlankDetector


def test_samples_converts_a_duration_at_2_khz_rounding_halves_up():
    from jident_ros.stream.rate import odd_samples, samples, samples_float
    assert samples(12, 5e-4) == 12 and isinstance(samples(12, 5e-4), int)     # the reference: unchanged
    assert samples(12, 2.5e-4) == 24 and samples(12, 1e-3) == 6 and samples(12, 1.25e-4) == 48
    assert samples(5, 1e-3) == 3 and samples(3, 1e-3) == 2          # 2.5 -> 3, 1.5 -> 2: halves up, not to even
    assert samples(1, 1e-3) == 1 and samples(1, 1e-3, minimum=2) == 2 and samples(0, 1e-3) == 1
    assert samples((24, 10), 2.5e-4) == (48, 20)
    assert samples(7, 2e-4) == 18                                    # 17.5 -> 18
    assert odd_samples(7, 5e-4) == 7 and odd_samples(7, 2.5e-4) == 15 and odd_samples(7, 1e-3) == 5
    assert samples_float(4.0, 2.5e-4) == 8.0 and samples_float(4.0, 5e-4) == 4.0
    with pytest.raises(ValueError, match="sample_period_s"):
        samples(4, 0.0)


def test_the_detector_s_default_counts_are_durations():
    for ts, contact, refine in ((5e-4, 32, 16), (2.5e-4, 64, 32), (1e-3, 16, 8)):
        det = FlankDetector(0.1, ts)
        assert (det.contact_samples, det.refine_samples) == (contact, refine)
    det = FlankDetector(0.1, 2.5e-4, contact_samples=32, refine_samples=10)     # given: kept
    assert (det.contact_samples, det.refine_samples) == (32, 10)
    ch = ("t", "alpha1", "alpha2", "m_el")
    # the reach back (128 at 2 kHz) and the window's 48 rows before the entry counted as the 24 ms they span at 2 kHz
    assert FlankDetector(0.1, 2.5e-4, channels=ch, nominal_inertia_kgm2=1.16).history_extra == 2 * 128 + 48
    assert FlankDetector(0.1, 5e-4, channels=ch, nominal_inertia_kgm2=1.16).history_extra == 128


def _untwisting(ts, seed=0, counts=65536, loss_s=0.3, ramp_s=0.01, drift_rad_s=-0.06, acc_rel=-10.0, length_s=1.5):
    """test_flank's light load reversal without a1, in seconds: the coupling untwists at a constant rate for
    ``ramp_s`` before its contact is lost at ``loss_s`` (delta drifts off its flank), then delta moves freely; the
    departure threshold comes ~10 ms after the loss.  (data, channels, row of the contact loss)."""
    n = int(round(length_s / ts))
    k = np.arange(n)
    t = 1.0 + k * ts
    x = int(round(loss_s / ts))
    before = np.clip(t - 1.0 - (loss_s - ramp_s), 0, ramp_s) * drift_rad_s
    tau = np.clip(t - 1.0 - loss_s, 0, None)
    delta = before + drift_rad_s * tau + 0.5 * acc_rel * tau ** 2
    q = 2 * np.pi / counts
    a2 = 50.0 * (t - 1.0) + 0.01 * np.sin(7 * t)
    a1 = a2 + 0.3 + delta + np.random.default_rng(seed).normal(0, 0.2 * q, n)
    quant = lambda a: np.round(a / q) * q                               # noqa: E731
    return np.column_stack([t, quant(a1), quant(a2)]), ("t", "alpha1", "alpha2"), x


def _late_departure(ts, with_a1=True, loss_s=0.3, ramp_s=0.01, gap_s=0.15, length_s=1.5, j1=1.16, r=0.1,
                    load_nm=40.0, gap_nm=-20.0):
    """test_flank's contact lost while delta leaves its flank slowly (a light load reversal with a1), in seconds: the
    coupling unloads over ``ramp_s``, the contact is lost at ``loss_s``, the motor decelerates from zero relative
    speed and re-contacts ``gap_s`` later; the departure comes ~13 ms after the loss.  (data, channels, loss row)."""
    n = int(round(length_s / ts))
    k = np.arange(n)
    t = 1.0 + k * ts
    x, g = int(round(loss_s / ts)), int(round((loss_s + gap_s) / ts))
    dt = np.clip(k - x, 0, None) * ts
    m_el = np.where((k < x) | (k >= g), load_nm, gap_nm)
    acc = np.where((k < x) | (k >= g), 0.0, gap_nm / j1)
    ramp_rows = int(round(ramp_s / ts))
    ramp = (k >= x - ramp_rows) & (k < x)
    m_el = np.where(ramp, load_nm * (x - k) / ramp_rows, m_el)
    a2 = 50.0 * (t - 1.0)
    a1 = a2 + 0.5 * (gap_nm / j1) * dt ** 2 + 0.3
    cols = {"t": t, "alpha1": a1, "alpha2": a2, "m_el": m_el, "a1": r * acc}
    ch = ("t", "alpha1", "alpha2", "m_el") + (("a1",) if with_a1 else ())
    return np.column_stack([cols[c] for c in ch]), ch, x


def _entry_times(data, ch, ts, **kw):
    det = FlankDetector(0.1, ts, channels=ch, samples_from_entry=int(round(0.5 / ts)), **kw)
    wins = [ev.window for ev in det.push(data, ch) + det.finish() if ev.kind == "window"]
    return [w.entry_time_s for w in wins]


@pytest.mark.parametrize("ts", [2.5e-4, 1.25e-4])
def test_an_untwisting_coupling_is_entered_at_the_same_time_at_4_and_8_khz_as_at_2_khz(ts):
    """Without a1, delta's free curvature (free_departure: DRIFT_* spans) moves the late departure back to the contact
    loss; with the spans counted at 2 kHz a 4 kHz recording searched half the time back (the vector drive's light load
    reversal at 4 kHz: +81 samples) -- converted, the entry lands within 1 ms of the 2 kHz one."""
    ref, ch, x_ref = _untwisting(5e-4)
    t_ref = _entry_times(ref, ch, 5e-4)
    assert len(t_ref) == 1 and abs(t_ref[0] - (1.0 + x_ref * 5e-4)) <= 1.6e-3     # test_flank: +-3 samples
    data, ch, x = _untwisting(ts)
    got = _entry_times(data, ch, ts)
    assert len(got) == 1
    assert abs(got[0] - t_ref[0]) <= 1e-3, (got[0] - t_ref[0]) / ts
    assert abs(got[0] - (1.0 + x * ts)) <= 2.5e-3       # the model's bias at 2 kHz (-1.5 ms) and 1 ms


def test_with_an_accelerometer_the_late_departure_moves_back_as_far_in_time_at_4_khz():
    """With a1 (back_to_load's fit and block, single_mass_run's search, the history kept: durations) the entry of a
    late departure goes back to the contact loss at 4 kHz as at 2 kHz, within 1 ms."""
    ref, ch, x_ref = _late_departure(5e-4)
    t_ref = _entry_times(ref, ch, 5e-4, nominal_inertia_kgm2=1.16)
    data, ch, x = _late_departure(2.5e-4)
    got = _entry_times(data, ch, 2.5e-4, nominal_inertia_kgm2=1.16)
    assert len(t_ref) == 1 and len(got) == 1
    assert abs(t_ref[0] - (1.0 + x_ref * 5e-4)) <= 1e-3
    assert abs(got[0] - t_ref[0]) <= 1e-3, (got[0] - t_ref[0]) / 2.5e-4


def _two_mass(ts, length_s=0.21, step_s=2.5e-5):
    """test_flank's two-mass drive whose coupling untwists off its flank as its load reverses, sampled every ``ts``
    (integrated at ``step_s``): (t, alpha1, alpha2, m_el) and the first row in the zone."""
    from test_flank import _untwisting_two_mass
    return _untwisting_two_mass(n=int(round(length_s / ts)), ts=ts, sub=int(round(ts / step_s)))


def test_the_coupling_model_searches_as_far_in_time_at_4_khz():
    """coupling_entry's fit and search (COUPLING_*: 26 ms before, 16 ms after, +-6 ms) at 4 kHz: the departure 3.5 ms
    (14 samples) before the contact loss is beyond a 12-sample search; converted, the model finds the loss."""
    from jident_ros.stream.flank_coupling import coupling_entry
    data, entry = _two_mass(2.5e-4)
    d = data[:, 1] - data[:, 2]
    flank = float(np.median(d[200:300]))
    dep = int(np.argmax(np.abs(d - flank) > 1.5e-3))
    assert entry - dep > 12                       # farther than the unconverted search
    e, gain, rms = coupling_entry(data[:, 1], d, data[:, 3], dep, 1.0 if d[dep] >= flank else -1.0, 2.5e-4)
    assert abs(e - entry) * 2.5e-4 <= 1e-3 and gain > 1.0 and rms < 1e-4, (e - entry, gain)     # within 1 ms


def test_the_untwist_model_keeps_its_one_kink_fits_at_8_khz():
    """untwist_entry (a coarse encoder's untwist: delta at rest, untwisting at a constant rate, then free) at 8 kHz:
    its change-point sums are taken in samples at 2 kHz; in 8 kHz samples the 4th powers over 4 x the rows failed the
    determinant test on every one-kink fit (a gain of inf, the entry 12-17 samples late on the second drive's 2^13)."""
    from jident_ros.stream.flank_zone import untwist_entry
    for ts in (5e-4, 1.25e-4):
        data, ch, x = _untwisting(ts, counts=8192, loss_s=0.3, ramp_s=0.004, drift_rad_s=-0.5, acc_rel=-60.0)
        d = data[:, 1] - data[:, 2]
        dep = int(np.argmax(np.abs(d - d[x - int(round(0.05 / ts))]) > 3e-3))
        e, gain = untwist_entry(d, dep, ts)
        assert math.isfinite(gain) and gain >= 1.0, (ts, gain)
        assert abs(e - x) * ts <= 1.5e-3, (ts, e - x)


def test_a_short_excursion_of_the_acceleration_does_not_end_the_gap_at_4_khz():
    """single_mass_run's gap run ends at 2 samples outside its tolerance at 2 kHz (1 ms): at 4 kHz the same 0.5 ms
    excursion of a filtered acceleration is 2 samples and ended the run there (the second drive's 2^13 re-contact
    1.75 ms early); converted, the run ends at the re-contact, at 2 kHz as at 4 kHz."""
    from jident_ros.stream.flank_free import single_mass_run
    for ts in (5e-4, 2.5e-4):
        f = int(round(5e-4 / ts))
        n, dep, end = 400 * f, 100 * f, 160 * f              # a gap of 30 ms from the departure
        rng = np.random.default_rng(1)
        m_el = np.where((np.arange(n) >= dep) & (np.arange(n) < end), -20.0, 40.0) + rng.normal(0, 0.05, n)
        acc = np.where((np.arange(n) >= dep) & (np.arange(n) < end), -20.0 / 1.16, 0.0) + rng.normal(0, 0.01, n)
        mid = (dep + end) // 2
        acc[mid:mid + f] += 3.0                              # 0.5 ms off the motor equation
        run = single_mass_run(m_el, acc, dep, 1.16, 48, 16 * f, sample_period_s=ts)
        assert run is not None and run[0] == dep and abs(run[1] - end) <= f, (ts, run)
