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
* :func:`render_level_histogram` gives the same histogram (and the image's
  extreme intensities) straight from the scalogram, without materialising
  the image: every pixel shows one data cell, so the histogram is a count of
  the drawn cells' levels weighted by how many pixels show each cell
  (:func:`drawn_cells`, :func:`level_histogram_from_cells`).

PNG files of X1 are written with matplotlib (``jident_ros.research.evaluation.report.save_intensity_png``).

Only numpy and the standard library are used.
"""

from __future__ import annotations

import functools

import numpy as np

from jident_ros.method.checks import finite_real_array, int_at_least, short

__all__ = [
    "X1_SHAPE",
    "DEFAULT_N_COLORS",
    "pixel_cell_indices",
    "drawn_cells",
    "render_intensity",
    "intensity_levels",
    "level_histogram",
    "level_histogram_from_cells",
    "render_level_histogram",
]

#: Shape (rows a, columns b) of the paper's intensity matrix X1: the plot
#: area of a default MATLAB figure (343 x 436 pixels, 149,548 pixels).
X1_SHAPE = (343, 436)

#: Length of MATLAB's default colour map before R2014b (``jet(64)``/``gray(64)``).
DEFAULT_N_COLORS = 64

_ORIGINS = ("upper", "lower")


# --------------------------------------------------------------------------
# validation helpers (one-line ValueError naming the argument)
# --------------------------------------------------------------------------


def _check_shape(shape) -> tuple:
    try:
        height, width = shape
    except (TypeError, ValueError):
        raise ValueError(f"shape: expected (n_rows, n_columns), got {short(shape)}") from None
    for value in (height, width):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"shape: expected two positive integers, got {short(shape)}")
    return int(height), int(width)


def _check_origin(origin) -> str:
    if origin not in _ORIGINS:
        raise ValueError(f"origin: expected one of {_ORIGINS}, got {short(origin)}")
    return origin


def _check_image(image) -> np.ndarray:
    array = finite_real_array("image", image, min_ndim=2)
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
        message = f"data_shape: expected (n_scales, n_samples), got {short(data_shape)}"
        raise ValueError(message) from None
    if len(tuple(data_shape)) < 2 or n_rows < 1 or n_columns < 1:
        raise ValueError(f"data_shape: expected two positive sizes, got {short(data_shape)}")
    height, width = _check_shape(shape)
    return _cell_indices_cached(n_rows, n_columns, height, width, _check_origin(origin))


@functools.lru_cache(maxsize=64)
def _drawn_cells_cached(n_rows: int, n_columns: int, height: int, width: int, origin: str):
    rows, columns = _cell_indices_cached(n_rows, n_columns, height, width, origin)
    row_pixels = np.bincount(rows, minlength=n_rows)
    column_pixels = np.bincount(columns, minlength=n_columns)
    drawn_rows = np.flatnonzero(row_pixels)
    drawn_columns = np.flatnonzero(column_pixels)
    out = (drawn_rows, row_pixels[drawn_rows], drawn_columns, column_pixels[drawn_columns])
    for array in out:
        array.setflags(write=False)
    return out


def drawn_cells(data_shape, shape=X1_SHAPE, origin: str = "upper"):
    """The data cells that appear in the image, and how many pixels show each.

    Pixel (a, b) shows cell ``(row_index[a], column_index[b])`` of
    :func:`pixel_cell_indices`, so the cell (r, q) covers
    ``row_pixels(r) * column_pixels(q)`` pixels; cells between pixel centres
    are not drawn.

    Parameters
    ----------
    data_shape, shape, origin
        As in :func:`pixel_cell_indices`.

    Returns
    -------
    rows : ndarray of int, shape (n_drawn_rows,)
        Data rows drawn, ascending (all 10 of a dyadic scalogram; 343 of the
        1024 rows of the linear reading).
    row_pixels : ndarray of int, shape (n_drawn_rows,)
        Pixel rows showing each of them (sums to ``shape[0]``).
    columns : ndarray of int, shape (n_drawn_columns,)
        Data columns drawn, ascending (436 of 2048 samples).
    column_pixels : ndarray of int, shape (n_drawn_columns,)
        Pixel columns showing each of them (sums to ``shape[1]``).
        All four arrays are cached and read-only.
    """
    rows, _ = pixel_cell_indices(data_shape, shape, origin)  # validates the arguments
    n_rows, n_columns = (int(v) for v in tuple(data_shape)[-2:])
    height, width = _check_shape(shape)
    return _drawn_cells_cached(n_rows, n_columns, height, width, origin)


def render_intensity(scalogram, shape=X1_SHAPE, n_colors: int = DEFAULT_N_COLORS, clim=None, origin: str = "upper") -> np.ndarray:
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
    data, (height, width), n_colors, origin, cmin, cmax = _rendering_arguments(scalogram, shape, n_colors, clim,
                                                                               origin)
    rows, columns = _cell_indices_cached(data.shape[-2], data.shape[-1], height, width, origin)
    sampled = data[..., rows[:, None], columns[None, :]]
    return _colour_levels(sampled, cmin[..., None, None], cmax[..., None, None], n_colors) / (n_colors - 1)


def _rendering_arguments(scalogram, shape, n_colors, clim, origin):
    """The checked arguments of a rendering (:func:`render_intensity`, :func:`render_level_histogram`):
    (data, (height, width), n_colors, origin, cmin, cmax), the colour limits of shape ``data.shape[:-2]``
    (each scalogram's minimum and maximum, MATLAB's automatic CLim, or ``clim``)."""
    data = finite_real_array("scalogram", scalogram, min_ndim=2)
    height_width = _check_shape(shape)
    n_colors = int_at_least("n_colors", n_colors, 2)
    origin = _check_origin(origin)
    if clim is None:
        cmin = data.min(axis=(-2, -1))
        cmax = data.max(axis=(-2, -1))
    else:
        limits = finite_real_array("clim", clim, min_ndim=1)
        if limits.shape != (2,) or not limits[0] < limits[1]:
            raise ValueError(f"clim: expected (cmin, cmax) with cmin < cmax, got {short(clim)}")
        cmin = np.full(data.shape[:-2], limits[0])
        cmax = np.full(data.shape[:-2], limits[1])
    return data, height_width, n_colors, origin, cmin, cmax


def _colour_levels(values, cmin, cmax, n_colors: int) -> np.ndarray:
    """MATLAB 'scaled' CDataMapping: colour index - 1 (float, 0..N-1) of every value.

    ``values`` (..., n, m); ``cmin``, ``cmax`` broadcast against it (e.g.
    shape (..., 1, 1)). ``cmax == cmin`` gives level 0.
    """
    span = np.asarray(cmax - cmin)
    flat = span == 0
    scaled = (values - cmin) / np.where(flat, 1.0, span) * n_colors
    level = np.clip(np.trunc(scaled), 0, n_colors - 1)  # index - 1
    if flat.any():
        level = np.where(flat, 0.0, level)
    return level


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
    n_colors = int_at_least("n_colors", n_colors, 2)
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


def level_histogram_from_cells(cells, cmin, cmax, row_pixels, column_pixels,
                               n_colors: int = DEFAULT_N_COLORS):
    """Level histogram of a rendered image, computed from its drawn cells only.

    Equals ``level_histogram(render_intensity(...))`` without the image: the
    cells are mapped to colour levels exactly as :func:`render_intensity`
    maps them, and each cell counts for the number of pixels showing it.

    Parameters
    ----------
    cells : ndarray, shape (..., n_drawn_rows, n_drawn_columns)
        Data values of the drawn cells (see :func:`drawn_cells`).
    cmin, cmax : float or ndarray, shape (...)
        Colour limits of each image (for automatic limits: the minimum and
        maximum over *all* data cells, drawn or not).
    row_pixels : ndarray of int, shape (n_drawn_rows,)
    column_pixels : ndarray of int, shape (n_drawn_columns,)
        Pixels showing each drawn row / column (from :func:`drawn_cells`).
    n_colors : int, optional
        Colour-map length N (default 64).

    Returns
    -------
    level_values : ndarray of float64, shape (N,)
        ``arange(N) / (N - 1)``.
    counts : ndarray of int64, shape (..., N)
        Pixels at each level; sums to ``sum(row_pixels) * sum(column_pixels)``.
    image_min, image_max : ndarray of float64, shape (...)
        Smallest and largest intensity in the image (``X1.min()``, ``X1.max()``).

    Notes
    -----
    No validation: a fast path for callers that hold the drawn cells. Cost:
    one level mapping and one weighted bincount over the drawn cells (4,360
    for a dyadic scalogram instead of 149,548 pixels).
    """
    cells = np.asarray(cells, dtype=np.float64)
    n_colors = int(n_colors)
    batch_shape = cells.shape[:-2]
    cmin = np.broadcast_to(np.asarray(cmin, dtype=np.float64), batch_shape)[..., None, None]
    cmax = np.broadcast_to(np.asarray(cmax, dtype=np.float64), batch_shape)[..., None, None]
    level = _colour_levels(cells, cmin, cmax, n_colors)
    per_image = level.reshape(-1, cells.shape[-2] * cells.shape[-1]).astype(np.intp)
    n_images = per_image.shape[0]
    pixels = np.multiply.outer(np.asarray(row_pixels, dtype=np.float64),
                               np.asarray(column_pixels, dtype=np.float64)).ravel()
    offsets = (np.arange(n_images) * n_colors)[:, None]
    counts = np.bincount((per_image + offsets).ravel(), weights=np.tile(pixels, n_images),
                         minlength=n_images * n_colors)
    counts = counts.astype(np.int64).reshape(batch_shape + (n_colors,))
    level_values = np.arange(n_colors) / (n_colors - 1)
    # every drawn cell covers at least one pixel: the extreme levels are the first and
    # last non-empty bins (cheaper than min/max over the cells)
    occupied = counts.reshape(n_images, n_colors) > 0
    lowest = np.argmax(occupied, axis=1)
    highest = n_colors - 1 - np.argmax(occupied[:, ::-1], axis=1)
    image_min = lowest.reshape(batch_shape) / (n_colors - 1)
    image_max = highest.reshape(batch_shape) / (n_colors - 1)
    return level_values, counts, image_min, image_max


def render_level_histogram(scalogram, shape=X1_SHAPE, n_colors: int = DEFAULT_N_COLORS, clim=None, origin: str = "upper"):
    """Level histogram and extreme intensities of :func:`render_intensity`'s image, without rendering it.

    Parameters
    ----------
    scalogram, shape, n_colors, clim, origin
        As in :func:`render_intensity`; ``scalogram`` has shape
        (..., n_scales, n_samples).

    Returns
    -------
    level_values : ndarray of float64, shape (N,)
    counts : ndarray of int64, shape (..., N)
        Identical to ``level_histogram(render_intensity(...), N)``.
    image_min, image_max : ndarray of float64, shape (...)
        Identical to ``X1.min(axis=(-2, -1))`` and ``X1.max(axis=(-2, -1))``.
    """
    data, _, n_colors, origin, cmin, cmax = _rendering_arguments(scalogram, shape, n_colors, clim, origin)
    rows, row_pixels, columns, column_pixels = drawn_cells(data.shape, shape, origin)
    cells = np.take(np.take(data, columns, axis=-1), rows, axis=-2)   # C-contiguous (..., rows, columns)
    return level_histogram_from_cells(cells, cmin, cmax, row_pixels, column_pixels, n_colors)
