"""trend_design's configurations: name=value pairs onto TrendConfig, a bad one is one argparse line."""
import pytest

from jident_ros.identify.trend import TrendConfig
from jident_ros.research.evaluation.trend_design import main, parse_config


def test_parse_config():
    assert parse_config("") == TrendConfig()
    c = parse_config("error_scale_prior_dof=None, cusum_reference_sd=1.25, relearn_windows=3, se_scale_down=False")
    assert c.error_scale_prior_dof is None and c.cusum_reference_sd == 1.25 and c.relearn_windows == 3
    assert c.se_scale_down is False


def test_a_bad_config_is_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--config", "error_scale_prior_dof=-1"])
    assert exc.value.code == 2 and "error_scale_prior_dof" in capsys.readouterr().err.splitlines()[-1]
