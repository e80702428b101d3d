"""A bounce's window (the excursion came back toward the flank it left: stream.layout.FLAG_BOUNCE) that goes on to
another entry inside it (FLAG_SECOND_ENTRY) and is shorter than the gap fit's change-point search gets no J1
(identify.gap.SHORT_BOUNCE_REASON): nothing but the motor's own fit shows that the coupling let go, and over so few
rows that fit cannot tell free rows from the coupling's swing before the crossing (which has its own window).  The
case it comes from: DOL draws set 8's d8-02 (docs/results.md, "Stop 35")."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from draws_cuts import DATA, draws_cut

from jident_ros.cli.offline import default_policy
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig, WindowInput
from jident_ros.identify.gap import SHORT_BOUNCE_REASON, resolution_limited
from jident_ros.research.evaluation.raw_inputs import flank_detector, raw_recordings, run_detector
from jident_ros.stream.flank import FlankDetector
from jident_ros.stream.layout import FLAG_BOUNCE, FLAG_SECOND_ENTRY, flag_names


@pytest.fixture(scope="module")
def system():
    return load_system_config()


def _recording(name: str, key: str) -> tuple:
    return draws_cut(name, key)[:2]


def _windows(data, ch) -> list:
    det = FlankDetector(0.1, 5e-4, channels=ch, nominal_inertia_kgm2=1.16)
    return [e.window for e in det.push(data, ch) + det.finish() if getattr(e, "window", None)]


def _d802_diagnoser(system):
    """The diagnosis as zoo_draws declares d8-02 (its b1, 1.25 x its Coulomb friction, a data sheet's 1 %, the torque
    estimate's chain)."""
    sysr = dataclasses.replace(system, motor=dataclasses.replace(system.motor, bearing_friction_nms_per_rad=0.00717))
    policy = default_policy(coulomb_friction_max_nm=0.77, torque_accuracy=0.01, torque_offset_rel_base=0.01,
                            torque_lag_max_s=0.00045, torque_filter_s=0.0002)
    return Diagnoser(sysr, load_method_config(), DiagnosisConfig(image_method=False), policy=policy)


def test_a_coupling_s_swing_short_of_the_zone_publishes_no_j1(system):
    """d8-02's slip reversal, JointState 2^16 clean (test/data/dol_draws_swing_before_gap.npz, rows 1000-3599): a soft
    coupling (k 3.1e4 N m/rad) untwists and swings back 0.7 mrad short of the zone; the gap opens 40 samples later
    (272-349 here).  The flank detector sees a bounce at 232 (re-contact 9 rows later) with the crossing's entry
    inside its window: flagged, no J1, OK (its resolution, no WARN).  Fitted anyway (the flag cleared) it gives J1
    about 1.29 for the drive's 0.957 (+35 %, the J1 the draws published).  The traversal that follows gets its own
    window and its J1."""
    d = np.load(DATA / "dol_draws_swing_before_gap.npz")
    true_entry = int(d["gap_entries"][0])
    wins = _windows(*_recording("dol_draws_swing_before_gap.npz", "js"))
    dg = _d802_diagnoser(system)
    bounce = wins[0]
    assert bounce.flags & FLAG_BOUNCE and bounce.flags & FLAG_SECOND_ENTRY and "bounce" in flag_names(bounce.flags)
    assert bounce.recontact_index - bounce.entry_index == 9
    assert round(bounce.entry_time_s / 5e-4) < true_entry - 20                   # no gap there
    r = dg.diagnose(bounce)
    assert r.inertia_kgm2 is None and r.level_name == "OK"
    assert "a bounce of 9 rows" in (r.refused_reason or "") and "change-point search (25 rows)" in r.refused_reason
    fitted = dg.diagnose(dataclasses.replace(bounce, flags=bounce.flags & ~FLAG_BOUNCE))
    assert fitted.inertia_kgm2 is not None and fitted.inertia_kgm2 / 0.957 - 1 > 0.2        # what the rule stops
    traversal = wins[1]
    assert not traversal.flags & FLAG_BOUNCE and math.isfinite(traversal.backlash_width_estimate_m)
    assert abs(round(traversal.entry_time_s / 5e-4) - true_entry) <= 2
    j1 = dg.diagnose(traversal).inertia_kgm2
    assert j1 is not None and abs(j1 / 0.957 - 1) < 0.1


def test_a_true_short_bounce_without_an_entry_inside_keeps_its_fit(system):
    """DOL set 4's d4-02 slip reversal (test/data/dol_draws_slip_reversal_rebound.npz, its JointState 2^16 clean): the
    line's slip opens a true 25-row gap (rows 208-233); the detector's window at 223 is a bounce of 10 rows, but its
    crossing (244) came from the rebound scan, no entry inside the window: fitted (the draws published it +0.8 %)."""
    wins = _windows(*_recording("dol_draws_slip_reversal_rebound.npz", "js"))
    assert [round(w.entry_time_s / 5e-4) for w in wins] == [223, 244]
    assert wins[0].flags & FLAG_BOUNCE and not wins[0].flags & FLAG_SECOND_ENTRY and not wins[1].flags & FLAG_BOUNCE
    r = _d802_diagnoser(system).diagnose(wins[0])
    assert r.gap is not None and "a bounce of" not in (r.refused_reason or "")


def test_only_a_bounce_shorter_than_the_search_before_another_entry_loses_its_fit(system):
    """Marked as a bounce with an entry inside, d8-02's traversal window (77 rows, longer than the 25-row change-point
    search) is fitted as without the marks; our simulator's traversal window (18 rows) gets SHORT_BOUNCE_REASON, and
    with either mark alone it is fitted as before."""
    both = FLAG_BOUNCE | FLAG_SECOND_ENTRY
    wins = _windows(*_recording("dol_draws_swing_before_gap.npz", "js"))
    dg = _d802_diagnoser(system)
    long_bounce = dataclasses.replace(wins[1], flags=wins[1].flags | both)
    assert WindowInput.from_window(long_bounce).bounce and WindowInput.from_window(long_bounce).second_entry
    assert long_bounce.recontact_index - long_bounce.entry_index == 77
    assert dg.diagnose(long_bounce).inertia_kgm2 == dg.diagnose(wins[1]).inertia_kgm2 is not None
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=4)[0]
    w = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"][0]
    assert w.recontact_index - w.entry_index == 18
    dg = Diagnoser(system, load_method_config(), DiagnosisConfig(image_method=False))
    ref = dg.diagnose(w).inertia_kgm2
    assert ref == pytest.approx(1.16, rel=0.02)
    r = dg.diagnose(dataclasses.replace(w, flags=w.flags | both))
    assert r.inertia_kgm2 is None and r.gap is None and r.level_name == "OK"
    assert r.refused_reason.removeprefix("gap: ") == SHORT_BOUNCE_REASON.format(rows=18, search=25)
    assert resolution_limited(SHORT_BOUNCE_REASON)
    for one in (FLAG_BOUNCE, FLAG_SECOND_ENTRY):
        assert dg.diagnose(dataclasses.replace(w, flags=w.flags | one)).inertia_kgm2 == ref


@pytest.mark.parametrize("rows, refused", [(1, True), (24, True), (25, False), (0, False)])
def test_the_search_length_is_the_boundary(system, rows, refused):
    """A bounce before another entry is refused up to 24 rows (the search is 25 at 2 kHz) and fitted from 25 on; a
    re-contact at the entry row itself is no gap length (the gap stage's own reason, not this rule's)."""
    rec = raw_recordings(system, (1.16,), (0.005,), steady_s=0.3, seed=4)[0]
    w = [e.window for e in run_detector(flank_detector(system), rec) if e.kind == "window"][0]
    marked = dataclasses.replace(w, flags=w.flags | FLAG_BOUNCE | FLAG_SECOND_ENTRY,
                                 recontact_index=w.entry_index + rows)
    r = Diagnoser(system, load_method_config(), DiagnosisConfig(image_method=False)).diagnose(marked)
    assert (SHORT_BOUNCE_REASON.format(rows=rows, search=25) in (r.refused_reason or "")) is refused
