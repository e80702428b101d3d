"""The windowing node on sensor_msgs/JointState (input: joint_states, detector auto = flank), live.

A simulated drive's samples go out as one JointState message per sample (motor: position alpha1, velocity
omega1, effort m_el; load: position alpha2, velocity omega2; header stamp = t), as ros2_control's
joint_state_broadcaster publishes them; the windowing node's flank detector captures the window and the
diagnostic node identifies J1 from it.
"""
from __future__ import annotations

import math

import pytest
from test_nodes import TIMEOUT, Proc, library, logs, node_env, procs, ros, statuses  # noqa: F401

J1 = 1.16


@pytest.mark.ros
def test_joint_states_input_windows_and_j1(node_env, library, ros, procs, tmp_path):
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    from jident_ros.config import load_system_config
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, qos_signals, status_values
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import DEFAULT_CHANNELS
    w = simulate_grid(load_system_config(), [Case(J1, 0.005, 0.025)] * 2)
    stream, _ = embed_windows(w, 600, start_time_s=1.0)
    col = {c: i for i, c in enumerate(DEFAULT_CHANNELS)}
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    est = ros.collect(Float64, "/js/inertia_estimate", qos_latched(10))
    # the writer keeps every message until acknowledged: a reliable KEEP_LAST writer whose history is shorter than
    # the burst overwrites what a busy subscriber has not taken yet (CI lost 5 messages that way at t = 1.2 s)
    pub = ros.node.create_publisher(JointState, "/js/joint_states", qos_signals(len(stream) + 10))
    ns = ["-r", "__ns:=/js"]
    diag = Proc(node_env, tmp_path, "diagnostic", *ns, "-p", f"pattern_library:={library}", "-p", "record:=false",
                "-p", "stale_after_s:=0.0")
    win = Proc(node_env, tmp_path, "windowing", *ns, "-p", "input:=joint_states", "-p", "signals_queue_depth:=10000")
    procs += [diag, win]
    assert ros.spin_until(lambda: pub.get_subscription_count() >= 1 and est.matched(), TIMEOUT), logs(win, diag)
    for k, row in enumerate(stream):
        t = float(row[col["t"]])
        sec = int(math.floor(t))
        m = JointState(name=["motor", "load"],
                       position=[float(row[col["alpha1"]]), float(row[col["alpha2"]])],
                       velocity=[float(row[col["omega1"]]), float(row[col["omega2"]])],
                       effort=[float(row[col["m_el"]]), math.nan])
        m.header.stamp = Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        pub.publish(m)
        if k % 200 == 199:
            ros.ex.spin_once(timeout_sec=0.01)
    results = lambda: statuses(diags, "jident_diagnostic: inertia", "/js/drive")  # noqa: E731
    # two cases: the second one's samples close the first window (the last one waits for more data)
    assert ros.spin_until(lambda: len(results()) >= 1, 2 * TIMEOUT), logs(win, diag)
    for s in results():
        v = status_values(s)
        assert v["status"] != "refused", s.message
    assert ros.spin_until(lambda: len(est) >= 1, 10), logs(win, diag)
    for m in est:
        assert abs(m.data - J1) / J1 < 0.05, [m.data for m in est]
    assert win.alive() and diag.alive(), logs(win, diag)
