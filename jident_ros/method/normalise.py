"""Normalisation of the scalogram image, paper eqs. (2)–(22), (23), (34)–(35).

Shapes: a signal window is (n_samples,) = (2048,); an image X1 is (343, 436).
Paper symbols in brackets.  The readings chosen where the paper is ambiguous are
documented in docs/method.md next to each equation number:

* eqs. (5) then (2) are two min–max maps onto the same kind of range
  [k3, 2 k3 − h3]; composed they are one affine map of the image X1 onto the
  range of the *tested* window (eq. 2's h3, k3), which is what we compute.
* eqs. (10)–(11), "first case" (a1, v2): h4 = min − max, k4 = min + max of the
  2048 samples.
* eqs. (12)–(21), "second case" (m_el, omega1, a2): the window sorted in
  descending order (eq. 22); m_e,L = the smallest of the L largest samples,
  m_d,L = their mean, L = 768, 1024, 1280, 1536; d_L = m_e,L − m_d,L.
  Eq. (12) literally reads h4 = d_1024 + d_1024 + d_1280 (a term repeated);
  the corrected reading (default) is h4 = d_768 + d_1024 + d_1280, the
  pattern of eq. (13) k4 = d_768 − d_1024 − d_1280 − d_1536.
  ``eq12="literal"`` keeps the printed form.
* eqs. (8)–(9): h3 = min(h4, k4), k3 = max(h4, k4).
* eq. (23): initial KHM centres S = 1 − k3; eq. (35): S1 = 1 − h3 (the
  paper's h_d3 is h3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Which of the paper's two cases each signal belongs to (section 4).
FIRST_CASE = ("a1", "v2")
SECOND_CASE = ("m_el", "omega1", "a2")
#: Prefix lengths of the sorted window used by eqs. (14)–(21).
PREFIX_LENGTHS = (768, 1024, 1280, 1536)


@dataclass(frozen=True)
class RangeParams:
    """The normalisation range of one window.

    Attributes
    ----------
    h4, k4 : float
        Eqs. (10)–(13).
    h3, k3 : float
        Eqs. (8)–(9): start and end of the range; the image is mapped onto
        [k3, 2 k3 − h3] (width k3 − h3).
    """

    h4: float
    k4: float

    @property
    def h3(self) -> float:
        return min(self.h4, self.k4)

    @property
    def k3(self) -> float:
        return max(self.h4, self.k4)


def _check_window(x, name="signal"):
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 2:
        raise ValueError(f"{name}: expected a 1-D window of >= 2 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: contains NaN or Inf (first at sample {int(np.flatnonzero(~np.isfinite(x))[0])})")
    return x


def sorted_prefix_stats(x) -> tuple[np.ndarray, np.ndarray]:
    """[m_e,L] and [m_d,L] of eqs. (14)–(22) for L in PREFIX_LENGTHS.

    The prefix lengths are fractions 3/8, 1/2, 5/8, 3/4 of 2048; for other
    window lengths the same fractions are used.
    """
    x = _check_window(x)
    n1 = np.sort(x)[::-1]  # eq. (22): descending
    lengths = [max(1, int(round(L * x.size / 2048))) for L in PREFIX_LENGTHS]
    me = np.array([n1[L - 1] for L in lengths])
    md = np.array([n1[:L].mean() for L in lengths])
    return me, md


def range_params(x, signal: str, eq12: str = "corrected") -> RangeParams:
    """h4 and k4 (hence h3, k3) of one window of the named signal."""
    x = _check_window(x, signal)
    if eq12 not in ("corrected", "literal"):
        raise ValueError(f"eq12: expected 'corrected' or 'literal', got {eq12!r}")
    if signal in FIRST_CASE:
        lo, hi = float(x.min()), float(x.max())
        return RangeParams(lo - hi, lo + hi)
    if signal in SECOND_CASE:
        me, md = sorted_prefix_stats(x)
        d = me - md
        h4 = d[0] + d[1] + d[2] if eq12 == "corrected" else d[1] + d[1] + d[2]
        k4 = d[0] - d[1] - d[2] - d[3]
        return RangeParams(float(h4), float(k4))
    raise ValueError(f"signal: expected one of {FIRST_CASE + SECOND_CASE}, got {signal!r}")


def map_to_range(image, rp: RangeParams) -> np.ndarray:
    """Eqs. (5) and (2): affine map of the image onto [k3, 2 k3 − h3].

    A constant image (k1 = h1) maps to k3 everywhere.
    """
    img = np.asarray(image, dtype=float)
    lo, hi = float(img.min()), float(img.max())
    width = rp.k3 - rp.h3
    if hi == lo:
        return np.full(img.shape, rp.k3)
    return (img - lo) * (width / (hi - lo)) + rp.k3


def map_levels(levels, image_min: float, image_max: float, rp: RangeParams) -> np.ndarray:
    """Same map as :func:`map_to_range` applied to a few distinct intensity levels."""
    lv = np.asarray(levels, dtype=float)
    if image_max == image_min:
        return np.full(lv.shape, rp.k3)
    return (lv - image_min) * ((rp.k3 - rp.h3) / (image_max - image_min)) + rp.k3


def initial_centre(rp: RangeParams) -> float:
    """Eq. (23): S = 1 − k3 (the same for all seven centres)."""
    return 1.0 - rp.k3


def h5_factor(centres: np.ndarray, ranges: list[RangeParams]) -> float:
    """Eq. (34): h5 = max(S, S1) / min(|h3|, k3) over a pattern set.

    ``centres`` are the pattern centres S (any shape) and S1 = 1 − h3 (eq. 35)
    per pattern.  The paper's denominator min(|h3|, k3) can be negative or
    zero when k3 <= 0 (a1 with |min| > max); we take min(|h3|, |k3|) and the
    absolute value of the ratio: h5 only scales H, so it never changes the
    argmin; it keeps H positive as the paper's tables are.
    """
    s1 = np.array([1.0 - r.h3 for r in ranges])
    num = max(float(np.max(centres)), float(np.max(s1)))
    den = min(min(abs(r.h3), abs(r.k3)) for r in ranges)
    if den == 0:
        return 1.0
    return abs(num / den)
