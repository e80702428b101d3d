"""The QoS a recording gives a topic the node subscribes to: what its publishers offer (rosbag2 records
``offered_qos_profiles`` the same way), so that ``ros2 bag play`` offers it again -- a latched ``drive/case``
is replayed latched.

From the ROS graph (``get_publishers_info_by_topic``) come each publisher's reliability, durability, deadline,
lifespan and liveliness.  History and depth do not travel in DDS discovery: the graph reports history UNKNOWN,
depth 0 (rmw_fastrtps, also for a publisher in the same process).  They are recorded as keep_last with the depth
the recorder itself subscribed with (``fallback``: for the case topics 100 messages, every case message it kept),
which is what a late subscriber of the replay can get.  Without a known publisher: ``fallback`` alone.
"""
from __future__ import annotations

from rclpy.qos import HistoryPolicy, QoSProfile


def offered_qos(node, topic: str, fallback: QoSProfile) -> list:
    """The profiles offered on ``topic`` (resolved name), one per distinct publisher profile."""
    out = []
    try:
        infos = node.get_publishers_info_by_topic(topic)
    except Exception:  # a graph query can fail while the node shuts down: record what it subscribed with
        infos = []
    for info in infos:
        q = info.qos_profile
        p = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=fallback.depth, reliability=q.reliability,
                       durability=q.durability, deadline=q.deadline, lifespan=q.lifespan, liveliness=q.liveliness,
                       liveliness_lease_duration=q.liveliness_lease_duration)
        if p not in out:
            out.append(p)
    return out or [fallback]
