"""replay node: republishes a recording's drive topics (and /clock) at a rate factor.

    ros2 run jident_ros replay out/run1 --ros-args -p rate:=10.0

Reads the bag directory (also one split into several .mcap files) or .mcap file with
:func:`jident_ros.bag.reader.read_bag` and republishes,
in receive-time order, every recorded topic whose name ends with one of ``topics`` (default
drive/signals, drive/backlash_width, drive/true_inertia, drive/case) on the corresponding *relative*
name, so ``-r __ns:=/press3`` replays into another namespace.  The messages go out as recorded
(CDR bytes, not re-encoded).  The pauses between messages are the recorded receive-time
differences divided by ``rate`` (0 = as fast as the windowing node reads: ``fast_sleep_s`` between
messages and at most ``max_lead_s`` drive seconds ahead of its ``drive/progress``, see ProgressGate).
With ``publish_clock``, /clock follows the ``t`` column of each drive/signals batch (recorded
/clock messages are not replayed), exactly as the simulator publishes it.
"""
from __future__ import annotations

import importlib
import itertools
import sys
import time
from pathlib import Path

from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from jident_ros.nodes.params import ParameterError, checked, declare_parameters, node_options, require
from jident_ros.nodes.ros_io import (
    LayoutError,
    array_from_multiarray,
    clock_msg,
    last_sample_time,
    qos_clock,
    qos_latched,
    qos_signals,
)
from jident_ros.nodes.runtime import ProgressGate, RunnableNode, drain, tick
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import REPLAY, REPLAY_PARAMS

#: keep-last depth of the replayed latched topics (drive/case, drive/backlash_width, drive/true_inertia)
REPLAY_LATCHED_DEPTH = 100

NODE_NAME = "jident_replay"
#: At rate 0, at most this many messages per tick of ``fast_sleep_s`` (while the windowing node's progress allows
#: them): one per tick capped the replay at 1 batch / fast_sleep_s (issue 25).
RATE0_MESSAGES_PER_TICK = 4

DEFAULTS = REPLAY

TYPES = {
    "std_msgs/msg/Float64MultiArray": ("std_msgs.msg", "Float64MultiArray"),
    "std_msgs/msg/Float64": ("std_msgs.msg", "Float64"),
}


def validate(values: dict, argv_bag: str | None):
    """The bag (also from the command line) and the topics (each parameter's type, range and choices are the
    schema's, checked before: :func:`jident_ros.nodes.params.coerce`)."""
    cfg = checked(values, DEFAULTS, DEFAULTS)
    if argv_bag:
        cfg["bag"] = argv_bag
    require("bag", cfg["bag"], bool(cfg["bag"]), "a recording (bag directory or .mcap file; "
            "give it as the first argument)")
    require("bag", cfg["bag"], Path(cfg["bag"]).expanduser().exists(), "an existing bag directory or .mcap file")
    require("topics", cfg["topics"], bool(cfg["topics"]) and all(t and not t.startswith("/") for t in cfg["topics"]),
            "a non-empty list of relative topic names")
    return cfg


def _positional(args) -> str | None:
    rest = remove_ros_args(args)[1:]
    if len(rest) > 1:
        raise ParameterError(f"parameter bag: expected one recording argument, got {rest!r}")
    return rest[0] if rest else None


def schema() -> dict:
    return dict(REPLAY_PARAMS)


class RatePacer:
    """When the next message may go out: the recorded receive-time differences divided by ``rate`` (rate > 0;
    rate 0: at once), and never more than the gate's ``max_lead_s`` drive seconds ahead of the windowing node's
    ``drive/progress`` (:class:`ProgressGate`, any rate).  Lossless at any rate: when the downstream falls behind
    at rate > 0, the replay pauses (back-pressure) instead of letting the reliable queue overwrite batches, counts
    the pauses and says so in a WARN (``warn(text)``) at the first pause of each episode; the schedule restarts
    from the first message after a pause (no burst to catch up).  ``clock``: monotonic seconds."""

    def __init__(self, rate: float, gate=None, warn=None, clock=time.monotonic):
        self.rate, self.gate, self.warn, self.clock = float(rate), gate, warn, clock
        self.wall0 = self.rec0 = None
        self.pauses = 0            # episodes in which the downstream was behind at rate > 0
        self.behind = False

    def due(self, log_ns: int, t_last: float | None) -> bool:
        """True when the message recorded at ``log_ns`` (a drive/signals batch ending at drive time ``t_last``,
        else None) may be published now."""
        if self.gate is not None and t_last is not None and not self.gate.allows(t_last):
            if self.rate > 0:
                if not self.behind:
                    self.pauses += 1
                    # no progress ever (no windowing node): the gate itself says so when it gives up waiting
                    if self.warn is not None and getattr(self.gate, "progress_wall", 0.0) is not None:
                        self.warn(self.behind_text(t_last))
                self.behind = True
                self.wall0 = None              # restart the schedule after the pause
            return False
        self.behind = False
        if self.rate <= 0:
            return True
        now = self.clock()
        if self.wall0 is None:
            self.wall0, self.rec0 = now, log_ns
        return self.wall0 + (log_ns - self.rec0) / 1e9 / self.rate <= now

    def behind_text(self, t_last: float) -> str:
        g = self.gate
        read = "nothing yet" if g.progress_t is None else f"t = {g.progress_t:.3f} s"
        return (f"downstream behind at rate {self.rate:g}: the windowing node has read to {read}, the next batch "
                f"ends at t = {t_last:.3f} s (max_lead_s {g.max_lead_s:g}): pausing the replay (back-pressure; "
                f"{self.pauses} pause(s) so far, nothing is dropped, the replay runs slower than asked)")

    def summary(self) -> str:
        """'' or what the back-pressure did at rate > 0 (for the final log line)."""
        if self.rate <= 0 or not self.pauses:
            return ""
        waited = self.gate.waited_s if self.gate is not None else 0.0
        return (f"; the downstream fell behind rate {self.rate:g} {self.pauses} time(s): paused {waited:.2f} s in "
                "all (back-pressure, no message dropped)")


class ReplayNode(RunnableNode, Node):
    """The replay node (composable: keyword arguments go to rclpy's Node; ``bag`` may be given as
    ``argv_bag``).  Replays from a timer: a state machine WAITING -> REPLAYING -> DONE; at rate > 0
    every tick publishes the messages due by the wall clock, at 0 one message per tick of
    ``fast_sleep_s`` when the windowing node's progress allows it (:class:`ProgressGate`)."""

    def __init__(self, argv_bag: str | None = None, **kwargs):
        super().__init__(kwargs.pop("node_name", NODE_NAME), **node_options(kwargs))
        self.schema = schema()
        self.cfg = validate(declare_parameters(self, self.schema, lambda v: validate(v, argv_bag)), argv_bag)
        self.exit_code = 0
        self.done = False
        try:
            from jident_ros.bag.errors import RecordingError  # the bag layer: optional mcap dependency
            from jident_ros.bag.reader import in_publish_order, read_bag  # the bag layer: optional mcap dependency
        except ImportError as exc:
            raise ParameterError(f"parameter bag: cannot read recordings here (jident_ros.bag.reader: {exc})")
        self.RecordingError = RecordingError
        self.bag = str(Path(self.cfg["bag"]).expanduser())
        try:
            # a killed recording is salvaged on the fly (one warning); the first message is read here so that a
            # missing, non-MCAP or damaged file is one line naming it before anything is published (exit 2)
            messages = iter(read_bag(self.bag, raw=True, on_salvage=self.get_logger().warning))
            first = next(messages, None)
        except RecordingError as exc:
            raise ParameterError(f"recording {exc}") from None
        except Exception as exc:
            raise ParameterError(f"parameter bag: {self.bag}: {exc}") from None
        # in the order the drive published them: a K2 or case message after the batches sent before it, although
        # the recorder may have received it first (replay = live)
        self.messages = in_publish_order(itertools.chain([] if first is None else [first], messages))
        self.pubs = {}
        self.pub_clock = (self.create_publisher(Clock, "/clock", qos_clock())
                          if self.cfg["publish_clock"] else None)
        self.counts = {}
        self.pending = None
        self.gate = None
        self.pacer = RatePacer(self.cfg["rate"])
        self.state = "waiting"
        c = self.cfg
        self.wait_deadline = time.monotonic() + c["wait_timeout_s"]
        self.settle_until = 0.0
        period = c["fast_sleep_s"] if c["rate"] == 0 else 0.005
        self.timer = self.create_timer(max(period, 1e-4), self.on_tick,
                                       clock=RosClock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"replaying {self.bag} at rate {c['rate']:g}")

    def _publisher(self, rel, msg_type):
        pub = self.pubs.get(rel)
        if pub is None:
            mod, cls = TYPES.get(msg_type, (None, None))
            if mod is None:
                return None
            typ = getattr(importlib.import_module(mod), cls)
            # the case topics keep their last REPLAY_LATCHED_DEPTH messages for a subscriber matched late (as the
            # simulator keeps every case's): a recorder then still gets the K2 each earlier window was cut with
            qos = qos_signals() if rel == "drive/signals" else qos_latched(REPLAY_LATCHED_DEPTH)
            pub = self.pubs[rel] = self.create_publisher(typ, rel, qos)
        return pub

    def _match(self, topic):
        for rel in self.cfg["topics"]:
            if topic == "/" + rel or topic.endswith("/" + rel):
                return rel
        return None

    # ----------------------------------------------------------------- replaying (timer)
    def on_tick(self):
        tick(self.state, {"waiting": self._tick_waiting, "replaying": self._tick_replaying}, self._failed)

    def _tick_waiting(self):
        c = self.cfg
        want = c["wait_for_subscribers"]
        if want > 0:
            pub = self._publisher("drive/signals", "std_msgs/msg/Float64MultiArray")
            if pub.get_subscription_count() < want:
                if time.monotonic() > self.wait_deadline:
                    self.get_logger().error("no subscriber of drive/signals; giving up")
                    self.exit_code = 1
                    self._finish()
                return
            self.settle_until = time.monotonic() + 0.2
        self.state = "replaying"
        if c["max_lead_s"] > 0:   # any rate: a downstream that falls behind slows the replay, never loses batches
            self.gate = ProgressGate(self, c["max_lead_s"], c["progress_timeout_s"])
            # one WARN per episode of falling behind, at most every 5 s (with the count so far); the total at the end
            self.pacer = RatePacer(c["rate"], self.gate,
                                   lambda text: self.get_logger().warning(text, throttle_duration_sec=5.0))

    def _next(self):
        """The next message to replay: (rel, pub, log_ns, raw, t_last) or None at the end."""
        for topic, msg_type, log_ns, raw in self.messages:
            rel = self._match(topic)
            if rel is None:
                continue
            pub = self._publisher(rel, msg_type)
            if pub is None:
                self.get_logger().warning(f"{topic}: type {msg_type} is not replayed", once=True)
                continue
            t_last = None
            if rel == "drive/signals" and (self.gate is not None or self.pub_clock is not None):
                t_last = self._last_t(deserialize_message(bytes(raw), Float64MultiArray))
            return rel, pub, log_ns, raw, t_last
        return None

    def _tick_replaying(self):
        c = self.cfg
        now = time.monotonic()
        if now < self.settle_until:
            return
        burst = 0
        while True:
            if self.pending is None:
                self.pending = self._next()
                if self.pending is None:
                    self._finish()
                    return
            rel, pub, log_ns, raw, t_last = self.pending
            if not self.pacer.due(log_ns, t_last):
                return                                  # not due yet, or the windowing node is behind: next tick
            pub.publish(bytes(raw))
            self.counts[rel] = self.counts.get(rel, 0) + 1
            if t_last is not None and self.pub_clock is not None:
                self.pub_clock.publish(clock_msg(t_last))
            self.pending = None
            if c["rate"] == 0:
                burst += 1
                if burst >= RATE0_MESSAGES_PER_TICK:
                    return                              # at most this many messages per tick of fast_sleep_s

    def _failed(self, exc: Exception) -> None:
        """A failure while replaying: one line, stop."""
        if isinstance(exc, self.RecordingError):  # damaged on the way: one line naming the file, exit status 2
            print(f"replay: recording {exc}", file=sys.stderr, flush=True)
            self.exit_code = 2
        else:  # a bad message: one line, exit status 1
            self.get_logger().error(f"replay of {self.bag} failed: {type(exc).__name__}: {exc}")
            self.exit_code = 1
        self._finish()

    def _finish(self):
        self.timer.cancel()
        if self.gate is not None:
            self.gate.close()
            self.gate = None
        if self.exit_code == 0:
            self.get_logger().info("replayed " + ", ".join(f"{n} x {k}" for k, n in self.counts.items())
                                   + self.pacer.summary() if self.counts else "nothing to replay: no matching topic")
        self.state = "done"
        self.done = True

    def finish(self, stopping) -> None:
        """After the spin: give reliable readers the last messages (runtime.drain: a WARN names a topic not
        acknowledged in time)."""
        drain(list(self.pubs.values()), self.get_logger(), stopping)

    @staticmethod
    def _last_t(msg):
        """Drive time of a drive/signals batch's last sample, or None (bad layout, no t)."""
        try:
            return last_sample_time(*array_from_multiarray(msg))
        except LayoutError:
            return None


def main(args=None) -> int:
    args = sys.argv if args is None else args
    return run_main(lambda argv: ReplayNode(argv_bag=_positional(argv)), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
