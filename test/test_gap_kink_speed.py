"""The steady-entry (kink) fit's shortcuts against their plain computation (issue 20's per-window cost).

gap_kink._kink_phi forms every candidate's trapezoid sums from the earliest entry row on and writes an unloading
coupling's terms only where they differ from a rigid coupling's (its R + 1 terms from the one before the kink row): the
same Φ to the last bit; gap_kink._kink_candidates fits the candidates by projecting (1, t) out (to rounding: κ within
1e-9, the same best candidate), and kink_locate's published fit is the plain computation's chosen candidate's, bit for
bit; gap_kink.kink_lag_variants interpolates the moved torque only over the rows the refits read (bit for bit).  The
plain computation they replace is written out here (the code of fe4eda0)."""
import numpy as np
import pytest

from jident_ros.identify import gap_kink, lapack
from jident_ros.identify.gap_kink import KINK_T0_ROWS


def _plain_phi(m, ts, entries, P, end, unload=None):
    """fe4eda0's Φ (candidate, row) of _plain_candidates: the torque's double trapezoid from each entry row."""
    rows = np.arange(P, end)
    s_arr = np.asarray(entries)
    n = end - P
    mm = m[..., P:end]
    keep = np.arange(n - 1)[None, :] >= (s_arr - P)[:, None]
    half = np.where(keep, 0.5 * (mm[..., 1:] + mm[..., :-1]), 0.0)
    if unload is not None:
        r_arr = np.asarray(unload)[:, None]
        w = np.clip((rows[None, :] - s_arr[:, None]) / np.maximum(r_arr, 1), 0.0, 1.0)
        csum = np.concatenate([np.zeros(mm.shape[:-1] + (1,)), np.cumsum(mm, axis=-1)], axis=-1)
        k0 = np.minimum(KINK_T0_ROWS, s_arr - P)
        c_idx = np.arange(s_arr.size)
        t0 = ((csum[s_arr - P] - csum[s_arr - P - k0]) if mm.ndim == 1
              else (csum[c_idx, s_arr - P] - csum[c_idx, s_arr - P - k0])) / k0
        free = np.where(rows[None, :] >= s_arr[:, None], mm - t0[:, None] * (1.0 - w), 0.0)
        half = np.where(r_arr > 0, 0.5 * (free[:, 1:] + free[:, :-1]), half)
    c1 = np.zeros((s_arr.size, n))
    half.cumsum(axis=1, out=c1[:, 1:])
    c1 *= ts
    phi = np.zeros((s_arr.size, n))
    (0.5 * (c1[:, 1:] + c1[:, :-1])).cumsum(axis=1, out=phi[:, 1:])
    return phi * ts


def _plain_candidates(m, ts, entries, P, end, y, unload=None, bounds=None):
    """gap_kink._kink_candidates as fe4eda0 computed it: every (candidate, row) array over all rows [P, end)."""
    rows = np.arange(P, end)
    s_arr = np.asarray(entries)
    n = end - P
    phi = _plain_phi(m, ts, entries, P, end, unload)
    hi = np.full(s_arr.size, end) if bounds is None else np.asarray(bounds[1])
    u = (rows[None, :] - s_arr[:, None]) * ts / np.maximum((hi - s_arr) * ts, ts)[:, None]
    n_rows = np.full(s_arr.size, float(n))
    y_sum = np.full(s_arr.size, y.sum())
    if bounds is not None:
        inside = (rows[None, :] >= np.asarray(bounds[0])[:, None]) & (rows[None, :] < hi[:, None])
        phi = np.where(inside, phi, 0.0)
        u = np.where(inside, u, 0.0)
        n_rows = inside.sum(axis=1).astype(float)
        y_sum = np.where(inside, y[None, :], 0.0).sum(axis=1)
    scales = np.maximum(np.abs(phi).max(axis=1), 1e-300)
    f = phi / scales[:, None]
    g = np.empty((s_arr.size, 3, 3))
    g[:, 0, 0] = n_rows
    g[:, 0, 1] = g[:, 1, 0] = u.sum(axis=1)
    g[:, 0, 2] = g[:, 2, 0] = f.sum(axis=1)
    g[:, 1, 1] = np.einsum("ij,ij->i", u, u)
    g[:, 1, 2] = g[:, 2, 1] = np.einsum("ij,ij->i", u, f)
    g[:, 2, 2] = np.einsum("ij,ij->i", f, f)
    xty = np.empty((s_arr.size, 3, 1))
    xty[:, 0, 0], xty[:, 1, 0], xty[:, 2, 0] = y_sum, u @ y, f @ y
    coef = lapack.solve(g, xty)[:, :, 0]
    res = y[None, :] - coef[:, :1] - coef[:, 1:2] * u - coef[:, 2:] * f
    if bounds is not None:
        res = np.where(inside, res, 0.0)
    return np.einsum("ij,ij->i", res, res), coef[:, 2] / scales, u, f, scales


def _check(m, entries, P, end, y, unload=None, runs=None):
    """_kink_candidates against the plain computation: Φ bit for bit, κ and the residual sums to rounding (the
    projection route against the 3 x 3 normal equations), and the same best candidate."""
    rss, kappa, phi = gap_kink._kink_candidates(m, 5e-4, entries, P, end, y, unload, runs)
    assert np.array_equal(phi, _plain_phi(m, 5e-4, entries, P, end, unload))
    bounds = None
    if runs is not None:
        bounds = (np.repeat([r[1] + P for r in runs], [r[0] for r in runs]),
                  np.repeat([r[2] + P for r in runs], [r[0] for r in runs]))
    p_rss, p_kappa, _, _, _ = _plain_candidates(m, 5e-4, entries, P, end, y, unload, bounds)
    np.testing.assert_allclose(kappa, p_kappa, rtol=1e-9)
    np.testing.assert_allclose(rss, p_rss, rtol=1e-6, atol=1e-9 * float(p_rss.max()))
    c0 = 0
    for rows, _, _ in (runs or [(len(entries), 0, 0)]):
        assert np.argmin(rss[c0:c0 + rows]) == np.argmin(p_rss[c0:c0 + rows])
        c0 += rows


def _signals(rng, n):
    t = np.arange(n) * 5e-4
    m = 40.0 + 3.0 * np.sin(7.0 * t) + 0.05 * rng.standard_normal(n)
    m[n // 2:] -= rng.uniform(5.0, 40.0)
    a = np.cumsum(np.cumsum(m)) * 1e-7 + 2.0 * t + 1e-5 * rng.standard_normal(n)
    return a, m


@pytest.mark.parametrize("seed", range(6))
def test_the_candidates_are_the_plain_computations(seed):
    """One torque: rigid candidates (unload None), every entry row with every unloading time, and mixed (entry row,
    unloading rows) pairs, over windows that start at row 0 and later."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(120, 400))
    a, m = _signals(rng, n)
    for _ in range(8):
        P = int(rng.integers(0, 40))
        end = int(rng.integers(P + 40, n + 1))
        s0 = int(rng.integers(P + 10, end - 20))
        entries = list(range(s0, min(s0 + int(rng.integers(1, 10)), end - 14)))
        y = a[P:end] - a[entries[0]]
        _check(m, entries, P, end, y)
        pairs = [(s, r) for s in entries for r in (0, 1, 2, 3, 4, 5, 6, 8) if end - s - r >= 6]
        _check(m, [p[0] for p in pairs], P, end, y, [p[1] for p in pairs])
        pick = rng.permutation(len(pairs))[:max(1, len(pairs) // 3)]
        _check(m, [pairs[i][0] for i in pick], P, end, y, [pairs[i][1] for i in pick])


@pytest.mark.parametrize("seed", range(4))
def test_the_stacked_candidates_are_the_plain_computations(seed):
    """A torque per candidate (kink_best_j1's lag variants) and rows per run of candidates (its variants' own rows),
    with and without unloading couplings."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(90, 200))
    a, m = _signals(rng, n)
    ms = np.stack([m, np.roll(m, 1), np.roll(m, -1)])
    for _ in range(6):
        end = n - int(rng.integers(0, 10))
        s0 = int(rng.integers(30, end - 30))
        runs = [(int(rng.integers(1, 6)), max(s0 - 25 + int(rng.integers(0, 3)), 0), end - k) for k in (2, 1, 0, 0)]
        entries = np.array([s0 + int(k) for k in rng.integers(0, 8, sum(r[0] for r in runs))])
        unl = rng.choice([0, 2, 4, 6], entries.size)
        which = rng.integers(0, 3, entries.size)
        y = a[:end] - a[0]
        for u_ in (unl, None):
            _check(ms[which], entries, 0, end, y, u_, runs)


def test_kink_locate_publishes_the_plain_best_candidates_fit_bit_for_bit():
    """kink_locate's J1 and residual are the plain computation's chosen candidate's _kink_solution, to the last bit (the
    candidates' sums only choose it)."""
    rng = np.random.default_rng(7)
    for _ in range(10):
        # a drive steady before the entry row s0: α1 = ω0 t + Φ_s0/J1 (the kink model) plus a quantum's noise
        n = int(rng.integers(150, 300))
        s0 = n // 2 + int(rng.integers(-3, 4))
        m = 40.0 + 0.05 * rng.standard_normal(n)
        m[s0:] += rng.uniform(5.0, 30.0) * (1.0 - np.exp(-np.arange(n - s0) / 10.0))
        phi = np.zeros(n)
        phi[s0:] = np.concatenate([[0.0], np.cumsum(0.5 * (m[s0 + 1:] + m[s0:-1]))]) * 5e-4
        phi[s0:] = np.concatenate([[0.0], np.cumsum(0.5 * (phi[s0 + 1:] + phi[s0:-1]))]) * 5e-4
        a = 3.0 * np.arange(n) * 5e-4 + phi / 1.1 + 1e-6 * rng.standard_normal(n)
        end = n - int(rng.integers(0, 20))
        fit = gap_kink.kink_locate(a, m, 5e-4, range(s0 - 4, s0 + 5), end, (0, 2, 4))
        pairs = sorted({(s, r) for s in range(s0 - 4, s0 + 5) for r in (0, 2, 4)})
        P = pairs[0][0] - 40
        y = a[P:end] - a[pairs[0][0]]
        rss, kappa, u, f, scales = _plain_candidates(m, 5e-4, [p[0] for p in pairs], P, end, y, [p[1] for p in pairs])
        k = int(np.argmin(rss))
        k1, res, _ = gap_kink._kink_solution(u[k], f[k], y, scales[k])
        assert fit["j1"] == 1.0 / k1 and np.array_equal(fit["residual"], res) and fit["start"] == pairs[k][0]


@pytest.mark.parametrize("seed", range(4))
def test_the_lag_variants_refits_are_the_whole_arrays_bit_for_bit(seed):
    """kink_lag_variants moves the torque over the rows its fits read only: those rows are np.interp's over the whole
    array, and kink_best_j1's J1 over them (with the re-contact trims, as gap._kink_refits stacks them) are the same
    as over the whole moved arrays."""
    rng = np.random.default_rng(200 + seed)
    n = int(rng.integers(150, 600))
    a, m = _signals(rng, n)
    end = int(rng.integers(n // 2 + 30, n))
    s0 = int(rng.integers(max(60, n // 2 - 20), n // 2 + 5))
    pairs = sorted({(s0 + int(k), int(r)) for k, r in zip(rng.integers(-3, 4, 9), rng.choice([0, 2, 4], 9))})
    lag = float(rng.uniform(2e-4, 1.5e-3))
    got = gap_kink.kink_lag_variants(m, 5e-4, pairs, end, lag)
    t = np.arange(n, dtype=float)
    plain = [(np.interp(t + sh, t, m), pairs, end) for sh in (-lag / 5e-4, lag / 5e-4)]
    lo = max(0, min(p[0] for p in pairs) - 40)
    for (x, _, _), (z, _, _) in zip(got, plain):
        assert np.array_equal(x[lo:end], z[lo:end])
    trims = [(m, pairs, end - k) for k in (1, 2)]
    fits = gap_kink.kink_best_j1(a, 5e-4, trims + got)
    assert all(isinstance(x, float) for x in fits) and fits == gap_kink.kink_best_j1(a, 5e-4, trims + plain)
