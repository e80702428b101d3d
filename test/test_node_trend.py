"""The diagnostic node's trend of J1 and the backlash width (issue 14 part 2).

Windows published on drive/window feed the node's TrendTracker: the smoothed J1 goes out on inertia_trend,
the width on backlash_width_trend, the "jident_diagnostic: trend" status reports it, and trend_state_file keeps
the state over a restart (written atomically after each window, read at start).  A state file that cannot be
read: ERROR status naming it, the file moved aside, a fresh start, the node runs on.  A bad trend parameter:
one line naming it, exit status 2.
"""
from __future__ import annotations

import dataclasses

import pytest
from test_node_params import _window
from test_nodes import TIMEOUT, Proc, logs, node_env, procs, ros, statuses  # noqa: F401

N_WINDOWS = 6


def _start(node_env, tmp_path, ns, state_file, *extra):
    return Proc(node_env, tmp_path, "diagnostic", "-r", f"__ns:=/{ns}", "-p", "image_method:=false",
                "-p", "record:=false", "-p", "stale_after_s:=0.0", "-p", "trend_commissioning_windows:=3",
                "-p", f"trend_state_file:={state_file}", *extra)


@pytest.mark.ros
def test_trend_published_reported_saved_and_resumed(node_env, ros, procs, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Float64MultiArray

    from jident_ros.identify.levels import ERROR
    from jident_ros.identify.trend import TrendTracker
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_level, status_values, window_to_msg
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    j_trend = ros.collect(Float64, "/tr/inertia_trend", qos_latched())
    w_trend = ros.collect(Float64, "/tr/backlash_width_trend", qos_latched())
    pub = ros.node.create_publisher(Float64MultiArray, "/tr/drive/window", qos_latched(N_WINDOWS))
    state = tmp_path / "trend.json"
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text('{"kind": "jident_ros.identify.trend", "vers')
    p = _start(node_env, tmp_path, "tr", state)
    bad = _start(node_env, tmp_path, "trbad", corrupt)
    procs += [p, bad]
    trend = lambda hw: statuses(diags, "jident_diagnostic: trend", hw)  # noqa: E731

    # a corrupt state file: ERROR naming it, moved aside (not overwritten), a fresh start; the node runs on
    assert ros.spin_until(lambda: trend("/trbad/drive"), TIMEOUT), logs(bad)
    s = trend("/trbad/drive")[-1]
    assert status_level(s) == ERROR and "trend state unusable" in s.message and str(corrupt) in s.message, s.message
    aside = list(tmp_path.glob("corrupt.json.corrupt-*"))
    assert len(aside) == 1 and aside[0].read_text().startswith('{"kind"') and not corrupt.exists(), aside
    assert bad.alive(), logs(bad)

    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1), logs(p)
    base = _window()
    for k in range(1, N_WINDOWS + 1):
        pub.publish(window_to_msg(dataclasses.replace(base, window_id=k, entry_time_s=base.entry_time_s + 10.0 * k)))
    done = lambda: any(status_values(s)["windows_updated"] == str(N_WINDOWS) for s in trend("/tr/drive"))  # noqa: E731
    assert ros.spin_until(done, 2 * TIMEOUT), logs(p)
    s = [s for s in trend("/tr/drive") if status_values(s)["windows_updated"] == str(N_WINDOWS)][-1]
    v = status_values(s)
    assert status_level(s) != ERROR and v["state_saves"] == str(N_WINDOWS) and v["skipped"] == "false", (s.message, v)
    # the windows are one case (J1 1.16 kg m^2, K2 5 mm): the trend follows the published gap estimates
    assert ros.spin_until(lambda: len(j_trend) >= 1 and len(w_trend) >= 1, 10), logs(p)
    assert abs(j_trend[-1].data - 1.16) / 1.16 < 0.05, j_trend[-1].data
    assert abs(float(v["inertia_kgm2"]) - j_trend[-1].data) < 1e-9 * j_trend[-1].data, v
    assert abs(w_trend[-1].data - 0.005) < 0.001, w_trend[-1].data
    saved = TrendTracker.load(state)
    assert saved.n_windows == N_WINDOWS
    assert p.stop() == 0, logs(p)

    # a restart reads the state: the window count goes on (the latched publisher is gone first, so that the
    # restarted node is not handed the same six windows again; those are skipped, test_trend)
    ros.node.destroy_publisher(pub)
    diags.clear()
    p2 = _start(node_env, tmp_path, "tr", state)
    procs.append(p2)
    assert ros.spin_until(lambda: trend("/tr/drive"), TIMEOUT), logs(p2)
    v = status_values(trend("/tr/drive")[-1])
    assert v["windows_updated"] == str(N_WINDOWS) and status_level(trend("/tr/drive")[-1]) != ERROR, v
    assert "trend state read from" in p2.text(), logs(p2)


@pytest.mark.ros
def test_bad_trend_parameter_is_one_line(node_env, tmp_path):
    p = Proc(node_env, tmp_path, "diagnostic", "-r", "__ns:=/trp", "-p", "image_method:=false", "-p", "record:=false",
             "-p", "trend_drift_alarm_pct:=1.0")
    rc = p.wait(TIMEOUT)
    out = p.text().strip().splitlines()
    assert rc == 2 and len(out) == 1 and "trend_drift_alarm_pct" in out[0] and "Traceback" not in out[0], logs(p)


@pytest.mark.ros
def test_trend_parameters_set_at_run_time_and_the_flank_width(node_env, ros, procs, tmp_path):
    """Settable trend_* parameters are validated (a bad one refused with the reason, the read-only ones
    refused) and take effect with the next window, the tracker's state kept; a flank-detector window's K2
    estimate is what the trend follows (width_source flank)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Float64MultiArray
    from test_node_params import _set

    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_values, window_to_msg
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    w_trend = ros.collect(Float64, "/trs/backlash_width_trend", qos_latched())
    pub = ros.node.create_publisher(Float64MultiArray, "/trs/drive/window", qos_latched(N_WINDOWS))
    p = _start(node_env, tmp_path, "trs", tmp_path / "trs.json")
    procs.append(p)
    node = "/trs/jident_diagnostic"
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1), logs(p)
    for name, value, reason in (("trend_drift_alarm_pct", 1.0, "trend_drift_alarm_pct"),   # below the 2 % warning
                                ("trend_innovation_clip_sd", 1.0, "trend_innovation_clip_sd"),   # not above k
                                ("trend_width_regression_windows", 10, "read-only"),
                                ("trend_inertia_baseline_kgm2", 1.2, "read-only"),
                                ("trend_state_file", "/tmp/x.json", "read-only")):
        r = _set(ros, node, name, value)
        assert not r.successful and reason in r.reason, (name, value, r.reason)
    r = _set(ros, node, "trend_commissioning_windows", 2)    # started with 3
    assert r.successful, r.reason
    base = _window()
    for k in (1, 2):
        w = dataclasses.replace(base, window_id=k, entry_time_s=base.entry_time_s + 10.0 * k, detector="flank",
                                backlash_width_estimate_m=0.0041 + 1e-5 * k, backlash_width_se_m=2e-6)
        pub.publish(window_to_msg(w))
    trend = lambda: [s for s in statuses(diags, "jident_diagnostic: trend", "/trs/drive")  # noqa: E731
                     if status_values(s).get("windows_updated") == "2"]
    assert ros.spin_until(trend, 2 * TIMEOUT), logs(p)
    v = status_values(trend()[-1])
    assert v["commissioning"] == "false", v           # 2 windows commissioned: the run-time value took effect
    assert v["width_source"] == "flank" and v["width_from_flank_detector"] == "2" and \
        v["width_from_gap_estimator"] == "0", v
    assert ros.spin_until(lambda: len(w_trend) >= 2, TIMEOUT), logs(p)
    assert abs(w_trend[-1].data - 0.00412) < 2e-6, w_trend[-1].data     # the flank estimate, not the window's 5 mm
    assert "parameters changed: trend_commissioning_windows = 2" in p.text(), logs(p)
