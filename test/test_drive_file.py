"""A drive file: one ROS 2 params file for `jident --config` and the nodes' --params-file (cli/drive_file.py,
docs/your_drive.md).  Before it, `jident diagnose` read the system configuration only: a drive's declaration
(torque accuracy, friction bands, gear ratio) had to be repeated as flags, and `jident trend` could not take it at
all (it diagnosed every drive with an exact torque declared)."""
from __future__ import annotations

from pathlib import Path

import pytest

from jident_ros.cli.drive_file import read_drive_file, resolve
from jident_ros.config import ConfigError, load_system_config

EXAMPLE = Path(__file__).resolve().parents[1] / "docs" / "examples" / "profiles" / "small_drive.yaml"

DRIVE = """\
/**:
  ros__parameters:
    motor:
      nominal_inertia_kgm2: 0.5
/**/jident_windowing:
  ros__parameters:
    gear_ratio: 2.5
    motor_joint: m1
    backlash_width_m: 0.004
/**/jident_diagnostic:
  ros__parameters:
    torque_accuracy: 0.03
    coulomb_friction_max_nm: 0.4
    publish_ambiguous: false
    record_dir: /tmp/x
"""


def _write(tmp_path, text, name="drive.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_drive_file_gives_the_system_configuration_and_each_nodes_settings(tmp_path):
    p = _write(tmp_path, DRIVE)
    assert load_system_config(p).motor.nominal_inertia_kgm2 == 0.5      # the /** section
    d = read_drive_file(p)
    # only what the CLI uses; record_dir and backlash_width_m are the nodes' alone
    assert d.diagnostic == {"torque_accuracy": 0.03, "coulomb_friction_max_nm": 0.4, "publish_ambiguous": False}
    assert d.windowing == {"gear_ratio": 2.5, "motor_joint": "m1"}
    assert d.policy() == d.diagnostic
    # a flag wins over the file, the file over the node's default
    assert resolve(None, d, "gear_ratio") == 2.5 and resolve(4.0, d, "gear_ratio") == 4.0
    assert resolve(None, d, "load_joint") == "load" and resolve(None, d, "imu_axis") == "x"
    # a plain system configuration (one section, or none) declares nothing
    assert read_drive_file(None).diagnostic == {} and read_drive_file("heavy_film").windowing == {}


@pytest.mark.parametrize("section,line,message", [
    ("jident_diagnostic", "torque_acuracy: 0.03", "/**/jident_diagnostic: torque_acuracy: not a parameter of jident_diagnostic"),
    ("jident_diagnostic", "torque_accuracy: 0.7", "/**/jident_diagnostic: torque_accuracy: must be >= 0 and < 0.5, got 0.7"),
    ("jident_diagnostic", "coulomb_friction_max_nm: lots", "coulomb_friction_max_nm: expected a finite number, got 'lots'"),
    ("jident_windowing", "gear_ratio: 0", "/**/jident_windowing: gear_ratio: must be >= -1000 and <= 1000 and != 0, got 0"),
    ("jident_windowing", "imu_axis: w", "/**/jident_windowing: imu_axis: must be one of x, y, z, got 'w'"),
])
def test_a_bad_drive_file_value_is_one_line_naming_the_file_section_and_key(tmp_path, capsys, section, line, message):
    from jident_ros.cli.main import main
    p = _write(tmp_path, f"/**:\n  ros__parameters:\n    motor:\n      nominal_inertia_kgm2: 1.16\n"
                         f"/**/{section}:\n  ros__parameters:\n    {line}\n")
    with pytest.raises(ConfigError, match=message.replace("*", r"\*").replace("(", r"\(")):
        read_drive_file(p)
    assert main(["diagnose", str(tmp_path / "none.csv"), "--config", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and str(p) in err[0], err


def test_a_node_parameter_in_the_system_section_says_where_it_belongs(tmp_path):
    p = _write(tmp_path, "/**:\n  ros__parameters:\n    torque_accuracy: 0.03\n")
    with pytest.raises(ConfigError, match=r"torque_accuracy: unknown section .*/\*\*/jident_diagnostic"):
        load_system_config(p)


def test_jident_diagnose_takes_the_drive_files_declaration_and_a_flag_overrides_it(tmp_path, monkeypatch):
    """The policy and the windowing settings reach diagnose_samples: from the file, a flag over it."""
    import jident_ros.cli.offline as offline
    from jident_ros.cli.main import main
    seen = []

    def fake(path, **kw):
        seen.append(kw)
        raise offline.OfflineError("stop here")
    monkeypatch.setattr(offline, "diagnose_samples", fake)
    p = _write(tmp_path, DRIVE)
    csv = _write(tmp_path, "t,alpha1\n0,0\n", "rec.csv")
    assert main(["diagnose", str(csv), "--config", str(p), "--no-image"]) == 2
    kw = seen[-1]
    assert kw["gear_ratio"] == 2.5 and kw["motor_joint"] == "m1" and kw["load_joint"] == "load"
    assert kw["policy"].torque_accuracy == 0.03 and kw["policy"].coulomb_friction_max_nm == 0.4
    assert kw["policy"].publish_ambiguous is False
    assert kw["policy"].torque_offset_rel_base == 0.01          # not in the file: the node's default
    main(["diagnose", str(csv), "--config", str(p), "--no-image", "--torque-accuracy", "0.05", "--gear-ratio", "3",
          "--publish-ambiguous"])
    kw = seen[-1]
    assert kw["policy"].torque_accuracy == 0.05 and kw["gear_ratio"] == 3.0 and kw["policy"].publish_ambiguous is True
    assert kw["policy"].coulomb_friction_max_nm == 0.4
    # without a drive file: the nodes' defaults, as before
    main(["diagnose", str(csv), "--no-image"])
    kw = seen[-1]
    assert kw["gear_ratio"] == 1.0 and kw["policy"].torque_accuracy == 0.0 and kw["motor_joint"] == "motor"


def test_jident_trend_takes_the_drive_files_declaration(tmp_path):
    import argparse

    from jident_ros.cli.trend import trend_options
    p = _write(tmp_path, DRIVE)
    args = argparse.Namespace(config=str(p), p=2.0, gap_method="auto", image_method=False, library=None,
                              backlash_width_m=None, detector="flank", gear_ratio=None, order="recorded")
    o = trend_options(args, None, None, 1)
    assert o.gear_ratio == 2.5 and o.policy.torque_accuracy == 0.03 and o.policy.coulomb_friction_max_nm == 0.4
    args.gear_ratio, args.config = 1.5, None
    o = trend_options(args, None, None, 1)
    assert o.gear_ratio == 1.5 and o.policy.torque_accuracy == 0.0


def test_jident_info_shows_the_example_drive_files_declaration(capsys):
    from jident_ros.cli.main import main
    assert main(["info", "--config", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    assert "gear_ratio 3 (motor turns per load-encoder turn)" in out
    assert "torque_accuracy 0.04, torque_offset_rel_base 0.04 (± 0.219 N m)" in out
    assert "jident_diagnostic: torque_accuracy 0.04" in out and "jident_windowing: gear_ratio 3.0" in out
