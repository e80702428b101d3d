"""Drive profiles (issue 13): the paper-consistent default and the named heavy-film stress profile."""
import subprocess
import sys

import pytest

from jident_ros.config import ConfigError, load_system_config, profile_names, resolve_config_path
from jident_ros.sim import Case, steady_state
from jident_ros.sim.profiles import film_share, with_film_share


def _load_pu(system):
    g = system.grid
    y, slip = steady_state(system, [Case(system.motor.nominal_inertia_kgm2, g.backlash_widths_m[0],
                                         g.pattern_consistency_pa_sn)], 0.0)
    r = system.load.wheel_radius_m
    v2 = y[9, 0]
    return r * (system.load.process_force_n + float(system.load.film_force_n(v2, g.pattern_consistency_pa_sn))) \
        / system.motor.base.torque_nm


def test_default_profile_is_paper_consistent_and_heavy_film_is_the_first_release():
    default, heavy = load_system_config(), load_system_config("heavy_film")
    assert 0.0001 <= film_share(default) <= 0.001          # 0.01-0.1 %, from the paper's H ratios
    assert film_share(heavy) == pytest.approx(0.295, abs=0.001)
    assert heavy.load.film_area_m2 == 0.14 and heavy.load.process_force_n == 1040.0
    # same load at the pattern eta_k: 0.6965 p.u.
    assert _load_pu(default) == pytest.approx(0.6965, abs=2e-4)
    assert _load_pu(heavy) == pytest.approx(_load_pu(default), rel=1e-4)
    # a profile changes only what it gives: the rest is config/system.yaml
    assert heavy.motor == default.motor and heavy.grid == default.grid


def test_with_film_share_keeps_the_load_and_sets_the_share():
    base = load_system_config()
    for share in (1e-4, 0.01, 0.3):
        s = with_film_share(base, share)
        assert film_share(s) == pytest.approx(share, rel=1e-6)
        assert _load_pu(s) == pytest.approx(_load_pu(base), rel=1e-6)
    with pytest.raises(ValueError, match="film share"):
        with_film_share(base, 1.5)


def test_profile_names_resolve_and_unknown_names_are_one_line():
    assert "heavy_film" in profile_names()
    assert resolve_config_path("heavy_film").name == "heavy_film.yaml"
    assert resolve_config_path(None).name == "system.yaml"
    with pytest.raises(ConfigError, match="neither a file nor a drive profile"):
        resolve_config_path("no_such_profile")


def test_jident_info_prints_the_film_share_of_the_profile():
    out = subprocess.run([sys.executable, "-m", "jident_ros.cli", "info", "--config", "heavy_film"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    row = [ln for ln in out.stdout.splitlines() if ln.strip().startswith("0.025 ")][0]
    assert row.split("|")[6].strip() == "29.5"
    out = subprocess.run([sys.executable, "-m", "jident_ros.cli", "info"], capture_output=True, text=True, timeout=60)
    row = [ln for ln in out.stdout.splitlines() if ln.strip().startswith("0.025 ")][0]
    assert float(row.split("|")[6]) == pytest.approx(0.03, abs=0.001)
