"""The classic MATLAB continuous wavelet transform (``cwt.m`` before R2016b, ``intwave``) for any wavelet with a
wavelet function: the transform behind :mod:`jident_ros.method.scalogram`.

The paper (section 3) computes, for every 2048-sample window of a simulated
signal (rows of its matrix N1: a1, m_el, omega1, a2, v2), a wavelet scalogram
with a *discrete* wavelet (``sym5`` for a1, omega1 and v2; ``db6`` for m_el
and a2) "with decomposition level 10", and then turns the scalogram picture
into the 343 x 436 intensity matrix X1 (see :mod:`jident_ros.method.image`).

``pywt.cwt`` only accepts continuous wavelets, so this module re-implements
the classic MATLAB algorithm (``cwt.m`` before R2016b, ``intwave``,
``wscalogram``), which works for any wavelet that has a wavelet function
``psi``::

    [psi_integ, xval] = intwave(wname, precis)   % cumsum(psi) * step
    xval = xval - xval(1); dxval = xval(2); xmax = xval(end);
    for k, a = scales(k):
        j = 1 + floor((0:a*xmax) / (a*dxval));
        if length(j) == 1, j = [1 1]; end
        f = fliplr(psi_integ(j));
        coefs(k,:) = -sqrt(a) * wkeep1(diff(wconv1(ySIG, f)), lenSIG);
    end
    S = abs(coefs).^2;  S = 100*S/sum(S(:))       % wscalogram

:func:`cwt_classic` evaluates the scales with FFTs, grouped by the transform
length their filters need (2 groups for the 10 dyadic scales): per group one
real FFT of the signal(s), one multiplication with the cached filter spectra
and one inverse FFT, then a gather of the kept samples; no loop over scales.
:func:`cwt_classic_direct` is the literal per-scale transcription kept as the
reference for the tests.

The readings of "decomposition level 10" (which scales): :mod:`jident_ros.method.scalogram`.

Symbols: ``signal`` is one row of the paper's N1 (2048 samples of one
physical quantity), ``coefs`` are the CWT coefficients C(a, b) at scale a and
sample b, and the returned percentage-energy ``scalogram`` is what the paper
renders into the image X1.

Only numpy, scipy and PyWavelets are used.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pywt
import scipy.fft

from jident_ros.method.checks import finite_real_array, int_at_least, short

__all__ = [
    "DEFAULT_PRECISION",
    "READINGS",
    "CwtFilterBank",
    "FftGroup",
    "integrated_wavelet",
    "wavelet_filter_bank",
    "cwt_classic",
    "cwt_classic_direct",
]

#: MATLAB's default ``precis`` for ``intwave`` / classic ``cwt``: the wavelet
#: function is computed with 10 cascade iterations (2**10 points per unit of
#: support). PyWavelets' own default (12 for ``pywt.cwt``) gives filters that
#: differ by about one percent, so 10 is used to stay close to MATLAB.
DEFAULT_PRECISION = 10

#: Accepted values of ``reading`` (interpretations of "decomposition level 10").
READINGS = ("dyadic", "linear", "swt")

_MAX_PRECISION = 16
# Target size (bytes) of the complex product of one FFT chunk: small enough to
# stay in cache (one or two signals for the dyadic scales), at least 1 signal.
_CHUNK_BYTES = 1 << 20
# Fixed cost of one FFT group (Python calls, rfft of the signal), in units of
# length * log2(length) (about 0.25 ns each here): ~25 us.
_GROUP_OVERHEAD = 1.0e5
# MATLAB's colon operator ``0:a*xmax`` tolerates round-off at the end point.
_COLON_RTOL = 4.0 * np.finfo(float).eps


# --------------------------------------------------------------------------
# validation helpers (one-line ValueError naming the argument)
# --------------------------------------------------------------------------


def _check_signal(signal) -> np.ndarray:
    array = finite_real_array("signal", signal)
    if array.ndim not in (1, 2):
        raise ValueError(
            f"signal: expected shape (n_samples,) or (n_signals, n_samples), got ndim={array.ndim}"
        )
    return array


def _check_scales(scales) -> tuple:
    array = finite_real_array("scales", scales)
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim != 1:
        raise ValueError(f"scales: expected a 1-D array of scales, got shape {array.shape}")
    if np.any(array <= 0):
        bad = array[array <= 0][0]
        raise ValueError(f"scales: must be positive, got {bad}")
    return tuple(float(a) for a in array)


def _check_precision(precision) -> int:
    if isinstance(precision, bool) or not isinstance(precision, (int, np.integer)):
        raise ValueError(f"precision: expected an integer, got {short(precision)}")
    if not 1 <= precision <= _MAX_PRECISION:
        raise ValueError(f"precision: must be in [1, {_MAX_PRECISION}], got {precision}")
    return int(precision)


def _check_wavelet_name(wavelet) -> str:
    if not isinstance(wavelet, str):
        raise ValueError(f"wavelet: expected a wavelet name such as 'sym5', got {short(wavelet)}")
    return wavelet


# --------------------------------------------------------------------------
# wavelet function and filters
# --------------------------------------------------------------------------


@functools.lru_cache(maxsize=32)
def _integrated_wavelet_cached(wavelet: str, precision: int):
    if wavelet in pywt.wavelist(kind="discrete"):
        values = pywt.Wavelet(wavelet).wavefun(level=precision)
        # orthogonal: (phi, psi, x); biorthogonal: (phi_d, psi_d, phi_r, psi_r, x).
        # MATLAB's intwave uses the (decomposition) psi in both cases.
        psi, xval = values[1], values[-1]
    else:
        try:
            continuous = pywt.ContinuousWavelet(wavelet)
        except ValueError:
            raise ValueError(
                f"wavelet: unknown wavelet name {wavelet!r} (see pywt.wavelist())"
            ) from None
        if continuous.complex_cwt:
            raise ValueError(
                f"wavelet: complex wavelet {wavelet!r} is not supported; use a real wavelet"
            )
        psi, xval = continuous.wavefun(level=precision)
    psi = np.asarray(psi, dtype=np.float64)
    xval = np.asarray(xval, dtype=np.float64)
    step = xval[1] - xval[0]
    psi_integ = np.cumsum(psi) * step
    xval = xval - xval[0]
    psi_integ.setflags(write=False)
    xval.setflags(write=False)
    return psi_integ, xval


def integrated_wavelet(wavelet: str, precision: int = DEFAULT_PRECISION):
    """Integral of the wavelet function, as MATLAB's ``intwave``.

    Parameters
    ----------
    wavelet : str
        PyWavelets name of a discrete (``'sym5'``, ``'db6'``, ``'bior2.2'``...)
        or real continuous (``'mexh'``, ``'morl'``, ``'gaus2'``...) wavelet.
    precision : int, optional
        Number of cascade iterations (MATLAB ``precis``); default 10.

    Returns
    -------
    psi_integ : ndarray, shape (n_points,)
        ``cumsum(psi) * dx``, the running integral of psi (read-only, cached).
    xval : ndarray, shape (n_points,)
        Abscissae shifted to start at 0 (``xval - xval[0]``), spacing ``dx``.

    Raises
    ------
    ValueError
        Unknown or complex wavelet, or precision outside [1, 16].
    """
    return _integrated_wavelet_cached(_check_wavelet_name(wavelet), _check_precision(precision))


def _scale_filter(psi_integ: np.ndarray, xval: np.ndarray, scale: float) -> np.ndarray:
    """MATLAB ``f = fliplr(psi_integ(j))`` for one scale ``a``."""
    dxval = xval[1]
    xmax = xval[-1]
    n_taps = int(math.floor(scale * xmax * (1.0 + _COLON_RTOL))) + 1  # numel(0:a*xmax)
    j = np.floor(np.arange(n_taps) / (scale * dxval)).astype(np.intp)
    np.minimum(j, psi_integ.size - 1, out=j)
    if j.size == 1:
        j = np.zeros(2, dtype=np.intp)  # MATLAB: if length(j)==1, j = [1 1]
    return psi_integ[j][::-1].copy()


@dataclass(frozen=True, eq=False)
class FftGroup:
    """Scales that share one FFT length inside a :class:`CwtFilterBank`.

    Attributes
    ----------
    rows : ndarray of int, shape (n_group,)
        Positions of these scales in the bank's ``scales`` (output rows).
    fft_length : int
        Transform length: the smallest fast length such that the kept samples
        of every scale in the group are free of circular wrap-around.
    spectra : ndarray of complex, shape (n_group, fft_length // 2 + 1)
        rfft of ``-sqrt(a) * conv(f, [1, -1])``: the filter, MATLAB's ``diff``
        and the ``-sqrt(a)`` factor folded into one frequency response.
    gather_index : ndarray of int, shape (n_group * n_samples,)
        Flat positions, in the inverse FFT of one signal viewed as
        (n_group * fft_length,), of the samples ``wkeep1`` keeps for each
        scale (the centre depends on each filter's own length).
    """

    rows: np.ndarray
    fft_length: int
    spectra: np.ndarray
    gather_index: np.ndarray

    @functools.cached_property
    def kept_starts(self) -> list:
        """First kept sample of each scale's inverse FFT row (``wkeep1``'s start), list of int (n_group,)."""
        n_rows = self.rows.size
        n_samples = self.gather_index.size // n_rows
        first = self.gather_index[::n_samples] - np.arange(n_rows) * self.fft_length
        return [int(v) for v in first]


@dataclass(frozen=True, eq=False)
class CwtFilterBank:
    """Per-scale filters of the classic CWT, with their spectra for one signal length.

    Attributes
    ----------
    wavelet : str
        Wavelet name.
    scales : ndarray, shape (n_scales,)
        Scales ``a`` (dimensionless, in samples).
    precision : int
        Cascade iterations used for psi (MATLAB ``precis``).
    n_samples : int
        Signal length the spectra were computed for.
    filters : tuple of ndarray
        ``filters[k]`` is MATLAB's ``f = fliplr(psi_integ(j))`` for ``scales[k]``,
        shape (filter_lengths[k],).
    filter_lengths : ndarray of int, shape (n_scales,)
    groups : tuple of FftGroup
        Scales grouped by FFT length (a few groups: short filters are not
        transformed at the length the longest filter needs). Each group costs
        one rfft of the signal, one product and one irfft of all its scales.

    All arrays are read-only because instances are cached.
    """

    wavelet: str
    scales: np.ndarray
    precision: int
    n_samples: int
    filters: tuple
    filter_lengths: np.ndarray
    groups: tuple

    @property
    def n_scales(self) -> int:
        return int(self.scales.size)

    @property
    def fft_lengths(self) -> tuple:
        """FFT length of every group."""
        return tuple(group.fft_length for group in self.groups)


def _fft_cost(length: int) -> float:
    return length * math.log2(length)


def _group_by_fft_length(required: np.ndarray) -> list:
    """Split scales into contiguous runs (by required length) minimising FFT cost.

    ``required[k]`` is the minimum transform length of scale k. A group of
    ``n`` scales at length L costs ``(n + 1) * L log2 L`` (n irfft rows plus
    the signal's rfft) plus a fixed per-group overhead; dynamic programming
    over the scales sorted by ``required`` gives the cheapest partition.
    Returns a list of (row indices, fft_length).
    """
    order = np.argsort(required, kind="stable")
    fast = np.array([scipy.fft.next_fast_len(int(r), real=True) for r in required[order]])
    weight = np.array([_fft_cost(int(n)) for n in fast])
    count = order.size
    best = np.zeros(count + 1)
    cut = np.zeros(count + 1, dtype=np.intp)
    for end in range(1, count + 1):  # group = order[start:end], length fast[end - 1]
        starts = np.arange(end)
        total = best[:end] + (end - starts + 1) * weight[end - 1] + _GROUP_OVERHEAD
        cut[end] = int(np.argmin(total))
        best[end] = total[cut[end]]
    groups = []
    end = count
    while end > 0:
        start = cut[end]
        groups.append((np.sort(order[start:end]), int(fast[end - 1])))
        end = start
    return groups[::-1]


def _group_spectra(filters, scales, fft_length: int) -> np.ndarray:
    # g = -sqrt(a) * conv(f, [1, -1]) can be longer than fft_length
    # (m + 1 < 2 * fft_length): it is folded modulo fft_length, whose DFT
    # equals g's DFT at those frequencies (the folded tail, like the wrapped
    # part of the convolution, only reaches discarded samples).
    folded = np.zeros((len(filters), 2 * fft_length))
    for row, (a, f) in enumerate(zip(scales, filters)):
        folded[row, : f.size] = f
        folded[row, 1 : f.size + 1] -= f
        folded[row, : f.size + 1] *= -math.sqrt(a)
    folded = folded[:, :fft_length] + folded[:, fft_length:]
    return scipy.fft.rfft(folded, axis=-1)


@functools.lru_cache(maxsize=8)
def _filter_bank_cached(wavelet: str, scales: tuple, precision: int, n_samples: int):
    psi_integ, xval = _integrated_wavelet_cached(wavelet, precision)
    scales_array = np.asarray(scales, dtype=np.float64)
    filters = tuple(_scale_filter(psi_integ, xval, a) for a in scales)
    lengths = np.array([f.size for f in filters], dtype=np.intp)
    # Per scale, coefs[b] = z[s0 + b] (b = 0..n-1) with z = conv(signal, g),
    # g = -sqrt(a) * conv(f, [1, -1]) of length m + 1 (so len(z) = n + m) and
    # s0 = floor((m - 2) / 2) + 1 = floor(m / 2) (wkeep1's centre, shifted by
    # one for MATLAB's diff). A circular convolution of length L equals z on
    # [s0, s0 + n) as soon as L >= n + m - s0 = n + ceil(m / 2): the wrapped
    # tail z[L:] only lands on indices < s0, which wkeep1 discards. This is
    # shorter than the full linear convolution (n + m) by about m / 2.
    required = n_samples + (lengths + 1) // 2
    start = lengths // 2
    groups = []
    for rows, fft_length in _group_by_fft_length(required):
        spectra = _group_spectra([filters[k] for k in rows], scales_array[rows], fft_length)
        row_offset = np.arange(rows.size)[:, None] * fft_length + start[rows][:, None]
        gather_index = (row_offset + np.arange(n_samples)).reshape(-1)
        for array in (rows, spectra, gather_index):
            array.setflags(write=False)
        groups.append(FftGroup(rows, fft_length, spectra, gather_index))
    for array in (scales_array, lengths) + filters:
        array.setflags(write=False)
    return CwtFilterBank(
        wavelet=wavelet,
        scales=scales_array,
        precision=precision,
        n_samples=n_samples,
        filters=filters,
        filter_lengths=lengths,
        groups=tuple(groups),
    )


def wavelet_filter_bank(
    wavelet: str,
    scales,
    precision: int = DEFAULT_PRECISION,
    n_samples: int = 2048,
) -> CwtFilterBank:
    """Build (or fetch from cache) the classic-CWT filters for a set of scales.

    Parameters
    ----------
    wavelet : str
        Wavelet name (``'sym5'``, ``'db6'``, ... or a real continuous wavelet).
    scales : array_like, shape (n_scales,)
        Positive scales ``a``; non-integer scales are allowed.
    precision : int, optional
        MATLAB ``precis`` (default 10).
    n_samples : int, optional
        Length of the signals to be transformed (default 2048 = 2^11, the
        paper's window: 48 samples before the backlash onset + 2000 after).

    Returns
    -------
    CwtFilterBank
        Cached on ``(wavelet, tuple(scales), precision, n_samples)``; the same
        object is returned for equal arguments.
    """
    return _filter_bank_cached(
        _check_wavelet_name(wavelet),
        _check_scales(scales),
        _check_precision(precision),
        int_at_least("n_samples", n_samples),
    )


# --------------------------------------------------------------------------
# transforms
# --------------------------------------------------------------------------


def cwt_classic(signal, scales, wavelet: str, precision: int = DEFAULT_PRECISION) -> np.ndarray:
    """Classic MATLAB continuous wavelet transform, evaluated with FFTs.

    Parameters
    ----------
    signal : array_like, shape (n_samples,) or (n_signals, n_samples)
        Real, finite samples (one row of the paper's N1 per signal).
    scales : array_like, shape (n_scales,)
        Positive scales ``a`` (in samples).
    wavelet : str
        Wavelet name, e.g. ``'sym5'`` or ``'db6'`` (paper section 3).
    precision : int, optional
        MATLAB ``precis`` for the wavelet function (default 10).

    Returns
    -------
    coefs : ndarray, shape (n_scales, n_samples) or (n_signals, n_scales, n_samples)
        Coefficients C(a, b) with rows ordered as ``scales``; equal to
        :func:`cwt_classic_direct` up to FFT round-off (~1e-13 relative).

    Notes
    -----
    Per group of scales sharing an FFT length (see :class:`CwtFilterBank`;
    typically 3-6 groups): one rfft of the signal(s), one product with the
    pre-computed spectra of all scales of the group, one irfft and a gather
    of the samples that MATLAB's ``wkeep1`` keeps. No loop over scales.
    """
    array = _check_signal(signal)
    bank = wavelet_filter_bank(wavelet, scales, precision, n_samples=array.shape[-1])
    batch = array.reshape(-1, array.shape[-1])
    n_signals, n_samples = batch.shape
    out = np.empty((n_signals, bank.n_scales, n_samples))
    for group in bank.groups:
        n_rows, n_freq = group.spectra.shape
        chunk = max(1, _CHUNK_BYTES // (n_rows * n_freq * 16))
        spectrum = scipy.fft.rfft(batch, n=group.fft_length, axis=-1)  # (n_signals, n_freq)
        product = np.empty((min(chunk, n_signals), n_rows, n_freq), dtype=np.complex128)
        # rows of a group are normally consecutive output rows (groups are runs of scales
        # sorted by filter length): copy each scale's kept block straight into the output
        first_row = int(group.rows[0])
        consecutive = np.array_equal(group.rows, np.arange(first_row, first_row + n_rows))
        starts = group.kept_starts
        kept = None if consecutive else np.empty((min(chunk, n_signals), n_rows * n_samples))
        for first in range(0, n_signals, chunk):
            stop = min(first + chunk, n_signals)
            size = stop - first
            np.multiply(spectrum[first:stop, None, :], group.spectra[None], out=product[:size])
            full = scipy.fft.irfft(product[:size], n=group.fft_length, axis=-1)  # (size, n_rows, fft_length)
            if consecutive:
                for i in range(size):
                    target = out[first + i, first_row:first_row + n_rows]
                    for row, start in enumerate(starts):
                        target[row] = full[i, row, start:start + n_samples]
            else:
                np.take(full.reshape(size, -1), group.gather_index, axis=1, out=kept[:size])
                out[first:stop, group.rows] = kept[:size].reshape(size, n_rows, n_samples)
            del full
    return out[0] if array.ndim == 1 else out


def cwt_classic_direct(
    signal, scales, wavelet: str, precision: int = DEFAULT_PRECISION
) -> np.ndarray:
    """Reference implementation: a literal per-scale transcription of MATLAB ``cwt``.

    Same parameters and result as :func:`cwt_classic` but slow (one
    ``np.convolve`` per scale and signal). Used to verify the FFT version.
    """
    array = _check_signal(signal)
    scale_values = _check_scales(scales)
    psi_integ, xval = integrated_wavelet(wavelet, precision)
    batch = array.reshape(-1, array.shape[-1])
    len_sig = batch.shape[-1]
    dxval = xval[1]
    xmax = xval[-1]
    coefs = np.empty((batch.shape[0], len(scale_values), len_sig))
    for k, a in enumerate(scale_values):
        # j = 1 + floor((0:a*xmax)/(a*dxval)), converted to 0-based indices
        colon = np.arange(int(math.floor(a * xmax * (1.0 + _COLON_RTOL))) + 1)
        j = np.floor(colon / (a * dxval)).astype(np.intp)
        j = np.minimum(j, psi_integ.size - 1)
        if j.size == 1:
            j = np.array([0, 0])
        f = psi_integ[j][::-1]
        for s, y_sig in enumerate(batch):
            conv = np.convolve(y_sig, f)  # wconv1: full convolution
            d = np.diff(conv)
            first = (d.size - len_sig) // 2  # wkeep1 centre, 0-based
            coefs[s, k] = -math.sqrt(a) * d[first : first + len_sig]
    return coefs[0] if array.ndim == 1 else coefs
