"""K-harmonic means (KHM) clustering of 1-D intensity levels.

Implements the clustering step of the paper (section 4, eqs. 23-30), which
follows Frackiewicz (2011) and the k-harmonic means algorithm of Zhang, Hsu &
Dayal (1999/2000).  With data ``x``, centres ``s_1..s_K``, ``d_i = |x - s_i|``
and ``p >= 2``:

* weight (eq. 26)      ``W(x)   = sum_i d_i^(-p-2) / (sum_i d_i^(-p))^2``
* membership (eq. 27)  ``M(i|x) = d_i^(-p-2) / sum_j d_j^(-p-2)``
* centres (eq. 30)     ``s_i    = sum_x c_x M(i|x) W(x) x / sum_x c_x M(i|x) W(x)``
  (``c_x`` = sample weight, e.g. histogram count; the paper uses ``c_x = 1``)
* performance function ``KHM(X, S) = sum_x c_x K / sum_i d_i^(-p)``
  (stored as ``objective_`` / ``inertia_``).

Iteration order: M and W are computed from the current centres, then the
centres are updated with eq. 30.  The paper's initial ``M = 1`` and ``W = 1``
(eqs. 24-25) are therefore only placeholders: they are overwritten before they
are ever used (using them in eq. 30 would collapse every centre onto the data
mean).

Numerics
--------
* Everything is float64.  Distances are handled through the ratios
  ``r_i = d_min / d_i`` in (0, 1] (``d_min`` = smallest distance of the sample),
  in the log domain: ``M(i|x) = r_i^(p+2) / sum_j r_j^(p+2)`` and
  ``W(x) = d_min^(p-2) sum r^(p+2) / (sum r^p)^2``, so ``d^(-p-2)`` is never
  formed and the fit neither overflows nor underflows to 0/0 for p = 9+ with
  distances anywhere between ~1e-300 and ~1e+300 (``weights()`` returns the
  true W, which can itself exceed float64 for huge distances and large p).
  In eq. 30 the per-cluster products ``c M W`` are rescaled by their maximum
  (the scale cancels in the ratio), so no cluster loses all its weight to
  underflow.
* A sample exactly equal to a centre (``d = 0``) is handled exactly (limit
  ``d -> 0``): it belongs fully to that centre (shared equally if several
  centres coincide with it) and has ``W = 0`` for p > 2, ``W = 1/m`` for p = 2
  (m = number of coinciding centres).  No NaN/Inf is produced.  If a cluster
  gets zero total weight in eq. 30 its centre is left unchanged.

Initialisation and duplicate centres
------------------------------------
``init="paper"`` puts every centre at ``init_value`` (the paper's ``1 - k3``,
eq. 23).  KHM is permutation-symmetric, so identical centres stay identical for
ever (the 7 "centres" would be 7 copies of a 1-centre solution).  Therefore
every group of ``m > 1`` identical initial centres at value ``v`` (whatever
``init``) is replaced, deterministically, by ``m`` evenly spaced values
``v + w * (j/(m-1) - 1/2)``, ``j = 0..m-1``: spread evenly over an interval of
width ``w = duplicate_spread * R`` centred on ``v``, where ``R`` is the range
(max - min) of the samples with positive weight (``max(|v|, 1)`` if all data are
equal).  Example: 7 centres at ``v = 0.2``, data range 1.3, spread 1.0 ->
``-0.45, -0.2333, -0.0167, 0.2, 0.4167, 0.6333, 0.85``.  If a spread value
collides with another initial centre, ``w`` is halved (up to 60 times).
``duplicate_spread=0`` keeps duplicates (literal eq. 23).
``init="quantile"`` uses the weighted quantiles at levels ``(k + 1/2)/K``
(midpoint-CDF interpolation, ``k = 0..K-1``); ``init`` may also be an explicit
array of ``K`` centres.  Initial centres (after spreading) are stored in
``init_centers_``.  Note: KHM has several local optima on histograms with
gaps, so the result can depend on the initialisation (it is deterministic).

Cycles and damping
------------------
Plain KHM is the fixed-point iteration ``S <- F(S)`` of eq. 30.  The most
negative eigenvalue of the Jacobian of ``F`` at the solution is roughly
``-(p - 2)`` (measured: -0.7 at p = 3, -1.05 at p = 3.25, -3.9 at p = 6, -7.0 at
p = 9 on 64-level histograms), so for p above about 3.25 the fixed point is
unstable and the iteration falls into a 2-cycle: the centre vector alternates
between two configurations.  Detection uses the steps
``D_t = S_t - S_{t-1}``: an iteration *oscillates* when the step reverses,
``cos(D_t, D_{t-1}) <= -0.5``, without decaying, ``||D_t|| >= 0.9 ||D_{t-1}||``.
Two consecutive oscillating iterations mark a detected cycle
(``cycle_detected_ = True``).  This covers a settled 2-cycle (the centres come
back to where they were two iterations ago, ``S_t ~= S_{t-2}``, while
``S_t != S_{t-1}``: cosine -1, ratio 1) and the growing period-2 instability
leading to it (cosine ~ -0.8, ratio ~ 3 at p = 9), which is caught after 2-3
iterations.  With ``damping="auto"`` each detection halves the relaxation
factor lambda of ``S_new = S + lambda (F(S) - S)`` (1 -> 0.5 -> 0.25 -> ...,
never below 1/1024) and restarts from the iterate with the smallest residual
(``S_best + lambda (F(S_best) - S_best)``).  Damping with lambda is stable when
``lambda < 2 / (1 - mu_min) ~ 2 / (p - 1)``; auto typically ends at 0.5 for
p in (3.25, 5], 0.25 for p = 6 and 0.125 for p = 9.  Damping does not change the
solution: fixed points of the damped map are exactly those of eq. 30.
``damping=None`` runs plain KHM (cycles are still detected and reported, but not
damped); a float in (0, 1] uses that fixed lambda.  ``damping_used_`` is the
final lambda and ``damping_history_`` lists ``(iteration, lambda)`` changes.

Convergence: ``max_i |F(S)_i - S_i| <= tol * R`` (the undamped fixed-point
residual, relative to the data range ``R``); the last undamped update is then
returned.  KHM converges linearly (slowest Jacobian eigenvalue ~0.9-0.96, and
damping slows that mode further), so ``tol=1e-10`` typically needs 50-600 and
occasionally ~1800 updates; hence the default ``max_iter=3000``.  Final centres
are sorted ascending (1-D data: cluster 0 is the darkest level), so results of
different fits can be compared element-wise (paper eq. 33).

Histogram
---------
Clustering the unique levels with their pixel counts as ``sample_weight`` is
mathematically identical to clustering all pixels (every term of eqs. 26-30
depends on the pixel only through its value).  ``fit_histogram(levels, counts)``
does this explicitly; ``fit`` does it automatically (``compress="auto"``) when
the number of distinct values is at most half the number of samples.
``compress=False`` forces clustering of the raw samples.
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


# ---------------------------------------------------------------------------
# Batched fit: many weighted 1-D histograms at once (the method's hot path)
# ---------------------------------------------------------------------------
def khm_fit_batch(levels, counts, init_values, n_clusters=7, p=2.0, max_iter=3000, tol=1e-9,
                  duplicate_spread=1.0, accelerate=True):
    """Fit KHM to B weighted histograms at once; paper initialisation (eq. 23).

    The same iteration as :class:`KHarmonicMeans` with ``init="paper"`` (and the
    same spreading of the identical initial centres), computed for a whole
    batch with a few array operations per iteration; with ``accelerate=True``
    histograms that have converged leave the batch, so a batch costs about what its slowest
    histogram costs in Python overhead plus the arithmetic of the rows still
    iterating (batching many histograms, e.g. five signals or 168 windows, is
    much cheaper than fitting them one by one).  For p = 2 it reaches the
    class's fixed point; for p >= 3 the relaxation schedules differ and, KHM
    having several local optima, the two may settle in different ones (both
    deterministic; each row's result does not depend on the rest of the batch).  The data of each
    histogram are first mapped to [0, 1] (KHM is equivariant under affine maps
    of the data), so d**(-p) never overflows; distances are divided by the
    per-level minimum distance as in the class.  Updates are relaxed,
    ``S <- S + lam (F(S) - S)``, starting from lam = min(1, 1.8/(p - 1))
    (the update's most negative Jacobian eigenvalue is about -(p - 2), see the
    module docstring) and halved per histogram whenever an oscillation is seen.

    Parameters
    ----------
    levels : array, shape (B, L) or (L,)
        Level values (rows may differ).  Levels with zero count are ignored.
    counts : array, shape (B, L)
        Non-negative weights (pixel counts).
    init_values : array, shape (B,)
        The paper's common initial centre 1 - k3 of each histogram.

    Returns
    -------
    centres : ndarray (B, n_clusters), sorted ascending
    info : dict with ``n_iter`` (int), ``converged`` (B,) bool, ``damping`` (B,) final lam
    """
    counts = np.asarray(counts, dtype=np.float64)
    if counts.ndim == 1:
        counts = counts[None, :]
    B, L = counts.shape
    x = np.broadcast_to(np.asarray(levels, dtype=np.float64), (B, L))
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(counts))):
        raise ValueError("levels/counts: must be finite")
    if np.any(counts < 0):
        raise ValueError(f"counts: must be >= 0, got min {counts.min()!r}")
    if not float(p) >= 2:
        raise ValueError(f"p must be >= 2 (paper eqs. 26-30 require p >= 2), got p={p!r}")
    init = np.broadcast_to(np.asarray(init_values, dtype=np.float64), (B,))
    K = int(n_clusters)
    pos = counts > 0
    if not np.all(pos.any(axis=1)):
        raise ValueError("counts: every histogram needs a positive count")
    big = np.finfo(np.float64).max
    lo = np.where(pos, x, big).min(axis=1)
    hi = np.where(pos, x, -big).max(axis=1)
    rng = hi - lo
    scale = np.where(rng > 0, rng, np.maximum(np.abs(init), 1.0))
    xn = (x - lo[:, None]) / scale[:, None]
    c = counts / counts.sum(axis=1, keepdims=True)
    v = (init - lo) / scale
    # the class spreads duplicates over duplicate_spread x data range, i.e. over
    # duplicate_spread in the normalised units used here
    s = v[:, None] + float(duplicate_spread) * (np.arange(K) / max(K - 1, 1) - 0.5)[None, :]
    p = float(p)
    lam = np.full(B, min(1.0, 1.8 / (p - 1.0)) if p > 2 else 1.0)
    if accelerate:
        s, it, converged = _squarem(xn, c, s, p, lam, tol, max_iter)
        centres = np.sort(s * scale[:, None] + lo[:, None], axis=1)
        return centres, {"n_iter": it, "converged": converged, "damping": lam}
    prev_step = np.zeros((B, K))
    warn = np.zeros(B, dtype=int)
    converged = np.zeros(B, dtype=bool)
    tiny = 1e-150  # floor on distances: r*r stays finite, powers underflow to 0 quietly
    it = 0
    for it in range(1, max_iter + 1):
        d = np.abs(xn[:, None, :] - s[:, :, None])          # (B, K, L)
        np.maximum(d, tiny, out=d)
        dmin = d.min(axis=1, keepdims=True)                  # (B, 1, L)
        r = d / dmin                                         # >= 1
        rp = r ** (-p)                                       # (B, K, L)
        bsum = rp.sum(axis=1, keepdims=True)                 # B_j
        w = (c[:, None, :] * dmin ** (p - 2.0)) / (bsum * bsum)   # c_j dmin^(p-2)/B_j^2
        q = rp / (r * r) * w                                 # M_ij W_j c_j (up to a common factor)
        num = (q * xn[:, None, :]).sum(axis=2)
        den = q.sum(axis=2)
        f = np.where(den > 0, num / np.where(den > 0, den, 1.0), s)
        step = f - s
        res = np.abs(step).max(axis=1)
        newly = (res <= tol) & ~converged
        converged |= newly
        if np.all(converged):
            s = np.where(converged[:, None], np.where(newly[:, None], f, s), s)
            break
        dot = (step * prev_step).sum(axis=1)
        n1 = np.sqrt((step * step).sum(axis=1))
        n0 = np.sqrt((prev_step * prev_step).sum(axis=1))
        osc = (dot <= -0.5 * n1 * n0) & (n1 >= 0.9 * n0) & (n0 > 100 * tol)
        warn = np.where(osc, warn + 1, 0)
        halve = warn >= 2
        lam = np.where(halve, np.maximum(lam * 0.5, 1.0 / 64), lam)
        warn = np.where(halve, 0, warn)
        upd = ~converged
        s = np.where(upd[:, None], s + lam[:, None] * step, np.where(newly[:, None], f, s))
        prev_step = step
    centres = np.sort(s * scale[:, None] + lo[:, None], axis=1)
    return centres, {"n_iter": it, "converged": converged, "damping": lam}


def _khm_update(xn, c, s, p, levels1=None, tiny=1e-150):
    """Eq. (30) with eqs. (26)-(27) for a batch of B histograms: F(s).

    Parameters
    ----------
    xn : ndarray, shape (B, L)
        Level values (normalised to [0, 1] by :func:`khm_fit_batch`).
    c : ndarray, shape (B, L)
        Level weights (pixel counts / total).
    s : ndarray, shape (B, K)
        Current centres.
    p : float
        KHM exponent, >= 2.
    levels1 : ndarray, shape (B, L, 2), optional
        ``stack((xn, ones), axis=2)`` (used for p = 2), precomputed by callers
        that update the same histograms many times.

    Returns
    -------
    ndarray, shape (B, K)
        Updated centres; a cluster whose total weight underflows to zero keeps
        its centre.

    Notes
    -----
    Distances are floored, ``d_il = max(|x_l - s_i|, tiny)``, and divided by
    the per-level minimum ``dmin_l``: with ``r = d / dmin >= 1``,
    ``M(i|x_l) W(x_l) c_l`` is proportional to
    ``q_il = r_il^(-p-2) c_l dmin_l^(p-2) / (sum_i r_il^(-p))^2`` (common
    factors cancel in eq. 30), and ``s_i = sum_l q_il x_l / sum_l q_il``.

    * p = 2 (the default, the per-window hot path) needs squares only:
      ``t = 1 / r^2 = dmin^2 / d^2`` from the squared distances (floored at
      ``tiny^2``), ``q = t^2 c / (sum_i t)^2``, and the two sums over the
      levels are one batched matrix product of q (B, K, L) with
      ``[x, 1]`` (B, L, 2).  This rounds differently from the textbook
      evaluation below (~1e-16 relative per update).
    * p > 2 keeps the textbook evaluation with pow() (the results of the
      accelerated fit are very sensitive to rounding for p = 6, 9, so it is
      not rearranged).
    """
    if p == 2.0:
        if levels1 is None:
            levels1 = np.stack((xn, np.ones_like(xn)), axis=2)
        d = xn[:, None, :] - s[:, :, None]              # (B, K, L)
        np.multiply(d, d, out=d)                         # d^2
        np.maximum(d, tiny * tiny, out=d)
        dmin = np.minimum.reduce(d, axis=1)              # (B, L)
        t = np.divide(dmin[:, None, :], d, out=d)        # r^-2, in (0, 1]
        bsum = np.add.reduce(t, axis=1)                  # (B, L), >= 1
        q = t * t
        q *= (c / (bsum * bsum))[:, None, :]
        nd = np.matmul(q, levels1)                       # (B, K, 2): numerator, denominator
        num, den = nd[..., 0], nd[..., 1]
        if den.all():   # den is a sum of non-negative terms: zero only if they all underflow
            return num / den
        return np.divide(num, den, out=s.copy(), where=den > 0)
    # p > 2: the textbook evaluation (pow()), in place where an input is no longer needed
    d = xn[:, None, :] - s[:, :, None]                  # (B, K, L)
    np.abs(d, out=d)
    np.maximum(d, tiny, out=d)
    dmin = d.min(axis=1, keepdims=True)                  # (B, 1, L)
    r = np.divide(d, dmin, out=d)
    r2 = r * r
    rp = np.power(r, -p)
    bsum = rp.sum(axis=1, keepdims=True)
    w = (c[:, None, :] * dmin ** (p - 2.0)) / (bsum * bsum)
    q = np.divide(rp, r2, out=rp)
    q *= w
    num = np.multiply(q, xn[:, None, :], out=r2).sum(axis=2)
    den = q.sum(axis=2)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), s)


def _squarem(xn, c, s, p, lam, tol, max_iter):
    """SQUAREM (Varadhan & Roland 2008, scheme S3) on the relaxed KHM map.

    g(s) = s + lam (F(s) - s).  One cycle: s1 = g(s), s2 = g(s1), r = s1 - s,
    v = s2 - 2 s1 + s, step length a = -|r|/|v| (at most -1), s' = s - 2 a r + a^2 v,
    then a stabilising s <- g(s').  A cycle whose extrapolation increases the
    residual falls back to s2.  Same fixed points as the plain iteration.

    Rows are independent: a row converges at the first iterate ``s_c`` whose
    residual ``|g(s_c) - s_c| / lam`` is at most ``tol``; it then leaves the
    batch (the remaining rows are compacted, so converged rows cost nothing)
    and its result is ``g(s_c)``.  If ``max_iter`` evaluations run out first,
    converged rows return ``s_c`` and the others their last iterate.

    Parameters
    ----------
    xn, c : ndarray, shape (B, L)
    s : ndarray, shape (B, K), initial centres
    p : float
    lam : ndarray, shape (B,), relaxation factors in (0, 1]
    tol : float
    max_iter : int, budget of F evaluations

    Returns
    -------
    (s (B, K), number of F evaluations, converged (B,) bool)
    """
    B = s.shape[0]
    converged = np.zeros(B, dtype=bool)
    at_conv = s.copy()       # s_c of every converged row
    after_conv = s.copy()    # g(s_c)
    active = np.arange(B)    # rows still iterating; xa, ca, la, levels1 and s hold only these
    xa, ca, la = xn, c, lam
    la2 = la[:, None]
    levels1 = np.stack((xn, np.ones_like(xn)), axis=2) if p == 2.0 else None
    unit = bool(np.all(lam == 1.0))   # g(s) = s + (F(s) - s): skip multiplying by 1
    evals = 0

    def g(x):
        step = _khm_update(xa, ca, x, p, levels1) - x
        return x + (step if unit else la2 * step)   # lam = 1: x + 1 * step == x + step

    while evals < max_iter:
        s1 = g(s)
        r = s1 - s
        res0 = np.maximum.reduce(np.abs(r), axis=1)
        if not unit:
            res0 /= la
        evals += 1
        done = res0 <= tol
        if done.any():
            rows = active[done]
            converged[rows] = True
            at_conv[rows], after_conv[rows] = s[done], s1[done]
            keep = ~done
            if not keep.any():
                return after_conv, evals, converged
            active = active[keep]
            xa, ca, la = xa[keep], ca[keep], la[keep]
            levels1 = None if levels1 is None else levels1[keep]
            la2 = la[:, None]
            s, s1, r, res0 = s[keep], s1[keep], r[keep], res0[keep]
        s2 = g(s1)
        evals += 1
        v = s2 - 2.0 * s1 + s
        nr = np.sqrt(np.add.reduce(r * r, axis=1))
        nv = np.sqrt(np.add.reduce(v * v, axis=1))
        if (nv > 0).all():
            a = np.minimum(-nr / nv, -1.0)
        else:
            a = np.minimum(np.where(nv > 0, -nr / np.where(nv > 0, nv, 1.0), -1.0), -1.0)
        a = a[:, None]
        ext = s - 2.0 * a * r + a * a * v
        new = g(ext)
        evals += 1
        res_new = np.maximum.reduce(np.abs(new - ext), axis=1)
        if not unit:
            res_new /= la
        # bad: the extrapolation increased the residual or is not finite (a NaN/Inf in
        # new makes res_new NaN/Inf, so "not <=" catches both in one comparison)
        bad = ~(res_new <= res0)
        s = np.where(bad[:, None], s2, new) if bad.any() else new
    out = at_conv.copy()     # max_iter reached: converged rows keep s_c
    out[active] = s
    return out, evals, converged
