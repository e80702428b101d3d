"""ROS 2 as its users run it (issue 22): launch-written params files, replay = live, foreign bags, stamped
estimates, aggregator names, recorded QoS, best-effort input.  The tests without ``ros`` need no rclpy."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml
from test_nodes import Proc, logs, node_env  # noqa: F401

from jident_ros.nodes.params import ParameterError
from jident_ros.nodes.runtime import check_params_files, load_params_file

REPO = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------- params files written by launch
def launch_params_file(tmp_path: Path, node_name: str, params: dict) -> Path:
    """A params file written exactly as launch_ros (jazzy, launch_ros/actions/node.py
    ``Node._create_params_file_from_dict``) writes one: ``yaml.dump`` of ``{node: {'ros__parameters':
    params}}``, default_flow_style=False; launch_ros' parameter evaluation turns list values into tuples."""
    path = tmp_path / f"launch_params_{node_name.strip('/').replace('/', '_')}"
    with open(path, "w") as h:
        yaml.dump({node_name: {"ros__parameters": params}}, h, default_flow_style=False)
    return path


def test_launch_written_params_file_is_accepted(tmp_path):
    path = launch_params_file(tmp_path, "/press3/jident_simulator",
                              {"inertias_kgm2": (1.16, 1.073), "channels": ("alpha1", "t"), "repeat": 1})
    assert "!!python/tuple" in path.read_text()          # what safe_load refused
    with pytest.raises(yaml.YAMLError):
        yaml.safe_load(path.read_text())
    check_params_files(["x", "--ros-args", "--params-file", str(path)])      # no ParameterError
    doc = load_params_file(path.read_text())
    assert doc["/press3/jident_simulator"]["ros__parameters"] == {
        "inertias_kgm2": [1.16, 1.073], "channels": ["alpha1", "t"], "repeat": 1}


def test_params_file_tags_never_construct_objects(tmp_path):
    """Any other python/ tag is read by its node kind (as rcl does), never run."""
    text = ("/**:\n  ros__parameters:\n    a: !!python/object/apply:os.system ['echo hi']\n"
            "    b: !!python/name:os.system ''\n    c: !custom 3\n")
    doc = load_params_file(text)["/**"]["ros__parameters"]
    assert doc == {"a": ["echo hi"], "b": "", "c": "3"}


def test_bad_params_files_still_give_one_line(tmp_path):
    (tmp_path / "bad.yaml").write_text("a: [1, 2\n")
    (tmp_path / "plain.yaml").write_text("backlash_width_m: 0.005\n")
    for name, text in (("bad.yaml", "not YAML"), ("plain.yaml", "not a ROS 2 params file")):
        with pytest.raises(ParameterError, match=text):
            check_params_files(["--params-file", str(tmp_path / name)])


@pytest.mark.ros
def test_node_starts_with_a_launch_written_params_file(node_env, tmp_path):  # noqa: F811
    """rcl reads the tuple as an array: the simulator runs its one case and stops waiting for its
    windowing node (exit 1 with the reason), not exit 2 on the params file."""
    ns = f"/lp{os.getpid()}"
    path = launch_params_file(tmp_path, f"{ns}/jident_simulator",
                              {"inertias_kgm2": (1.16,), "wait_timeout_s": 2.0, "publish_clock": False})
    p = Proc(node_env, tmp_path, "simulator", "-r", f"__ns:={ns}", "--params-file", str(path))
    rc = p.wait()
    assert rc == 1 and "no subscription" in p.text() and "params-file" not in p.text(), logs(p)


@pytest.mark.ros
@pytest.mark.parametrize("delay_s", [0.3, 1.5])
def test_sigint_while_a_node_is_starting_ends_quietly(node_env, tmp_path, delay_s):  # noqa: F811
    """launch stops every node with SIGINT as soon as one exits, also a node still importing: status 0 and
    no KeyboardInterrupt traceback (jident_ros/nodes/entry.py), whenever the signal comes."""
    import signal
    import time

    p = Proc(node_env, tmp_path, "diagnostic", "-p", "record:=false")
    time.sleep(delay_s)
    p.p.send_signal(signal.SIGINT)
    rc = p.wait()
    assert rc == 0 and "Traceback" not in p.text() and "KeyboardInterrupt" not in p.text(), logs(p)
