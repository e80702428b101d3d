"""raw_scenario's command line: an --out that already holds recordings is one line, not a traceback."""
import pytest

from jident_ros.research.evaluation.raw_scenario import main


def test_an_out_directory_with_recordings_is_one_line(tmp_path, capsys):
    (tmp_path / "rec_000").mkdir()
    with pytest.raises(SystemExit) as exc:
        main(["--out", str(tmp_path), "--windows", "2"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "--out" in err[-1] and "already holds recordings" in err[-1] and "Traceback" not in "".join(err)


def test_a_step_outside_the_scenario_is_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--out", str(tmp_path / "new"), "--windows", "2"])      # the step at recording 24 of 2
    assert exc.value.code == 2
    assert "j1_step_at_window" in capsys.readouterr().err.strip().splitlines()[-1]
