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


def test_one_tracker_per_window_kind(tmp_path):
    """Recordings of an entry (se 0.2 %) and a return window (se 2 %, 3 % low: another bias): one tracker per kind
    flags the -2.5 % step at the stepped recording's first entry + 1, none before."""
    import numpy as np

    from jident_ros.research.evaluation import trend_relative as trl
    from jident_ros.research.evaluation.trend_design import by_kind
    rng = np.random.default_rng(0)
    pools = {}
    for j in (trl.J1_BASE, trl.J1_STEP):
        n = 40
        entry = j * (1 + 0.002 * rng.standard_normal(n))
        ret = j * (0.97 + 0.02 * rng.standard_normal(n))
        pools[j] = {"j1": np.ravel(np.column_stack([entry, ret])),
                    "se": np.ravel(np.column_stack([np.full(n, 0.002 * j), np.full(n, 0.02 * j)])),
                    "rec": np.repeat(np.arange(n), 2)}
    f = tmp_path / "pools.json"
    trl.save_pools({"pools": pools, "counts": {}}, f)
    r = by_kind(f, TrendConfig(), 20)
    assert r["within_5"] == 20 and r["before"] == 0, r
