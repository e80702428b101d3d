"""Parameters and /diagnostics of RUNNING nodes (issue 11 part 3, issue 15 items 4, 6, 7, 10, 11).

Through the parameter services every ROS node offers (what ``ros2 param describe/set/get`` call; there is
no ros2cli wheel): ``describe_parameters`` gives each parameter's type, description and range from the
schema (jident_ros/parameters.py); ``set_parameters`` refuses every invalid value with a reason and every
accepted one takes effect; a parameter request is answered while the simulator streams.  Besides: the
diagnostic node is a lifecycle node that autostarts to active, reports lost windows (window_id gaps) and
windows that do not match its configuration.
"""
from __future__ import annotations

import dataclasses
import math
import os
import statistics
import subprocess
import sys
import time

import numpy as np
import pytest
from test_nodes import (  # noqa: F401
    REPO,
    TIMEOUT,
    Proc,
    _good_stream,
    library,
    logs,
    node_env,
    one_line_failures,
    procs,
    ros,
    statuses,
)

#: Read-only parameter services: their request is sent again when no answer came within READ_RETRY_S.  A response
#: can be lost when the request goes out as soon as the service is discovered, before the server has matched the
#: client's response reader (ros2/demos#304, ros2/rmw_fastrtps#238; a CI run: list_parameters of a windowing node
#: never answered in 60 s); a read is safe to repeat, a set is not (it would apply twice).
READ_SERVICES = ("ListParameters", "DescribeParameters", "GetParameters")
READ_RETRY_S = 10.0


def _call(ros, srv_type, name, request, timeout=TIMEOUT):
    import time
    client = ros.node.create_client(srv_type, name)
    try:
        assert ros.spin_until(client.service_is_ready, timeout), f"{name}: no service"
        end = time.monotonic() + timeout
        step = READ_RETRY_S if srv_type.__name__ in READ_SERVICES else timeout
        while True:
            fut = client.call_async(request)
            if ros.spin_until(fut.done, max(min(step, end - time.monotonic()), 0.0)):
                return fut.result()
            assert time.monotonic() < end, f"{name}: no answer"
    finally:
        ros.node.destroy_client(client)


def _set(ros, node, name, value):
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    req = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    (result,) = _call(ros, SetParameters, f"{node}/set_parameters", req).results
    return result


def _get(ros, node, name):
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python
    (v,) = _call(ros, GetParameters, f"{node}/get_parameters", GetParameters.Request(names=[name])).values
    return parameter_value_to_python(v)


def _describe(ros, node, schema):
    from rcl_interfaces.srv import DescribeParameters, ListParameters
    names = _call(ros, ListParameters, f"{node}/list_parameters", ListParameters.Request()).result.names
    assert set(schema) <= set(names), sorted(set(schema) - set(names))
    descs = _call(ros, DescribeParameters, f"{node}/describe_parameters",
                  DescribeParameters.Request(names=list(schema))).descriptors
    return dict(zip(schema, descs))


def _check_descriptors(descs, schema):
    from rcl_interfaces.msg import ParameterType as T

    from jident_ros.nodes.params import parameter_type
    for name, p in schema.items():
        d = descs[name]
        assert d.name == name and d.type == parameter_type(p.default), name
        assert d.description == p.description and d.read_only == p.read_only, name
        if d.type == T.PARAMETER_DOUBLE and (p.min is not None or p.max is not None):
            (r,) = d.floating_point_range
            # an exclusive end is shown as the nearest value inside (issue 24: describe = validation)
            lo = -math.inf if p.min is None else (math.nextafter(p.min, math.inf) if p.min_exclusive else p.min)
            hi = math.inf if p.max is None else (math.nextafter(p.max, -math.inf) if p.max_exclusive else p.max)
            assert r.from_value == lo and r.to_value == hi, name
        elif d.type == T.PARAMETER_INTEGER and (p.min is not None or p.max is not None):
            (r,) = d.integer_range
            assert r.from_value == p.min + p.min_exclusive and r.to_value == p.max - p.max_exclusive, name
            assert r.step == 1, name
        else:
            assert not d.floating_point_range and not d.integer_range, name
        if p.choices:
            assert d.additional_constraints == "one of " + ", ".join(p.choices), name


def _window(window_id=1, **changes):
    from jident_ros.stream.detector import BacklashDetector
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    _, (stream, _) = _good_stream()
    (ev,) = BacklashDetector(0.005, 0.1, 5e-4).push(stream, DEFAULT_CHANNELS)
    return dataclasses.replace(ev.window, window_id=window_id, **changes)


# --------------------------------------------------------------------------- windowing


@pytest.mark.ros
def test_windowing_parameters_described_validated_and_applied(node_env, ros, procs, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    from jident_ros.nodes import windowing
    from jident_ros.nodes.ros_io import qos_diagnostics, status_values
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    win = Proc(node_env, tmp_path, "windowing", "-r", "__ns:=/pw", "-p", "diagnostics_period_s:=0.2")
    procs.append(win)
    node = "/pw/jident_windowing"
    _check_descriptors(_describe(ros, node, windowing.schema()), windowing.schema())
    # invalid values: refused with the reason (rclpy: type, range, read-only; ours: the node's checks)
    bad = [("backlash_width_m", -1.0, "backlash_width_m"), ("backlash_width_m", "abc", "type"),
           ("backlash_width_m", 0.0, "backlash_width_m"), ("backlash_width_m", 2.0, "backlash_width_m"),
           ("backlash_width_m", float("nan"), "backlash_width_m"), ("gap_tolerance", 0.5, "gap_tolerance"),
           ("channels", ["alpha1"], "read-only"), ("load.wheel_radius_m", 0.2, "read-only"),
           ("window_queue_depth", 5, "read-only")]
    for name, value, reason in bad:
        r = _set(ros, node, name, value)
        assert not r.successful and reason in r.reason, (name, value, r.reason)
    assert _get(ros, node, "backlash_width_m") == 0.005
    # valid values take effect: the detector's K2 in the rate status, an integer given for a float
    for name, value, want in [("backlash_width_m", 0.007, 0.007), ("gap_tolerance", 2, 2.0),
                              ("hardware_id", "/press9", "/press9")]:
        r = _set(ros, node, name, value)
        assert r.successful, (name, r.reason)
        assert _get(ros, node, name) == want
    rate = lambda: statuses(diags, "jident_windowing: rate", "/press9")  # noqa: E731
    assert ros.spin_until(lambda: rate()), logs(win)
    v = status_values(rate()[-1])
    assert float(v["backlash_width_m"]) == 0.007 and float(v["threshold_rad"]) == pytest.approx(0.07)
    assert win.alive(), logs(win)


# --------------------------------------------------------------------------- diagnostic


@pytest.fixture(scope="module")
def diag_node(node_env, library, tmp_path_factory):
    """A running diagnostic node in /pd, started with gap_method:=off (YAML false on the command line)."""
    tmp = tmp_path_factory.mktemp("pd")
    p = Proc(node_env, tmp, "diagnostic", "-r", "__ns:=/pd", "-p", f"pattern_library:={library}",
             "-p", "gap_method:=off", "-p", "stale_after_s:=0.0")
    yield p
    p.stop()


@pytest.mark.ros
def test_diagnostic_is_a_lifecycle_node_active_after_start(diag_node, ros):
    from lifecycle_msgs.msg import State
    from lifecycle_msgs.srv import GetState
    st = _call(ros, GetState, "/pd/jident_diagnostic/get_state", GetState.Request())
    assert st.current_state.id == State.PRIMARY_STATE_ACTIVE, (st.current_state, logs(diag_node))


@pytest.mark.ros
def test_diagnostic_parameters_described_validated_and_applied(diag_node, library, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    from jident_ros.nodes import diagnostic
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_values, window_to_msg
    node = "/pd/jident_diagnostic"
    _check_descriptors(_describe(ros, node, diagnostic.schema()), diagnostic.schema())
    assert _get(ros, node, "gap_method") == "off"   # -p gap_method:=off is YAML false: accepted as off
    bad = [("p", 4.0, "method.p_values"), ("p", "two", "type"), ("gap_method", "fast", "gap_method"),
           ("image_method", False, "image_method"),      # with gap_method off nothing would be identified
           ("stale_after_s", -1.0, "stale_after_s"), ("record_dir", "/tmp/x", "read-only"),
           ("method.p_values", [2.0], "read-only")]
    for name, value, reason in bad:
        r = _set(ros, node, name, value)
        assert not r.successful and reason in r.reason, (name, value, r.reason)
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    pub = ros.node.create_publisher(Float64MultiArray, "/pd/drive/window", qos_latched(10))
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1)
    results = lambda: statuses(diags, "jident_diagnostic: inertia", "/pd/drive")  # noqa: E731
    # each accepted change takes effect on the next window
    for k, (changes, check) in enumerate([
            ({"p": 3.0}, lambda v: float(v["p"]) == 3.0 and "gap_j1_kgm2" not in v),
            ({"gap_method": False, "p": 2.0}, lambda v: float(v["p"]) == 2.0 and "gap_j1_kgm2" not in v),
            ({"gap_method": "none"}, lambda v: "gap_j1_kgm2" not in v),
            ({"gap_method": "auto"}, lambda v: v["estimate_source"] == "gap" and "gap_j1_kgm2" in v)]):
        for name, value in changes.items():
            r = _set(ros, node, name, value)
            assert r.successful, (name, value, r.reason)
        n = len(results())
        pub.publish(window_to_msg(_window(window_id=k + 1)))
        assert ros.spin_until(lambda: len(results()) > n)
        v = status_values(results()[-1])
        assert check(v), (changes, results()[-1].message, v)
    assert _get(ros, node, "gap_method") == "auto"


def _publish_retrying(ros, pub, msg, tries=100):
    """Publish; when this test's own reliable writer refuses for a moment in a burst ("cannot publish data":
    the DDS writer blocked past its max_blocking_time), spin briefly and retry: the burst is about the
    node's counting, not about this writer."""
    from rclpy._rclpy_pybind11 import RCLError
    for _ in range(tries - 1):
        try:
            return pub.publish(msg)
        except RCLError:
            ros.ex.spin_once(timeout_sec=0.02)
    return pub.publish(msg)


@pytest.mark.ros
def test_diagnostic_reports_lost_and_mismatched_windows(node_env, library, ros, procs, tmp_path):
    """window_id gaps are counted and named (a burst of 408 windows: every window diagnosed or counted
    lost); a window whose length, sample period or wheel radius differ from the configuration is not
    diagnosed (ERROR naming the field)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    from jident_ros.identify.levels import ERROR, WARN
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_level, status_values, window_to_msg
    from jident_ros.stream.layout import Window
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    pub = ros.node.create_publisher(Float64MultiArray, "/lost/drive/window", qos_latched(50))
    p = Proc(node_env, tmp_path, "diagnostic", "-r", "__ns:=/lost", "-p", f"pattern_library:={library}",
             "-p", "stale_after_s:=0.0")
    procs.append(p)
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1), logs(p)
    results = lambda: statuses(diags, "jident_diagnostic: inertia", "/lost/drive")  # noqa: E731
    task = lambda: statuses(diags, "jident_diagnostic: diagnosis", "/lost/drive")  # noqa: E731
    base = _window()
    for k in (1, 2, 3, 7, 8):
        pub.publish(window_to_msg(dataclasses.replace(base, window_id=k)))
    assert ros.spin_until(lambda: len(results()) >= 5), logs(p)
    assert ros.spin_until(lambda: any(status_values(s)["windows_lost"] == "3" for s in task()))
    s = [s for s in task() if status_values(s)["windows_lost"] == "3"][0]
    assert status_level(s) == WARN and "3 window(s) lost" in s.message and status_values(s)["lost_window_ids"] == "4-6"
    # mismatches: sample period, length, wheel radius
    bad = [dataclasses.replace(base, window_id=9, sample_period_s=1e-3),
           Window(base.data[:-100], base.channels, base.entry_index, base.entry_time_s, base.backlash_width_m,
                  base.wheel_radius_m, base.sample_period_s, 10),
           dataclasses.replace(base, window_id=11, wheel_radius_m=0.2)]
    for w in bad:
        pub.publish(window_to_msg(w))
    assert ros.spin_until(lambda: len(results()) >= 8), logs(p)
    for s, what in zip(results()[5:8], ("sample period", "length 1948", "wheel radius")):
        assert status_level(s) == ERROR and "does not match the configuration" in s.message and what in s.message, \
            s.message
    # a burst of 408 windows (ids 12..419) into the keep-last-50 queue: every one diagnosed or counted lost
    n0 = len(results())
    for k in range(12, 12 + 408):
        _publish_retrying(ros, pub, window_to_msg(dataclasses.replace(base, window_id=k)))
    assert ros.spin_until(lambda: any(status_values(s)["last_window_id"] == "419" for s in task()), 2 * TIMEOUT), \
        logs(p)
    last = [s for s in task() if status_values(s)["last_window_id"] == "419"][-1]
    v = status_values(last)
    diagnosed = len(results()) - n0
    lost = int(v["windows_lost"]) - 3
    print(f"burst of 408 windows: {diagnosed} diagnosed, {lost} counted lost")
    assert diagnosed + lost == 408 and int(v["windows_seen"]) == n0 + diagnosed, v
    assert p.alive(), logs(p)


# --------------------------------------------------------------------------- simulator


@pytest.mark.ros
def test_simulator_answers_parameter_requests_while_streaming(node_env, ros, procs, tmp_path):
    """Timers, not a blocking loop: at real time, get_parameters/describe_parameters answer within 0.5 s
    (median of 10 calls; the old blocking loop answered after the stream, 3 s)."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters
    from std_msgs.msg import Float64MultiArray

    from jident_ros.nodes import simulator
    from jident_ros.nodes.ros_io import qos_signals
    signals = ros.collect(Float64MultiArray, "/ps/drive/signals", qos_signals())
    # the subscriber is this test (no windowing node): wait_for_node "" = any subscriber
    sim = Proc(node_env, tmp_path, "simulator", "-r", "__ns:=/ps", "-p", "real_time_factor:=1.0",
               "-p", "repeat:=0", "-p", "inertias_kgm2:=[1.16]", "-p", "publish_clock:=false",
               "-p", 'wait_for_node:=""')
    procs.append(sim)
    assert ros.spin_until(lambda: len(signals) >= 20), logs(sim)
    _check_descriptors(_describe(ros, "/ps/jident_simulator", simulator.schema()), simulator.schema())
    waits = []
    for k in range(10):
        n = len(signals)
        t0 = time.monotonic()
        if k % 2:
            _call(ros, GetParameters, "/ps/jident_simulator/get_parameters",
                  GetParameters.Request(names=["real_time_factor"]))
        else:
            _call(ros, DescribeParameters, "/ps/jident_simulator/describe_parameters",
                  DescribeParameters.Request(names=["batch_size"]))
        waits.append(time.monotonic() - t0)
        assert ros.spin_until(lambda: len(signals) > n, 5.0)   # still streaming
    print("parameter service answers while streaming [s]:", [f"{w:.3f}" for w in waits])
    assert statistics.median(waits) < 0.5 and max(waits) < 2.0, waits
    r = _set(ros, "/ps/jident_simulator", "real_time_factor", 2.0)
    assert not r.successful and "read-only" in r.reason


@pytest.mark.ros
def test_simulator_warns_when_it_starts_without_a_subscriber(node_env, tmp_path):
    from jident_ros.parameters import SIMULATOR
    assert SIMULATOR["wait_for_subscribers"] == 1
    p = Proc(node_env, tmp_path, "simulator", "-r", "__ns:=/nobody", "-p", "wait_for_subscribers:=0",
             "-p", "inertias_kgm2:=[1.16]", "-p", "real_time_factor:=0.0", "-p", "publish_clock:=false")
    assert p.wait() == 0, logs(p)
    assert "starting without any subscriber" in p.text(), logs(p)


@pytest.mark.ros
def test_simulator_waits_for_the_windowing_node_not_any_subscriber(node_env, ros, procs, tmp_path):
    """wait_for_node (default jident_windowing): a subscriber of drive/signals that is not the windowing node
    (here this test, as the diagnostic node's recorder would be) does not start the stream.

    It failed once in a clean-clone run (not reproduced here, idle or under load).  Made less dependent on
    its surroundings: the namespace is unique to this run (a ROS_DOMAIN_ID chosen as pid % 100 + 1 can be
    shared with another run, whose simulator would then feed this subscriber), the deadline is 4 s (the
    simulator must have matched this subscriber by then), and the refusal names the missing node in both
    of its forms."""
    from std_msgs.msg import Float64MultiArray

    from jident_ros.nodes.ros_io import qos_signals
    from jident_ros.parameters import SIMULATOR
    assert SIMULATOR["wait_for_node"] == "jident_windowing"
    ns = f"/wn{os.getpid()}"
    signals = ros.collect(Float64MultiArray, f"{ns}/drive/signals", qos_signals())
    p = Proc(node_env, tmp_path, "simulator", "-r", f"__ns:={ns}", "-p", "inertias_kgm2:=[1.16]",
             "-p", "wait_timeout_s:=4.0", "-p", "publish_clock:=false")
    procs.append(p)
    assert ros.spin_until(signals.matched), logs(p)      # the simulator's publisher sees this subscriber
    ros.spin_until(lambda: p.p.poll() is not None, TIMEOUT)
    assert p.wait() == 1 and not signals, logs(p)
    assert (f"no subscription of {ns}/drive/signals by a node named 'jident_windowing' (1 subscriber(s) of "
            "other nodes;") in p.text(), logs(p)


# --------------------------------------------------------------------------- one line, exit 2


@pytest.mark.ros
def test_params_file_errors_and_model_overload_give_one_line(node_env, tmp_path):
    (tmp_path / "malformed.yaml").write_text("a: [1, 2\n")
    (tmp_path / "plain.yaml").write_text("backlash_width_m: 0.005\n")
    (tmp_path / "empty.yaml").write_text("")
    cases = [
        ("windowing", ["--params-file", str(tmp_path / "missing.yaml")], "missing.yaml", "cannot read"),
        ("windowing", ["--params-file", str(tmp_path / "malformed.yaml")], "malformed.yaml", "not YAML"),
        ("diagnostic", ["--params-file", str(tmp_path / "plain.yaml")], "plain.yaml", "not a ROS 2 params file"),
        ("windowing", ["--params-file", str(tmp_path / "empty.yaml")], "empty.yaml", "not a ROS 2 params file"),
        ("simulator", ["-p", "consistencies_pa_sn:=[1000000.0]"], "consistencies_pa_sn", "pull-out torque"),
        ("diagnostic", ["-p", "gap_method:=fast"], "gap_method", "fast"),
    ]
    lines = one_line_failures(node_env, tmp_path, [(node, args) for node, args, _, _ in cases])
    for line, (_, _, a, b) in zip(lines, cases):
        assert a in line and b in line and "Traceback" not in line, line


def test_cli_gap_method_none(tmp_path):
    r = subprocess.run([sys.executable, "-m", "jident_ros.cli", "diagnose", "--help"], capture_output=True, text=True,
                       timeout=60, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert "none" in r.stdout and r.returncode == 0


def test_schema_defaults_fit_their_ranges():
    """Every default is inside its own range and choices (the declared descriptors would refuse it)."""
    from jident_ros import parameters as P
    from jident_ros.nodes.params import coerce
    for schema in (P.SIMULATOR_PARAMS, P.WINDOWING_PARAMS, P.DIAGNOSTIC_PARAMS, P.REPLAY_PARAMS):
        for name, p in schema.items():
            assert coerce(name, p.default, p) == p.default, name
            assert p.description and "\n" not in p.description, name
    assert np.isfinite(P.MAX_DEPTH)


@pytest.mark.parametrize("which", ["SIMULATOR_PARAMS", "WINDOWING_PARAMS", "DIAGNOSTIC_PARAMS", "REPLAY_PARAMS"])
def test_interfaces_doc_holds_the_generated_parameter_tables(which):
    from jident_ros import parameters as P
    doc = (REPO / "docs" / "interfaces.md").read_text()
    assert P.markdown_table(getattr(P, which)) in doc, f"regenerate the {which} table (parameters.markdown_table)"


def test_cli_flags_that_mirror_node_parameters_take_their_help_from_the_schema():
    """`jident diagnose --image-min-margin ...` and `jident trend --drift-warn-pct ...`: the --help is the
    schema's description, unit, range and default (parameters.cli_help), not a second wording."""
    import argparse

    from jident_ros import parameters as P
    from jident_ros.cli.main import build_parser
    from jident_ros.cli.trend import MIRRORED_FLAGS
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    mirrored = {"diagnose": ["--image-min-margin", "--plausible-min-ratio", "--plausible-max-ratio", "--p",
                             "--torque-accuracy", "--coulomb-friction-max-nm", "--viscous-friction-band-nms-per-rad",
                             "--torque-offset-rel-base", "--torque-lag-max-s", "--publish-ambiguous"],
                "trend": list(MIRRORED_FLAGS)}
    for command, flags in mirrored.items():
        actions = {o: a for a in sub.choices[command]._actions for o in a.option_strings}
        for flag in flags:
            name = ("trend_" if command == "trend" else "") + flag[2:].replace("-", "_")
            assert actions[flag].help == P.cli_help(name), flag
            assert P.DIAGNOSTIC_PARAMS[name].description.replace("%", "%%") in actions[flag].help
    from jident_ros.identify.verdict import VerdictPolicy
    assert set(P.POLICY_CLI_FLAGS) <= {f.name for f in dataclasses.fields(VerdictPolicy)}
    diag = {o: a for a in sub.choices["diagnose"]._actions for o in a.option_strings}
    assert "--no-publish-ambiguous" in diag          # a bool policy key: --x / --no-x
    gap = diag["--gap-method"]
    assert gap.help.startswith(P.cli_help("gap_method")) and tuple(gap.choices) == P.GAP_METHODS


def test_trend_parameters_and_units_come_from_the_schema():
    from jident_ros import parameters as P
    from jident_ros.identify.trend_config import NODE_ONLY, PARAMETER_FIELDS, ZERO_IS_NONE
    assert PARAMETER_FIELDS == P.TREND_FIELDS and NODE_ONLY == set(P.TREND_NODE_ONLY)
    assert ZERO_IS_NONE == {P.TREND_FIELDS[n] for n, p in P.TREND_PARAMS.items() if p.zero_is_none}
    assert P.unit_of("trend_width_limit_m") == "m" and P.unit_of("max_bag_size_bytes") == "bytes"
    assert P.unit_of("stale_after_s") == "s" and P.unit_of("p") == "" and P.unit_of("trend_drift_warn_pct") == "%"


def test_the_chain_config_fields_are_described_by_the_node_schema():
    """Each field of the monitor's frozen configs (DiagnosisConfig, DetectorConfig) is a node parameter of the one
    schema (description, unit, range, choices, run-time), or says why not; from_parameters maps them."""
    import dataclasses

    from jident_ros import parameters as P
    from jident_ros.identify.diagnosis import DiagnosisConfig
    from jident_ros.identify.monitor import DetectorConfig
    for cls, schema in ((DiagnosisConfig, P.DIAGNOSTIC_PARAMS), (DetectorConfig, P.WINDOWING_PARAMS)):
        fields = {f.name for f in dataclasses.fields(cls)}
        assert set(cls.PARAMETERS) == fields, cls.__name__
        for field, name in cls.PARAMETERS.items():
            assert name is None or name in schema, (cls.__name__, field)
    d = DiagnosisConfig.from_parameters(dict(P.DIAGNOSTIC, gap_method="none", p=3.0, image_method=True))
    assert (d.p, d.gap_method, d.image_method) == (3.0, "off", True)
    assert DiagnosisConfig.from_parameters(P.DIAGNOSTIC) == DiagnosisConfig()
    w = DetectorConfig.from_parameters(dict(P.WINDOWING, gap_tolerance=2.0), "flank", ("t", "alpha1", "alpha2"))
    assert (w.kind, w.gap_tolerance, w.channels, w.backlash_width_m) == ("flank", 2.0, ("t", "alpha1", "alpha2"), 0.005)


def test_model_parameters_are_described_by_their_dataclass_docstrings():
    """The dotted model parameters (config/system.yaml) take their description from the Attributes of the config
    dataclass (one place), with the unit; the method's fall back to the field name where it has none."""
    from jident_ros.nodes.params import describe_field, field_docs, method_defaults, system_defaults
    docs = field_docs()
    assert all(name in docs for name in system_defaults()), [n for n in system_defaults() if n not in docs]
    assert describe_field("load.wheel_radius_m") == "load: Radius of the drive wheel [r], m (config/system.yaml; fixed at start)"
    for name in list(system_defaults()) + list(method_defaults()):
        text = describe_field(name)
        assert text and "\n" not in text and text.endswith("fixed at start)"), name
