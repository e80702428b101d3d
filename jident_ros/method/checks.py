"""Argument checks of the paper pipeline's functions (scalogram, image): a bad argument gives one
ValueError line naming the argument and what it got, never a NumPy traceback."""
from __future__ import annotations

import numpy as np


def short(value) -> str:
    """``repr(value)`` on one line, cut to 60 characters."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def finite_real_array(name: str, value, min_ndim: int = 0) -> np.ndarray:
    """``value`` as a non-empty float64 array of finite real numbers with at least ``min_ndim``
    dimensions, or a one-line ValueError naming ``name``."""
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name}: expected a numeric array, got {short(value)}")
    try:
        array = np.asarray(value)
    except Exception as exc:  # ragged nested sequences and the like
        raise ValueError(f"{name}: not convertible to an array ({exc})") from None
    if array.dtype.kind == "c":
        raise ValueError(f"{name}: expected real values, got complex dtype {array.dtype}")
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


def int_at_least(name: str, value, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum`` (a bool is not an integer here), or a one-line ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer, got {short(value)}")
    if value < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {value}")
    return int(value)
