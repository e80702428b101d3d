"""Wavelet scalograms computed the way MATLAB's classic ``cwt`` / ``wscalogram`` do (paper section 3).

The transform itself (the classic MATLAB ``cwt`` for discrete wavelets, evaluated with FFTs): :mod:`jident_ros.
method.cwt`.  Here: the percentage-energy scalogram (``wscalogram``), its cells
for the image, the scales of each reading of "decomposition level 10" and the stationary-wavelet alternative.

Readings of "decomposition level 10" (see :func:`scales_for_reading`):

``"dyadic"`` (default)
    10 CWT scales ``2**1 ... 2**10``; one row per scale.
``"linear"``
    1024 CWT scales ``1, 2, ..., 2**10`` (MATLAB's usual ``cwt(x, 1:N, ...)``
    call with N = 2^10).
``"swt"``
    the 10 detail bands of the stationary (undecimated) wavelet transform at
    level 10 (:func:`swt_scalogram`); 2048 = 2^11 samples allow level 10.

Only numpy, scipy and PyWavelets are used.
"""

from __future__ import annotations

import numpy as np
import pywt

from jident_ros.method.checks import int_at_least, short
from jident_ros.method.cwt import DEFAULT_PRECISION, READINGS, _check_signal, _check_wavelet_name, cwt_classic

__all__ = [
    "READINGS",
    "scalogram",
    "percentage_energy_cells",
    "scales_for_reading",
    "swt_details",
    "swt_scalogram",
    "wavelet_coefficients",
    "wavelet_scalogram",
]


def scalogram(coefs) -> np.ndarray:
    """Percentage of energy per coefficient, as MATLAB ``wscalogram``.

    Parameters
    ----------
    coefs : array_like, shape (..., n_scales, n_samples)
        Wavelet coefficients C(a, b) (real or complex).

    Returns
    -------
    ndarray, shape (..., n_scales, n_samples)
        ``S = 100 * |C|**2 / sum(|C|**2)``, the sum taken over the last two
        axes, so every scalogram is non-negative and sums to 100.

    Raises
    ------
    ValueError
        Fewer than 2 dimensions, empty, non-finite, or an all-zero
        scalogram (percentages undefined).
    """
    if isinstance(coefs, (str, bytes)):
        raise ValueError(f"coefs: expected a numeric array, got {short(coefs)}")
    try:
        array = np.asarray(coefs)
    except Exception as exc:
        raise ValueError(f"coefs: not convertible to an array ({exc})") from None
    if array.dtype.kind not in "biufc":
        raise ValueError(f"coefs: expected numbers, got dtype {array.dtype}")
    if array.ndim < 2:
        raise ValueError(
            f"coefs: expected shape (..., n_scales, n_samples), got ndim={array.ndim}"
        )
    if array.size == 0:
        raise ValueError(f"coefs: is empty (shape {array.shape})")
    if not np.isfinite(array).all():
        where = tuple(int(i) for i in np.argwhere(~np.isfinite(array))[0])
        raise ValueError(f"coefs: contains non-finite value {array[where]} at index {where}")
    energy = np.abs(array.astype(np.complex128 if array.dtype.kind == "c" else np.float64)) ** 2
    total = energy.sum(axis=(-2, -1), keepdims=True)
    if np.any(total == 0):
        raise ValueError("coefs: all coefficients are zero, percentage energy is undefined")
    return 100.0 * energy / total


def percentage_energy_cells(coefs, rows, columns, overwrite: bool = False):
    """Some cells of the scalogram ``100 |C|**2 / sum |C|**2`` and its extremes, without forming it.

    What an image of the scalogram needs (see
    :func:`jident_ros.method.image.drawn_cells`): the values of the drawn
    cells and the automatic colour limits, i.e. the minimum and maximum over
    *all* cells. Equal, bit for bit, to indexing and reducing
    :func:`scalogram`'s result (the percentage map is monotone, so its
    extremes are the images of the energy's extremes), with four passes over
    the coefficients instead of about ten.

    Parameters
    ----------
    coefs : ndarray, shape (..., n_scales, n_samples)
        Wavelet coefficients C(a, b), real or complex, finite.
    rows : array of int, shape (n_rows,)
    columns : array of int, shape (n_columns,)
        Scale rows and sample columns wanted.
    overwrite : bool, optional
        Allow squaring a float64 C-contiguous ``coefs`` in place (saves one
        array of the size of ``coefs``; its content is then the energy).

    Returns
    -------
    cells : ndarray of float64, shape (..., n_rows, n_columns)
        ``scalogram(coefs)[..., rows[:, None], columns[None, :]]``.
    smallest, largest : ndarray of float64, shape (...)
        ``scalogram(coefs).min(axis=(-2, -1))`` and ``.max(axis=(-2, -1))``.

    Raises
    ------
    ValueError
        Fewer than 2 dimensions, non-finite coefficients or an all-zero scalogram.
    """
    array = np.asarray(coefs)
    if array.ndim < 2 or array.size == 0 or array.dtype.kind not in "biufc":
        scalogram(array)  # raises the matching ValueError
    if array.dtype.kind == "c":
        energy = np.abs(array.astype(np.complex128, copy=False)) ** 2
    elif overwrite and array.dtype == np.float64 and array.flags.c_contiguous and array.flags.writeable:
        energy = np.multiply(array, array, out=array)
    else:
        array = array.astype(np.float64, copy=False)
        energy = array * array
    total = energy.sum(axis=(-2, -1))
    if not (np.all(np.isfinite(total)) and np.all(total > 0)):
        scalogram(coefs if not overwrite else energy)  # names the problem
        raise ValueError("coefs: the energy overflows float64")
    smallest = 100.0 * energy.min(axis=(-2, -1)) / total
    largest = 100.0 * energy.max(axis=(-2, -1)) / total
    # two takes (columns, then rows): C-contiguous cells, much faster than one fancy index
    picked = np.take(np.take(energy, columns, axis=-1), rows, axis=-2)
    cells = 100.0 * picked / total[..., None, None]
    return cells, smallest, largest


# --------------------------------------------------------------------------
# readings of "decomposition level 10"
# --------------------------------------------------------------------------


def scales_for_reading(reading: str = "dyadic", level: int = 10) -> np.ndarray:
    """Scales for one reading of the paper's "decomposition level 10".

    Parameters
    ----------
    reading : {'dyadic', 'linear', 'swt'}
        ``'dyadic'``: ``2**arange(1, level + 1)`` (10 scales, 2 ... 1024);
        ``'linear'``: ``arange(1, 2**level + 1)`` (1024 scales, 1 ... 1024);
        ``'swt'``: the nominal scales ``2**arange(1, level + 1)`` of the SWT
        detail bands d1 ... d10; the bands themselves come from
        :func:`swt_scalogram`, not from :func:`cwt_classic`.
    level : int, optional
        Decomposition level (default 10, as in the paper).

    Returns
    -------
    ndarray of float, shape (n_scales,)
    """
    level = int_at_least("level", level)
    if reading == "linear":
        return np.arange(1, 2**level + 1, dtype=np.float64)
    if reading in ("dyadic", "swt"):
        return 2.0 ** np.arange(1, level + 1)
    raise ValueError(f"reading: expected one of {READINGS}, got {short(reading)}")


def swt_details(signal, wavelet: str, level: int = 10) -> np.ndarray:
    """Detail bands of the stationary wavelet transform (the ``'swt'`` reading).

    Parameters
    ----------
    signal : array_like, shape (n_samples,) or (n_signals, n_samples)
        ``n_samples`` must be a multiple of ``2**level`` (2048 = 2^11 allows
        level 10).
    wavelet : str
        Discrete wavelet name, e.g. ``'sym5'``.
    level : int, optional
        Decomposition level (default 10).

    Returns
    -------
    ndarray, shape (level, n_samples) or (n_signals, level, n_samples)
        Rows are the detail bands d1 (finest, scale 2) ... d_level (coarsest),
        so row 0 is the smallest scale as in :func:`cwt_classic`. Computed
        with ``pywt.swt(..., trim_approx=True, norm=True)``: with ``norm=True``
        the transform of an orthogonal wavelet is energy preserving, so the
        bands' energies are comparable; the approximation band is dropped.
    """
    array = _check_signal(signal)
    wavelet = _check_wavelet_name(wavelet)
    if wavelet not in pywt.wavelist(kind="discrete"):
        raise ValueError(f"wavelet: expected a discrete wavelet name for the SWT, got {wavelet!r}")
    level = int_at_least("level", level)
    n_samples = array.shape[-1]
    if n_samples % (2**level):
        raise ValueError(
            f"signal: length {n_samples} is not a multiple of 2**level = {2**level}"
        )
    bands = pywt.swt(array, wavelet, level=level, axis=-1, trim_approx=True, norm=True)
    # bands = [cA_level, cD_level, ..., cD_1]; keep details, finest first
    return np.stack(bands[:0:-1], axis=-2)


def swt_scalogram(signal, wavelet: str, level: int = 10) -> np.ndarray:
    """Percentage-energy scalogram of the SWT detail bands (``'swt'`` reading).

    Returns :func:`scalogram` of :func:`swt_details`: shape (level, n_samples)
    or (n_signals, level, n_samples), non-negative, summing to 100 per signal.
    """
    return scalogram(swt_details(signal, wavelet, level))


def wavelet_scalogram(signal, wavelet: str, reading: str = "dyadic", precision: int = DEFAULT_PRECISION) -> np.ndarray:
    """Scalogram of one or many signals under a reading of "level 10".

    Parameters
    ----------
    signal : array_like, shape (n_samples,) or (n_signals, n_samples)
    wavelet : str
        ``'sym5'`` for a1, omega1, v2; ``'db6'`` for m_el, a2 (paper section 3).
    reading : {'dyadic', 'linear', 'swt'}
        See :func:`scales_for_reading`.
    precision : int, optional
        MATLAB ``precis`` (CWT readings only).

    Returns
    -------
    ndarray, shape ([n_signals,] n_scales, n_samples)
        Percentage energy per coefficient (the paper's scalogram, input of
        the image X1); rows ordered from the smallest scale.
    """
    return scalogram(wavelet_coefficients(signal, wavelet, reading, precision))


def wavelet_coefficients(signal, wavelet: str, reading: str = "dyadic", precision: int = DEFAULT_PRECISION) -> np.ndarray:
    """The coefficients whose percentage energy :func:`wavelet_scalogram` returns.

    Parameters
    ----------
    signal, wavelet, reading, precision
        As in :func:`wavelet_scalogram`.

    Returns
    -------
    ndarray of float64, shape ([n_signals,] n_scales, n_samples)
        :func:`cwt_classic` at :func:`scales_for_reading`'s scales, or the
        :func:`swt_details` bands for ``'swt'``; a new array (the caller may
        overwrite it, e.g. ``percentage_energy_cells(..., overwrite=True)``).
    """
    if reading == "swt":
        return swt_details(signal, wavelet, level=10)
    scales = scales_for_reading(reading)
    return cwt_classic(signal, scales, wavelet, precision)
