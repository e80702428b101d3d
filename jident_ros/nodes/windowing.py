"""windowing node: detects the backlash-zone entry in ``drive/signals`` and publishes ``drive/window``.

Runs :class:`jident_ros.stream.detector.BacklashDetector` (paper inequality 1, |alpha1 - alpha2| < K2/r)
on every batch.  A captured window (48 + 2000 samples) goes out on ``drive/window``; a dropped one
is reported on ``/diagnostics`` with its reason (WARN), and a summary goes out every
``diagnostics_period_s``.  Bad input never stops the node: every callback is guarded, a failure is
reported (ERROR) and the node goes on.

    ros2 run jident_ros windowing --ros-args -p backlash_width_m:=0.005
"""
from __future__ import annotations

import math
import time

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import Float64, Float64MultiArray

from jident_ros.identify.levels import ERROR, OK, STALE, WARN
from jident_ros.identify.monitor import DetectorConfig, make_detector
from jident_ros.nodes.diagnostics import DiagnosticsPublisher, drive_hardware_id, make_updater, status_name
from jident_ros.nodes.params import (
    RuntimeParameters,
    checked,
    declare_parameters,
    node_options,
    node_schema,
    require,
    system_config,
)
from jident_ros.nodes.ros_io import (
    LayoutError,
    array_from_multiarray,
    last_sample_time,
    make_status,
    qos_latched,
    qos_signals,
    window_to_msg,
)
from jident_ros.nodes.runtime import RunnableNode, events_executor
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import WINDOWING, WINDOWING_PARAMS
from jident_ros.stream.detector import REASONS
from jident_ros.stream.imu_skew import IMU_SKEW_TOLERANCE_SAMPLES, ImuSkewGuard
from jident_ros.stream.inputs import IMU_WAIT_S, JointStateAdapter
from jident_ros.stream.layout import KNOWN_CHANNELS
from jident_ros.stream.text import plain_numbers

NODE_NAME = "jident_windowing"
#: Event statuses (a dropped window or batch, an internal error).
INPUT_TASK = "input"      # event status "<ns>/jident_windowing: input": a publisher whose QoS cannot match
STATUS_TASK = "windows"   # event status "<ns>/jident_windowing: windows": a dropped window or batch
#: Periodic task (diagnostics_period_s, steady clock): "jident_windowing: rate".
RATE_TASK = "rate"

DEFAULTS = WINDOWING


def validate(values: dict):
    """The rules across parameters and inside lists (each parameter's type, range and choices are the schema's,
    checked before: :func:`jident_ros.nodes.params.coerce`)."""
    cfg = checked(values, DEFAULTS, DEFAULTS)
    ch = cfg["channels"]
    for c in ch:
        require("channels", ch, c in KNOWN_CHANNELS and c != "t",
                f"a list of channel names from {', '.join(k for k in KNOWN_CHANNELS if k != 't')}")
    require("channels", ch, len(set(ch)) == len(ch), "a list without repeated names")
    if detector_kind(cfg) == "dynamics":
        require("channels", ch, "m_el" in ch and ("a1" in ch or "alpha1" in ch),
                "a list holding m_el and a1 or alpha1 (the dynamics detector's load torque)")
    else:
        require("channels", ch, "alpha1" in ch and "alpha2" in ch, "a list holding alpha1 and alpha2 (inequality 1)")
    require("motor_joint", cfg["motor_joint"], bool(cfg["motor_joint"]) and cfg["motor_joint"] != cfg["load_joint"],
            "a joint name other than load_joint")
    system = system_config(values)
    return cfg, system


def detector_kind(cfg: dict) -> str:
    """The detector a configuration runs: ``detector``, or for auto: flank for joint_states (dynamics when the
    channels hold no alpha2: a drive without a load encoder), paper for signals."""
    if cfg["detector"] != "auto":
        return cfg["detector"]
    if cfg["input"] != "joint_states":
        return "paper"
    return "flank" if "alpha2" in cfg["channels"] else "dynamics"


def schema() -> dict:
    """Every parameter of the node: its own (jident_ros/parameters.py) and the model's (system.yaml)."""
    return node_schema(WINDOWING_PARAMS)


def input_qos(depth: int, reliability: str):
    """The input subscriptions' QoS: drive/signals' (keep last ``depth``, volatile), reliable or best effort."""
    from rclpy.qos import ReliabilityPolicy
    qos = qos_signals(depth)
    qos.reliability = ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort" else ReliabilityPolicy.RELIABLE
    return qos


class WindowingNode(RunnableNode, Node):
    """The windowing node (composable: keyword arguments go to rclpy's Node)."""

    def __init__(self, **kwargs):
        super().__init__(kwargs.pop("node_name", NODE_NAME), **node_options(kwargs))
        self.schema = schema()
        values = declare_parameters(self, self.schema, validate)
        self.cfg, self.system = validate(values)
        c, s = self.cfg, self.system
        self.detector_kind = detector_kind(c)
        chans = ("t",) + tuple(c["channels"])
        if c["input"] == "joint_states":   # JointState carries alpha1, omega1, m_el, alpha2, omega2 (+ a1 from Imu)
            chans = tuple(ch for ch in chans if ch in ("t", "alpha1", "omega1", "m_el", "alpha2", "omega2")
                          or (ch == "a1" and c["use_imu"]))
        self.detector = self._make_detector(chans)
        self.hardware_id = drive_hardware_id(self, c["hardware_id"])
        self.diag = DiagnosticsPublisher(self)
        self.pub_window = self.create_publisher(Float64MultiArray, "drive/window",
                                                qos_latched(c["window_queue_depth"]))
        self.adapter = None
        qos_in = input_qos(c["signals_queue_depth"], c["input_reliability"])
        events = SubscriptionEventCallbacks(incompatible_qos=self.on_incompatible_qos)
        self.incompatible_qos = 0
        if c["input"] == "joint_states":
            from sensor_msgs.msg import Imu, JointState  # only this input needs sensor_msgs (ros-sensor-msgs)
            # the channel set from the configuration (channels, use_imu), never from the first message
            # a sample waits for its Imu message (and an Imu message for its sample) at least as long as a queue's
            # backlog: one topic's backlog can come before the other's (inputs.IMU_WAIT_S)
            wait = max(int(c["signals_queue_depth"]), math.ceil(IMU_WAIT_S / s.sampling.sample_period_s))
            self.adapter = JointStateAdapter(s.sampling.sample_period_s, c["motor_joint"], c["load_joint"],
                                             c["batch_size"], c["use_imu"], c["imu_axis"], imu_wait_samples=wait,
                                             channels=chans)
            # raw subscriptions, decoded by rosbags' CDR deserialiser: half the CPU of rclpy's message conversion
            # (JointState 8 vs 14 us, Imu 8 vs 23 us; bench/bench_jointstate.py, docs/results.md)
            self._cdr = get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr
            self.sub = self.create_subscription(JointState, "joint_states", self.on_joint_state_cdr, qos_in, raw=True,
                                                event_callbacks=events)
            if c["use_imu"]:
                self.sub_imu = self.create_subscription(Imu, "imu", self.on_imu_cdr, qos_in, raw=True,
                                                        event_callbacks=events)
        else:
            self.sub = self.create_subscription(Float64MultiArray, "drive/signals", self.on_signals, qos_in,
                                                event_callbacks=events)
        # the simulator's back-pressure at real_time_factor 0 (and anyone's progress bar)
        self.pub_progress = (self.create_publisher(Float64, "drive/progress", qos_signals(10))
                             if c["progress_every_batches"] > 0 else None)
        self.batches_since_progress = 0
        if c["backlash_width_from_topic"]:
            self.sub_width = self.create_subscription(Float64, "drive/backlash_width", self.on_width,
                                                      qos_latched())
        self.errors = 0
        self.drops_since_summary = 0
        # with use_imu: every batch through the Imu skew check (jident diagnose's chain): a window whose a1 is out of
        # step is detected again without a1 by a new detector (the adapter goes on without a1)
        self.skew = (ImuSkewGuard(self.adapter, lambda chans: self._make_detector(
            tuple(ch for ch in self.detector.channels if ch != "a1")), self._imu_skew_found)
            if self.adapter is not None and c["use_imu"] else None)
        self._input_mark = (0, 0, 0)      # adapter messages, samples, samples without their Imu at the last rate status
        self._rate_mark = (time.monotonic(), 0, 0, 0)
        self._last_batch_wall = time.monotonic()   # steady time, samples, batches, windows at last status
        self.updater = make_updater(self, c["diagnostics_period_s"], self.diag)
        self.updater.setHardwareID(self.hardware_id)
        self.updater.add(RATE_TASK, self.rate_status)
        self.parameters = RuntimeParameters(self, self.schema, values, validate, self.on_parameters)
        if self.detector_kind == "flank":
            self.get_logger().info(f"watching {self.resolve_topic_name(self.sub.topic_name)} for flank departures "
                                   f"(no K2); windows on {self.resolve_topic_name('drive/window')}")
            return
        if self.detector_kind == "dynamics":
            self.get_logger().info(f"watching {self.resolve_topic_name(self.sub.topic_name)} for the load-torque drop "
                                   f"of contact loss (m_el - J1 dω1/dt; no angles, no K2); windows on "
                                   f"{self.resolve_topic_name('drive/window')}")
            return
        self.get_logger().info(
            f"watching {self.resolve_topic_name('drive/signals')} for |alpha1 - alpha2| < K2/r = "
            f"{self.detector.threshold_rad:.6g} rad (K2 = {c['backlash_width_m']:g} m"
            f"{', following drive/backlash_width' if c['backlash_width_from_topic'] else ''}); windows of "
            f"{self.detector.window_length} samples on {self.resolve_topic_name('drive/window')}")

    def _make_detector(self, chans):
        return make_detector(self.system, DetectorConfig.from_parameters(self.cfg, self.detector_kind, chans))

    def make_executor(self):
        """The executor runtime.main spins this node with: rclpy's EventsExecutor (:func:`events_executor`), for
        ``input: joint_states`` (one message per sample, 2 callbacks per sample with the Imu: SingleThreadedExecutor
        rebuilds its wait set for every callback, about 3/4 of the node's CPU at 2 kHz, bench/bench_jointstate.py
        --profile) and for ``signals`` alike (one batch of 50 samples per message: the executor cost 4-5x the
        batch's own work, bench/bench_ros.py --profile, issue 25).  Before Jazzy: SingleThreadedExecutor."""
        from rclpy.executors import SingleThreadedExecutor
        return events_executor(self) or SingleThreadedExecutor(context=self.context)

    # ----------------------------------------------------------------- parameters at run time
    def on_parameters(self, changed: dict) -> None:
        """Apply accepted changes (validated by RuntimeParameters): K2, the gap tolerance, hardware_id."""
        self.cfg.update(changed)
        if "backlash_width_m" in changed:
            self.detector.set_backlash_width(changed["backlash_width_m"])
            self.get_logger().info(f"backlash width K2 = {self.detector.backlash_width_m:g} m (parameter; "
                                   f"threshold {self.detector.threshold_rad:.6g} rad)")
        if "gap_tolerance" in changed:
            self.detector.gap_tolerance = float(changed["gap_tolerance"])
        if "hardware_id" in changed:
            self.hardware_id = drive_hardware_id(self, changed["hardware_id"])
            self.updater.setHardwareID(self.hardware_id)

    # ----------------------------------------------------------------- callbacks
    def on_signals(self, msg):
        self._last_batch_wall = time.monotonic()
        try:
            try:
                arr, channels = array_from_multiarray(msg)
            except LayoutError as exc:
                self._publish_events([self.detector.reject("layout", str(exc))])
            else:
                self._batches([(arr, channels)])
        except Exception as exc:  # never die on input: report, reset, go on
            self._report_error("drive/signals callback", exc)

    def on_joint_state_cdr(self, data: bytes):
        """A serialized sensor_msgs/JointState (raw subscription)."""
        self._last_batch_wall = time.monotonic()
        try:
            msg = self._cdr(data, "sensor_msgs/msg/JointState")
            st = msg.header.stamp
            self._batches(self.adapter.push(st.sec + 1e-9 * st.nanosec, msg.name, msg.position, msg.velocity,
                                            msg.effort))
        except Exception as exc:  # never die on input: report, reset, go on
            self._report_error("joint_states callback", exc)

    def on_imu_cdr(self, data: bytes):
        """A serialized sensor_msgs/Imu (raw subscription)."""
        try:
            msg = self._cdr(data, "sensor_msgs/msg/Imu")
            st = msg.header.stamp
            self._batches(self.adapter.push_imu(st.sec + 1e-9 * st.nanosec, msg.linear_acceleration))
        except Exception as exc:
            self._report_error("imu callback", exc)

    def _batches(self, batches):
        """Push (array, channels) batches through the detector; publish what each one gives."""
        for arr, channels in batches:
            if self.skew is not None:
                self.detector, events = self.skew.push(self.detector, arr, channels)
            else:
                events = self.detector.push(arr, channels)
            self._progress(arr, channels)
            self._publish_events(events)

    def _publish_events(self, events):
        """A window on drive/window; a dropped window or batch on /diagnostics (with its reason)."""
        for ev in events:
            if ev.kind == "window":
                self.pub_window.publish(window_to_msg(ev.window))
            else:
                self._report_drop(ev)

    def _imu_skew_found(self, text: str) -> None:
        """A window's Imu a1 out of step with the encoder (:class:`ImuSkewGuard`): a WARN says so; a1 is left out
        from now on and the window is detected again from the encoder (``window_dropped`` only when it was not)."""
        lost = self.skew.last_lost
        if lost:
            self.drops_since_summary += 1
        self.get_logger().warning(text)
        self.diag.publish(make_status(status_name(self, STATUS_TASK), WARN, text, self.hardware_id, self._values(
            [("reason", "imu_skew"), ("window_dropped", lost)])))

    def close(self) -> None:
        """At shutdown: a window in progress is reported as cut off by the end of the data."""
        try:
            for ev in self.detector.finish():
                self._report_drop(ev)
        except Exception:
            pass

    def _progress(self, arr, channels):
        """drive/progress: the drive time of the last sample read, every progress_every_batches batches."""
        if self.pub_progress is None:
            return
        self.batches_since_progress += 1
        if self.batches_since_progress >= self.cfg["progress_every_batches"]:
            t = last_sample_time(arr, channels)
            if t is not None:
                self.batches_since_progress = 0
                self.pub_progress.publish(Float64(data=t))

    def on_width(self, msg):
        try:
            w = float(msg.data)
            if not (math.isfinite(w) and w > 0):
                raise ValueError(f"backlash width {w!r} m on drive/backlash_width: must be > 0")
            if w != self.detector.backlash_width_m:
                self.detector.set_backlash_width(w)
                self.get_logger().info(f"backlash width K2 = {w:g} m (threshold {self.detector.threshold_rad:.6g} rad)")
        except Exception as exc:
            self._report_error("drive/backlash_width callback", exc, reset=False)

    def on_incompatible_qos(self, info) -> None:
        """A publisher of the input topic offers a QoS this subscription cannot match (no sample of it will
        arrive): one log line naming the topic, the policy and what to change, and from then on a periodic task
        "jident_windowing: input" that is ERROR while such a publisher exists (checked again each period, so a
        diagnostics listener that starts later still sees it, and it turns OK when the publisher goes)."""
        self.incompatible_qos = int(getattr(info, "total_count", self.incompatible_qos + 1))
        self._qos_policy = getattr(getattr(info, "last_policy_kind", None), "name", "unknown").replace("_QOS_POLICY", "")
        text = self._incompatible_text(self.incompatible_qos)
        self.get_logger().error(text)
        self.diag.publish(make_status(status_name(self, INPUT_TASK), ERROR, text, self.hardware_id,
                                      [("topic", self.resolve_topic_name(self.sub.topic_name)),
                                       ("policy", self._qos_policy),
                                       ("incompatible_qos_publishers", self.incompatible_qos),
                                       ("input_reliability", self.cfg["input_reliability"])]))
        if not getattr(self, "_input_task", False):
            self._input_task = True
            self.updater.add(INPUT_TASK, self.input_status)

    def _incompatible_text(self, n: int) -> str:
        topic = self.resolve_topic_name(self.sub.topic_name)
        policy = getattr(self, "_qos_policy", "unknown")
        hint = (f"the publisher is best effort and input_reliability is {self.cfg['input_reliability']}: set "
                "input_reliability:=best_effort" if policy.endswith("RELIABILITY") and
                self.cfg["input_reliability"] == "reliable" else "compare its QoS with docs/interfaces.md")
        return (f"{topic}: {n} publisher(s) offer a QoS this subscription cannot match "
                f"(policy {policy}; {hint}); no sample arrives from them")

    def _incompatible_now(self) -> int:
        """How many publishers of the input topic cannot match this subscription now (rclpy's own check)."""
        from rclpy.qos import QoSCompatibility, qos_check_compatible
        topic = self.resolve_topic_name(self.sub.topic_name)
        n = 0
        for info in self.get_publishers_info_by_topic(topic):
            try:
                compat = qos_check_compatible(info.qos_profile, self.sub.qos_profile)[0]
            except Exception:  # noqa: BLE001  (an unknown policy value: cannot tell, do not count)
                continue
            n += compat == QoSCompatibility.ERROR
        return n

    def input_status(self, stat):
        """Periodic task "jident_windowing: input", added at the first incompatible-QoS event: ERROR while a
        publisher of the input topic cannot match, OK once none is left."""
        topic = self.resolve_topic_name(self.sub.topic_name)
        now = self._incompatible_now()
        stat.add("topic", topic)
        stat.add("policy", getattr(self, "_qos_policy", "unknown"))
        stat.add("incompatible_qos_publishers", now)
        stat.add("incompatible_qos_events_total", self.incompatible_qos)
        stat.add("input_reliability", self.cfg["input_reliability"])
        if now:
            stat.summary(ERROR, self._incompatible_text(now))
        else:
            stat.summary(OK, f"{topic}: no publisher with an incompatible QoS now "
                             f"({self.incompatible_qos} seen since start)")
        return stat

    def rate_status(self, stat):
        """Periodic task "jident_windowing: rate" (steady clock): samples, batches and windows per second
        since the last status; WARN when something was dropped in the period; STALE when no drive/signals
        batch arrived in the period (REP 107: the input stopped)."""
        d = self.detector
        now = time.monotonic()
        t0, s0, b0, w0 = self._rate_mark
        dt = max(now - t0, 1e-9)
        batches = d.batches_seen - b0
        stat.add("samples_per_s", (d.samples_seen - s0) / dt)
        stat.add("batches_per_s", batches / dt)
        stat.add("windows_in_period", d.windows_captured - w0)
        stat.add("dropped_in_period", self.drops_since_summary)
        stat.add("period_s", dt)
        for k, v in self._values():
            stat.add(k, v)
        ad = self.adapter
        msgs = samples = unmatched = 0
        if ad is not None:
            mark = (ad.counts["messages"], ad.counts["samples"], ad.counts["imu_unmatched"])
            msgs, samples, unmatched = (a - b for a, b in zip(mark, self._input_mark))
            self._input_mark = mark
        if ad is not None and msgs > 0 and samples == 0:
            # JointStates arrive but none is usable (a renamed joint, an empty field): say which, by name
            top = ad.problems()[:2]
            why = "; ".join(f"{text} ({n}x)" for text, n in top) or ad.last_problem or "no usable sample"
            stat.summary(ERROR, f"{msgs} JointState message(s) in the last {dt:.1f} s, none usable: {why}")
        elif batches == 0 and ad is not None and samples > 0 and (ad.waiting_for_imu or unmatched):
            # usable JointStates but no batch: held for their Imu messages, or dropped without one
            stat.summary(WARN, f"{samples} JointState sample(s) in the last {dt:.1f} s but no batch: "
                               f"{ad.waiting_for_imu} waiting for their Imu message, {unmatched} dropped without one "
                               f"(imu_unmatched; {ad.counts['imu_messages']} Imu message(s) since start)")
        elif batches == 0:
            what = "joint_states" if ad is not None else "drive/signals"
            never = d.batches_seen == 0 and (ad is None or ad.counts["messages"] == 0)
            stat.summary(STALE, f"no {what} received yet" if never
                         else f"no {what} for {now - self._last_batch_wall:.1f} s")
        elif self.drops_since_summary or msgs > samples or unmatched:
            parts = []
            if self.drops_since_summary:
                parts.append(f"{self.drops_since_summary} window(s)/batch(es) dropped")
            if msgs > samples:
                parts.append(f"{msgs - samples} JointState message(s) dropped (last: {ad.last_problem})")
            if unmatched:
                parts.append(f"{unmatched} JointState sample(s) dropped without their Imu message (imu_unmatched)")
            stat.summary(WARN, f"{'; '.join(parts)} in the last {dt:.1f} s")
        else:
            stat.summary(OK, f"{(d.samples_seen - s0) / dt:.0f} samples/s, {d.windows_captured} window(s) "
                         "captured, no drops in the period")
        self._rate_mark = (now, d.samples_seen, d.batches_seen, d.windows_captured)
        self.drops_since_summary = 0
        return stat

    # ----------------------------------------------------------------- reporting
    def _values(self, extra=()):
        d = self.detector
        vals = list(extra) + [
            ("windows_captured", d.windows_captured), ("dropped_total", d.dropped_total),
            ("empty_batches", d.counts["empty"]), ("samples_seen", d.samples_seen),
            ("batches_seen", d.batches_seen), ("callback_errors", self.errors),
            ("backlash_width_m", d.backlash_width_m), ("threshold_rad", d.threshold_rad),
            ("capturing", d.capturing), ("detector", self.detector_kind), ("input", self.cfg["input"]),
            ("input_reliability", self.cfg["input_reliability"]),
            ("incompatible_qos_publishers", getattr(self, "incompatible_qos", 0))]
        if self.adapter is not None:
            vals += [(f"jointstate.{k}", v) for k, v in self.adapter.counts.items()]
            problems = self.adapter.problems()
            if problems:
                vals.append(("jointstate.top_problem", f"{problems[0][0]} ({problems[0][1]}x)"))
            if self.adapter.use_imu or self.adapter.a1_dropped:
                sk = (self.skew.report if self.skew is not None else None) or {}
                vals += [("imu_skew_s", "unknown" if sk.get("skew_s") is None else sk["skew_s"]),
                         ("imu_skew_tolerance_s", IMU_SKEW_TOLERANCE_SAMPLES * self.adapter.sample_period_s),
                         ("windows_imu_skew", 0 if self.skew is None else self.skew.skews),
                         ("windows_dropped_imu_skew", 0 if self.skew is None else self.skew.dropped),
                         ("a1_used", self.adapter.use_imu)]
            vals += [(f"jitter.{k}", v) for k, v in self.adapter.jitter().items()]
        vals += [(f"dropped.{r}", d.counts[r]) for r in REASONS if r != "empty"]
        vals += [(f"windows_lost.{r}", n) for r, n in getattr(d, "windows_lost", {}).items()]
        return vals

    def _report_drop(self, ev):
        if ev.reason != "empty":
            self.drops_since_summary += 1
        what = "window dropped" if ev.window_dropped else ("batch reported" if ev.reason == "empty"
                                                          else "batch dropped")
        text = plain_numbers(f"{what}: {ev.reason}: {ev.detail}")
        self.get_logger().warning(text, throttle_duration_sec=1.0)
        self.diag.publish(make_status(status_name(self, STATUS_TASK), WARN, text, self.hardware_id, self._values(
            [("reason", ev.reason), ("detail", ev.detail), ("window_dropped", ev.window_dropped)])))

    def _report_error(self, where, exc, reset=True):
        self.errors += 1
        if reset:
            self.detector.reset()
            if self.skew is not None:
                self.skew.reset()
        text = plain_numbers(f"internal error in {where}: {type(exc).__name__}: {exc}")
        self.get_logger().error(text, throttle_duration_sec=1.0)
        try:
            self.diag.publish(make_status(status_name(self, STATUS_TASK), ERROR, text, self.hardware_id,
                                          self._values([("reason", "internal_error")])))
        except Exception:
            pass


def main(args=None) -> int:
    return run_main(lambda argv: WindowingNode(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
