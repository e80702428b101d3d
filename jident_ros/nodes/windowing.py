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

from jident_ros.identify.levels import ERROR, OK, WARN
from jident_ros.nodes.diagnostics import DiagnosticsPublisher, drive_hardware_id
from jident_ros.nodes.params import checked, declare_parameters, require, system_config, system_defaults
from jident_ros.nodes.ros_io import (
    LayoutError,
    array_from_multiarray,
    last_sample_time,
    make_status,
    qos_latched,
    qos_signals,
    window_to_msg,
)
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import WINDOWING
from jident_ros.stream.detector import REASONS, BacklashDetector
from jident_ros.stream.flank import FlankDetector
from jident_ros.stream.inputs import IMU_AXES, JointStateAdapter
from jident_ros.stream.layout import KNOWN_CHANNELS

NODE_NAME = "jident_windowing"
STATUS_NAME = "jident: windowing"

DEFAULTS = WINDOWING


def validate(values: dict):
    cfg = checked(values, DEFAULTS, DEFAULTS)
    w = cfg["backlash_width_m"]
    require("backlash_width_m", w, w > 0, "a finite number > 0")
    ch = cfg["channels"]
    for c in ch:
        require("channels", ch, c in KNOWN_CHANNELS and c != "t",
                f"a list of channel names from {', '.join(k for k in KNOWN_CHANNELS if k != 't')}")
    require("channels", ch, len(set(ch)) == len(ch), "a list without repeated names")
    require("channels", ch, "alpha1" in ch and "alpha2" in ch, "a list holding alpha1 and alpha2 (inequality 1)")
    require("gap_tolerance", cfg["gap_tolerance"], cfg["gap_tolerance"] > 1, "a number > 1")
    for n in ("signals_queue_depth", "window_queue_depth"):
        require(n, cfg[n], cfg[n] >= 1, "an integer >= 1")
    require("diagnostics_period_s", cfg["diagnostics_period_s"], cfg["diagnostics_period_s"] >= 0, "a number >= 0")
    require("progress_every_batches", cfg["progress_every_batches"], cfg["progress_every_batches"] >= 0,
            "an integer >= 0 (0 = off)")
    require("input", cfg["input"], cfg["input"] in ("signals", "joint_states"), "signals or joint_states")
    require("detector", cfg["detector"], cfg["detector"] in ("auto", "flank", "paper"), "auto, flank or paper")
    require("gear_ratio", cfg["gear_ratio"], cfg["gear_ratio"] > 0, "a finite number > 0")
    require("motor_joint", cfg["motor_joint"], bool(cfg["motor_joint"]) and cfg["motor_joint"] != cfg["load_joint"],
            "a joint name other than load_joint")
    require("imu_axis", cfg["imu_axis"], cfg["imu_axis"] in IMU_AXES, "x, y or z")
    require("batch_size", cfg["batch_size"], cfg["batch_size"] >= 1, "an integer >= 1")
    if cfg["detector"] == "auto":
        cfg["detector"] = "flank" if cfg["input"] == "joint_states" else "paper"
    system = system_config(values)
    return cfg, system


def _node_class():
    from rclpy.node import Node
    from std_msgs.msg import Float64, Float64MultiArray


    class WindowingNode(Node):
        def __init__(self):
            super().__init__(NODE_NAME)
            defaults = dict(DEFAULTS, **system_defaults())
            self.cfg, self.system = validate(declare_parameters(self, defaults))
            c, s = self.cfg, self.system
            common = dict(samples_before_entry=s.sampling.samples_before_entry,
                          samples_from_entry=s.sampling.samples_from_entry, gap_tolerance=c["gap_tolerance"])
            chans = ("t",) + tuple(c["channels"])
            if c["input"] == "joint_states":   # JointState carries alpha1, omega1, m_el, alpha2, omega2 (+ a1)
                chans = tuple(ch for ch in chans if ch in ("t", "alpha1", "omega1", "m_el", "alpha2", "omega2")
                              or (ch == "a1" and c["use_imu"]))
            if c["detector"] == "flank":
                self.detector = FlankDetector(s.load.wheel_radius_m, s.sampling.sample_period_s, channels=chans,
                                              gear_ratio=c["gear_ratio"],
                                              nominal_inertia_kgm2=s.motor.nominal_inertia_kgm2, **common)
            else:
                self.detector = BacklashDetector(c["backlash_width_m"], s.load.wheel_radius_m,
                                                 s.sampling.sample_period_s, channels=chans, **common)
            self.hardware_id = drive_hardware_id(self, c["hardware_id"])
            self.diag = DiagnosticsPublisher(self)
            self.pub_window = self.create_publisher(Float64MultiArray, "drive/window",
                                                    qos_latched(c["window_queue_depth"]))
            self.adapter = None
            if c["input"] == "joint_states":
                from sensor_msgs.msg import Imu, JointState
                self.adapter = JointStateAdapter(s.sampling.sample_period_s, c["motor_joint"], c["load_joint"],
                                                 c["batch_size"], c["use_imu"], c["imu_axis"])
                self.sub = self.create_subscription(JointState, "joint_states", self.on_joint_state,
                                                    qos_signals(c["signals_queue_depth"]))
                if c["use_imu"]:
                    self.sub_imu = self.create_subscription(Imu, "imu", self.on_imu, qos_signals(c["signals_queue_depth"]))
            else:
                self.sub = self.create_subscription(Float64MultiArray, "drive/signals", self.on_signals,
                                                    qos_signals(c["signals_queue_depth"]))
            # the simulator's back-pressure at real_time_factor 0 (and anyone's progress bar)
            self.pub_progress = (self.create_publisher(Float64, "drive/progress", qos_signals(10))
                                 if c["progress_every_batches"] > 0 else None)
            self.batches_since_progress = 0
            if c["backlash_width_from_topic"]:
                self.sub_width = self.create_subscription(Float64, "drive/backlash_width", self.on_width,
                                                          qos_latched())
            self.errors = 0
            self.drops_since_summary = 0
            if c["diagnostics_period_s"] > 0:
                self.timer = self.create_timer(c["diagnostics_period_s"], self.on_timer)
            if c["detector"] == "flank":
                self.get_logger().info(f"watching {self.resolve_topic_name(self.sub.topic_name)} for flank departures "
                                       f"(no K2); windows on {self.resolve_topic_name('drive/window')}")
            else:
                self.get_logger().info(
                f"watching {self.resolve_topic_name('drive/signals')} for |alpha1 - alpha2| < K2/r = "
                f"{self.detector.threshold_rad:.6g} rad (K2 = {c['backlash_width_m']:g} m"
                f"{', following drive/backlash_width' if c['backlash_width_from_topic'] else ''}); windows of "
                f"{self.detector.window_length} samples on {self.resolve_topic_name('drive/window')}")

        # ----------------------------------------------------------------- callbacks
        def on_signals(self, msg):
            try:
                try:
                    arr, channels = array_from_multiarray(msg)
                except LayoutError as exc:
                    events = [self.detector.reject("layout", str(exc))]
                else:
                    events = self.detector.push(arr, channels)
                    self._progress(arr, channels)
                for ev in events:
                    if ev.kind == "window":
                        self.pub_window.publish(window_to_msg(ev.window))
                    else:
                        self._report_drop(ev)
            except Exception as exc:  # never die on input: report, reset, go on
                self._report_error("drive/signals callback", exc)

        def on_joint_state(self, msg):
            try:
                st = msg.header.stamp
                self._batches(self.adapter.push(st.sec + 1e-9 * st.nanosec, msg.name, msg.position, msg.velocity,
                                                msg.effort))
            except Exception as exc:  # never die on input: report, reset, go on
                self._report_error("joint_states callback", exc)

        def on_imu(self, msg):
            try:
                st = msg.header.stamp
                self._batches(self.adapter.push_imu(st.sec + 1e-9 * st.nanosec, msg.linear_acceleration))
            except Exception as exc:
                self._report_error("imu callback", exc)

        def _batches(self, batches):
            for arr, channels in batches:
                events = self.detector.push(arr, channels)
                self._progress(arr, channels)
                for ev in events:
                    if ev.kind == "window":
                        self.pub_window.publish(window_to_msg(ev.window))
                    else:
                        self._report_drop(ev)

        def destroy_node(self):
            try:   # a window in progress when the node stops: reported as cut_off
                for ev in self.detector.finish():
                    self._report_drop(ev)
            except Exception:
                pass
            return super().destroy_node()

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

        def on_timer(self):
            try:
                level = WARN if self.drops_since_summary else OK
                msg = (f"{self.drops_since_summary} window(s) dropped in the last period" if level
                       else f"{self.detector.windows_captured} window(s) captured, no drops in the last period")
                self.diag.publish(make_status(STATUS_NAME, level, msg, self.hardware_id, self._values()))
                self.drops_since_summary = 0
            except Exception as exc:
                self.get_logger().error(f"diagnostics summary failed: {type(exc).__name__}: {exc}")

        # ----------------------------------------------------------------- reporting
        def _values(self, extra=()):
            d = self.detector
            vals = list(extra) + [
                ("windows_captured", d.windows_captured), ("dropped_total", d.dropped_total),
                ("empty_batches", d.counts["empty"]), ("samples_seen", d.samples_seen),
                ("batches_seen", d.batches_seen), ("callback_errors", self.errors),
                ("backlash_width_m", d.backlash_width_m), ("threshold_rad", d.threshold_rad),
                ("capturing", d.capturing), ("detector", self.cfg["detector"]), ("input", self.cfg["input"])]
            if self.adapter is not None:
                vals += [(f"jointstate.{k}", v) for k, v in self.adapter.counts.items()]
                vals += [(f"jitter.{k}", v) for k, v in self.adapter.jitter().items()]
            vals += [(f"dropped.{r}", d.counts[r]) for r in REASONS if r != "empty"]
            return vals

        def _report_drop(self, ev):
            if ev.reason != "empty":
                self.drops_since_summary += 1
            what = "window dropped" if ev.window_dropped else ("batch reported" if ev.reason == "empty"
                                                              else "batch dropped")
            text = f"{what}: {ev.reason}: {ev.detail}"
            self.get_logger().warning(text, throttle_duration_sec=1.0)
            self.diag.publish(make_status(STATUS_NAME, WARN, text, self.hardware_id, self._values(
                [("reason", ev.reason), ("detail", ev.detail), ("window_dropped", ev.window_dropped)])))

        def _report_error(self, where, exc, reset=True):
            self.errors += 1
            if reset:
                self.detector.reset()
            text = f"internal error in {where}: {type(exc).__name__}: {exc}"
            self.get_logger().error(text, throttle_duration_sec=1.0)
            try:
                self.diag.publish(make_status(STATUS_NAME, ERROR, text, self.hardware_id,
                                              self._values([("reason", "internal_error")])))
            except Exception:
                pass

    return WindowingNode


def main(args=None) -> int:
    return run_main(lambda: _node_class()(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
