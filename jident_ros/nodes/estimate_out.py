"""The diagnostic node's stamped estimate, beside the kept ``inertia_estimate`` (std_msgs/Float64):

* ``inertia_estimate/stamped`` -- geometry_msgs/InertiaStamped: ``header.stamp`` = the window's entry time on
  the drive clock (``entry_time_s``, the stamp of the sample that entered the backlash zone: what identifies
  the window in ``drive/window`` and in the recording), ``header.frame_id`` = "" (no TF frame),
  ``inertia.izz`` = J1 in kg m^2 (about the motor shaft, taken as the z axis); ``m``, ``com`` and
  the other moments are 0: not estimated.
* ``inertia_estimate/detail`` -- std_msgs/Float64MultiArray, one labelled row (the drive/case layout):
  ``window_id, entry_time_s, inertia_kgm2, inertia_std_error_kgm2, level`` -- the uncertainty (the gap fit's
  standard error; NaN when the published value is the image method's class, which has none) and the window id
  that the stamped message cannot carry.

Both latched (transient local, depth 10), published once per window that gets an estimate, after its diagnosis.
"""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import InertiaStamped
from std_msgs.msg import Float64MultiArray

from jident_ros.nodes.ros_io import multiarray_from_array

DETAIL_LABEL = "window_id,entry_time_s,inertia_kgm2,inertia_std_error_kgm2,level"
STAMPED_TOPIC = "inertia_estimate/stamped"
DETAIL_TOPIC = "inertia_estimate/detail"
#: (topic, type) of what this module publishes, for the recorder
TOPICS = ((STAMPED_TOPIC, "geometry_msgs/msg/InertiaStamped"), (DETAIL_TOPIC, "std_msgs/msg/Float64MultiArray"))


def drive_time(t_s: float) -> tuple[int, int]:
    """(sec, nanosec) of a drive-clock time in seconds (builtin_interfaces/Time; negative times clamp to 0)."""
    ns = max(0, int(round(float(t_s) * 1e9)))
    return ns // 1_000_000_000, ns % 1_000_000_000


def std_error_of(values) -> float:
    """The gap fit's standard error of J1 from a diagnosis' key-values (NaN when there is none)."""
    v = dict(values).get("gap_std_error_kgm2")
    try:
        v = float(v)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


class StampedEstimate:
    """Creates the two lifecycle publishers on ``node``; :meth:`publish` sends one window's pair and returns the
    messages (for the recorder)."""

    def __init__(self, node, qos, frame_id: str = ""):
        self.frame_id = frame_id
        self._Inertia = InertiaStamped
        self.pub_stamped = node.create_lifecycle_publisher(InertiaStamped, STAMPED_TOPIC, qos)
        self.pub_detail = node.create_lifecycle_publisher(Float64MultiArray, DETAIL_TOPIC, qos)

    def publish(self, window_id: int, entry_time_s: float, inertia_kgm2: float, values, level: int) -> tuple:
        msg = self._Inertia()
        msg.header.stamp.sec, msg.header.stamp.nanosec = drive_time(entry_time_s)
        msg.header.frame_id = self.frame_id
        msg.inertia.izz = float(inertia_kgm2)
        row = np.array([[window_id, entry_time_s, inertia_kgm2, std_error_of(values), level]], dtype=float)
        detail = multiarray_from_array(row, DETAIL_LABEL.split(","))
        self.pub_stamped.publish(msg)
        self.pub_detail.publish(detail)
        return msg, detail
