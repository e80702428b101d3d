"""The fused verdict's documented rules (fusion.py docstring, docs/method.md "Fused verdict").

* image vote: weight (margin − 1) per signal, the heaviest class wins, a tie of a signal's two best classes has no
  say, with every margin at 1 the paper's fused class decides;
* verdict: the gap estimate when there is one, else the vote; 'between classes' when no class lies within
  BETWEEN_Z = 3 standard errors of the gap J1 (tested at 2.5 and 3.5 standard errors, and exactly at 3: within);
  a standard error not carried is recovered from the 95 % interval (half-width / 1.96).
Pure Python, milliseconds.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from jident_ros.identify.fusion import BETWEEN_Z, fuse_verdict, image_vote
from jident_ros.identify.gap import GapEstimate
from jident_ros.method.patterns import SignalAnswer

CLASSES = (1.16, 1.131, 1.102, 1.073, 0.957, 1.189, 1.218)


def answer(signal, class_index, margin):
    return SignalAnswer(signal, 2.0, np.zeros(7), class_index, 0.0, margin)


def gap(j1, se, half_width=None):
    h = 1.96 * se if half_width is None else half_width
    return GapEstimate(j1, se, (j1 - h, j1 + h), 0.0, 48, 68, "acceleration", "angles")


def test_between_z_is_three():
    assert BETWEEN_Z == 3.0


@pytest.mark.parametrize("z, between", [(0.0, False), (2.5, False), (2.99, False), (3.01, True), (3.5, True),
                                        (-2.5, False), (-3.5, True)])
def test_between_classes_at_three_standard_errors(z, between):
    se = 0.002
    v = fuse_verdict(CLASSES, {}, 1, gap(1.131 + z * se, se))
    assert v.between_classes is between
    assert v.source == "gap" and v.inertia_kgm2 == pytest.approx(1.131 + z * se, abs=0)
    if between:
        assert v.class_index is None and v.class_inertia_kgm2 is None
    else:
        assert v.class_index == 1 and v.class_inertia_kgm2 == 1.131


def test_exactly_three_standard_errors_is_within():
    """'no class lies within 3 standard errors': a class at exactly 3 se is within (values exact in binary)."""
    v = fuse_verdict((1.0, 3.0), {}, None, gap(1.75, 0.25))
    assert not v.between_classes and v.class_index == 0
    v = fuse_verdict((1.0, 3.0), {}, None, gap(1.75, 0.25), between_z=2.0)
    assert v.between_classes


def test_between_z_parameter():
    se = 0.002
    g = gap(1.131 + 2.5 * se, se)
    assert not fuse_verdict(CLASSES, gap=g).between_classes
    assert fuse_verdict(CLASSES, gap=g, between_z=2.0).between_classes
    assert not fuse_verdict(CLASSES, gap=gap(1.131 + 3.5 * se, se), between_z=4.0).between_classes


@pytest.mark.parametrize("z, between", [(2.5, False), (2.98, False), (3.02, True), (3.5, True)])
def test_standard_error_from_the_interval_when_not_carried(z, between):
    """An estimate without its standard error (NaN): se = half-width of the 95 % interval / 1.96."""
    se = 0.002
    g = gap(1.102 - z * se, math.nan, half_width=1.96 * se)
    v = fuse_verdict(CLASSES, {}, None, g)
    assert v.between_classes is between
    assert v.class_index == (None if between else 2)


def test_verdict_prefers_the_gap_and_reports_agreement():
    g = gap(1.1605, 0.001)
    v = fuse_verdict(CLASSES, {"a1": answer("a1", 0, 2.0)}, None, g)
    assert (v.source, v.class_index, v.class_inertia_kgm2, v.image_class_index, v.agree) == ("gap", 0, 1.16, 0, True)
    assert v.gap is g and v.reason == ""
    v = fuse_verdict(CLASSES, {"a1": answer("a1", 3, 2.0)}, None, g)
    assert v.class_index == 0 and v.image_class_index == 3 and v.agree is False
    assert v.inertia_kgm2 == 1.1605                               # the continuous gap J1, not the class
    v = fuse_verdict(CLASSES, None, None, g)
    assert v.image_class_index is None and v.agree is None and v.class_index == 0


def test_verdict_without_a_gap_is_the_image_vote():
    v = fuse_verdict(CLASSES, {"a1": answer("a1", 3, 2.0)}, 5, None, "no re-contact")
    assert (v.source, v.inertia_kgm2, v.class_index, v.class_inertia_kgm2) == ("image", 1.073, 3, 1.073)
    assert v.between_classes is False and v.gap is None and v.agree is None and v.reason == "no re-contact"
    v = fuse_verdict(CLASSES, {}, 5, None)
    assert v.class_index == 5 and v.inertia_kgm2 == 1.189
    with pytest.raises(ValueError, match="neither"):
        fuse_verdict(CLASSES, {}, None, None)


def test_vote_weight_is_margin_minus_one():
    # one signal at margin 3 (weight 2) against two at 1.9 (0.9 each, 1.8 together): the single one wins
    a = {"a1": answer("a1", 2, 3.0), "m_el": answer("m_el", 4, 1.9), "v2": answer("v2", 4, 1.9)}
    assert image_vote(a) == 2
    # ... and loses to two at 2.1 (2.2 together)
    a = {"a1": answer("a1", 2, 3.0), "m_el": answer("m_el", 4, 2.1), "v2": answer("v2", 4, 2.1)}
    assert image_vote(a) == 4
    # weights add up per class: 1.5 + 1.5 (class 6) against 2.5 (class 0)
    a = {"a1": answer("a1", 0, 3.5), "m_el": answer("m_el", 6, 2.5), "v2": answer("v2", 6, 2.5)}
    assert image_vote(a) == 6


def test_a_signal_whose_two_best_classes_tie_has_no_say():
    a = {"a1": answer("a1", 6, 1.0), "m_el": answer("m_el", 1, 1.01)}
    assert image_vote(a) == 1
    assert image_vote(a, fused_class_index=3) == 1
    # every margin at 1: the paper's fused class decides (also when it is beyond every voted class)
    assert image_vote({"a1": answer("a1", 2, 1.0), "v2": answer("v2", 0, 1.0)}, fused_class_index=6) == 6
    assert image_vote({"a1": answer("a1", 2, 1.0)}, fused_class_index=None) is None
    assert image_vote({}, fused_class_index=4) == 4
    assert image_vote({}) is None


def test_an_infinite_margin_is_a_confident_vote():
    """margin = inf (the best class has H = 0): the signal votes with a large finite weight."""
    a = {"a1": answer("a1", 5, math.inf), "m_el": answer("m_el", 1, 3.0), "v2": answer("v2", 1, 3.0)}
    assert image_vote(a) == 5
    assert image_vote({"a1": answer("a1", 5, math.inf)}, fused_class_index=2) == 5


def test_an_infinite_margin_weighs_as_a_margin_of_11():
    """fusion.py docstring: margin = inf votes with weight 10, as margin 11: it beats a single signal at 10.95
    (weight 9.95) and loses to one at 11.05 (10.05)."""
    assert image_vote({"a1": answer("a1", 5, math.inf), "m_el": answer("m_el", 1, 10.95)}) == 5
    assert image_vote({"a1": answer("a1", 5, math.inf), "m_el": answer("m_el", 1, 11.05)}) == 1


def test_a_verdict_is_immutable():
    v = fuse_verdict(CLASSES, {}, 1, gap(1.131, 0.002))
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.between_classes = True
