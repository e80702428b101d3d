"""The blind draws' targets table (research/evaluation/draws_targets.py): what each column counts."""
import json

import pytest

from jident_ros.research.evaluation import draws_targets


def _summary(**kw):
    base = {"found": 0, "traversals": 0, "trav_published": 0, "published_off": 0, "covered": 0, "with_interval": 0,
            "offsets": [], "k2_errors": []}
    return {**base, **kw}


def _res(model="vector"):
    speed, other = draws_targets.SPEED_EVENTS[model][0], "load reversal light"
    groups = {
        f"JointState 2^16 clean|{speed}": _summary(traversals=10, trav_published=9, k2_errors=[0.01, 0.02, 0.09]),
        f"JointState 2^16 30 dB|{speed}": _summary(traversals=10, trav_published=4, k2_errors=[0.5]),
        f"JointState 2^16 clean|{other}": _summary(traversals=10, trav_published=0, k2_errors=[0.03]),
        f"JointState+Imu 2^16 30 dB|{speed}": _summary(traversals=10, trav_published=10),
    }
    rows = {"s9-01": _summary(found=39, traversals=40, offsets=[0, 1, -3, 2, 5], published_off=0, covered=9,
                              with_interval=10, false_steady=0, false_same_flank=1, false_other=2,
                              between_on_class=0, wrong_class=0)}
    return {"model": model, "seed": 9, "rows": rows, "groups": groups, "commit": "abc1234"}


def test_row_counts_each_target():
    cells = draws_targets.row(_res())
    assert cells["set"] == "vector 9 (1)"
    assert cells["found"] == "**39/40 (98 %)**"              # every traversal: missed
    assert cells["false"] == "**1** (2)"                     # steady + same flank, then the other false entries
    assert cells["entry"] == "**3/5 (60 %)**"
    assert cells["clean"] == "9/10 (90 %)"                   # speed events, JointState clean, no Imu
    assert cells["noisy"] == "**4/10 (40 %)**"
    assert cells["all"] == "**13/30 (43 %)**"              # every JointState (no Imu) traversal
    assert cells["covers"] == "9/10 (90 %)"
    assert cells["k2"] == "2.5 %"                            # median over the clean inputs: 0.01 0.02 0.03 0.09
    assert cells["off"] == "0"


def test_row_dol_speed_events_are_the_slips():
    cells = draws_targets.row(_res("dol"))
    assert cells["set"] == "DOL 9 (1)"
    assert cells["clean"] == "9/10 (90 %)"


def test_a_false_entry_j1_counts_as_off():
    res = _res()
    res["rows"]["s9-01"]["published_on_false"] = 1
    assert draws_targets.row(res)["off"] == "**1**"


def test_main_prints_and_refuses_old_files(tmp_path, capsys):
    good, old = tmp_path / "v9.json", tmp_path / "old.json"
    good.write_text(json.dumps(_res()))
    old.write_text(json.dumps({k: v for k, v in _res().items() if k != "groups"}))
    assert draws_targets.main([str(good), "--results", "-"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(draws_targets.TITLE) and "| vector 9 (1) |" in out
    assert draws_targets.main([str(old), "--results", "-"]) == 2
    assert "no 'groups'" in capsys.readouterr().err


@pytest.mark.parametrize("text", ["{", ""])
def test_main_unreadable_file_one_line(tmp_path, capsys, text):
    f = tmp_path / "bad.json"
    f.write_text(text)
    assert draws_targets.main([str(f), "--results", "-"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("draws_targets: error:") and err.count("\n") == 1


def test_a_folder_of_json_files_is_named_as_one_pattern(tmp_path):
    for name in ("a.json", "b.json", "c.json"):
        (tmp_path / name).write_text("{}")
    every = [str(tmp_path / n) for n in ("a.json", "b.json", "c.json")]
    assert draws_targets._files_text(every) == f"{tmp_path}/*.json"
    assert draws_targets._files_text(every[:2] + every[2:]) == f"{tmp_path}/*.json"
    assert draws_targets._files_text(every[:2]) == " ".join(every[:2])      # two: as given
    (tmp_path / "d.json").write_text("{}")
    assert draws_targets._files_text(every) == " ".join(every)              # not every file of the folder


def test_the_columns_read_the_labels_and_events_the_draws_write():
    """draws_targets picks zoo_draws' groups by sensor label and event name ('label|event', zoo_draws.run): a renamed
    sensor or event would leave its columns at 0/0, so the names are checked against the draws' own."""
    from jident_ros.research.evaluation import zoo_dol, zoo_draws, zoo_variants
    for model, sensors, events in (("vector", zoo_variants.SENSORS, zoo_variants.EVENTS),
                                   ("dol", zoo_dol.SWEEP_SENSORS, zoo_draws.DOL_EVENTS)):
        assert set(draws_targets.SPEED_EVENTS[model]) <= {e.replace("_", " ") for e in events}, model
        js = [s[0] for s in sensors if draws_targets._js(s[0])]
        assert js and all("Imu" not in lab and "2^16" in lab for lab in js), (model, js)
        assert any(lab.endswith("clean") for lab in js) and any(lab.endswith("30 dB") for lab in js), model


def test_event_rows_say_where_targets_are_missed():
    speed = draws_targets.SPEED_EVENTS["dol"][0]
    groups = {
        f"JointState 2^16 clean|{speed}": _summary(traversals=4, found=2, trav_published=1, offsets=[0, 9],
                                                   missed_gap_rows=[2, 12], missed_kinds=["none", "located"],
                                                   reasons={"gap: gap too short: a shallow gap": 1}),
        f"JointState+Imu 2^16 30 dB|{speed}": _summary(traversals=4, found=3, trav_published=3, offsets=[1, -1, 5],
                                                       missed_gap_rows=[-1], missed_kinds=["spanned"],
                                                       reasons={"other": 5}),
    }
    res = {"model": "dol", "seed": 9, "rows": {}, "groups": groups}
    (line,) = draws_targets.event_rows([res, res])          # two sets of one model: one row per event
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[:3] == ["DOL", speed, "10/16 (62 %)"]
    assert cells[3] == "2/6"                  # the 2-sample gap of each set; 12 samples and unknown are not short
    assert cells[4] == "2 / 2"                # located / spanned by a window entered elsewhere, over both sets
    assert cells[5] == "50 % / 67 %"          # within ±2 without an Imu (0 of 0, 9) and with one (1, -1 of 1, -1, 5)
    assert cells[6] == "20 %"                 # 9 twice of the 10 entries: 8 or more samples late
    assert cells[7] == "2/8 (25 %)"           # J1 published on the traversals without an Imu only
    assert cells[8] == "2/2: gap too short: a shallow gap"     # the Imu input's refusals not counted


def test_event_rows_old_files_show_no_gap_lengths():
    res = _res()
    (line, *_) = draws_targets.event_rows([res])
    assert "| – | – |" in line                # files written before missed_gap_rows and missed_kinds were counted


def test_every_published_window_is_judged_for_off_and_coverage():
    """Stop 48: a J1 from an early entry whose fit lies in a true gap, and one from a second window of a gap, count in
    'off' by their error and in the coverage (until stop 47 the coverage was over the first windows alone and an
    early entry's J1 more than 10 % off was not counted)."""
    res = _res()
    row = res["rows"]["s9-01"]
    row["false_in_gap_errors"] = [0.12, -0.02]
    row["false_in_gap_covered"] = 1
    row["repeat_published"], row["repeat_covered"] = 2, 1
    cells = draws_targets.row(res)
    assert cells["off"] == "**1**"
    assert cells["covers"] == "**11/14 (79 %)**"       # below 85 %: bold
