"""Tests of jident_ros.method.scalogram (classic MATLAB-style CWT scalograms)."""

import numpy as np
import pytest
import pywt

from jident_ros.method import cwt
from jident_ros.method import scalogram as sc

N_SAMPLES = 2048  # 2**11, the paper's window


@pytest.fixture(scope="module")
def signals():
    rng = np.random.default_rng(1234)
    t = np.arange(N_SAMPLES)
    base = np.sin(2 * np.pi * t / 97.0) + 0.3 * rng.standard_normal((5, N_SAMPLES))
    base[:, 48:] += np.exp(-(t[48:] - 48) / 300.0)  # a transient, like a backlash onset
    return base


def relative_error(actual, expected):
    return np.max(np.abs(actual - expected)) / np.max(np.abs(expected))


# scale 0.1: a*xmax < 1 for sym5/db6, so MATLAB's j has one element -> j = [1 1];
# scale 1 and 1.5: short and non-integer filters; 1024: filter longer than the signal.
EDGE_SCALES = [0.1, 1.0, 1.5, 2.0, 3.7, 8.0, 33.3, 256.0, 1024.0]


@pytest.mark.parametrize("wavelet", ["sym5", "db6"])
def test_fft_transform_equals_direct_convolution(signals, wavelet):
    fast = cwt.cwt_classic(signals[0], EDGE_SCALES, wavelet)
    direct = cwt.cwt_classic_direct(signals[0], EDGE_SCALES, wavelet)
    assert fast.shape == (len(EDGE_SCALES), N_SAMPLES)
    assert relative_error(fast, direct) < 1e-10
    # per scale too, so that small-scale rows are not hidden by large ones
    for row_fast, row_direct in zip(fast[1:], direct[1:]):
        assert relative_error(row_fast, row_direct) < 1e-10


def test_fft_transform_equals_direct_for_odd_length_and_dyadic_scales(signals):
    x = signals[1, :1001]
    scales = sc.scales_for_reading("dyadic")
    fast = cwt.cwt_classic(x, scales, "db6")
    assert relative_error(fast, cwt.cwt_classic_direct(x, scales, "db6")) < 1e-10


def test_single_tap_scale_uses_matlab_two_tap_filter():
    # When a * xmax < 1, MATLAB's j has one element and is replaced by [1 1]:
    # the filter is psi_integ[0] * [1, 1] and the kept diff of the full
    # convolution is -sqrt(a) * p0 * (y[k+1] - y[k-1]) (zero outside y).
    psi_integ, xval = cwt.integrated_wavelet("mexh")  # psi_integ[0] != 0 for mexh
    scale = 0.5 / xval[-1]
    y = np.random.default_rng(3).standard_normal(64)
    padded = np.concatenate([[0.0], y, [0.0]])
    expected = -np.sqrt(scale) * psi_integ[0] * (padded[2:] - padded[:-2])
    assert psi_integ[0] != 0
    tolerance = 1e-9 * np.abs(expected).max()
    for transform in (cwt.cwt_classic_direct, cwt.cwt_classic):
        coefs = transform(y, [scale], "mexh")
        assert coefs.shape == (1, y.size)
        np.testing.assert_allclose(coefs[0], expected, rtol=0, atol=tolerance)


def test_matches_pywt_cwt_for_a_continuous_wavelet(signals):
    # pywt.cwt implements the same classic algorithm for continuous wavelets:
    # an independent check of signs, filter sampling and the kept centre.
    scales = np.arange(1, 80, 3.5)
    ours = cwt.cwt_classic(signals[2], scales, "mexh", precision=10)
    theirs, _ = pywt.cwt(signals[2], scales, "mexh", precision=10, method="conv")
    assert relative_error(ours, theirs) < 1e-10


def test_batch_equals_per_signal(signals):
    scales = [1.0, 1.5, 4.0, 16.0, 512.0]
    batch = cwt.cwt_classic(signals, scales, "sym5")
    assert batch.shape == (signals.shape[0], len(scales), N_SAMPLES)
    for signal, coefs in zip(signals, batch):
        expected = cwt.cwt_classic(signal, scales, "sym5")
        np.testing.assert_allclose(coefs, expected, rtol=0, atol=1e-12)


def test_batch_larger_than_one_chunk_equals_per_signal(signals):
    many = np.concatenate([signals] * 3)  # 15 signals: several FFT chunks
    scales = sc.scales_for_reading("dyadic")
    batch = cwt.cwt_classic(many, scales, "db6")
    for signal, coefs in zip(many, batch):
        expected = cwt.cwt_classic(signal, scales, "db6")
        np.testing.assert_allclose(coefs, expected, rtol=0, atol=1e-12)


def test_filter_bank_is_cached_and_read_only():
    scales = sc.scales_for_reading("dyadic")
    bank = cwt.wavelet_filter_bank("sym5", scales, n_samples=N_SAMPLES)
    assert cwt.wavelet_filter_bank("sym5", list(scales), 10, N_SAMPLES) is bank
    assert cwt.wavelet_filter_bank("sym5", scales, 12, N_SAMPLES) is not bank
    # MATLAB: numel(0:a*xmax) taps, xmax = 9 for sym5 (support 0..2N-1)
    np.testing.assert_array_equal(bank.filter_lengths, np.floor(scales * 9) + 1)
    # every scale is in exactly one FFT group, long enough for its kept samples
    rows = np.concatenate([group.rows for group in bank.groups])
    np.testing.assert_array_equal(np.sort(rows), np.arange(scales.size))
    for group in bank.groups:
        assert group.spectra.shape == (group.rows.size, group.fft_length // 2 + 1)
        assert group.gather_index.shape == (group.rows.size * N_SAMPLES,)
        assert np.all(group.fft_length >= N_SAMPLES + np.ceil(bank.filter_lengths[group.rows] / 2))
    assert len(bank.groups) > 1  # short filters are not padded to the longest one
    with pytest.raises(ValueError):
        bank.groups[0].spectra[0, 0] = 0


def test_unsorted_and_repeated_scales_keep_their_order(signals):
    scales = [64.0, 1.0, 1024.0, 1.5, 64.0, 3.0]
    fast = cwt.cwt_classic(signals[:2], scales, "db6")
    direct = cwt.cwt_classic_direct(signals[:2], scales, "db6")
    assert relative_error(fast, direct) < 1e-10
    np.testing.assert_array_equal(fast[:, 0], fast[:, 4])


def test_scalogram_is_percentage_energy(signals):
    coefs = cwt.cwt_classic(signals, sc.scales_for_reading("dyadic"), "sym5")
    energy = sc.scalogram(coefs)
    assert energy.shape == coefs.shape
    assert np.all(energy >= 0)
    np.testing.assert_allclose(energy.sum(axis=(-2, -1)), 100.0, rtol=1e-12)
    np.testing.assert_allclose(energy[0], 100 * coefs[0] ** 2 / np.sum(coefs[0] ** 2))


def test_precision_10_differs_from_pywt_default_12(signals):
    # MATLAB's intwave uses precis = 10; PyWavelets' cwt default is 12. The
    # cascade-algorithm psi differs, so the coefficients move by about 1-2 %:
    # this is why precision=10 is the default here.
    scales = sc.scales_for_reading("dyadic")
    c10 = cwt.cwt_classic(signals[0], scales, "sym5")
    c12 = cwt.cwt_classic(signals[0], scales, "sym5", precision=12)
    assert cwt.DEFAULT_PRECISION == 10
    assert np.array_equal(cwt.cwt_classic(signals[0], scales, "sym5", precision=10), c10)
    assert relative_error(c12, c10) > 2e-3


@pytest.mark.parametrize("wavelet", ["sym5", "db6"])
@pytest.mark.parametrize("period", [16.0, 48.0])
def test_sinusoid_energy_peaks_at_its_pseudo_frequency_scale(wavelet, period):
    t = np.arange(N_SAMPLES)
    x = np.sin(2 * np.pi * t / period)
    scales = np.arange(1.0, 4 * period, 0.25)
    energy = sc.scalogram(cwt.cwt_classic(x, scales, wavelet))
    per_scale = energy[:, 400:-400].sum(axis=1)  # away from the edges
    expected = period * pywt.central_frequency(wavelet, precision=10)
    # |C(a)|^2 = a * |Psi(a * w)|^2 * const: without the factor a the peak is
    # the wavelet's spectral peak, at the pseudo-frequency scale P * Fc ...
    assert scales[np.argmax(per_scale / scales)] == pytest.approx(expected, rel=0.1)
    # ... and the raw energy peaks a little above it (sqrt(a) normalisation).
    assert 1.0 <= scales[np.argmax(per_scale)] / expected <= 1.25


def test_readings():
    np.testing.assert_array_equal(sc.scales_for_reading("dyadic"), 2.0 ** np.arange(1, 11))
    linear = sc.scales_for_reading("linear")
    assert linear.size == 1024 and linear[0] == 1 and linear[-1] == 2**10
    np.testing.assert_array_equal(sc.scales_for_reading(), sc.scales_for_reading("dyadic"))
    with pytest.raises(ValueError, match="reading"):
        sc.scales_for_reading("wavelet packets")


def test_swt_reading(signals):
    details = sc.swt_details(signals[0], "sym5")
    assert details.shape == (10, N_SAMPLES)
    # rows are d1 (finest) ... d10 (coarsest)
    reference = pywt.swt(signals[0], "sym5", level=10, trim_approx=True, norm=True)
    np.testing.assert_array_equal(details[0], reference[-1])
    np.testing.assert_array_equal(details[9], reference[1])
    energy = sc.swt_scalogram(signals, "sym5")
    assert energy.shape == (signals.shape[0], 10, N_SAMPLES)
    np.testing.assert_allclose(energy.sum(axis=(-2, -1)), 100.0, rtol=1e-12)
    np.testing.assert_allclose(energy[0], sc.scalogram(details))
    with pytest.raises(ValueError, match="signal"):
        sc.swt_details(signals[0, :2000], "sym5")


@pytest.mark.parametrize("reading, n_rows", [("dyadic", 10), ("linear", 1024), ("swt", 10)])
def test_wavelet_scalogram_all_readings(signals, reading, n_rows):
    energy = sc.wavelet_scalogram(signals[0], "db6", reading=reading)
    assert energy.shape == (n_rows, N_SAMPLES)
    assert energy.sum() == pytest.approx(100.0)


@pytest.mark.parametrize(
    "kwargs, argument",
    [
        (dict(signal=np.zeros((2, 2, 8))), "signal"),
        (dict(signal=np.array([1.0, np.nan, 2.0])), "signal"),
        (dict(signal=np.array([1.0, np.inf])), "signal"),
        (dict(signal=np.array([])), "signal"),
        (dict(signal=np.zeros((0, 16))), "signal"),
        (dict(signal="abc"), "signal"),
        (dict(signal=np.ones(8) * 1j), "signal"),
        (dict(scales=[1.0, 0.0]), "scales"),
        (dict(scales=[-2.0]), "scales"),
        (dict(scales=[]), "scales"),
        (dict(scales=[[1.0, 2.0]]), "scales"),
        (dict(scales=[1.0, np.nan]), "scales"),
        (dict(wavelet="sym99"), "wavelet"),
        (dict(wavelet="cmor1.5-1.0"), "wavelet"),
        (dict(wavelet=pywt.Wavelet("sym5")), "wavelet"),
        (dict(precision=0), "precision"),
        (dict(precision=2.5), "precision"),
    ],
)
@pytest.mark.parametrize("transform", [cwt.cwt_classic, cwt.cwt_classic_direct])
def test_bad_input_raises_value_error_naming_argument(transform, kwargs, argument):
    arguments = dict(signal=np.ones(16), scales=[1.0, 2.0], wavelet="sym5")
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=f"^{argument}: ") as info:
        transform(**arguments)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "coefs",
    [np.ones(5), np.zeros((2, 3)), np.full((2, 3), np.nan), np.empty((0, 3)), "x"],
)
def test_scalogram_bad_input(coefs):
    with pytest.raises(ValueError, match="^coefs: "):
        sc.scalogram(coefs)


# ------------------------------------------------- cells of the scalogram for the image
@pytest.mark.parametrize("reading", sc.READINGS)
def test_wavelet_coefficients_are_what_wavelet_scalogram_squares(signals, reading):
    coefs = sc.wavelet_coefficients(signals[:2], "db6", reading)
    np.testing.assert_array_equal(sc.scalogram(coefs), sc.wavelet_scalogram(signals[:2], "db6", reading))


@pytest.mark.parametrize("batch", [False, True])
def test_percentage_energy_cells_equal_the_scalogram_bit_for_bit(signals, batch):
    coefs = cwt.cwt_classic(signals if batch else signals[0], sc.scales_for_reading("dyadic"), "sym5")
    full = sc.scalogram(coefs)
    rows, columns = np.array([0, 3, 9]), np.array([2, 7, 100, 2045])
    for overwrite in (False, True):
        work = coefs.copy()
        cells, smallest, largest = sc.percentage_energy_cells(work, rows, columns, overwrite=overwrite)
        np.testing.assert_array_equal(cells, full[..., rows[:, None], columns[None, :]])
        np.testing.assert_array_equal(smallest, full.min(axis=(-2, -1)))
        np.testing.assert_array_equal(largest, full.max(axis=(-2, -1)))
        if overwrite:
            np.testing.assert_array_equal(work, coefs * coefs)  # squared in place
        else:
            np.testing.assert_array_equal(work, coefs)
    # complex coefficients: |C|^2
    z = coefs + 1j * coefs[..., ::-1]
    cells, smallest, largest = sc.percentage_energy_cells(z, rows, columns)
    np.testing.assert_array_equal(cells, sc.scalogram(z)[..., rows[:, None], columns[None, :]])


@pytest.mark.parametrize("coefs", [np.ones(5), np.zeros((2, 3)), np.full((2, 3), np.nan), np.empty((0, 3)),
                                   np.array([[1.0, np.inf]])])
def test_percentage_energy_cells_bad_input(coefs):
    with pytest.raises(ValueError, match="^coefs: "):
        sc.percentage_energy_cells(coefs, [0], [0])


def test_kept_starts_match_the_gather_index():
    bank = cwt.wavelet_filter_bank("sym5", sc.scales_for_reading("linear"), n_samples=N_SAMPLES)
    for group in bank.groups:
        starts = np.array(group.kept_starts)
        expected = (np.arange(group.rows.size)[:, None] * group.fft_length + starts[:, None]
                    + np.arange(N_SAMPLES)).reshape(-1)
        np.testing.assert_array_equal(expected, group.gather_index)
        np.testing.assert_array_equal(starts, bank.filter_lengths[group.rows] // 2)
