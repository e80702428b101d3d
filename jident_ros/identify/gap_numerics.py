"""The gap fits' numerical kernels (identify/gap_free.py's, issue 20's per-window budget): cumulative trapezoids, the
change-point scans' cumulative sums and closed-form 3 x 3 inverse, the change-point refits' row pairs, numpy's
np.diff(x, 2), np.sign(np.gradient(x)) and np.median as their own steps, the robust noise scale, the encoder quantum and
the double trapezoid's adjoint; and the memos, each a :class:`ScopedMemo`: one window's torque-independent decisions
(:func:`window_memo`) and an evaluation's fits (:func:`fit_cache`, moved here from gap.py when gap.py was split by fit,
issue 20: the split-off fits memoise through it).  Each kernel gives numpy's numbers bit for bit, or (the closed-form
inverse, a decision only) LAPACK's to rounding; test/test_gap_speed.py checks them.  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from contextlib import contextmanager
from functools import lru_cache, wraps

import numpy as np

try:
    # np.einsum without its Python wrapper: with optimize=False (its default) np.einsum passes its operands (and out)
    # to this very function
    from numpy._core._multiarray_umath import c_einsum as _einsum
except ImportError:                                      # pragma: no cover - another numpy
    _einsum = np.einsum


def _cumtrapz(x: np.ndarray, ts: float) -> np.ndarray:
    out = np.empty(x.size)
    out[0] = 0.0
    (0.5 * (x[1:] + x[:-1])).cumsum(out=out[1:])
    return out * ts


#: The unique elements of a symmetric 3 x 3 matrix, row-major upper triangle: (0,0) (0,1) (0,2) (1,1) (1,2) (2,2).
_SYM3_I = np.array([0, 0, 0, 1, 1, 2])
_SYM3_J = np.array([0, 1, 2, 1, 2, 2])


def _scan_sums(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cumulative sums over the rows of X (n x 3) and y, with a zero row in front, (n + 1, 10): the unique elements of
    x xᵀ (:data:`_SYM3_I`, :data:`_SYM3_J`), x y and y²; a row range's normal equations are a difference of two rows."""
    n = X.shape[0]
    S = np.empty((n + 1, 10))
    S[0] = 0.0
    np.multiply(X[:, _SYM3_I], X[:, _SYM3_J], out=S[1:, :6])
    np.multiply(X, y[:, None], out=S[1:, 6:9])
    np.multiply(y, y, out=S[1:, 9])
    S[1:].cumsum(axis=0, out=S[1:])
    return S


def _sym3_inverse(U: np.ndarray) -> np.ndarray:
    """Inverses, (k, 3, 3), of a stack of symmetric 3 x 3 matrices given by their unique elements (k, 6) (order
    :data:`_SYM3_I`), each regularised by 1e-12 of its mean diagonal element, by the adjugate over the determinant.

    The change-point scans' normal matrices (34-190 of them per scan): numpy's batched ``inv`` (and ``solve``) calls
    LAPACK once per matrix, ~0.5 us each, so a scan's inverses cost 20-100 us; the closed form is a few dozen array
    operations for the whole stack.  It serves a decision (the χ² and forecast tests), not a published number:
    equal to LAPACK's to rounding for the scaled, regularised matrices the scans build."""
    a, b, c, d, e, f = U.T
    t = (a + d + f) * (1e-12 / 3.0)
    a, d, f = a + t, d + t, f + t
    i00, i01, i02 = d * f - e * e, c * e - b * f, b * e - c * d
    i11, i12, i22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * i00 + b * i01 + c * i02
    return (np.array([i00, i01, i02, i01, i11, i12, i02, i12, i22]) / det).T.reshape(-1, 3, 3)


@lru_cache(maxsize=256)
def _trim_rows(n: int, trims: tuple, both: tuple = ()) -> tuple:
    """Row bounds (lo, hi) of the intervals [k, n) and [0, n - k) for k in ``trims``, and [k, n - k) for k in ``both``
    (the change-point term)."""
    lo = np.array([k for k in trims] + [0 for _ in trims] + list(both), dtype=np.intp)
    hi = np.array([n for _ in trims] + [n - k for k in trims] + [n - k for k in both], dtype=np.intp)
    return lo, hi


def _ar1_inflation(res: np.ndarray) -> float:
    """The variance factor (1 + ρ)/(1 − ρ) of a least-squares slope whose residual ``res`` has lag-1 autocorrelation
    ρ > 0 (quantisation at low speed, a misfit; ρ <= 0 is not credited; 1 − ρ at least 1e-6)."""
    rr = float(res @ res)
    rho = max(float(res[1:] @ res[:-1]) / rr, 0.0) if rr > 0 else 0.0
    return (1.0 + rho) / max(1.0 - rho, 1e-6)


def _diff2(x: np.ndarray) -> np.ndarray:
    """``np.diff(x, 2)`` of a 1-D array: the same two subtractions, without np.diff's generic set-up."""
    d = x[1:] - x[:-1]
    return d[1:] - d[:-1]


def _gradient_sign(x: np.ndarray) -> np.ndarray:
    """``np.sign(np.gradient(x))`` (unit spacing, first-order ends): the sign of the central difference inside and of
    the one-sided ones at the ends (np.gradient's halving does not change a sign), without np.gradient's generic-axis
    set-up (most of its cost on a short array)."""
    d = np.empty(x.size)
    np.subtract(x[2:], x[:-2], out=d[1:-1])
    d[0] = x[1] - x[0]
    d[-1] = x[-1] - x[-2]
    return np.sign(d)


def _quantum(alpha: np.ndarray) -> float:
    """The encoder's count (the smallest non-zero second difference: whole counts on a quantised angle), 0
    when the angle looks continuous."""
    d = np.abs(_diff2(alpha))
    d = d[d > 1e-10 * max(1.0, float(np.abs(alpha).max()))]     # a zero second difference, to rounding
    if d.size < 5:
        return 0.0
    # a quantised angle moves by whole counts: the second differences are integer multiples of the count; the
    # smallest one may be several counts (try its 1/1 .. 1/4, the largest that divides them all)
    q0 = float(d.min())
    for div in (1, 2, 3, 4):
        q = q0 / div
        k = d / q
        if float(np.abs(k - np.rint(k)).max()) < 0.01:
            return q
    return 0.0


def _median(x: np.ndarray) -> np.float64:
    """``np.median`` of a 1-D float array, bit for bit (the middle one or two of a partition, averaged as numpy's
    mean sums: from +0.0; NaN when one is NaN), without its generic-axis overhead (a third of its time)."""
    n = x.size
    h = n // 2
    if n % 2:
        part = np.partition(x, (h, n - 1))
        m = (0.0 + part[h]) / 1.0
    else:
        part = np.partition(x, (h - 1, h, n - 1))
        m = (0.0 + part[h - 1] + part[h]) / 2.0
    return np.float64(np.nan) if np.isnan(part[-1]) else m


def _robust_noise(x: np.ndarray) -> float:
    d2 = _diff2(np.asarray(x, float))
    if d2.size < 3:
        return 0.0
    return float(1.4826 * _median(np.abs(d2 - _median(d2))) / np.sqrt(6.0))


def _double_trapz_adjoint(row: np.ndarray, ts: float) -> np.ndarray:
    """G = Wᵀ row with (W x)_k = the double trapezoid integral of x from the first row to row k."""
    n = row.size
    # single trapezoid T: (T x)_k = ts (x_0/2 + x_1 + ... + x_{k-1} + x_k/2) for k >= 1, 0 for k = 0
    def t_adj(v):
        # (Tᵀ v)_i = ts Σ_k v_k w_ki ; w_ki = 1/2 at i = 0 or i = k (k>=1), 1 for 0 < i < k
        if n < 2:
            return np.zeros(n)
        rev = v[::-1].cumsum()[::-1]          # Σ_{k >= i} v_k
        out = 0.5 * v
        out[0] = 0.5 * float(rev[1])
        out[1:n - 1] += rev[2:]                  # + Σ_{k > i} v_k
        out *= ts
        return out
    return t_adj(t_adj(row))


def chi2_upper(dof: np.ndarray, z: float) -> np.ndarray:
    """The quantile of χ² with ``dof`` degrees of freedom at the normal quantile ``z`` (gap_free's CHANGEPOINT_P,
    gap_load's LOAD_CHANGEPOINT_P) by Wilson-Hilferty: within 1 % of scipy's from 3 degrees of freedom on; a scipy
    call per scan cost more than the scan."""
    v = np.asarray(dof, float)
    c = 2.0 / (9.0 * v)
    return v * (1.0 - c + z * np.sqrt(c)) ** 3


@lru_cache(maxsize=64)
def chi2_bounds(n: int, p: int, z: float) -> np.ndarray:
    """:func:`chi2_upper` of max(k - p, 1) degrees of freedom for k = 0 .. n, a χ² test's quantile for every interval
    length (read-only: shared)."""
    out = chi2_upper(np.maximum(np.arange(n + 1) - p, 1), z)
    out.flags.writeable = False
    return out


class ScopedMemo:
    """A memo (a dict) kept only while :meth:`scope` is active: ``memo`` is None outside it (nothing kept); nested
    scopes share the outer one's dict, dropped when the outermost one ends.  :func:`window_memo`'s and
    :func:`fit_cache`'s (one class for the two scoped dicts that were each a module global)."""

    __slots__ = ("memo",)

    def __init__(self):
        self.memo: dict | None = None

    @contextmanager
    def scope(self):
        outer = self.memo
        if outer is None:
            self.memo = {}
        try:
            yield
        finally:
            if outer is None:
                self.memo = None


#: The decisions kept while one window is estimated (:func:`window_memo`; its ``memo`` None outside it).
WINDOW_MEMO = ScopedMemo()


def window_memo():
    """Keep the torque-independent decisions of one window's fits (the free angle fit's candidate intervals, the load
    side's free bound) while active: a window's lag check (gap._lag_checked) and its cross-check fit the same rows
    again with another declared lag, and these decisions do not read the lag.  Scoped to one call of
    gap.estimate_inertia, so nothing is kept from one window (or one monkeypatched constant) to the next.  Nested
    uses share the outer one's memo."""
    return WINDOW_MEMO.scope()


def memo_get(key):
    """The value kept under ``key`` in the active :func:`window_memo` (None: none kept, or no memo active)."""
    memo = WINDOW_MEMO.memo
    return None if memo is None else memo.get(key)


def memo_put(key, value):
    """Keep ``value`` under ``key`` in the active :func:`window_memo` (nothing outside one); returns ``value``."""
    memo = WINDOW_MEMO.memo
    if memo is not None:
        memo[key] = value
    return value


#: Memo of the angle fits (gap_angle._angle_fits), gap_a1._joint_fit and gap_steady.pre_entry_steady while
#: :func:`fit_cache` is active (its ``memo`` None: off, the default).
FIT_MEMO = ScopedMemo()


def fit_cache():
    """Memoise the angle fits (free angle fit and steady-entry fit), the joint a1 fit and the pre-entry steadiness
    test by their inputs while active.

    An evaluation runs several channel sets on one window: the cross-checked model choice ('auto' with a1 and
    alpha1) and the 'angle' fit over the same alpha1, torque and gap interval do the same angle fits, and the a1
    fits of two channel sets (the interval from the angles and from the a1 signature) test the same pre-entry
    torque and often fit the same interval; with the cache the second is a lookup (the same
    inputs give the same numbers: pure functions of them).  Off by
    default (the runtime path sees each window once); the research evaluation turns it on around a sweep."""
    return FIT_MEMO.scope()


def _memoised(fn):
    """``fn`` memoised by its arguments' values while :func:`fit_cache` is active (arrays by their bytes)."""
    def key_of(v):
        if isinstance(v, np.ndarray):
            return v.dtype.str, v.shape, v.tobytes()
        if isinstance(v, dict):
            return tuple((k, key_of(x)) for k, x in sorted(v.items()))
        if isinstance(v, (tuple, list)):
            return type(v).__name__, tuple(key_of(x) for x in v)
        return v

    @wraps(fn)
    def wrapper(*args, **kwargs):
        memo = FIT_MEMO.memo
        if memo is None:
            return fn(*args, **kwargs)
        key = (fn.__name__, tuple(key_of(a) for a in args), tuple((k, key_of(v)) for k, v in sorted(kwargs.items())))
        try:
            return memo[key]
        except KeyError:
            out = memo[key] = fn(*args, **kwargs)
            return out
    return wrapper
