"""The parameter schema and the `jident` command line."""
import subprocess
import sys

import numpy as np
import pytest

from jident_ros.cli import main
from jident_ros.config import ConfigError, load_system_config, system_config_from_dict


@pytest.mark.parametrize("data, field", [
    ({"motor": {"stator_resistance_pu": -1}}, "motor.stator_resistance_pu"),
    ({"motor": {"pole_pairs": 1.5}}, "motor.pole_pairs"),
    ({"load": {"wheel_radius_m": "abc"}}, "load.wheel_radius_m"),
    ({"load": {"flow_index": 3.0}}, "load.flow_index"),
    ({"load": {"no_such_thing": 1.0}}, "load.no_such_thing"),
    ({"grid": {"backlash_widths_m": [0.001, -0.002]}}, "grid.backlash_widths_m[1]"),
    ({"grid": {"pattern_consistency_pa_sn": 0.03}}, "grid.pattern_consistency_pa_sn"),
    ({"sampling": {"integration_substeps": 0}}, "sampling.integration_substeps"),
    ({"motor": {"magnetizing_reactance_pu": 2.0}}, "motor.magnetizing_reactance_pu"),
    ({"bogus": {}}, "bogus"),
])
def test_bad_values_name_the_field_and_value(data, field):
    with pytest.raises(ConfigError) as err:
        system_config_from_dict(data)
    msg = str(err.value)
    assert msg.startswith(field)
    assert "\n" not in msg


def test_ros_params_wrapper_and_yaml11_exponents(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("/**:\n  ros__parameters:\n    load:\n      clutch_stiffness_nm_per_rad: 2.5e4\n")
    assert load_system_config(p).load.clutch_stiffness_nm_per_rad == 25000.0


def test_missing_config_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match="nope.yaml"):
        load_system_config(tmp_path / "nope.yaml")


def test_cli_simulate_writes_windows_and_plot(tmp_path, capsys):
    out, png = tmp_path / "case.npz", tmp_path / "case.png"
    assert main(["simulate", "--j1", "1.073", "--backlash", "0.005", "--eta", "0.025",
                 "--out", str(out), "--plot", str(png)]) == 0
    with np.load(out) as z:
        assert z["signal_a1"].shape == (1, 2048)
        assert float(z["inertia_kgm2"][0]) == 1.073
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 20000


@pytest.mark.parametrize("argv, needle", [
    (["simulate", "--backlash", "-0.001"], "-0.001"),
    (["simulate", "--eta", "0"], "--eta"),
    (["simulate", "--j1", "-2"], "-2"),
    (["simulate", "--j1", "abc"], "abc"),
    (["simulate", "--unknown-option"], "--unknown-option"),
    (["simulate", "--grid", "--j1", "1.1"], "--grid"),
])
def test_cli_bad_input_is_one_line(argv, needle, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1 and err.startswith("jident: error:")


def test_cli_info_runs(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "S_b" in out and "0.025" in out


def test_cli_as_module_entry_point():
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and "jident" in r.stdout


def test_cli_build_patterns_and_refusal_of_a_foreign_library(tmp_path, capsys):
    from jident_ros.config import load_method_config
    from jident_ros.method.patterns import LibraryMismatch, PatternLibrary
    out = tmp_path / "lib.npz"
    assert main(["build-patterns", "--p", "2", "--out", str(out), "--quiet"]) == 0
    system, method = load_system_config(), load_method_config().replace(p_values=(2.0,))
    lib = PatternLibrary.load(out, system, method)
    assert lib.centres.shape == (1, 6, 5, 7, 7)
    with pytest.raises(LibraryMismatch, match="method.eq12"):
        PatternLibrary.load(out, system, method.replace(eq12="literal"))


def test_cli_evaluate_rejects_bad_p(capsys):
    assert main(["evaluate", "--p", "-1"]) == 2
    assert "--p" in capsys.readouterr().err


def test_cli_gap_methods_are_the_diagnosis_gap_methods():
    from jident_ros.cli import CLI_GAP_METHODS
    from jident_ros.diagnosis import GAP_METHODS
    assert CLI_GAP_METHODS == GAP_METHODS
