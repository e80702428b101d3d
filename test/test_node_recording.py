"""The diagnostic node records by default (issue 11 part 4) and reports its recorder (issue 15 item 5).

* default parameters: a rosbag2-named bag under $JIDENT_DATA_DIR/bags, finalised on SIGTERM, read by
  rosbags, holding the drive/signals the test published (wall-clock stamps) and the node's own
  "jident_diagnostic: recorder" statuses (OK);
* an unusable record root (a file): a periodic ERROR status naming it and the reason; the node runs on.
"""
from __future__ import annotations

import os
import re
import time

import numpy as np
import pytest
from test_nodes import Proc, Ros, library, logs, node_env  # noqa: F401  (fixtures)

from jident_ros.nodes.diagnostics import status_task

pytestmark = pytest.mark.ros


def _batch(i: int):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension
    data = np.zeros((50, 9))
    data[:, 0] = 1.0 + (i * 50 + np.arange(50)) * 5e-4
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="sample", size=50, stride=450),
                      MultiArrayDimension(label="t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2", size=9, stride=9)]
    msg.data = data.reshape(-1).tolist()
    return msg


def _recorder_statuses(arrays, hw):
    return [s for a in arrays for s in a.status if status_task(s.name) == "jident_diagnostic: recorder" and s.hardware_id == hw]


def test_default_parameters_leave_a_bag_that_rosbags_reads(node_env, library, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from rosbags.highlevel import AnyReader
    from std_msgs.msg import Float64MultiArray

    from jident_ros.nodes.ros_io import qos_signals
    env = dict(node_env, JIDENT_DATA_DIR=str(tmp_path / "data"))
    ros = Ros("jident_test_rec_default")
    diag_in = ros.collect(DiagnosticArray, "/diagnostics", 10)
    pub = ros.node.create_publisher(Float64MultiArray, "/recdef/drive/signals", qos_signals())
    node = Proc(env, tmp_path, "diagnostic", "-r", "__ns:=/recdef", "-p", f"pattern_library:={library}",
                "-p", "stale_after_s:=0.0")
    try:
        assert ros.spin_until(lambda: any(s.level == b"\x00" for s in _recorder_statuses(diag_in, "/recdef/drive")),
                              60), logs(node)
        assert ros.spin_until(lambda: pub.get_subscription_count() >= 1, 30), logs(node)
        t0 = time.time_ns()
        for i in range(5):
            pub.publish(_batch(i))
            ros.spin_until(lambda: False, 0.05)
        ros.spin_until(lambda: False, 1.5)
        assert node.stop() == 0, logs(node)
        t1 = time.time_ns()
    finally:
        node.stop()
        ros.close()
    (bag,) = [p for p in (tmp_path / "data" / "bags").iterdir() if p.is_dir()]   # and the manifest
    assert re.fullmatch(r"rosbag2_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d", bag.name)
    assert (bag / "metadata.yaml").is_file() and not (bag / ".jident_reserve").exists()
    with AnyReader([bag]) as reader:
        rows = [(c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    signals = [(t, m) for topic, t, m in rows if topic == "/recdef/drive/signals"]
    assert len(signals) == 5
    assert [float(m.data[0]) for _, m in signals] == [1.0 + i * 50 * 5e-4 for i in range(5)]
    assert all(t0 <= t <= t1 for t, _ in signals)          # wall clock, not a ROS clock
    recorder_status = [s for topic, _, m in rows if topic == "/diagnostics" for s in m.status
                       if status_task(s.name) == "jident_diagnostic: recorder"]
    assert recorder_status and recorder_status[0].level == 0


def test_unusable_record_root_is_an_error_status(node_env, library, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    (tmp_path / "afile").write_text("x")
    ros = Ros("jident_test_rec_bad")
    diag_in = ros.collect(DiagnosticArray, "/diagnostics", 10)
    node = Proc(node_env, tmp_path, "diagnostic", "-r", "__ns:=/recbad", "-p", f"pattern_library:={library}",
                "-p", f"record_root:={tmp_path / 'afile'}", "-p", "stale_after_s:=0.0")
    try:
        assert ros.spin_until(lambda: len(_recorder_statuses(diag_in, "/recbad/drive")) >= 2, 60), logs(node)
        st = _recorder_statuses(diag_in, "/recbad/drive")
        assert all(s.level == b"\x02" for s in st)
        assert "not recording" in st[0].message and "afile: is a file" in st[0].message, st[0].message
        assert node.alive(), logs(node)
    finally:
        node.stop()
        ros.close()
    assert os.path.isfile(tmp_path / "afile")
