"""replay node: republishes a recording's drive topics (and /clock) at a rate factor.

    ros2 run jident_ros replay out/run1 --ros-args -p rate:=10.0

Reads the bag directory (also one split into several .mcap files) or .mcap file with
:func:`jident_ros.bag.recording.read_bag` and republishes,
in receive-time order, every recorded topic whose name ends with one of ``topics`` (default
drive/signals, drive/backlash_width, drive/true_inertia, drive/case) on the corresponding *relative*
name, so ``-r __ns:=/press3`` replays into another namespace.  The messages go out as recorded
(CDR bytes, not re-encoded).  The pauses between messages are the recorded receive-time
differences divided by ``rate`` (0 = as fast as the windowing node reads: ``fast_sleep_s`` between
messages and at most ``max_lead_s`` drive seconds ahead of its ``drive/progress``, see ProgressGate).
With ``publish_clock``, /clock follows the ``t`` column of each drive/signals batch (recorded
/clock messages are not replayed), exactly as the simulator publishes it.

A recording its recorder never finalised (killed) is replayed by salvaging it on the fly (one warning
line says so); a missing, non-MCAP or damaged recording is one line naming the file and the problem, exit
status 2.
"""
from __future__ import annotations

import importlib
import sys
import time
from pathlib import Path

from jident_ros.nodes.params import ParameterError, checked, declare_parameters, require
from jident_ros.nodes.ros_io import (
    LayoutError,
    array_from_multiarray,
    clock_msg,
    last_sample_time,
    qos_clock,
    qos_latched,
    qos_signals,
)
from jident_ros.nodes.runtime import ProgressGate
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import REPLAY

NODE_NAME = "jident_replay"

DEFAULTS = REPLAY

TYPES = {
    "std_msgs/msg/Float64MultiArray": ("std_msgs.msg", "Float64MultiArray"),
    "std_msgs/msg/Float64": ("std_msgs.msg", "Float64"),
}


def validate(values: dict, argv_bag: str | None):
    cfg = checked(values, DEFAULTS, DEFAULTS)
    if argv_bag:
        cfg["bag"] = argv_bag
    require("bag", cfg["bag"], bool(cfg["bag"]), "a recording (bag directory or .mcap file; "
            "give it as the first argument)")
    require("bag", cfg["bag"], Path(cfg["bag"]).expanduser().exists(), "an existing bag directory or .mcap file")
    require("rate", cfg["rate"], cfg["rate"] >= 0, "a number >= 0 (0 = as fast as possible)")
    require("fast_sleep_s", cfg["fast_sleep_s"], 0 <= cfg["fast_sleep_s"] <= 1, "a number in [0, 1]")
    require("max_lead_s", cfg["max_lead_s"], cfg["max_lead_s"] >= 0, "a number >= 0 (0 = no back-pressure)")
    require("progress_timeout_s", cfg["progress_timeout_s"], cfg["progress_timeout_s"] > 0, "a number > 0")
    require("topics", cfg["topics"], bool(cfg["topics"]) and all(t and not t.startswith("/") for t in cfg["topics"]),
            "a non-empty list of relative topic names")
    require("wait_for_subscribers", cfg["wait_for_subscribers"], cfg["wait_for_subscribers"] >= 0, "an integer >= 0")
    require("wait_timeout_s", cfg["wait_timeout_s"], cfg["wait_timeout_s"] > 0, "a number > 0")
    return cfg


def _positional(args) -> str | None:
    from rclpy.utilities import remove_ros_args
    rest = remove_ros_args(args)[1:]
    if len(rest) > 1:
        raise ParameterError(f"parameter bag: expected one recording argument, got {rest!r}")
    return rest[0] if rest else None


def _node_class(args):

    from rclpy.node import Node
    from rclpy.serialization import deserialize_message
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64MultiArray


    class ReplayNode(Node):
        def __init__(self):
            super().__init__(NODE_NAME)
            self.cfg = validate(declare_parameters(self, DEFAULTS), _positional(args))
            self.exit_code = 0
            try:
                from jident_ros.bag.recording import RecordingError, read_bag
            except ImportError as exc:
                raise ParameterError(f"parameter bag: cannot read recordings here (jident_ros.bag.recording: {exc})")
            self.read_bag, self.RecordingError = read_bag, RecordingError
            self.bag = str(Path(self.cfg["bag"]).expanduser())
            try:
                read_bag(self.bag, raw=True)  # checks the files (named, MCAP) before anything is published
            except RecordingError as exc:
                raise ParameterError(f"recording {exc}") from None
            self.pubs = {}
            self.pub_clock = (self.create_publisher(Clock, "/clock", qos_clock())
                              if self.cfg["publish_clock"] else None)
            self._imp = importlib
            self.get_logger().info(f"replaying {self.bag} at rate {self.cfg['rate']:g}")

        def _publisher(self, rel, msg_type):
            pub = self.pubs.get(rel)
            if pub is None:
                mod, cls = TYPES.get(msg_type, (None, None))
                if mod is None:
                    return None
                typ = getattr(self._imp.import_module(mod), cls)
                qos = qos_signals() if rel == "drive/signals" else qos_latched()
                pub = self.pubs[rel] = self.create_publisher(typ, rel, qos)
            return pub

        def _match(self, topic):
            for rel in self.cfg["topics"]:
                if topic == "/" + rel or topic.endswith("/" + rel):
                    return rel
            return None

        def run(self):
            c = self.cfg
            if c["wait_for_subscribers"] > 0:
                pub = self._publisher("drive/signals", "std_msgs/msg/Float64MultiArray")
                deadline = time.monotonic() + c["wait_timeout_s"]
                while self.context.ok() and pub.get_subscription_count() < c["wait_for_subscribers"]:
                    if time.monotonic() > deadline:
                        self.get_logger().error("no subscriber of drive/signals; giving up")
                        self.exit_code = 1
                        return
                    time.sleep(0.05)
                time.sleep(0.2)
            gate = (ProgressGate(self, c["max_lead_s"], c["progress_timeout_s"])
                    if c["rate"] == 0 and c["max_lead_s"] > 0 else None)
            try:
                self._replay(gate)
            except self.RecordingError as exc:  # damaged on the way: one line, status 2
                raise ParameterError(f"recording {exc}") from None
            finally:
                if gate is not None:
                    gate.close()

        def _replay(self, gate):
            c = self.cfg
            wall0 = rec0 = None
            counts = {}
            for topic, msg_type, log_ns, raw in self.read_bag(self.bag, raw=True,
                                                              on_salvage=self.get_logger().warning):
                if not self.context.ok():
                    return
                rel = self._match(topic)
                if rel is None:
                    continue
                pub = self._publisher(rel, msg_type)
                if pub is None:
                    self.get_logger().warning(f"{topic}: type {msg_type} is not replayed", once=True)
                    continue
                if c["rate"] > 0:
                    if wall0 is None:
                        wall0, rec0 = time.monotonic(), log_ns
                    delay = wall0 + (log_ns - rec0) / 1e9 / c["rate"] - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                elif c["fast_sleep_s"] > 0:
                    time.sleep(c["fast_sleep_s"])
                t_last = None
                if rel == "drive/signals" and (gate is not None or self.pub_clock is not None):
                    t_last = self._last_t(deserialize_message(bytes(raw), Float64MultiArray))
                if gate is not None and t_last is not None:
                    gate.wait(t_last)
                pub.publish(bytes(raw))
                counts[rel] = counts.get(rel, 0) + 1
                if t_last is not None and self.pub_clock is not None:
                    self._publish_clock(t_last)
            if self.context.ok():
                self.get_logger().info("replayed " + ", ".join(f"{n} x {k}" for k, n in counts.items())
                                       if counts else "nothing to replay: no matching topic")
                from rclpy.duration import Duration
                for pub in self.pubs.values():
                    try:
                        pub.wait_for_all_acked(Duration(seconds=5.0))
                    except Exception:
                        time.sleep(0.5)

        @staticmethod
        def _last_t(msg):
            """Drive time of a drive/signals batch's last sample, or None (bad layout, no t)."""
            try:
                return last_sample_time(*array_from_multiarray(msg))
            except LayoutError:
                return None

        def _publish_clock(self, t: float):
            self.pub_clock.publish(clock_msg(t))

    return ReplayNode


def main(args=None) -> int:
    args = sys.argv if args is None else args
    return run_main(lambda: _node_class(args)(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
