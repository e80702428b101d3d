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

    # a restart reads the state: the window count goes on
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
