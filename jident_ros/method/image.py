"""Render a scalogram into the paper's intensity matrix X1, without a plotting library.

In the paper (section 4) every scalogram is shown as a default MATLAB figure
and the colour intensities of the pixels of its plot area form the matrix
X1 with 343 rows (a = 1..343) and 436 columns (b = 1..436), i.e.
149,548 pixels. X1 is then normalised into X2 and X3 (eqs. 2-7) and
clustered with k-harmonic means (eqs. 23-30).

This module reproduces that picture deterministically:

* :func:`render_intensity` samples the scalogram at the centre of every
  pixel, the way MATLAB ``image``/``imagesc`` draws a matrix over the axes
  (row 1 of the data, the smallest scale, at the top: ``'ij'`` axes), maps
  each value to a colour index with MATLAB's ``'scaled'`` CDataMapping and
  returns the ``gray(N)`` intensity of that index, i.e. X1 in [0, 1].
* :func:`intensity_levels` and :func:`level_histogram` give the N discrete
  grey levels and their pixel counts, so a clusterer can work on at most N
  weighted values instead of 149,548 pixels.
* :func:`write_png` writes an 8-bit PNG (grey, or an analytic ``'jet'``
  colour map like the paper's Fig. 2) using only ``zlib`` and ``struct``.

Only numpy and the standard library are used.
"""

from __future__ import annotations

import functools
import os
import struct
import zlib
from pathlib import Path

import numpy as np

__all__ = [
    "X1_SHAPE",
    "DEFAULT_N_COLORS",
    "COLORMAPS",
    "pixel_cell_indices",
    "render_intensity",
    "intensity_levels",
    "level_histogram",
    "write_png",
]

#: Shape (rows a, columns b) of the paper's intensity matrix X1: the plot
#: area of a default MATLAB figure (343 x 436 pixels, 149,548 pixels).
X1_SHAPE = (343, 436)

#: Length of MATLAB's default colour map before R2014b (``jet(64)``/``gray(64)``).
DEFAULT_N_COLORS = 64

#: Colour maps understood by :func:`write_png`.
COLORMAPS = ("gray", "jet")

_ORIGINS = ("upper", "lower")


# --------------------------------------------------------------------------
# validation helpers (one-line ValueError naming the argument)
# --------------------------------------------------------------------------


def _short(value) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _real_array(name: str, value, min_ndim: int) -> np.ndarray:
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name}: expected a numeric array, got {_short(value)}")
    try:
        array = np.asarray(value)
    except Exception as exc:  # ragged nested sequences and the like
        raise ValueError(f"{name}: not convertible to an array ({exc})") from None
    if array.dtype.kind not in "biuf":
        raise ValueError(f"{name}: expected real numbers, got dtype {array.dtype}")
    if array.ndim < min_ndim:
        raise ValueError(f"{name}: expected at least {min_ndim} dimensions, got ndim={array.ndim}")
    if array.size == 0:
        raise ValueError(f"{name}: is empty (shape {array.shape})")
    array = array.astype(np.float64, copy=False)
    finite = np.isfinite(array)
    if not finite.all():
        where = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise ValueError(f"{name}: contains non-finite value {array[where]} at index {where}")
    return array


def _int_at_least(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer, got {_short(value)}")
    if value < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {value}")
    return int(value)


def _check_shape(shape) -> tuple:
    try:
        height, width = shape
    except (TypeError, ValueError):
        raise ValueError(f"shape: expected (n_rows, n_columns), got {_short(shape)}") from None
    for value in (height, width):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"shape: expected two positive integers, got {_short(shape)}")
    return int(height), int(width)


def _check_origin(origin) -> str:
    if origin not in _ORIGINS:
        raise ValueError(f"origin: expected one of {_ORIGINS}, got {_short(origin)}")
    return origin


def _check_image(image) -> np.ndarray:
    array = _real_array("image", image, min_ndim=2)
    low, high = array.min(), array.max()
    if low < 0.0 or high > 1.0:
        bad = low if low < 0.0 else high
        raise ValueError(f"image: intensities must lie in [0, 1], got {bad}")
    return array


# --------------------------------------------------------------------------
# rendering
# --------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def _cell_indices_cached(n_rows: int, n_columns: int, height: int, width: int, origin: str):
    # Pixel k (0-based) has its centre at (k + 1/2) / size of the axes extent;
    # the data cell under it is floor((k + 1/2) * n / size), in integers.
    rows = ((2 * np.arange(height) + 1) * n_rows) // (2 * height)
    columns = ((2 * np.arange(width) + 1) * n_columns) // (2 * width)
    if origin == "lower":
        rows = n_rows - 1 - rows
    rows = rows.astype(np.intp)
    columns = columns.astype(np.intp)
    rows.setflags(write=False)
    columns.setflags(write=False)
    return rows, columns


def pixel_cell_indices(data_shape, shape=X1_SHAPE, origin: str = "upper"):
    """Data cell drawn under the centre of every pixel.

    Parameters
    ----------
    data_shape : tuple of int
        ``(n_scales, n_samples)`` of the scalogram (extra leading entries
        are ignored).
    shape : tuple of int, optional
        Image size ``(n_rows, n_columns)``; default X1's (343, 436).
    origin : {'upper', 'lower'}, optional
        ``'upper'`` (default): data row 0 (smallest scale) on the top pixel
        row, as MATLAB ``image``/``imagesc`` with ``YDir = 'reverse'``;
        ``'lower'``: flipped vertically (``YDir = 'normal'``).

    Returns
    -------
    row_index : ndarray of int, shape (n_rows,)
        Data row under pixel row a - 1 (0-based).
    column_index : ndarray of int, shape (n_columns,)
        Data column under pixel column b - 1 (0-based).
        Both are cached and read-only.
    """
    try:
        n_rows, n_columns = (int(v) for v in tuple(data_shape)[-2:])
    except (TypeError, ValueError):
        message = f"data_shape: expected (n_scales, n_samples), got {_short(data_shape)}"
        raise ValueError(message) from None
    if len(tuple(data_shape)) < 2 or n_rows < 1 or n_columns < 1:
        raise ValueError(f"data_shape: expected two positive sizes, got {_short(data_shape)}")
    height, width = _check_shape(shape)
    return _cell_indices_cached(n_rows, n_columns, height, width, _check_origin(origin))


def render_intensity(
    scalogram,
    shape=X1_SHAPE,
    n_colors: int = DEFAULT_N_COLORS,
    clim=None,
    origin: str = "upper",
) -> np.ndarray:
    """Grey intensity image X1 of a scalogram, as a MATLAB figure's plot area.

    Parameters
    ----------
    scalogram : array_like, shape (..., n_scales, n_samples)
        Scalogram(s) (e.g. percentage energy from
        :func:`jident_ros.method.scalogram.scalogram`); rows are scales, row 0
        the smallest. Leading axes are a batch of independent images.
    shape : tuple of int, optional
        ``(n_rows, n_columns)`` of the image; default (343, 436), the paper's
        a = 1..343, b = 1..436.
    n_colors : int, optional
        Colour-map length N (default 64), at least 2.
    clim : (float, float) or None, optional
        Colour limits ``(cmin, cmax)`` with cmin < cmax. ``None`` (default):
        the minimum and maximum of each scalogram (MATLAB's automatic CLim).
    origin : {'upper', 'lower'}, optional
        Vertical orientation, see :func:`pixel_cell_indices`; default
        ``'upper'`` (smallest scale at the top).

    Returns
    -------
    X1 : ndarray of float64, shape (..., n_rows, n_columns)
        Intensities ``(index - 1) / (N - 1)`` in [0, 1], where each pixel
        shows the data cell under its centre and
        ``index = clamp(fix((C - cmin) / (cmax - cmin) * N) + 1, 1, N)``
        (MATLAB ``'scaled'`` CDataMapping into ``gray(N)``). When
        ``cmax == cmin`` (constant scalogram, automatic limits) every pixel
        gets index 1, intensity 0.

    Notes
    -----
    Nearest-cell sampling, as MATLAB draws an image without smoothing: with
    2048 samples on 436 columns only 436 sample columns are drawn (about one
    in 4.7), while the automatic colour limits still come from all the data,
    so the image need not reach intensity 1 if the maximum lies between
    pixel centres. Cost: one gather of n_rows x n_columns cells per image
    (index maps cached per data shape) plus min/max over the data.
    """
    data = _real_array("scalogram", scalogram, min_ndim=2)
    height, width = _check_shape(shape)
    n_colors = _int_at_least("n_colors", n_colors, 2)
    origin = _check_origin(origin)
    if clim is None:
        cmin = data.min(axis=(-2, -1), keepdims=True)
        cmax = data.max(axis=(-2, -1), keepdims=True)
    else:
        limits = _real_array("clim", clim, min_ndim=1)
        if limits.shape != (2,) or not limits[0] < limits[1]:
            raise ValueError(f"clim: expected (cmin, cmax) with cmin < cmax, got {_short(clim)}")
        cmin, cmax = limits[0], limits[1]
    rows, columns = _cell_indices_cached(data.shape[-2], data.shape[-1], height, width, origin)
    sampled = data[..., rows[:, None], columns[None, :]]
    span = np.asarray(cmax - cmin)
    flat = span == 0
    scaled = (sampled - cmin) / np.where(flat, 1.0, span) * n_colors
    level = np.clip(np.trunc(scaled), 0, n_colors - 1)  # index - 1
    if flat.any():
        level = np.where(flat, 0.0, level)
    return level / (n_colors - 1)


def intensity_levels(image, n_colors: int = DEFAULT_N_COLORS) -> np.ndarray:
    """Integer grey levels 0..N-1 of an intensity image.

    Parameters
    ----------
    image : array_like, shape (..., n_rows, n_columns)
        Intensities in [0, 1], e.g. X1 from :func:`render_intensity`.
    n_colors : int, optional
        Number of levels N (default 64); should match the rendering.

    Returns
    -------
    ndarray of int, same shape
        ``round(image * (N - 1))``: the colour index minus one of every pixel.
    """
    array = _check_image(image)
    n_colors = _int_at_least("n_colors", n_colors, 2)
    return np.rint(array * (n_colors - 1)).astype(np.intp)


def level_histogram(image, n_colors: int = DEFAULT_N_COLORS):
    """Weighted histogram of the grey levels of one or many images.

    Parameters
    ----------
    image : array_like, shape (..., n_rows, n_columns)
        Intensities in [0, 1] (X1).
    n_colors : int, optional
        Number of levels N (default 64).

    Returns
    -------
    level_values : ndarray of float64, shape (N,)
        Intensity of each level, ``arange(N) / (N - 1)``.
    counts : ndarray of int64, shape (..., N)
        Number of pixels at each level; sums to n_rows * n_columns
        (149,548 for X1) per image. Clustering ``level_values`` weighted by
        ``counts`` is equivalent to clustering all pixels.
    """
    levels = intensity_levels(image, n_colors)
    n_colors = int(n_colors)
    batch_shape = levels.shape[:-2]
    per_image = levels.reshape(-1, levels.shape[-2] * levels.shape[-1])
    n_images = per_image.shape[0]
    offsets = (np.arange(n_images) * n_colors)[:, None]
    counts = np.bincount((per_image + offsets).ravel(), minlength=n_images * n_colors)
    counts = counts.astype(np.int64).reshape(batch_shape + (n_colors,))
    level_values = np.arange(n_colors) / (n_colors - 1)
    return level_values, counts


# --------------------------------------------------------------------------
# PNG output
# --------------------------------------------------------------------------


def _jet_rgb(values: np.ndarray) -> np.ndarray:
    """Analytic MATLAB-like ``jet``: dark blue (0) -> cyan -> yellow -> dark red (1)."""
    v = values[..., None]
    centres = np.array([3.0, 2.0, 1.0])  # red, green, blue
    return np.clip(1.5 - np.abs(4.0 * v - centres), 0.0, 1.0)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def write_png(path, image, colormap: str = "gray") -> Path:
    """Write an intensity image as an 8-bit PNG (standard library only).

    Parameters
    ----------
    path : str or os.PathLike
        Output file name.
    image : array_like, shape (n_rows, n_columns)
        Intensities in [0, 1] (X1); row 0 is the top row of the picture.
    colormap : {'gray', 'jet'}, optional
        ``'gray'`` (default): one 8-bit channel, ``round(255 * image)``.
        ``'jet'``: RGB through an analytic jet colour map, for a colour
        picture like the paper's Fig. 2.

    Returns
    -------
    pathlib.Path
        The written file: PNG signature, IHDR (bit depth 8, colour type 0 or
        2), one zlib-compressed IDAT with filter type 0 on every row, IEND.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path: expected a file name, got {_short(path)}")
    array = _check_image(image)
    if array.ndim != 2:
        raise ValueError(f"image: expected shape (n_rows, n_columns), got ndim={array.ndim}")
    if colormap == "gray":
        pixels = np.rint(array * 255.0).astype(np.uint8)
        colour_type = 0
    elif colormap == "jet":
        pixels = np.rint(_jet_rgb(array) * 255.0).astype(np.uint8)
        colour_type = 2
    else:
        raise ValueError(f"colormap: expected one of {COLORMAPS}, got {_short(colormap)}")
    height, width = array.shape
    rows = pixels.reshape(height, -1)
    scanlines = np.zeros((height, rows.shape[1] + 1), dtype=np.uint8)  # filter byte 0
    scanlines[:, 1:] = rows
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    payload = (
        b"\x89PNG\r\n\x1a\n"
        + _png_chunk(b"IHDR", header)
        + _png_chunk(b"IDAT", zlib.compress(scanlines.tobytes(), 9))
        + _png_chunk(b"IEND", b"")
    )
    out = Path(path)
    out.write_bytes(payload)
    return out
