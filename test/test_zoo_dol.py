"""The DOL zoo's bookkeeping (jident_ros.research.evaluation.zoo_dol): the slip's same-flank gap counted with the
traversals, the declared drive, the list of misleading windows and the results section.  The report itself
simulates and diagnoses for minutes (slow test)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from jident_ros.research.evaluation import zoo, zoo_dol


def _truth_recording(gaps):
    return SimpleNamespace(name="dol_x", truth={"gaps": gaps, "backlash_width_m": 0.005, "reference_radius_m": 0.1,
                                                "gear_ratio": 1.0, "sample_period_s": 5e-4, "event": {"index": 1200}})


GAPS = [{"entry_index": 1208, "recontact_index": 1225, "traversal": False, "event_gap": True},     # the slip
        {"entry_index": 1300, "recontact_index": 1320, "traversal": False, "event_gap": False},    # a bounce
        {"entry_index": 1400, "recontact_index": 1450, "traversal": True, "event_gap": False}]


def test_the_slip_gap_counts_as_a_traversal_and_bounces_do_not(tmp_path, monkeypatch):
    monkeypatch.setattr(zoo_dol.vd_record, "write", lambda out, r, f: f"{r.name}.{f}")
    zr = zoo_dol._recording(_truth_recording(GAPS), "slip_drop", "forward", 1.16, 65536, None, tmp_path, ("csv",))
    assert [g["traversal"] for g in zr.gaps] == [True, False, True]
    assert zr.traversing_event and zr.event == "slip drop" and zr.event_index == 1200 and zr.model == zoo_dol.MODEL
    steady = zoo_dol._recording(_truth_recording([]), "steady", "forward", 1.16, 65536, None, tmp_path, ("csv",))
    assert not steady.traversing_event


def test_a_same_flank_gap_before_a_slip_reversals_crossing_is_a_bounce(tmp_path, monkeypatch):
    """A slip reversal's soft coupling that unloads past the zone's edge and springs back before the crossing: its
    first gap (the truth's event_gap) returns to the flank it left, a bounce; only the slip drop's is a traversal."""
    monkeypatch.setattr(zoo_dol.vd_record, "write", lambda out, r, f: f"{r.name}.{f}")
    gaps = [{"entry_index": 1214, "recontact_index": 1229, "traversal": False, "event_gap": True},   # 0.8 mrad deep
            {"entry_index": 1248, "recontact_index": 1333, "traversal": True, "event_gap": False}]   # the crossing
    zr = zoo_dol._recording(_truth_recording(gaps), "slip_reversal", "forward", 1.16, 65536, None, tmp_path, ("csv",))
    assert [g["traversal"] for g in zr.gaps] == [False, True]
    drop = zoo_dol._recording(_truth_recording(gaps), "slip_drop", "forward", 1.16, 65536, None, tmp_path, ("csv",))
    assert [g["traversal"] for g in drop.gaps] == [True, True]


def _win(idx, gap, published=True, j1=1.16, ci=(1.1, 1.2), reason=None):
    return {"index": idx, "gap": gap, "published": published, "j1": j1 if published else None, "source": "gap",
            "ci95": list(ci) if published else None, "reason": reason, "status": "", "k2": 0.005, "gap_entry": idx}


def _zr(gaps=GAPS, event="slip drop", traversing=True, j1=1.073):
    gl = [{"entry_index": g["entry_index"], "recontact_index": g["recontact_index"],
           "traversal": zoo_dol.traversal(g, event.replace(" ", "_"))} for g in gaps]
    return zoo.ZooRecording(zoo_dol.MODEL, "dol_slip_drop_fwd", event, traversing, "forward", j1, 0.005, 0.1, 1.0,
                            65536, None, 5e-4, 1200, gl)


def test_misses_lists_far_off_and_uncovered_windows_once_per_gap():
    zr = _zr()
    res = {"windows": [_win(1211, 0, j1=0.70, ci=(0.69, 0.71)),        # the paper's -35 %: listed
                       _win(1215, 0, j1=0.70, ci=(0.69, 0.71)),        # a second window on the same gap: not again
                       _win(1301, 1, j1=1.08, ci=(1.075, 1.085)),       # a bounce, 0.7 % off, CI misses: listed
                       _win(1402, 2, j1=1.07, ci=(1.0, 1.2)),           # fine: not listed
                       _win(100, None, j1=1.1)],                        # a published false entry: listed
           "cut_off": []}
    m = zoo_dol.misses({("JointState 2^16", "slip drop", "clean"): [(zr, res)]})
    assert [(x["kind"], x["gap"]) for x in m] == [("traversal", 0), ("bounce", 1), ("false entry", None)]
    assert m[0]["entry_offset"] == 3 and m[0]["error"] == pytest.approx(0.70 / 1.073 - 1)


def test_declared_is_what_the_data_sheet_gives():
    d = zoo_dol.declared()
    assert d["coulomb_friction_max_nm"] == pytest.approx(1.5) and d["bearing_friction_nms_per_rad"] == 0.02
    assert d["torque_accuracy"] == 0.01 and d["torque_offset_rel_base"] == 0.01 and d["torque_lag_max_s"] == 2.5e-4


def test_cases_cover_every_event_both_ways_and_the_second_class():
    c = zoo_dol.cases()
    assert len(c) == 2 * 6 + 2 * 4
    assert (1.073, "slip_drop", "reverse") in c and (1.073, "steady", "forward") not in c


def test_markdown_names_the_targets_and_the_misses():
    zr = _zr()
    res_one = {"windows": [_win(1211, 0, j1=0.70, ci=(0.69, 0.71)), _win(1402, 2, j1=1.07, ci=(1.0, 1.2))],
               "cut_off": []}
    zsteady = _zr([], event="steady", traversing=False, j1=1.16)
    res_steady = {"windows": [_win(300, None, published=False, reason="x")], "cut_off": []}
    groups = {("JointState 2^16", "slip drop", "clean"): [(zr, res_one)],
              ("JointState 2^16", "steady", "clean"): [(zsteady, res_steady)]}
    tot = {("JointState 2^16", "clean"): zoo.summarise([x for v in groups.values() for x in v])}
    res = {"rows": {k: zoo.summarise(v) for k, v in groups.items()}, "totals": tot,
           "all": tot[("JointState 2^16", "clean")], "misses": zoo_dol.misses(groups), "files": 2, "recordings": 2,
           "elapsed_s": 1.0}
    md = zoo_dol.markdown(res, "cmd", "abc1234")
    assert md.startswith("## The zoo on a drive-on-line motor") and "abc1234" in md
    assert "| every traversal found | 2/2 |" in md         # the slip and the traversal, not the bounce
    assert "| 0 false entries (steady / same-flank / other) | 1 / 0 / 0 |" in md
    assert "| JointState 2^16 clean, slip events: published ≥ 80 % | 2/2 (100 %) |" in md
    assert "| 0 published > 10 % off (all inputs, traversal and bounce windows) | 1 |" in md
    assert "| dol_slip_drop_fwd | JointState 2^16 | traversal | +3 | +3 | 0.7 (1.073) | 0.69 … 0.71 | -34.8 % |" in md
    assert "| JointState 2^16 | slip drop | clean |" in md
    assert "| K2 median error ≤ 5 %, clean (all inputs; the flank-to-flank events: slip drop's excursion is no width) | – |" in md


@pytest.mark.slow
def test_quick_report(tmp_path):
    from jident_ros.research.vector_drive.model import motulator_available
    if motulator_available():
        pytest.skip(motulator_available())
    res = zoo_dol.run(tmp_path, log=lambda t: None, quick=True)
    tot = res["totals"][("JointState 2^16", "clean")]
    assert tot["recordings"] == 2 and tot["traversals"] == 1 and tot["found"] == 1
    assert tot.get("false_steady", 0) == 0


def test_sweep_varies_one_property_from_the_zoo_drive():
    from jident_ros.research.vector_drive.dol import DolParams
    sw = zoo_dol.sweep()
    assert sw[0][0] == "base" and sw[0][2] == DolParams()
    assert len({n for n, _, _ in sw}) == len(sw)
    base = DolParams()
    for name, _, p in sw[1:]:
        changed = [k for k in ("slip_load_ratio", "wheel_inertia_kgm2") if getattr(p, k) != getattr(base, k)]
        changed += [k for k in ("backlash_width_m", "stiffness_nm_per_rad") if getattr(p.mechanics, k) !=
                    getattr(base.mechanics, k)]
        # a sensor variant keeps the drive and changes its sensors (and, declared, what its user declares)
        changed += list(zoo_dol.SWEEP_SENSOR_VARIANTS.get(name, {}))
        assert len(changed) == 1, name
    assert set(zoo_dol.SWEEP_DECLARED) <= set(zoo_dol.SWEEP_SENSOR_VARIANTS)


def test_sweep_misses_of_the_base_drive_are_listed_once():
    zr = _zr()
    groups = {("JointState 2^16", "slip drop", "clean"): [(zr, {"windows": [_win(1211, 0, j1=0.70, ci=(0.69, 0.71))],
                                                               "cut_off": []})]}
    one = zoo_dol.misses(groups)
    sw_groups = {(f"{v}: JointState 2^16 clean", "slip drop", "clean"): v_items for v in ("base", "light wheel")
                 for v_items in groups.values()}
    tot = zoo.summarise(groups[("JointState 2^16", "slip drop", "clean")])
    res = {"rows": {("JointState 2^16", "slip drop", "clean"): tot}, "totals": {("JointState 2^16", "clean"): tot},
           "all": tot, "misses": one, "files": 1, "recordings": 1, "elapsed_s": 1.0,
           "sweep": {"rows": {"base": tot, "light wheel": tot}, "misses": zoo_dol.misses(sw_groups), "elapsed_s": 1.0}}
    md = zoo_dol.markdown(res, "cmd", "abc")
    assert md.count("| dol_slip_drop_fwd |") == 2          # the zoo's window and the light wheel's, not base's again
    assert "light wheel: JointState 2^16 clean" in md and "base: JointState" not in md
    assert "| light wheel | the wheel 0.06 kg m² (what stays after the slip) | 1/2 |" in md
