"""Conversions between numpy and the ROS messages of the node set, QoS profiles and diagnostics.

rclpy and the message packages are imported inside the functions, so importing this module never
needs ROS.  The layouts themselves are defined (and tested without ROS) in :mod:`jident_ros.stream.detector`.
"""
from __future__ import annotations

import array
import inspect
import math
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from jident_ros.identify.levels import ERROR, LEVEL_NAMES, OK, STALE, WARN  # noqa: F401  (re-exported)
from jident_ros.stream.layout import LayoutError, Window, pack, unpack
from jident_ros.stream.text import plain_numbers

# --------------------------------------------------------------------------- subscriptions


class WithMessageInfo:
    """A subscription callback ``fn(msg, info)`` (info: rclpy's MessageInfo dict, e.g. its ``source_timestamp``)
    that works on every executor.  rclpy gives a callback the message info when its signature takes two
    arguments (``Subscription.callback``'s setter inspects it; ``__signature__`` says two here); the
    SingleThreadedExecutor then calls ``cb(msg, info)``, but rclpy 9.1's EventsExecutor calls ``cb((msg, info))``,
    one tuple (its HandleSubscriptionReady; a plain two-argument callback fails there with "SystemError: null
    argument to internal routine").  Both calls reach ``fn(msg, info)`` (issue 25: the diagnostic node records the
    publish time and spins the EventsExecutor)."""

    __slots__ = ("fn",)
    __signature__ = inspect.Signature([inspect.Parameter("msg", inspect.Parameter.POSITIONAL_ONLY),
                                       inspect.Parameter("info", inspect.Parameter.POSITIONAL_ONLY)])

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, *args):
        if len(args) == 1:      # rclpy 9.1 EventsExecutor: one (msg, info) tuple
            msg, info = args[0]
        else:
            msg, info = args
        return self.fn(msg, info)


# --------------------------------------------------------------------------- Float64MultiArray


def _to_msg(data: np.ndarray, dims, data_offset: int):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=int(size), stride=int(stride))
                      for label, size, stride in dims]
    msg.layout.data_offset = int(data_offset)
    # array.array('d') is the message's native storage: no per-element conversion
    msg.data = array.array("d", np.ascontiguousarray(data, dtype=np.float64).tobytes())
    return msg


def multiarray_from_array(values: np.ndarray, channels: Sequence[str]):
    """(n, c) samples + channel names -> std_msgs/Float64MultiArray (drive/signals layout)."""
    return _to_msg(*pack(values, channels))


def array_from_multiarray(msg) -> tuple[np.ndarray, tuple]:
    """std_msgs/Float64MultiArray -> ((n, c) array, channel names).  Raises LayoutError."""
    data = np.frombuffer(msg.data, dtype=np.float64) if len(msg.data) else np.empty(0)
    arr, channels, _ = unpack(data, msg.layout.dim, msg.layout.data_offset)
    return arr, channels


def last_sample_time(arr: np.ndarray, channels) -> float | None:
    """Drive time t of a batch's last sample (an ``array_from_multiarray`` result), or None when the
    batch is empty, has no t column, or its t is not a finite time >= 0."""
    if "t" not in channels or arr.shape[0] == 0:
        return None
    t = float(arr[-1, list(channels).index("t")])
    return t if np.isfinite(t) and t >= 0 else None


def clock_msg(t: float):
    """rosgraph_msgs/Clock at drive time t, s (the simulator's and the replay's /clock)."""
    from rosgraph_msgs.msg import Clock
    msg = Clock()
    msg.clock.sec = int(np.floor(t))
    msg.clock.nanosec = min(int(round((t - msg.clock.sec) * 1e9)), 999_999_999)
    return msg


def window_to_msg(window: Window):
    """Window -> std_msgs/Float64MultiArray (drive/window layout: header in data_offset)."""
    return _to_msg(*window.pack())


def window_from_msg(msg) -> Window:
    """std_msgs/Float64MultiArray (drive/window layout) -> Window.  Raises LayoutError."""
    data = np.frombuffer(msg.data, dtype=np.float64) if len(msg.data) else np.empty(0)
    return Window.unpack(data, msg.layout.dim, msg.layout.data_offset)


def float64(value: float):
    from std_msgs.msg import Float64
    return Float64(data=float(value))


# --------------------------------------------------------------------------- QoS


def qos_signals(depth: int = 1000):
    """drive/signals: reliable, volatile, keep last ``depth`` batches."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def qos_latched(depth: int = 1):
    """Reliable, transient-local, keep last ``depth``: a late subscriber gets the last messages."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def qos_clock():
    """/clock publisher: keep last 1, reliable, volatile.  A reliable writer also serves the
    best-effort readers of rclpy's/rclcpp's TimeSource."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def qos_diagnostics():
    """/diagnostics: reliable, volatile, keep last 100 (as diagnostic_updater's publisher)."""
    return qos_signals(100)


# --------------------------------------------------------------------------- diagnostics


def format_value(v: Any) -> str:
    """KeyValue text: floats with repr precision, vectors space-separated."""
    if isinstance(v, str):
        return plain_numbers(v)
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return repr(f) if math.isfinite(f) else ("nan" if f != f else ("inf" if f > 0 else "-inf"))
    if isinstance(v, (list, tuple, np.ndarray)):
        return " ".join(format_value(x) for x in (v.tolist() if isinstance(v, np.ndarray) else v))
    return str(v)


def make_status(name: str, level: int, message: str, hardware_id: str = "",
                values: Mapping[str, Any] | Iterable[tuple] = ()):
    """diagnostic_msgs/DiagnosticStatus; ``values`` become KeyValue pairs (see format_value)."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    st = DiagnosticStatus()
    st.level = bytes([int(level)])
    st.name = str(name)
    st.message = plain_numbers(str(message))
    st.hardware_id = str(hardware_id)
    items = values.items() if isinstance(values, Mapping) else values
    st.values = [KeyValue(key=str(k), value=format_value(v)) for k, v in items]
    return st


def make_diagnostic_array(stamp, statuses: Sequence):
    """diagnostic_msgs/DiagnosticArray with ``stamp`` (builtin_interfaces/Time) and the statuses."""
    from diagnostic_msgs.msg import DiagnosticArray
    arr = DiagnosticArray()
    arr.header.stamp = stamp
    arr.status = list(statuses)
    return arr


def status_level(status) -> int:
    """Level of a DiagnosticStatus as an int (the field is a 1-byte bytes object in rclpy)."""
    lv = status.level
    return lv[0] if isinstance(lv, (bytes, bytearray)) else int(lv)


def status_values(status) -> dict:
    """KeyValues of a DiagnosticStatus as a dict."""
    return {kv.key: kv.value for kv in status.values}


__all__ = ["OK", "WARN", "ERROR", "STALE", "LEVEL_NAMES", "LayoutError", "multiarray_from_array",
           "array_from_multiarray", "last_sample_time", "clock_msg", "window_to_msg", "window_from_msg", "float64", "qos_signals",
           "qos_latched", "qos_clock", "qos_diagnostics", "format_value", "make_status",
           "make_diagnostic_array", "status_level", "status_values"]
