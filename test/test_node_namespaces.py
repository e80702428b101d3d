"""Two drives in two namespaces with use_sim_time (issue 15, item 2).

Both simulators publish the global /clock (as `ros2 run` without a remap does), so each drive's nodes see
the two drive clocks interleaved.  STALE follows the nodes' steady clock: every window of each drive is
diagnosed (6/6), and no STALE status appears while windows arrive (after a drive's last window, its input has
really stopped: STALE is then right).  The second drive has its /clock
remapped into its namespace, as the launch file does for a namespaced drive.
"""
from __future__ import annotations

import pytest
from test_nodes import TIMEOUT, Proc, library, logs, node_env, procs, ros, statuses  # noqa: F401

INERTIAS = "[1.16, 1.073, 1.218, 1.131, 1.102, 1.189]"


@pytest.mark.ros
def test_two_drives_with_sim_time_each_get_six_of_six_windows_and_no_false_stale(node_env, library, ros, procs,
                                                                                  tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64

    from jident_ros.identify.levels import STALE
    from jident_ros.nodes.ros_io import qos_diagnostics, qos_latched, status_level, status_values
    diags = ros.collect(DiagnosticArray, "/diagnostics", qos_diagnostics())
    drives = {"/d1": [], "/d2": ["-r", "/clock:=/d2/clock"]}
    est = {ns: ros.collect(Float64, f"{ns}/inertia_estimate", qos_latched(10)) for ns in drives}
    for ns, remap in drives.items():
        common = ["-r", f"__ns:={ns}", *remap, "-p", "use_sim_time:=true"]
        procs.append(Proc(node_env, tmp_path, "diagnostic", *common, "-p", f"pattern_library:={library}",
                          "-p", "stale_after_s:=3.0"))
        procs.append(Proc(node_env, tmp_path, "windowing", *common))
    # this test hears each diagnostic node before the first window (inertia_estimate keeps only the last)
    assert ros.spin_until(lambda: all(e.matched() for e in est.values())), logs(*procs)
    for ns, remap in drives.items():
        procs.append(Proc(node_env, tmp_path, "simulator", "-r", f"__ns:={ns}", *remap, "-p", "cases:=zip",
                          "-p", f"inertias_kgm2:={INERTIAS}", "-p", "real_time_factor:=2.0",
                          "-p", "wait_for_subscribers:=1", "-p", "wait_timeout_s:=60.0"))
    assert ros.spin_until(lambda: all(len(e) >= 6 for e in est.values()), 3 * TIMEOUT), logs(*procs)
    ros.spin_until(lambda: False, 1.5)
    for ns in drives:
        def task(ns=ns):
            return statuses(diags, "jident_diagnostic: diagnosis", f"{ns}/drive")
        assert ros.spin_until(lambda: any(status_values(s)["windows_diagnosed"] == "6" for s in task()), 10), ns
        task = task()
        last = status_values(task[-1])
        assert last["drive_model_declared"] == "false", last        # nothing declared: the simulator's exact torque
        assert last["windows_diagnosed"] == "6" and last["windows_lost"] == "0" and last["last_window_id"] == "6", last
        # a false STALE is one while windows still arrive (before the sixth is diagnosed); once a drive's
        # simulator has finished, "no input for 3 s" is true (the other drive may still be running under load)
        stale = [s.message for s in task if status_level(s) == STALE and "received yet" not in s.message
                 and int(status_values(s)["windows_diagnosed"]) < 6]
        assert not stale, (ns, stale)
        for got, true in zip([m.data for m in est[ns]], [1.16, 1.073, 1.218, 1.131, 1.102, 1.189]):
            assert abs(got - true) / true < 0.01, (ns, got, true)
