"""The re-contact row from the relative angle delta (stream/flank.py: delta_recontact, _delta_arrived) and the K2
that follows from it (estimate_width)."""
from pathlib import Path

import numpy as np
import pytest

from jident_ros.stream import flank_delta

DATA = Path(__file__).parent / "data" / "dol_light_reversal_recontact.npz"


def _cut():
    z = np.load(DATA)
    window = {k: np.asarray(z[k], float) for k in ("alpha1", "alpha2", "a1")}
    return window, z


def _width(window, z):
    return flank_delta.estimate_width(window, int(z["entry_index"]), float(z["wheel_radius_m"]), float(z["sample_period_s"]),
                                      flank_rad=float(z["flank_rad"]), angle_quantum_rad=float(z["quantum"]))


def test_dol_light_reversal_k2_from_delta():
    """motulator's line-fed motor (the DOL zoo's light load reversal, J1 1.16, clean, with a1): its torque falls as it
    speeds up in the 149-sample gap, so a1 drops below 0.6 of its entry value 80 samples before the re-contact."""
    window, z = _cut()
    res = _width(window, z)
    assert res.how == "traversal"
    assert abs(res.recontact_index - int(z["true_recontact"])) <= 2
    assert res.width_m == pytest.approx(float(z["true_width_m"]), rel=0.03)


def test_dol_light_reversal_without_the_delta_rule_is_wrong(monkeypatch):
    """The same window read from the acceleration alone (the rule before): the test above would catch its loss."""
    monkeypatch.setattr(flank_delta, "RECONTACT_FROM_DELTA", False)
    window, z = _cut()
    res = _width(window, z)
    assert res.recontact_index < int(z["true_recontact"]) - 40
    assert not res.width_m == pytest.approx(float(z["true_width_m"]), rel=0.5)


def _traversal(untwist_rows=0, rows=400, e=60, q=0.0):
    """delta of a synthetic traversal: on its flank to e, (optionally) the coupling's untwist of 4 mrad in 3 rows and
    a rest, free relative acceleration across a 0.1 rad zone, then a damped spring at the far flank."""
    d = np.zeros(rows)
    k = e
    if untwist_rows:
        d[e:e + 3] = np.array([1.5e-3, 3e-3, 4e-3])
        d[e + 3:e + 3 + untwist_rows] = 4e-3
        k = e + 3 + untwist_rows
    base = d[k - 1]
    acc = 2e-5                                       # rad per row^2: 0.1 rad in about 100 rows
    contact = None
    v = 0.0
    x = base
    for i in range(k, rows):
        if contact is None and x >= base + 0.1:
            contact = i
        if contact is None:
            v += acc
        else:                                        # spring and damper on the far flank
            v += -0.03 * (x - (base + 0.1)) - 0.2 * v
        x += v
        d[i] = x
    contact = int(np.argmax(d >= base + 0.1))          # the first row at (or past) the far flank
    if q:
        d = np.floor(d / q) * q
    return d, e, contact


@pytest.mark.parametrize("untwist", [0, 15])
@pytest.mark.parametrize("q", [0.0, 2 * np.pi / 2 ** 13])
def test_delta_recontact_synthetic(untwist, q):
    """Within 2 rows of the contact with and without the untwist's rest (which holds still for 15 rows: not a
    contact, its travel is 4 % of the zone), at ideal angles and a 2^13 encoder's quantum."""
    d, e, contact = _traversal(untwist, q=q)
    g = flank_delta.delta_recontact(d, e, q)
    assert abs(g - contact) <= 2


def test_delta_recontact_travel_share_guards_the_untwist(monkeypatch):
    """Without the travel-share guard the untwist's rest is read as the contact."""
    monkeypatch.setattr(flank_delta, "RECONTACT_MIN_TRAVEL_SHARE", 0.0)
    d, e, contact = _traversal(15)
    assert flank_delta.delta_recontact(d, e, 0.0) < contact - 50


def test_delta_arrived():
    d, e, contact = _traversal()
    assert flank_delta._delta_arrived(d, e, contact, 0.0)
    assert not flank_delta._delta_arrived(d, e, e + (contact - e) // 2, 0.0)
    assert flank_delta._delta_arrived(d, e, -1, 0.0)          # no row to check: the caller's stands


def test_bounce_then_traversal_back_is_not_the_contact():
    """A bounce (delta leaves its flank and comes back to it), then a traversal across the zone in the same direction
    (the second drive's 2^13 bounce windows): the search ends at the bounce's return, so its contact is never placed
    at the traversal's far flank (J1 was then fitted over 24 contact rows: +2.8 %, another class named)."""
    d, e, contact = _traversal()
    bounce = np.concatenate([np.zeros(60), 0.02 * np.sin(np.linspace(0, np.pi, 40)), np.zeros(20)])
    d2 = np.concatenate([bounce, d[e:] + 0.0])
    assert flank_delta.delta_recontact(d2, 60, 0.0) == -1
    assert flank_delta._delta_arrived(d2, 60, 101, 0.0)


def test_return_guard_matters(monkeypatch):
    monkeypatch.setattr(flank_delta, "RECONTACT_RETURN_SHARE", -1.0)
    d, e, contact = _traversal()
    bounce = np.concatenate([np.zeros(60), 0.02 * np.sin(np.linspace(0, np.pi, 40)), np.zeros(20)])
    d2 = np.concatenate([bounce, d[e:] + 0.0])
    assert flank_delta.delta_recontact(d2, 60, 0.0) > 200


def test_travel_of_a_few_quanta_is_not_read():
    """A quantised delta that travels fewer than RECONTACT_MIN_TRAVEL_QUANTA counts (a slip's small excursion behind
    a soft coupling's untwist at 2^13) keeps the acceleration's row: -1 here, True from _delta_arrived."""
    q = 2 * np.pi / 2 ** 13
    d, e, contact = _traversal(q=q)
    small = np.floor((d - d[0]) * (20 * q / 0.1) / q) * q        # the same motion scaled to a 20-count zone
    assert flank_delta.delta_recontact(small, e, q) == -1
    assert flank_delta._delta_arrived(small, e, e + 5, q)
    assert abs(flank_delta.delta_recontact(d, e, q) - contact) <= 2


def _there_and_back():
    """_traversal's window, then delta crosses back to the flank it left (from row 260, 100 rows) and rests there: a
    traversal and its traversal back in one window (vector set 11's s11-12)."""
    d, e, contact = _traversal(rows=260)
    back = d[-1] - (d[-1] - d[e - 1]) * np.sin(np.linspace(0.0, np.pi / 2, 100)) ** 2
    return np.concatenate([d, back, np.full(100, d[e - 1])]), e, contact


def test_a_traversal_and_its_traversal_back_are_read_up_to_the_return(monkeypatch):
    """delta comes back to its flank, but the travel before the return is the window's farthest: the delta rule reads
    the rows before the return (the re-contact at the far flank, not the acceleration's early row); with
    RECONTACT_RETURN_TRAVERSAL_SHARE above 1 (no such window read, the rule before stop 37) it gives none."""
    d, e, contact = _there_and_back()
    assert flank_delta._first_return(flank_delta._travel(d, e), 0.0) is not None
    assert abs(flank_delta.delta_recontact(d, e, 0.0) - contact) <= 2
    assert not flank_delta._delta_arrived(d, e, e + 8, 0.0)
    monkeypatch.setattr(flank_delta, "RECONTACT_RETURN_TRAVERSAL_SHARE", 1.01)
    assert flank_delta.delta_recontact(d, e, 0.0) == -1
    assert flank_delta._delta_arrived(d, e, e + 8, 0.0)


def test_a_bounce_before_a_crossing_is_not_read_at_any_share_below_its_own(monkeypatch):
    """The bounce of test_bounce_then_traversal_back_is_not_the_contact travels 0.02 of the crossing's 0.1 before its
    return: below RECONTACT_RETURN_TRAVERSAL_SHARE, so nothing is read (-1; DOL set 3's d3-03 lost its J1 when every
    window with a return was read).  With the share at 0 the bounce's rows are read and its turn inside the zone is
    taken for the contact."""
    d, e, contact = _traversal()
    bounce = np.concatenate([np.zeros(60), 0.02 * np.sin(np.linspace(0, np.pi, 40)), np.zeros(20)])
    d2 = np.concatenate([bounce, d[e:] + 0.0])
    assert flank_delta.delta_recontact(d2, 60, 0.0) == -1
    monkeypatch.setattr(flank_delta, "RECONTACT_RETURN_TRAVERSAL_SHARE", 0.0)
    assert 60 < flank_delta.delta_recontact(d2, 60, 0.0) < 100                # inside the bounce, 20 rows long
