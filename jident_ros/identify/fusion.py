"""One verdict per window from the image method and the gap estimator.

* image vote: each signal's class votes with weight (margin − 1) (a signal whose
  two best classes tie has no say; an infinite margin, the best class at H = 0,
  weighs 10, as a margin of 11 would); the class with the largest total wins.  With
  every margin at 1 the paper's fused H decides (:func:`patterns.fuse`).
* gap: the continuous J1 with its 95 % interval (:mod:`gap`) and its nearest class.
* verdict: the best continuous J1 is the gap estimate when there is one (it is
  physics, not pattern matching: docs/method.md), else the voted class's J1.
  ``between_classes`` is set when no class lies within ``between_z`` standard
  errors of the gap J1 (default 3: a flag is an alarm, and at 1.96 standard errors
  one on-class window in twenty would raise it; with a 95 % interval that already
  holds no class, a 3-σ band is the stricter test; docs/method.md "Fusion");
  ``agree`` tells whether the image vote and the gap's nearest class coincide.
Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from jident_ros.identify.gap import GapEstimate, nearest_class

#: Standard errors within which a class must lie for the gap J1 to be "on" it.
BETWEEN_Z = 3.0


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
                 gap: Optional[GapEstimate] = None, gap_reason: str = "", between_z: float = BETWEEN_Z) -> Verdict:
    """Combine the image answers and the gap estimate of one window."""
    classes = np.asarray(classes_kgm2, dtype=float)
    img = image_vote(answers or {}, fused_class_index)
    if gap is not None:
        k = nearest_class(gap.inertia_kgm2, classes)
        se = gap.std_error_kgm2
        if not np.isfinite(se):   # an estimate carried without its standard error: from the 95 % interval
            se = 0.5 * (gap.ci95_kgm2[1] - gap.ci95_kgm2[0]) / 1.96
        between = bool(abs(gap.inertia_kgm2 - classes[k]) > between_z * se)
        agree = None if img is None else bool(img == k)
        return Verdict(gap.inertia_kgm2, "gap", None if between else k, None if between else float(classes[k]),
                       bool(between), img, gap, agree, "")
    if img is None:
        raise ValueError("fuse_verdict: neither an image answer nor a gap estimate")
    return Verdict(float(classes[img]), "image", img, float(classes[img]), False, img, None, None, gap_reason)
