"""Model inputs that make the simulation diverge are refused before it runs (issue 15 item 9)."""
import subprocess
import sys

import numpy as np
import pytest

from jident_ros.config import load_system_config
from jident_ros.nodes.params import ParameterError
from jident_ros.nodes.simulator import DEFAULTS, validate
from jident_ros.sim import Case, check_stable, paper_grid_cases, simulate_grid
from jident_ros.sim.checks import SimulationDiverges, check_finite, rk4_amplification


@pytest.fixture(scope="module")
def system():
    return load_system_config()


def test_rk4_amplification_matches_the_known_stability_limits():
    assert rk4_amplification(np.array([-2.78])) < 1 < rk4_amplification(np.array([-2.8]))   # real axis 2.785
    assert rk4_amplification(np.array([2.8j])) < 1 < rk4_amplification(np.array([2.9j]))    # imaginary 2 sqrt 2


def test_the_paper_grid_passes(system):
    check_stable(system, paper_grid_cases(system))


def test_an_absurd_inertia_is_refused_with_the_reason(system):
    with pytest.raises(SimulationDiverges) as exc:
        check_stable(system, [Case(1e-9, 0.005, 0.025)])
    msg = str(exc.value)
    assert "J1 = 1e-09" in msg and "too fast for the RK4 step" in msg and "\n" not in msg
    # simulate_grid refuses it before integrating; without the check the same run is NaN
    with pytest.raises(SimulationDiverges):
        simulate_grid(system, [Case(1e-9, 0.005, 0.025)])
    with np.errstate(all="ignore"):
        raw = simulate_grid(system, [Case(1e-9, 0.005, 0.025)], check=False)
    assert not np.isfinite(raw.signals["omega1"]).all()
    with pytest.raises(SimulationDiverges, match="not finite"):
        check_finite(raw)


def test_more_substeps_is_the_remedy_when_there_is_one(system):
    cases = [Case(1e-4, 0.005, 0.025)]
    with pytest.raises(SimulationDiverges, match=r"integration_substeps to >= (\d+)") as exc:
        check_stable(system, cases)
    need = int(exc.value.args[0].split(">= ")[1].split(" ")[0])
    check_stable(system, cases, substeps=need)   # the proposed step passes


def test_the_cli_says_it_in_one_line_and_exits_2():
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "simulate", "--j1", "1e-9", "--quiet"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "would diverge" in r.stderr


def test_the_simulator_node_refuses_it_at_parameter_validation():
    values = dict(DEFAULTS, inertias_kgm2=[1e-9])
    with pytest.raises(ParameterError, match="with the model: .*would diverge"):
        validate(values)
    validate(dict(DEFAULTS))   # the defaults pass
