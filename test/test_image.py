"""Tests of jident_ros.method.image (scalogram -> 343 x 436 intensity matrix X1)."""

import warnings

import numpy as np
import pytest

from jident_ros.method import image as im

N_PIXELS = 343 * 436  # 149,548


@pytest.fixture(scope="module")
def scalogram():
    # smooth along time (blocks of 8 samples, wider than a pixel) so that every
    # block, hence the minimum and the maximum, is under some pixel centre
    rng = np.random.default_rng(7)
    data = np.repeat(rng.gamma(0.5, size=(10, 256)), 8, axis=1)
    return 100 * data / data.sum()


def test_output_shape_range_and_levels(scalogram):
    x1 = im.render_intensity(scalogram)
    assert x1.shape == im.X1_SHAPE == (343, 436)
    assert x1.dtype == np.float64
    assert x1.min() == 0.0 and x1.max() == 1.0
    # only the 64 grey levels of gray(64) occur
    np.testing.assert_allclose(x1 * 63, np.rint(x1 * 63), atol=1e-12)


def test_step_is_drawn_at_the_expected_pixel_row_and_column():
    data = np.zeros((10, 2048))
    data[3:, :] = 1.0  # data rows 3..9 (larger scales) are bright
    x1 = im.render_intensity(data)
    # data row 3 starts at 3/10 of the height: 102.9 px; pixel row 102 has its
    # centre at 102.5 (still data row 2), pixel row 103 at 103.5 (data row 3)
    assert np.all(x1[:103] == 0.0)
    assert np.all(x1[103:] == 1.0)
    flipped = im.render_intensity(data, origin="lower")
    np.testing.assert_array_equal(flipped, x1[::-1])

    data = np.zeros((10, 2048))
    data[:, 1000:] = 5.0
    x1 = im.render_intensity(data)
    # sample 1000 starts at 1000/2048 * 436 = 212.9 px
    assert np.all(x1[:, :213] == 0.0)
    assert np.all(x1[:, 213:] == 1.0)


def test_pixel_cell_indices_sample_pixel_centres():
    rows, columns = im.pixel_cell_indices((10, 2048))
    assert rows.shape == (343,) and columns.shape == (436,)
    assert rows[0] == 0 and rows[-1] == 9 and columns[0] == 2 and columns[-1] == 2045
    assert np.all(np.diff(rows) >= 0) and np.all(np.diff(columns) > 0)
    # each data row covers 34 or 35 pixel rows (343 / 10)
    assert set(np.bincount(rows)) <= {34, 35}
    assert im.pixel_cell_indices((10, 2048))[0] is rows  # cached
    # more pixels than cells: every cell is drawn
    rows_small, columns_small = im.pixel_cell_indices((3, 5), shape=(6, 10))
    np.testing.assert_array_equal(rows_small, [0, 0, 1, 1, 2, 2])
    np.testing.assert_array_equal(columns_small, np.repeat(np.arange(5), 2))


def test_cells_between_pixel_centres_are_not_drawn_but_set_the_limits():
    # 2048 samples on 436 columns: like MATLAB's nearest-neighbour image
    # drawing, most samples are skipped, but the colour limits still come from
    # all the data (automatic CLim).
    data = np.zeros((10, 2048))
    data[0, 1] = 100.0  # column 1 is not under any pixel centre
    data[0, 2] = 50.0  # column 2 is (pixel column 0)
    x1 = im.render_intensity(data)
    assert x1.max() == pytest.approx(32 / 63)  # fix(0.5 * 64) + 1 = 33


def test_constant_input_does_not_divide_by_zero():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x1 = im.render_intensity(np.full((10, 2048), 0.004883))
    assert np.all(x1 == 0.0)


def test_scaled_mapping_follows_matlab_formula():
    n = 64
    low, high = -3.0, 5.0
    values = np.array(
        [
            low,
            low + (high - low) * 0.999 / n,  # still index 1
            low + (high - low) * 1.001 / n,  # index 2
            low + (high - low) * 0.5,  # fix(32) + 1 = 33
            high - (high - low) * 0.001 / n,  # index 64
            high,  # fix(64) + 1 = 65, clamped to 64
        ]
    )
    data = np.tile(values[:, None], (1, 8))
    x1 = im.render_intensity(data, shape=(6, 8), n_colors=n)
    expected_index = np.array([1, 1, 2, 33, 64, 64])
    np.testing.assert_allclose(x1[:, 0], (expected_index - 1) / (n - 1))
    assert x1.min() == 0.0 and x1.max() == 1.0


def test_clim_clamps_values_outside_the_limits():
    data = np.array([[-1.0, 0.0, 0.5, 1.0, 2.0]])
    x1 = im.render_intensity(data, shape=(1, 5), n_colors=4, clim=(0.0, 1.0))
    # indices: clamp(1), 1, fix(2)+1 = 3, clamp(5) = 4, clamp = 4
    np.testing.assert_allclose(x1[0], np.array([0, 0, 2, 3, 3]) / 3)


def test_batch_renders_each_scalogram_with_its_own_limits(scalogram):
    batch = np.stack([scalogram, 2 * scalogram + 1, scalogram[::-1]])
    x1 = im.render_intensity(batch)
    assert x1.shape == (3, 343, 436)
    for one, image in zip(batch, x1):
        np.testing.assert_array_equal(image, im.render_intensity(one))
    np.testing.assert_array_equal(x1[0], x1[1])  # affine change: same picture


def test_histogram_counts_reproduce_the_levels(scalogram):
    x1 = im.render_intensity(scalogram)
    levels = im.intensity_levels(x1)
    assert levels.dtype.kind == "i" and levels.min() == 0 and levels.max() == 63
    np.testing.assert_allclose(levels / 63, x1, atol=1e-12)
    level_values, counts = im.level_histogram(x1, 64)
    assert level_values.shape == (64,) and counts.shape == (64,)
    assert counts.sum() == N_PIXELS == 149_548
    np.testing.assert_array_equal(counts, np.bincount(levels.ravel(), minlength=64))
    # weighted histogram gives the same mean intensity as all pixels
    assert np.dot(level_values, counts) / N_PIXELS == pytest.approx(x1.mean(), rel=1e-12)

    _, batch_counts = im.level_histogram(np.stack([x1, 1 - x1]), 64)
    assert batch_counts.shape == (2, 64)
    np.testing.assert_array_equal(batch_counts[0], counts)
    np.testing.assert_array_equal(batch_counts[1], counts[::-1])


def test_x1_png_through_matplotlib(tmp_path, scalogram):
    """The report writes X1 with matplotlib's imsave (the hand-written PNG writer is gone)."""
    from matplotlib.image import imread

    from jident_ros.research.evaluation.report import save_intensity_png
    x1 = im.render_intensity(scalogram)
    path = save_intensity_png(tmp_path / "x1.png", x1, "gray")
    pixels = imread(path)
    assert pixels.shape[:2] == (343, 436)
    np.testing.assert_allclose(pixels[..., 0], x1, atol=1.0 / 255 + 1e-9)
    jet = imread(save_intensity_png(tmp_path / "jet.png", np.array([[0.0, 1.0]]), "jet"))
    assert jet[0, 0, 2] > 0.4 and jet[0, 0, 0] == 0       # dark blue
    assert jet[0, 1, 0] > 0.4 and jet[0, 1, 2] == 0       # dark red


@pytest.mark.parametrize(
    "call, argument",
    [
        (lambda: im.render_intensity(np.ones(5)), "scalogram"),
        (lambda: im.render_intensity(np.array([[1.0, np.nan]])), "scalogram"),
        (lambda: im.render_intensity(np.array([[1.0, -np.inf]])), "scalogram"),
        (lambda: im.render_intensity(np.empty((0, 4))), "scalogram"),
        (lambda: im.render_intensity([[1, 2], [3]]), "scalogram"),
        (lambda: im.render_intensity(np.ones((2, 2)) * 1j), "scalogram"),
        (lambda: im.render_intensity(np.ones((2, 2)), shape=(0, 5)), "shape"),
        (lambda: im.render_intensity(np.ones((2, 2)), shape=(343,)), "shape"),
        (lambda: im.render_intensity(np.ones((2, 2)), n_colors=1), "n_colors"),
        (lambda: im.render_intensity(np.ones((2, 2)), n_colors=64.0), "n_colors"),
        (lambda: im.render_intensity(np.ones((2, 2)), clim=(1.0, 1.0)), "clim"),
        (lambda: im.render_intensity(np.ones((2, 2)), clim=(2.0, 1.0)), "clim"),
        (lambda: im.render_intensity(np.ones((2, 2)), clim=(0.0, np.nan)), "clim"),
        (lambda: im.render_intensity(np.ones((2, 2)), origin="left"), "origin"),
        (lambda: im.intensity_levels(np.full((2, 2), 1.5)), "image"),
        (lambda: im.intensity_levels(np.full((2, 2), -0.1)), "image"),
        (lambda: im.level_histogram(np.zeros((2, 2)), n_colors=0), "n_colors"),
        (lambda: im.pixel_cell_indices((5,)), "data_shape"),
    ],
)
def test_bad_input_raises_value_error_naming_argument(call, argument):
    with pytest.raises(ValueError, match=f"^{argument}: ") as info:
        call()
    assert "\n" not in str(info.value)


# ---------------------------------------------------- histogram without the image
@pytest.mark.parametrize("data_shape,shape", [((10, 2048), (343, 436)), ((1024, 2048), (343, 436)),
                                              ((3, 5), (6, 10)), ((7, 9), (4, 3))])
@pytest.mark.parametrize("origin", ["upper", "lower"])
def test_drawn_cells_count_the_pixels_of_every_cell(data_shape, shape, origin):
    rows, row_pixels, columns, column_pixels = im.drawn_cells(data_shape, shape, origin)
    pixel_rows, pixel_columns = im.pixel_cell_indices(data_shape, shape, origin)
    np.testing.assert_array_equal(rows, np.unique(pixel_rows))
    np.testing.assert_array_equal(columns, np.unique(pixel_columns))
    np.testing.assert_array_equal(row_pixels, np.bincount(pixel_rows)[rows])
    np.testing.assert_array_equal(column_pixels, np.bincount(pixel_columns)[columns])
    assert row_pixels.sum() == shape[0] and column_pixels.sum() == shape[1]
    assert np.all(row_pixels > 0) and np.all(column_pixels > 0)
    assert im.drawn_cells(data_shape, shape, origin)[0] is rows  # cached
    with pytest.raises(ValueError):
        rows[0] = 1


def _rendered_histogram(data, **kwargs):
    x1 = im.render_intensity(data, **kwargs)
    levels, counts = im.level_histogram(x1, kwargs.get("n_colors", im.DEFAULT_N_COLORS))
    return levels, counts, x1.min(axis=(-2, -1)), x1.max(axis=(-2, -1))


@pytest.mark.parametrize("kwargs", [{}, {"origin": "lower"}, {"clim": (0.05, 0.5)}, {"n_colors": 7},
                                    {"shape": (20, 30)}, {"shape": (400, 3000)}])
def test_render_level_histogram_equals_histogram_of_rendered_image(scalogram, kwargs):
    batch = np.stack([scalogram, 3 * scalogram[::-1] + 0.1, scalogram ** 2])
    for data in (scalogram, batch):
        expected = _rendered_histogram(data, **kwargs)
        got = im.render_level_histogram(data, **kwargs)
        for e, g in zip(expected, got):
            assert g.shape == e.shape
            np.testing.assert_array_equal(g, e)
        assert got[1].dtype == np.int64
        shape = kwargs.get("shape", im.X1_SHAPE)
        assert np.all(got[1].sum(axis=-1) == shape[0] * shape[1])


def test_render_level_histogram_of_random_and_constant_data():
    rng = np.random.default_rng(3)
    data = rng.gamma(0.3, size=(4, 1024, 2048))  # the linear reading's shape
    data[1] = 0.25                               # constant: every pixel at level 0
    for e, g in zip(_rendered_histogram(data), im.render_level_histogram(data)):
        np.testing.assert_array_equal(g, e)
    _, counts, lo, hi = im.render_level_histogram(data[1])
    assert counts[0] == 343 * 436 and lo == hi == 0.0


def test_level_histogram_from_cells_weights_cells_by_their_pixels():
    # 2 x 3 drawn cells, rows shown by 1 and 2 pixel rows, columns by 1, 1, 3 pixel columns
    cells = np.array([[0.0, 1.0, 2.0], [3.0, 4.0, 8.0]])
    levels, counts, lo, hi = im.level_histogram_from_cells(cells, 0.0, 8.0, [1, 2], [1, 1, 3], n_colors=4)
    # level = clip(fix(v / 8 * 4), 0, 3): 0, 0, 1 / 1, 2, 3
    np.testing.assert_array_equal(counts, [1 + 1, 3 + 2, 2, 2 * 3])
    np.testing.assert_array_equal(levels, np.arange(4) / 3)
    assert lo == 0.0 and hi == 1.0
    _, counts, lo, hi = im.level_histogram_from_cells(cells[None] + 1.0, [1.0], [9.0], [1, 2], [1, 1, 3], 4)
    assert counts.shape == (1, 4) and lo.shape == hi.shape == (1,)
