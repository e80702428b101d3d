"""draws_oracle: the J1 the blind draws' data hold over the true gap rows (research report, docs/results.md)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from jident_ros.research.evaluation import draws_oracle as O
from jident_ros.research.evaluation import zoo


def _gap(j1=1.1, constant_nm=3.0, n=130, ts=5e-4):
    t = np.arange(n) * ts
    torque = 20.0 * np.sin(2 * np.pi * t / (n * ts)) - 10.0            # swings through the gap
    acc = (torque - constant_nm) / j1
    omega = 150.0 + np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * ts)])
    alpha = 3.0 + np.concatenate([[0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * ts)])
    return t, alpha, torque


def test_the_constant_fit_recovers_j1_beside_a_constant_torque_and_the_plain_one_does_not():
    t, alpha, torque = _gap()
    j, rel_se = O.constant_fit(t, alpha, torque, 0, t.size)
    assert j == pytest.approx(1.1, rel=1e-6) and rel_se < 1e-6
    plain = zoo.oracle_fit(t, alpha, torque, 0, t.size)
    assert abs(plain / 1.1 - 1) > 0.05                                   # the constant biases the plain oracle


def test_the_offset_shift_is_what_a_constant_moves_j1_by():
    t, alpha, torque = _gap(constant_nm=0.0)
    j = zoo.oracle_fit(t, alpha, torque, 0, t.size)
    g = {"entry_index": 0, "recontact_index": t.size}
    assert O._shift(t, alpha, torque, g, j, 0.0) == pytest.approx(0.0, abs=1e-9)
    small, large = O._shift(t, alpha, torque, g, j, 0.5), O._shift(t, alpha, torque, g, j, 5.0)
    assert 0 < small < large


@pytest.mark.parametrize(("row", "reach"), [
    (("l", "e", 0.01, None, 0.05, math.inf), True),          # within 3 %, the offset moves it 5 %
    (("l", "e", 0.01, None, 0.20, math.inf), False),         # the declared offset alone fills the interval
    (("l", "e", 0.20, 0.01, 0.20, 0.01), True),              # the constant fitted holds it
    (("l", "e", 0.20, 0.01, 0.20, 0.08), False),             # ... but its own interval is too wide
    (("l", "e", None, None, math.inf, math.inf), False),
])
def test_within_reach(row, reach):
    assert O.reachable(row) is reach


def test_seed_lists():
    assert O.parse_seeds("1-3,7") == [1, 2, 3, 7]
    assert O.main(["--seeds", "x"]) == 2


def test_the_two_models_sections_have_their_own_headings():
    """docs/results.md holds one section per model: zoo.replace_section finds a section by its heading up to '('."""
    heads = {O.markdown([], m, [1], {}, "cmd", "abc", 1.0).splitlines()[0].split("(")[0] for m in ("vector", "dol")}
    assert len(heads) == 2
