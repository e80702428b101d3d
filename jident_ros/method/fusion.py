"""One verdict per window from the image method and the gap estimator.

* image vote: each signal's class votes with weight (margin − 1) (a signal whose
  two best classes tie has no say); the class with the largest total wins.  With
  every margin at 1 the paper's fused H decides (:func:`patterns.fuse`).
* gap: the continuous J1 with its 95 % interval (:mod:`gap`) and its nearest class.
* verdict: the best continuous J1 is the gap estimate when there is one (it is
  physics, not pattern matching: docs/method.md), else the voted class's J1.
  ``between_classes`` is set when the gap J1 is farther from its nearest class
  than its interval's half-width and the interval contains no class;
  ``agree`` tells whether the image vote and the gap's nearest class coincide.
Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .gap import GapEstimate, nearest_class


@dataclass(frozen=True)
class Verdict:
    """The fused answer for one window (J1 values in kg m^2)."""

    inertia_kgm2: float                 # best continuous J1 (published on inertia_estimate)
    source: str                         # 'gap' or 'image'
    class_index: Optional[int]          # nearest class, None when between classes
    class_inertia_kgm2: Optional[float]
    between_classes: bool
    image_class_index: Optional[int]    # the margin-weighted vote of the five signals
    gap: Optional[GapEstimate]
    agree: Optional[bool]               # image vote == gap's nearest class (None if either is missing)
    reason: str = ""                    # why the gap estimate is missing, if it is


def image_vote(answers: dict, fused_class_index: Optional[int] = None) -> Optional[int]:
    """Margin-weighted vote of the per-signal classes (SignalAnswer objects)."""
    if not answers:
        return fused_class_index
    n = max(a.class_index for a in answers.values()) + 1
    votes = np.zeros(max(n, 1 + (fused_class_index or 0)))
    for a in answers.values():
        w = a.margin - 1.0 if np.isfinite(a.margin) else 10.0
        votes[a.class_index] += max(w, 0.0)
    if votes.max() <= 0:
        return fused_class_index
    return int(np.argmax(votes))


def fuse_verdict(classes_kgm2, answers: dict | None = None, fused_class_index: Optional[int] = None,
                 gap: Optional[GapEstimate] = None, gap_reason: str = "") -> Verdict:
    """Combine the image answers and the gap estimate of one window."""
    classes = np.asarray(classes_kgm2, dtype=float)
    img = image_vote(answers or {}, fused_class_index)
    if gap is not None:
        k = nearest_class(gap.inertia_kgm2, classes)
        lo, hi = gap.ci95_kgm2
        half = 0.5 * (hi - lo)
        inside = np.any((classes >= lo) & (classes <= hi))
        between = (abs(gap.inertia_kgm2 - classes[k]) > half) and not inside
        agree = None if img is None else bool(img == k)
        return Verdict(gap.inertia_kgm2, "gap", None if between else k, None if between else float(classes[k]),
                       bool(between), img, gap, agree, "")
    if img is None:
        raise ValueError("fuse_verdict: neither an image answer nor a gap estimate")
    return Verdict(float(classes[img]), "image", img, float(classes[img]), False, img, None, None, gap_reason)
