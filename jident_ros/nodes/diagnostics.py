"""/diagnostics publishing shared by the nodes (REP 107 statuses)."""
from __future__ import annotations

from jident_ros.nodes.ros_io import make_diagnostic_array, qos_diagnostics


def drive_hardware_id(node, given: str = "") -> str:
    """hardware_id for /diagnostics: the parameter when set, else the resolved namespace of the
    drive topics (``/drive``, ``/press3/drive``): Float64MultiArray has no header to carry one."""
    return given or node.resolve_topic_name("drive")


class DiagnosticsPublisher:
    """Publishes DiagnosticArrays on /diagnostics stamped with the node's clock; remembers the last."""

    def __init__(self, node, topic: str = "/diagnostics"):
        self.node = node
        self.pub = node.create_publisher(_diagnostic_array_type(), topic, qos_diagnostics())
        self.last = None

    def publish(self, *statuses):
        msg = make_diagnostic_array(self.node.get_clock().now().to_msg(), statuses)
        self.pub.publish(msg)
        self.last = msg
        return msg


def _diagnostic_array_type():
    from diagnostic_msgs.msg import DiagnosticArray
    return DiagnosticArray
