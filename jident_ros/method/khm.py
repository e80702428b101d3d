"""K-harmonic means (KHM) clustering of 1-D intensity levels.

Implements the clustering step of the paper (section 4, eqs. 23-30) for the pipeline: :func:`khm_fit_batch` fits
many weighted level histograms at once.  The scikit-learn-like estimator ``KHarmonicMeans`` (fit/predict/
membership/weights on any 1-D data; the reference the batched fit is tested against) is research code:
:mod:`jident_ros.research.khm_reference`.  The paper's clustering step
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

import numpy as np

__all__ = ["khm_fit_batch"]


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
    xn, c, s, lo, scale = _normalised(levels, counts, init_values, p, int(n_clusters), duplicate_spread)
    p = float(p)
    lam = np.full(xn.shape[0], min(1.0, 1.8 / (p - 1.0)) if p > 2 else 1.0)
    if accelerate:
        s, it, converged = _squarem(xn, c, s, p, lam, tol, max_iter)
    else:
        s, it, converged, lam = _relaxed_iteration(xn, c, s, p, lam, tol, max_iter)
    centres = np.sort(s * scale[:, None] + lo[:, None], axis=1)
    return centres, {"n_iter": it, "converged": converged, "damping": lam}


def _normalised(levels, counts, init_values, p, K, duplicate_spread):
    """The checked histograms mapped to [0, 1]: (levels xn (B, L), weights c summing to 1 per row, the spread
    initial centres s (B, K), the offsets lo (B,) and scales (B,) that map back)."""
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
    return xn, c, s, lo, scale


def _relaxed_iteration(xn, c, s, p, lam, tol, max_iter):
    """The plain relaxed fixed-point iteration (``accelerate=False``): (s, iterations, converged, final lam)."""
    B, K = s.shape
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
    return s, it, converged, lam


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
        ext = _squarem_point(s, s1, s2, r)
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


def _squarem_point(s, s1, s2, r):
    """SQUAREM's extrapolated point s - 2 a r + a^2 v, v = s2 - 2 s1 + s, a = -|r|/|v| (at most -1; -1 where
    v = 0), per row."""
    v = s2 - 2.0 * s1 + s
    nr = np.sqrt(np.add.reduce(r * r, axis=1))
    nv = np.sqrt(np.add.reduce(v * v, axis=1))
    if (nv > 0).all():
        a = np.minimum(-nr / nv, -1.0)
    else:
        a = np.minimum(np.where(nv > 0, -nr / np.where(nv > 0, nv, 1.0), -1.0), -1.0)
    a = a[:, None]
    return s - 2.0 * a * r + a * a * v
