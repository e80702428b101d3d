"""diagnostic node: identifies J1 from every window on ``drive/window``.

A thin ROS adapter over :func:`jident_ros.identify.diagnosis.diagnose_window` (the same per-window diagnosis
``jident diagnose`` runs offline on a recording).  For each window:

1. the gap estimate (:func:`jident_ros.identify.gap.estimate_inertia`: J1 by least squares over the
   samples inside the backlash zone) -- when the policy accepts it, it is published at once on
   ``inertia_estimate`` (std_msgs/Float64, kg m^2, transient local): the best continuous J1;
2. the paper's image method (:func:`jident_ros.method.patterns.identify_window`, KHM exponent ``p``)
   against the pattern library; when the window has no usable gap, its fused class goes out on
   ``inertia_estimate`` only when it is trusted (fused margin >= ``image_min_margin``, a library width
   matching the window's K2);
3. one DiagnosticStatus "jident: inertia" on ``/diagnostics`` (REP 107), graded by the publishing
   policy (:mod:`jident_ros.identify.verdict`; the table of docs/interfaces.md): OK for the nominal
   class; WARN for a deviating class, a J1 between classes, or the image method disagreeing inside its
   validity domain; ERROR when nothing could be diagnosed (refused input or estimate) or the pattern
   library is unusable; a STALE status when no window arrived for ``stale_after_s``.  A J1 goes out
   on ``inertia_estimate`` only when the data support it (plausible band, width consistency, no
   ambiguous interval, the image method's class only above ``image_min_margin``).

Unless ``record`` is false, the windows (and with ``record_signals`` the drive's signals), the estimates
and the statuses are recorded (jident_ros.bag.recorder.Recorder) into a rosbag2 bag
``<record_root>/rosbag2_YYYY_MM_DD-HH_MM_SS/``, split by ``max_bag_size_bytes`` / ``max_bag_duration_s``,
old bags deleted by ``retention_max_total_bytes`` / ``retention_max_age_s``, stamped with the wall clock,
finalised on shutdown.  A status "jident: recorder" (1 Hz) reports it: OK while recording, ERROR with
the reason (unusable root, disk full: the part written is finalised) and the dropped messages.

    ros2 run jident_ros diagnostic --ros-args -p record_root:=out/bags
"""
from __future__ import annotations

import time
from pathlib import Path

from jident_ros.identify.diagnosis import GAP_METHODS, detector_arguments, diagnose_window
from jident_ros.identify.levels import ERROR, LEVEL_NAMES, OK, STALE
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.verdict import VerdictPolicy
from jident_ros.nodes.diagnostics import DiagnosticsPublisher, drive_hardware_id
from jident_ros.nodes.params import (
    checked,
    declare_parameters,
    method_config,
    method_defaults,
    require,
    system_config,
    system_defaults,
)
from jident_ros.nodes.ros_io import LayoutError, make_status, qos_latched, qos_signals, window_from_msg
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import DIAGNOSTIC

NODE_NAME = "jident_diagnostic"
STATUS_NAME = "jident: inertia"
RECORDER_STATUS_NAME = "jident: recorder"

DEFAULTS = DIAGNOSTIC


def validate(values: dict):
    cfg = checked(values, DEFAULTS, DEFAULTS)
    system = system_config(values)
    method = method_config(values)
    require("p", cfg["p"], cfg["p"] in [float(p) for p in method.p_values],
            f"one of method.p_values {list(method.p_values)}")
    require("gap_method", cfg["gap_method"], cfg["gap_method"] in GAP_METHODS,
            "one of " + ", ".join(GAP_METHODS))
    require("stale_after_s", cfg["stale_after_s"], cfg["stale_after_s"] >= 0, "a number >= 0 (0 = never)")
    for n in ("window_queue_depth", "signals_queue_depth"):
        require(n, cfg[n], cfg[n] >= 1, "an integer >= 1")
    for n in ("max_bag_size_bytes", "max_bag_duration_s", "retention_max_total_bytes", "retention_max_age_s"):
        require(n, cfg[n], cfg[n] >= 0, "a number >= 0 (0 = no limit)")
    require("image_method", cfg["image_method"], cfg["image_method"] or cfg["gap_method"] != "off",
            "true when gap_method is off (nothing would be identified)")
    for name, what in VerdictPolicy.from_params(cfg).problems():
        require(name, cfg[name], False, what)
    return cfg, system, method


def library_path(cfg, system, method) -> Path:
    if cfg["pattern_library"]:
        return Path(cfg["pattern_library"]).expanduser()
    return default_library_path(system, method)


def _node_class():
    from rclpy.node import Node
    from std_msgs.msg import Float64, Float64MultiArray


    class DiagnosticNode(Node):
        def __init__(self):
            super().__init__(NODE_NAME)
            defaults = dict(DEFAULTS, **system_defaults(), **method_defaults())
            self.cfg, self.system, self.method = validate(declare_parameters(self, defaults))
            c = self.cfg
            self.policy = VerdictPolicy.from_params(c)
            self.hardware_id = drive_hardware_id(self, c["hardware_id"])
            self.nominal = float(self.system.motor.nominal_inertia_kgm2)
            self.diag = DiagnosticsPublisher(self)
            self.pub_estimate = self.create_publisher(Float64, "inertia_estimate", qos_latched())
            self.bag = self.recorder = None
            self.bag_topics = {}
            self.windows_seen = 0
            self.last_estimate = None
            self._stale_reported_at = None
            self._start_recording()
            self.library, self.library_error = None, None
            if c["image_method"]:
                self._load_library()
            self.sub_window = self.create_subscription(Float64MultiArray, "drive/window", self.on_window,
                                                       qos_latched(c["window_queue_depth"]))
            if self.bag is not None and c["record_signals"]:
                sq = qos_signals(c["signals_queue_depth"])
                # raw: the CDR bytes go to the recording as received, never decoded here
                self.create_subscription(Float64MultiArray, "drive/signals",
                                         lambda m: self._record("drive/signals", m), sq, raw=True)
                deep = qos_latched(100)  # keep every case message while a window is being diagnosed
                for name in ("drive/backlash_width", "drive/true_inertia"):
                    self.create_subscription(Float64, name, lambda m, n=name: self._record(n, m), deep)
                self.create_subscription(Float64MultiArray, "drive/case",
                                         lambda m: self._record("drive/case", m), deep)
            if self.recorder is not None or self.recorder_error:  # steady clock: no /clock can stop it
                from rclpy.clock import Clock, ClockType
                steady = Clock(clock_type=ClockType.STEADY_TIME)
                # a chunk never waits long in memory (flush_age_s 0.5 s), even when messages pause
                self.flush_timer = self.create_timer(0.25, self._flush_bag, clock=steady)
                self.recorder_timer = self.create_timer(1.0, self._publish_recorder_status, clock=steady)
            self._last_window_ns = None
            self._start_ns = None
            if c["stale_after_s"] > 0:
                self.timer = self.create_timer(min(1.0, c["stale_after_s"] / 2), self.on_timer)
            if self.library_error:
                # repeated (1 Hz, steady clock) while it lasts: a subscriber that joins later still sees it
                from rclpy.clock import Clock, ClockType
                self._publish_library_error()
                self.library_timer = self.create_timer(1.0, self._publish_library_error,
                                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
            self.get_logger().info(
                f"ready: windows from {self.resolve_topic_name('drive/window')}, J1 on "
                f"{self.resolve_topic_name('inertia_estimate')} (p = {c['p']:g}, gap method {c['gap_method']}, "
                f"image method {'on' if c['image_method'] else 'off'})")

        # ----------------------------------------------------------------- library
        def _load_library(self):
            c = self.cfg
            self.library_path = library_path(c, self.system, self.method)
            log = self.get_logger()
            self.library, self.library_error = load_pattern_library(
                self.library_path, self.system, self.method, c["build_if_missing"], log=log.info, warn=log.warning)
            if self.library_error:
                log.error(self.library_error)

        def _publish_library_error(self):
            try:
                self._publish_status(make_status(STATUS_NAME, ERROR, self.library_error, self.hardware_id,
                                                 [("pattern_library", str(self.library_path)),
                                                  ("windows_seen", self.windows_seen)]))
            except Exception as exc:
                self.get_logger().error(f"status failed: {type(exc).__name__}: {exc}", once=True)

        # ----------------------------------------------------------------- recording
        def _start_recording(self):
            c = self.cfg
            self.recorder, self.recorder_error = None, None
            if not c["record"]:
                return
            log = self.get_logger()
            try:
                from jident_ros.bag.recorder import Recorder, RecorderError
            except ImportError as exc:  # mcap / rosbags (the 'mcap' extra) missing: say so, run on
                self.recorder_error = f"not recording: {exc} (the recorder needs mcap and rosbags)"
                log.error(self.recorder_error)
                return
            if c["record_dir"]:
                log.warning("record_dir is deprecated: use record_root (bags get rosbag2 names under it)")
            try:
                self.recorder = Recorder(
                    c["record_root"] or None, bag_dir=c["record_dir"] or None,
                    max_bag_size_bytes=c["max_bag_size_bytes"], max_bag_duration_s=c["max_bag_duration_s"],
                    retention_max_total_bytes=c["retention_max_total_bytes"],
                    retention_max_age_s=c["retention_max_age_s"],
                    custom_data={"node": self.get_fully_qualified_name()}, log=log.info)
                topics = [("drive/window", "std_msgs/msg/Float64MultiArray", qos_latched(c["window_queue_depth"])),
                          ("inertia_estimate", "std_msgs/msg/Float64", qos_latched()),
                          ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", self.diag.pub.qos_profile)]
                if c["record_signals"]:
                    topics += [("drive/signals", "std_msgs/msg/Float64MultiArray", qos_signals(c["signals_queue_depth"])),
                               ("drive/backlash_width", "std_msgs/msg/Float64", qos_latched()),
                               ("drive/true_inertia", "std_msgs/msg/Float64", qos_latched()),
                               ("drive/case", "std_msgs/msg/Float64MultiArray", qos_latched())]
                for name, typ, qos in topics:
                    full = self.resolve_topic_name(name)
                    self.recorder.add_topic(full, typ, qos)
                    self.bag_topics[name] = (full, typ)
                log.info(f"recording to {self.recorder.bag_dir}")
            except (RecorderError, ValueError) as exc:
                self.recorder_error = f"not recording: {exc}"
                log.error(self.recorder_error)
                self._close_bag()
            self.bag = self.recorder

        def _record(self, name, msg):
            if self.recorder is not None:  # wall-clock stamp, never raises: drops are counted
                self.recorder.write(*self.bag_topics[name], msg)

        def _flush_bag(self):
            if self.recorder is not None:
                self.recorder.maybe_flush()

        def _publish_recorder_status(self):
            try:
                if self.recorder_error:
                    self._publish_status(make_status(RECORDER_STATUS_NAME, ERROR, self.recorder_error,
                                                     self.hardware_id, [("record_root", self.cfg["record_root"])]))
                    return
                if self.recorder is None:
                    return
                st = self.recorder.status()
                level = ERROR if st["state"] == "error" else OK
                if level == OK and self.get_clock().now().nanoseconds == 0:
                    return  # use_sim_time and no /clock yet: an OK status can wait for a stamp
                text = (f"recording to {st['bag']}" if level == OK
                        else f"recording stopped: {st['error']}; {st['messages_dropped']} message(s) dropped")
                values = [(k, st[k]) for k in ("bag", "file", "files", "bytes_written", "messages_written",
                                               "messages_dropped", "splits", "bags_deleted", "bytes_deleted")]
                values += [(f"dropped: {k}", v) for k, v in st["drop_reasons"].items()]
                self._publish_status(make_status(RECORDER_STATUS_NAME, level, text, self.hardware_id, values))
            except Exception as exc:
                self.get_logger().error(f"recorder status failed: {type(exc).__name__}: {exc}", once=True)

        def _close_bag(self):
            rec, self.recorder = self.recorder, None
            if rec is not None:
                rec.close()

        def close(self):
            self._close_bag()

        # ----------------------------------------------------------------- windows
        def on_window(self, msg):
            t_recv = time.perf_counter()
            try:
                self._record("drive/window", msg)
                self._last_window_ns = self.get_clock().now().nanoseconds
                self._stale_reported_at = None
                self.windows_seen += 1
                self._diagnose(msg, t_recv)
            except Exception as exc:  # never die on a window: report, go on
                text = f"window could not be diagnosed: internal error {type(exc).__name__}: {exc}"
                self.get_logger().error(text)
                try:
                    self._publish_status(make_status(STATUS_NAME, ERROR, text, self.hardware_id))
                except Exception:
                    pass

        def _publish_estimate(self, j1):
            m = Float64(data=float(j1))
            self.pub_estimate.publish(m)
            self._record("inertia_estimate", m)
            self.last_estimate = float(j1)

        def _publish_status(self, status):
            arr = self.diag.publish(status)
            self._record("/diagnostics", arr)

        def _diagnose(self, msg, t_recv):
            c = self.cfg
            try:
                win = window_from_msg(msg)
            except LayoutError as exc:
                text = f"window could not be diagnosed: unreadable drive/window message: {exc}"
                self.get_logger().error(text)
                self._publish_status(make_status(STATUS_NAME, ERROR, text, self.hardware_id))
                return
            # the gap estimate goes out on inertia_estimate (on_estimate) before the image method runs
            d = diagnose_window(win.as_dict(), win.entry_index, win.backlash_width_m, win.wheel_radius_m,
                                win.sample_period_s, library=self.library, system=self.system, method=self.method,
                                p=c["p"], gap_method=c["gap_method"], image_method=c["image_method"],
                                nominal_kgm2=self.nominal, library_error=self.library_error or "",
                                window_id=win.window_id, entry_time_s=win.entry_time_s,
                                on_estimate=self._publish_estimate, started_at=t_recv, policy=self.policy,
                                **detector_arguments(win))
            if d.diagnosed:
                self.get_logger().info(f"window {win.window_id} (entry t = {win.entry_time_s:.4f} s): {d.message} "
                                       f"[{LEVEL_NAMES[d.level]}]")
            else:
                self.get_logger().error(d.message)
            self._publish_status(make_status(STATUS_NAME, d.level, d.message, self.hardware_id, d.values))

        # ----------------------------------------------------------------- stale
        def on_timer(self):
            try:
                now = self.get_clock().now().nanoseconds
                if now == 0:
                    return  # use_sim_time and no /clock yet
                if self._start_ns is None:
                    self._start_ns = now
                last = self._last_window_ns if self._last_window_ns is not None else self._start_ns
                stale = self.cfg["stale_after_s"]
                age = (now - last) / 1e9
                if age < stale:
                    return
                if self._stale_reported_at is not None and (now - self._stale_reported_at) / 1e9 < stale:
                    return
                self._stale_reported_at = now
                what = ("no window received yet" if self._last_window_ns is None
                        else f"no window for {age:.1f} s")
                vals = [("stale_after_s", stale), ("windows_seen", self.windows_seen)]
                if self.last_estimate is not None:
                    vals.append(("last_estimate_kgm2", self.last_estimate))
                self._publish_status(make_status(STATUS_NAME, STALE, what, self.hardware_id, vals))
            except Exception as exc:
                self.get_logger().error(f"stale check failed: {type(exc).__name__}: {exc}")

    return DiagnosticNode


def main(args=None) -> int:
    return run_main(lambda: _node_class()(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
