"""``numpy.linalg.solve``, ``inv`` and ``lstsq`` for float64 arrays, without their per-call argument handling.

The gap stage solves ~30 small systems a window (the joint a1 fit's Newton steps on 4 x 4 and 5 x 5 normal equations,
the free angle fit's and the kink fit's 3 x 3 and 4 x 4 ones) and a few least squares; numpy.linalg's Python wrappers
(array conversion, dtype resolution, shape checks: ~25 Python calls each) cost more than the LAPACK call on such
sizes.  These functions call the same LAPACK gufuncs numpy.linalg calls (``numpy.linalg._umath_linalg``), with the
same arguments and the same floating-point error handling (a singular matrix raises LinAlgError), so every number is
the one numpy.linalg returns, bit for bit (test_gap_speed.py compares them).  Anything but float64 arrays, or a numpy
without that module, goes to numpy.linalg itself.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import numpy as np

try:
    # numpy 2's numpy.linalg calls these with the arguments below (1.x named and dispatched them differently)
    if np.lib.NumpyVersion(np.__version__) < "2.0.0":
        raise ImportError("numpy < 2")
    from numpy.linalg import _umath_linalg as _gufuncs

    _SOLVE1, _SOLVE, _INV, _LSTSQ = _gufuncs.solve1, _gufuncs.solve, _gufuncs.inv, _gufuncs.lstsq
except (ImportError, AttributeError):          # pragma: no cover - another numpy: numpy.linalg itself
    _gufuncs = None

_EPS = float(np.finfo(np.float64).eps)
_F8 = np.dtype(np.float64)


def _singular(err, flag):
    raise np.linalg.LinAlgError("Singular matrix")


def _no_convergence(err, flag):
    raise np.linalg.LinAlgError("SVD did not converge in Linear Least Squares")


try:
    # np.errstate(call=..., invalid="call", over/divide/under="ignore") as numpy's errstate.__enter__ sets it, built once
    # (errstate builds its state object on every entry: ~1 us a call, as much as a small solve)
    from numpy._core import _ufunc_config

    _CONTEXT = _ufunc_config._extobj_contextvar
    _STATE_SINGULAR = _ufunc_config._make_extobj(call=_singular, invalid="call", over="ignore", divide="ignore",
                                                 under="ignore")
    _STATE_NO_CONVERGENCE = _ufunc_config._make_extobj(call=_no_convergence, invalid="call", over="ignore",
                                                       divide="ignore", under="ignore")
except (ImportError, AttributeError, TypeError):          # pragma: no cover - another numpy: np.errstate itself
    _CONTEXT = None


def _float64(a, b=None) -> bool:
    """Whether the gufuncs apply: float64 ndarrays (and the module found)."""
    if _gufuncs is None or type(a) is not np.ndarray or a.dtype != _F8:
        return False
    return b is None or (type(b) is np.ndarray and b.dtype == _F8)


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.solve(a, b)``: a (..., M, M), b (M,) or (..., M, K)."""
    if not _float64(a, b):
        return np.linalg.solve(a, b)
    if _CONTEXT is None:                                  # pragma: no cover - another numpy
        with np.errstate(call=_singular, invalid="call", over="ignore", divide="ignore", under="ignore"):
            return (_SOLVE1 if b.ndim == 1 else _SOLVE)(a, b, signature="dd->d")
    token = _CONTEXT.set(_STATE_SINGULAR)
    try:
        return (_SOLVE1 if b.ndim == 1 else _SOLVE)(a, b, signature="dd->d")
    finally:
        _CONTEXT.reset(token)


def inv(a: np.ndarray) -> np.ndarray:
    """``np.linalg.inv(a)``: a (..., M, M)."""
    if not _float64(a):
        return np.linalg.inv(a)
    if _CONTEXT is None:                                  # pragma: no cover - another numpy
        with np.errstate(call=_singular, invalid="call", over="ignore", divide="ignore", under="ignore"):
            return _INV(a, signature="d->d")
    token = _CONTEXT.set(_STATE_SINGULAR)
    try:
        return _INV(a, signature="d->d")
    finally:
        _CONTEXT.reset(token)


def lstsq(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.lstsq(a, b, rcond=None)[0]`` for a (M, N) with M > 0 and b (M,): the solution only."""
    if not _float64(a, b) or a.ndim != 2 or b.ndim != 1 or a.shape[0] == 0:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    m, n = a.shape
    if _CONTEXT is None:                                  # pragma: no cover - another numpy
        with np.errstate(call=_no_convergence, invalid="call", over="ignore", divide="ignore", under="ignore"):
            x = _LSTSQ(a, b[:, None], _EPS * max(n, m), signature="ddd->ddid")[0]
        return x[:, 0]
    token = _CONTEXT.set(_STATE_NO_CONVERGENCE)
    try:
        x = _LSTSQ(a, b[:, None], _EPS * max(n, m), signature="ddd->ddid")[0]
    finally:
        _CONTEXT.reset(token)
    return x[:, 0]


def _self_check() -> bool:
    """The private gufuncs agree with numpy.linalg on a probe, bit for bit (a numpy whose private calling convention
    moved is caught here, once at import, instead of failing -- or answering differently -- in a window)."""
    a = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]])
    b = np.array([1.0, 2.0, 3.0])
    m = np.vstack([a, [[1.0, -1.0, 0.5]]])
    y = np.array([1.0, 2.0, 3.0, 0.5])
    try:
        return (np.array_equal(solve(a, b), np.linalg.solve(a, b))
                and np.array_equal(solve(a[None], b[None, :, None]), np.linalg.solve(a[None], b[None, :, None]))
                and np.array_equal(inv(a), np.linalg.inv(a))
                and np.array_equal(lstsq(m, y), np.linalg.lstsq(m, y, rcond=None)[0]))
    except Exception:           # noqa: BLE001 - any failure of the private path: numpy.linalg itself
        return False


if _gufuncs is not None and not _self_check():     # pragma: no cover - a numpy that moved its gufuncs
    _gufuncs = None
