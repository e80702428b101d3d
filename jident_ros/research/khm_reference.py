"""K-harmonic means as a scikit-learn-like estimator: the reference implementation (research code).

:class:`KHarmonicMeans` (``fit``/``predict``/``membership``/``weights``, ``cluster_centers_``, sample weights,
histograms, damping of the 2-cycles) is the reference the pipeline's batched fit
(:func:`jident_ros.method.khm.khm_fit_batch`, the only KHM the product runs) is tested against
(test/test_khm*.py, test/test_method.py).  The maths, the numerics, the initialisation, the cycles and the damping:
the docstring of :mod:`jident_ros.method.khm`.  Never imported by the runtime (test/test_layers.py).
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np

__all__ = ["KHarmonicMeans", "ConvergenceWarning", "khm_objective"]


class ConvergenceWarning(UserWarning):
    """KHM iteration stopped at ``max_iter`` without converging."""


# Oscillation (2-cycle) detection parameters, see module docstring.
_OSC_COSINE = -0.5          # cos(D_t, D_{t-1}) <= this: the step reverses
_OSC_AMPLITUDE = 0.9        # ||D_t|| >= amplitude * ||D_{t-1}||: not decaying
_OSC_PATIENCE = 2           # consecutive oscillating iterations
_MIN_DAMPING = 1.0 / 1024.0


def _fmt(value):
    try:
        return repr(value) if np.ndim(value) == 0 else f"array with shape {np.shape(value)}"
    except Exception:  # pragma: no cover - defensive
        return repr(value)


def _as_float_array(value, name):
    """``value`` as a float64 array, an (n, 1) column as shape (n,); a ValueError naming ``name`` if not numeric."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {_fmt(value)}") from exc
    if arr.ndim == 2 and arr.shape[1] == 1:
        arr = arr[:, 0]
    return arr


def _check_1d(X, name="X"):
    arr = _as_float_array(X, name)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise ValueError(
            f"{name} must be 1-D data of shape (n_samples,) or (n_samples, 1), "
            f"got shape {np.shape(arr)}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape}); need at least one sample")
    if not np.all(np.isfinite(arr)):
        bad = float(arr[~np.isfinite(arr)][0])
        raise ValueError(f"{name} contains non-finite values (e.g. {bad!r}); "
                         "NaN and Inf are not allowed")
    return np.ascontiguousarray(arr)


def _check_weights(sample_weight, n, name="sample_weight"):
    if sample_weight is None:
        return np.ones(n)
    w = _as_float_array(sample_weight, name)
    if w.ndim != 1 or w.shape[0] != n:
        raise ValueError(f"{name} must have shape ({n},) to match X, got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        bad = float(w[~np.isfinite(w)][0])
        raise ValueError(f"{name} contains non-finite values (e.g. {bad!r})")
    if np.any(w < 0):
        raise ValueError(f"{name} must be non-negative, got {float(w[w < 0][0])!r}")
    if not np.any(w > 0):
        raise ValueError(f"{name} must contain at least one positive value (all are zero)")
    return w


def _log_ratios(x, s):
    """Return (log r, log d_min) with r = d_min / d, d = |x - s|, exact at d = 0."""
    D = np.abs(x[:, None] - s[None, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        logD = np.log(D)
        logdmin = logD.min(axis=1)
        logr = logdmin[:, None] - logD
    # Rows with d_min = 0: coinciding centres get r = 1 (log 0), others r = 0 (-inf).
    zero = D == 0.0
    if zero.any():
        logr[zero] = 0.0
    return logr, logdmin


def _terms(x, s, p):
    """Log-domain building blocks of eqs. 26-27 for data x and centres s.

    Returns (logr, logA, logB, logdmin) where A = sum r^(p+2) and B = sum r^p
    (both >= 1 because r = 1 for the nearest centre).
    """
    logr, logdmin = _log_ratios(x, s)
    rp = np.exp(p * logr)
    rp2 = rp * np.exp(2.0 * logr)
    logA = np.log(rp2.sum(axis=1))
    logB = np.log(rp.sum(axis=1))
    return logr, logA, logB, logdmin


def _log_weight(logA, logB, logdmin, p):
    # log W = (p-2) log d_min + log A - 2 log B ; (p-2)*log(0) is 0 for p == 2.
    if p == 2.0:
        return logA - 2.0 * logB
    with np.errstate(invalid="ignore"):
        return (p - 2.0) * logdmin + logA - 2.0 * logB


def _membership(x, s, p):
    logr, logA, _, _ = _terms(x, s, p)
    return np.exp((p + 2.0) * logr - logA[:, None])


def khm_objective(x, s, p, sample_weight=None):
    """KHM performance function ``sum_x c_x K / sum_i |x - s_i|^(-p)``."""
    x = _check_1d(x)
    s = _check_1d(s, "centers")
    c = _check_weights(sample_weight, x.shape[0])
    _, _, logB, logdmin = _terms(x, s, float(p))
    with np.errstate(divide="ignore", over="ignore"):
        per = np.exp(p * logdmin - logB)
    return float(s.shape[0] * np.dot(c, per))


def _update(x, logc, s, p):
    """One application of eq. 30 (with eqs. 26-27 recomputed from s)."""
    logr, logA, logB, logdmin = _terms(x, s, p)
    logW = _log_weight(logA, logB, logdmin, p)
    # log(c M W) for every (sample, cluster)
    L = (p + 2.0) * logr - logA[:, None] + (logW + logc)[:, None]
    m = L.max(axis=0)
    ok = np.isfinite(m)
    new = s.copy()
    if ok.any():
        # (cluster, sample) layout: pairwise summation along contiguous rows,
        # no BLAS, so identical centres get bit-identical updates.
        E = np.exp(L.T[ok] - m[ok, None])
        new[ok] = (E * x).sum(axis=1) / E.sum(axis=1)
    return new


def _weighted_quantiles(x, c, q):
    # Aggregate equal values first, so that raw samples and their histogram
    # give the same quantiles (midpoint-CDF interpolation between levels).
    xs, inv = np.unique(x, return_inverse=True)
    cs = np.bincount(inv.ravel(), weights=c, minlength=xs.size)
    cdf = (np.cumsum(cs) - 0.5 * cs) / cs.sum()
    return np.interp(q, cdf, xs)


def _iterate(x, logc, s, p, lam, auto, max_iter, thresh):
    """Fixed-point iteration of eq. 30 with optional adaptive damping.

    Returns (centres, n_iter, converged, cycle_detected, lambda, events);
    ``events`` lists ``(iteration, new_lambda)`` for every damping change.
    """
    cycle = False
    converged = False
    events = []
    prev_step, prev_norm, osc = None, 0.0, 0
    best_res, s_best, u_best = np.inf, s, s
    n_iter = 0
    for n_iter in range(1, max_iter + 1):
        u = _update(x, logc, s, p)
        r = u - s
        res = float(np.max(np.abs(r)))
        if res <= thresh:
            s = u
            converged = True
            break
        if res < best_res:
            best_res, s_best, u_best = res, s, u
        step = lam * r
        norm = float(np.sqrt(np.dot(step, step)))
        if prev_step is not None and norm > 0 and prev_norm > 0:
            cos = float(np.dot(step, prev_step)) / (norm * prev_norm)
            if cos <= _OSC_COSINE and norm >= _OSC_AMPLITUDE * prev_norm:
                osc += 1
            else:
                osc = 0
        if osc >= _OSC_PATIENCE:
            cycle = True
            osc = 0
            if auto and lam > _MIN_DAMPING:
                lam = max(0.5 * lam, _MIN_DAMPING)
                events.append((n_iter, lam))
                # restart, damped, from the iterate with the smallest residual
                s = s_best + lam * (u_best - s_best)
                prev_step, prev_norm = None, 0.0
                continue
        s = s + step
        prev_step, prev_norm = step, norm
    return s, n_iter, converged, cycle, lam, events


class KHarmonicMeans:
    """K-harmonic means clustering of 1-D data (paper eqs. 23-30).

    Parameters
    ----------
    n_clusters : int, default 7
        Number of centres K (the paper uses 7).
    p : float, default 2.0
        KHM exponent, ``p >= 2`` (the paper's "additional optimisation parameter").
    init : {"paper", "quantile"} or array of shape (n_clusters,), default "paper"
        "paper": every centre at ``init_value`` (eq. 23: ``1 - k3``), then
        duplicates are spread (see module docstring).  "quantile": weighted
        quantiles of the data.  Array: explicit centres (duplicates spread too).
    init_value : float or None
        Required with ``init="paper"``: the common initial centre ``1 - k3``.
    max_iter : int, default 3000
        Maximum number of eq. 30 updates.
    tol : float, default 1e-10
        Convergence when ``max |F(S) - S| <= tol * data range``.
    damping : "auto", None or float in (0, 1], default "auto"
        "auto": detect 2-cycles and halve the relaxation factor; None: plain
        KHM; float: fixed relaxation factor lambda.
    duplicate_spread : float >= 0, default 1.0
        Width, as a fraction of the data range, of the interval over which
        duplicate initial centres are spread evenly (centred on their value).
        0 keeps duplicates (literal eq. 23; they then never separate).
    compress : "auto", bool, default "auto"
        Cluster the unique values weighted by their counts (exactly equivalent,
        much faster).  "auto": when #unique <= n_samples / 2.

    Attributes
    ----------
    cluster_centers_ : ndarray (n_clusters,), sorted ascending
    init_centers_ : ndarray (n_clusters,), initial centres after spreading
    labels_ : ndarray (n_samples,), ``predict`` of the fitted data
    n_iter_ : int, number of eq. 30 updates performed
    converged_ : bool
    cycle_detected_ : bool, a 2-cycle/oscillation was detected
    damping_used_ : float, final relaxation factor lambda (1.0 = undamped)
    damping_history_ : list of (iteration, lambda), every damping change
    objective_, inertia_ : float, KHM performance function at the final centres
    n_features_in_ : int, always 1
    """

    def __init__(self, n_clusters=7, p=2.0, init="paper", init_value=None,
                 max_iter=3000, tol=1e-10, damping="auto", duplicate_spread=1.0,
                 compress="auto"):
        self.n_clusters = n_clusters
        self.p = p
        self.init = init
        self.init_value = init_value
        self.max_iter = max_iter
        self.tol = tol
        self.damping = damping
        self.duplicate_spread = duplicate_spread
        self.compress = compress

    # ------------------------------------------------------------------ checks
    def _validate_params(self):
        K = self.n_clusters
        if isinstance(K, (bool, np.bool_)) or not isinstance(K, numbers.Integral) or K < 1:
            raise ValueError(f"n_clusters must be an integer >= 1, got {K!r}")
        p = self.p
        if (isinstance(p, (bool, np.bool_)) or not isinstance(p, numbers.Real)
                or not np.isfinite(p)):
            raise ValueError(f"p must be a finite real number >= 2, got {p!r}")
        if p < 2:
            raise ValueError(
                f"p must be >= 2 (paper eqs. 26-30 require p >= 2), got p={float(p)!r}")
        mi = self.max_iter
        if isinstance(mi, (bool, np.bool_)) or not isinstance(mi, numbers.Integral) or mi < 1:
            raise ValueError(f"max_iter must be an integer >= 1, got {mi!r}")
        tol = self.tol
        if not isinstance(tol, numbers.Real) or not np.isfinite(tol) or tol < 0:
            raise ValueError(f"tol must be a finite real number >= 0, got {tol!r}")
        dmp = self.damping
        if not (dmp is None or (isinstance(dmp, str) and dmp == "auto")):
            if (isinstance(dmp, (bool, np.bool_)) or not isinstance(dmp, numbers.Real)
                    or not (0 < dmp <= 1)):
                raise ValueError(
                    f"damping must be 'auto', None or a float in (0, 1], got {dmp!r}")
        sp = self.duplicate_spread
        if (isinstance(sp, (bool, np.bool_)) or not isinstance(sp, numbers.Real)
                or not np.isfinite(sp) or sp < 0):
            raise ValueError(f"duplicate_spread must be a finite real number >= 0, got {sp!r}")
        if not (self.compress == "auto" or isinstance(self.compress, (bool, np.bool_))):
            raise ValueError(f"compress must be 'auto', True or False, got {self.compress!r}")
        return int(K), float(p)

    # -------------------------------------------------------------------- init
    def _initial_centers(self, x, c, K, scale_range):
        init = self.init
        if isinstance(init, str):
            if init == "paper":
                v = self.init_value
                if v is None:
                    raise ValueError(
                        "init='paper' requires init_value (the paper's 1 - k3, eq. 23), "
                        "got init_value=None")
                if (isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real)
                        or not np.isfinite(v)):
                    raise ValueError(f"init_value must be a finite real number, got {v!r}")
                s = np.full(K, float(v))
            elif init == "quantile":
                s = _weighted_quantiles(x, c, (np.arange(K) + 0.5) / K)
            else:
                raise ValueError(
                    f"init must be 'paper', 'quantile' or an array of {K} centres, got {init!r}")
        else:
            s = _check_1d(init, "init").copy()
            if s.shape[0] != K:
                raise ValueError(
                    f"init array must have n_clusters={K} centres, got {s.shape[0]}")
        return self._spread_duplicates(s, scale_range)

    def _spread_duplicates(self, s, data_range):
        s = np.array(s, dtype=np.float64)
        vals, inv, cnt = np.unique(s, return_inverse=True, return_counts=True)
        if np.all(cnt == 1) or self.duplicate_spread == 0:
            return s
        out = s.copy()
        for g in np.flatnonzero(cnt > 1):
            v = vals[g]
            idx = np.flatnonzero(inv == g)
            m = idx.size
            R = data_range if data_range > 0 else max(abs(v), 1.0)
            width = float(self.duplicate_spread) * R
            others = np.delete(out, idx)
            for _ in range(60):
                cand = v + width * (np.arange(m) / (m - 1) - 0.5)
                if np.unique(cand).size == m and not np.isin(cand, others).any():
                    break
                width *= 0.5
            else:  # pragma: no cover - needs pathological floating point input
                raise ValueError(f"could not separate {m} duplicate initial centres at {v!r}")
            out[idx] = cand
        return out

    # --------------------------------------------------------------------- fit
    def fit(self, X, sample_weight=None):
        """Fit KHM to 1-D data ``X`` (optionally weighted, e.g. by counts)."""
        K, p = self._validate_params()
        x_all = _check_1d(X)
        c_all = _check_weights(sample_weight, x_all.shape[0])
        x, c, inv = x_all, c_all, None
        if self.compress is True or self.compress == "auto":
            levels, inverse = np.unique(x_all, return_inverse=True)
            if self.compress is True or levels.size * 2 <= x_all.size:
                x, inv = levels, inverse.ravel()
                c = np.bincount(inv, weights=c_all, minlength=levels.size)
        self._fit_arrays(x, c, K, p)
        # labels are a function of the value only: label the levels, then map back
        self.labels_ = self.predict(x_all) if inv is None else self.predict(x)[inv]
        return self

    def fit_histogram(self, levels, counts):
        """Fit to a histogram: distinct ``levels`` with pixel ``counts``.

        Exactly equivalent to fitting the expanded pixel array.
        """
        K, p = self._validate_params()
        x = _check_1d(levels, "levels")
        c = _check_weights(counts, x.shape[0], "counts")
        self._fit_arrays(x, c, K, p)
        self.labels_ = self.predict(x)
        return self

    def _fit_arrays(self, x, c, K, p):
        keep = c > 0
        if not keep.all():
            x, c = x[keep], c[keep]
        with np.errstate(divide="ignore"):
            logc = np.log(c)
        data_range = float(x.max() - x.min())
        scale = data_range if data_range > 0 else max(float(np.abs(x).max()), 1.0)
        thresh = float(self.tol) * scale

        s = self._initial_centers(x, c, K, data_range)
        self.init_centers_ = s.copy()

        auto = isinstance(self.damping, str)
        lam0 = 1.0 if (auto or self.damping is None) else float(self.damping)
        s, it, converged, cycle, lam, events = _iterate(
            x, logc, s, p, lam0, auto, int(self.max_iter), thresh)
        n_iter = it

        if not converged:
            warnings.warn(
                f"KHarmonicMeans did not converge in max_iter={self.max_iter} iterations "
                f"(p={p}, damping={self.damping!r}, lambda={lam}, cycle_detected={cycle})",
                ConvergenceWarning, stacklevel=3)
        self.cluster_centers_ = np.sort(s)
        self.n_iter_ = n_iter
        self.converged_ = converged
        self.cycle_detected_ = cycle
        self.damping_used_ = lam
        self.damping_history_ = events
        self.objective_ = khm_objective(x, self.cluster_centers_, p, c)
        self.inertia_ = self.objective_
        self.n_features_in_ = 1
        return self

    # ----------------------------------------------------------------- predict
    def _check_fitted(self):
        if not hasattr(self, "cluster_centers_"):
            raise RuntimeError("KHarmonicMeans instance is not fitted yet; call fit first")

    def membership(self, X):
        """Soft memberships M(i|x) of eq. 27, shape (n_samples, n_clusters); rows sum to 1."""
        self._check_fitted()
        return _membership(_check_1d(X), self.cluster_centers_, float(self.p))

    def weights(self, X):
        """KHM weights W(x) of eq. 26, shape (n_samples,)."""
        self._check_fitted()
        p = float(self.p)
        _, logA, logB, logdmin = _terms(_check_1d(X), self.cluster_centers_, p)
        with np.errstate(over="ignore"):
            return np.exp(_log_weight(logA, logB, logdmin, p))

    def predict(self, X):
        """Hard labels: argmax of the memberships (index into ``cluster_centers_``)."""
        return np.argmax(self.membership(X), axis=1)

    def fit_predict(self, X, sample_weight=None):
        return self.fit(X, sample_weight).labels_

    def score(self, X, sample_weight=None):
        """Negative KHM performance function (higher is better, sklearn style)."""
        self._check_fitted()
        return -khm_objective(X, self.cluster_centers_, float(self.p), sample_weight)
