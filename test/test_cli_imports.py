"""`jident` without ROS, and each subcommand imports only what it runs (issues 19 and 23).

* With rclpy (and every ROS message package) blocked by a meta-path finder, every non-ROS subcommand runs:
  --help, simulate (one case and a scenario recording), info, diagnose, trend, salvage, samples.
* `jident --help` loads neither numpy nor scipy; `jident simulate` loads no scipy.stats, no offline diagnosis,
  no method pipeline, no bag layer.
* The parser built for one command lists the same commands, with the same help, as the full parser.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: The blocker: importing any of these raises ImportError, as on a machine without ROS.
BLOCKER = textwrap.dedent("""
    import sys
    BLOCKED = {"rclpy", "rcl_interfaces", "std_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
               "builtin_interfaces", "lifecycle_msgs", "diagnostic_updater", "launch", "launch_ros", "rpyutils",
               "rosidl_runtime_py", "rosidl_parser", "rclpy_message_converter"}

    class NoRos:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"{name} is blocked: this test runs jident without ROS")
            return None

    sys.meta_path.insert(0, NoRos())
""")


def _run(code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO), JIDENT_CACHE_DIR=os.environ.get("JIDENT_CACHE_DIR", ""))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=str(REPO))


def _modules_after(argv: list) -> set:
    """The modules loaded by ``jident <argv>`` in a fresh interpreter (rclpy blocked)."""
    code = BLOCKER + textwrap.dedent(f"""
        import json
        from jident_ros.cli.main import main
        try:
            rc = main({argv!r})
        except SystemExit as exc:          # --help
            rc = exc.code
        assert rc == 0, rc
        print(json.dumps(sorted(sys.modules)))
    """)
    r = _run(code)
    assert r.returncode == 0, r.stderr[-3000:]
    return set(json.loads(r.stdout.strip().splitlines()[-1]))


def test_every_offline_subcommand_runs_without_ros(tmp_path):
    rec, out = tmp_path / "rec", tmp_path / "out"
    steps = [
        ["--help"],
        ["--version"],
        ["info"],
        ["simulate", "--j1", "1.073", "--out", str(tmp_path / "one.npz"), "--quiet"],
        ["simulate", "--help"],
        ["simulate", "--scenario", "wear", "--windows", "3", "--out", str(rec), "--quiet"],
        ["diagnose", str(rec), "--no-image", "--quiet", "--json", str(tmp_path / "d.json")],
        ["trend", str(rec), "--out", str(out), "--commissioning-windows", "2", "--jobs", "1", "--quiet"],
        ["salvage", str(rec), str(tmp_path / "salvaged")],
        ["diagnose", str(tmp_path / "salvaged"), "--no-image", "--quiet"],
        ["samples", str(rec), str(tmp_path / "per_sample")],
    ]
    code = BLOCKER + textwrap.dedent(f"""
        from jident_ros.cli.main import main
        for argv in {steps!r}:
            try:
                rc = main(argv)
            except SystemExit as exc:      # --help, --version
                rc = exc.code
            print("RC", rc, *argv[:2], flush=True)
            assert rc == 0, (argv, rc)
        try:
            import rclpy  # noqa: F401
        except ImportError:
            pass
        else:
            raise AssertionError("the blocker let rclpy through")
        assert "rclpy" not in sys.modules
    """)
    r = _run(code)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-3000:])
    assert r.stdout.count("RC 0") == len(steps), r.stdout
    assert len(json.loads((tmp_path / "d.json").read_text())["windows"]) == 3
    assert (out / "trend.csv").is_file() and (tmp_path / "one.npz").is_file()


def test_demo_help_needs_no_ros():
    """`jident demo` is the ROS command: it imports rclpy when it starts the nodes, not to print its help."""
    code = BLOCKER + textwrap.dedent("""
        from jident_ros.cli.main import main
        try:
            rc = main(["demo", "--help"])
        except SystemExit as exc:
            rc = exc.code
        print("RC", rc)
        assert "rclpy" not in sys.modules
    """)
    r = _run(code)
    assert r.returncode == 0 and "RC 0" in r.stdout and "--scenario" in r.stdout, r.stderr[-2000:]


def test_help_loads_no_numpy_no_scipy():
    mods = _modules_after(["--help"])
    assert not {m for m in mods if m.split(".")[0] in ("numpy", "scipy", "rosbags", "mcap", "rclpy", "yaml")}
    assert not {m for m in mods if m.startswith("jident_ros.")} - {"jident_ros.cli", "jident_ros.cli.main",
                                                                   "jident_ros.parameters"}


def test_simulate_loads_only_the_simulator():
    mods = _modules_after(["simulate", "--j1", "1.073", "--quiet"])
    heavy = {"scipy.stats", "scipy.signal", "scipy.fft", "rosbags", "mcap", "rclpy", "matplotlib"}
    assert not mods & heavy, mods & heavy
    ours = {m for m in mods if m.startswith("jident_ros.")}
    assert "jident_ros.sim.simulate" in ours
    assert not {m for m in ours if m.split(".")[1] in ("method", "identify", "evaluation", "bag", "nodes",
                                                       "stream", "research")}, ours
    assert not {"jident_ros.cli.trend", "jident_ros.cli.scenario", "jident_ros.cli.offline"} & ours


def test_one_command_parser_lists_what_the_full_parser_lists():
    from jident_ros.cli.main import CLI_VARIANTS, build_parser
    from jident_ros.method.pipeline import VARIANTS
    assert CLI_VARIANTS == VARIANTS
    full = build_parser().format_help()
    for command in ("", "simulate", "trend", "info", "evaluate"):
        assert build_parser(command).format_help() == full, command


def test_simulate_options_are_the_full_parsers(capsys):
    """The two-step parse of `jident simulate` (without, then with the scenario options) keeps the full
    parser's errors and help."""
    from jident_ros.cli.main import main
    assert main(["simulate", "--bogus"]) == 2
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err
    assert main(["simulate", "--windows", "0", "--scenario", "wear"]) == 2
    assert "--windows" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    assert "--scenario" in capsys.readouterr().out
