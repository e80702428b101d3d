"""diagnostic node: identifies J1 from every window on ``drive/window``.

For each window:

1. the gap estimate (:func:`jident_ros.method.gap.estimate_inertia`: J1 by least squares over the
   samples inside the backlash zone) -- when there is one it is published at once on
   ``inertia_estimate`` (std_msgs/Float64, kg m^2, transient local): the best continuous J1;
2. the paper's image method (:func:`jident_ros.method.patterns.identify_window`, KHM exponent ``p``)
   against the pattern library; when the window has no usable gap its fused class J1 is what goes
   out on ``inertia_estimate``;
3. one DiagnosticStatus "jident: inertia" on ``/diagnostics`` (REP 107): OK when the identified
   class is the nominal J1, WARN when it deviates, ERROR when the window could not be diagnosed or
   the pattern library is unusable; a STALE status when no window arrived for ``stale_after_s``.

With ``record_dir`` set, the windows (and with ``record_signals`` the drive's signals), the estimates
and the statuses are logged to an MCAP recording (jident_ros.recording.BagWriter) closed on shutdown.

    ros2 run jident_ros diagnostic --ros-args -p record_dir:=out/run1
"""
from __future__ import annotations

import time
from pathlib import Path

from . import (DiagnosticsPublisher, checked, declare_parameters, drive_hardware_id, main as run_main,
               method_config, method_defaults, require, system_config, system_defaults)

NODE_NAME = "jident_diagnostic"
STATUS_NAME = "jident: inertia"

#: Parameters of this node (besides config/system.yaml and config/method.yaml), with their defaults.
DEFAULTS = {
    "pattern_library": "",        # .npz; "" = the CLI's default path (~/.cache/jident_ros/patterns-<hash>.npz)
    "build_if_missing": True,     # build (and save) the library when the file does not exist
    "p": 2.0,                     # KHM exponent, one of method.p_values
    "image_method": True,         # run the paper's image method on every window
    "gap_method": "auto",         # auto | acceleration | speed | off
    "hardware_id": "",            # default: the resolved drive namespace, e.g. /drive
    "stale_after_s": 5.0,         # STALE status after this long without a window; 0 = never
    "record_dir": "",             # MCAP recording (bag directory); "" = no recording
    "record_signals": True,       # also record drive/signals (+ drive/backlash_width, true_inertia, case)
    "window_queue_depth": 50,
    "signals_queue_depth": 1000,
}


def validate(values: dict):
    cfg = checked(values, DEFAULTS, DEFAULTS)
    system = system_config(values)
    method = method_config(values)
    require("p", cfg["p"], cfg["p"] in [float(p) for p in method.p_values],
            f"one of method.p_values {list(method.p_values)}")
    require("gap_method", cfg["gap_method"], cfg["gap_method"] in ("auto", "acceleration", "speed", "off"),
            "one of auto, acceleration, speed, off")
    require("stale_after_s", cfg["stale_after_s"], cfg["stale_after_s"] >= 0, "a number >= 0 (0 = never)")
    for n in ("window_queue_depth", "signals_queue_depth"):
        require(n, cfg[n], cfg[n] >= 1, "an integer >= 1")
    require("image_method", cfg["image_method"], cfg["image_method"] or cfg["gap_method"] != "off",
            "true when gap_method is off (nothing would be identified)")
    return cfg, system, method


def library_path(cfg, system, method) -> Path:
    if cfg["pattern_library"]:
        return Path(cfg["pattern_library"]).expanduser()
    from ..cli import default_library_path
    return default_library_path(system, method)


def _node_class():
    from rclpy.node import Node
    from std_msgs.msg import Float64, Float64MultiArray

    from ..method.gap import NoGapError, estimate_inertia, nearest_class
    from ..method.patterns import LibraryMismatch, PatternLibrary, identify_window
    from ..method.pipeline import SIGNALS
    from ..ros_io import (ERROR, LEVEL_NAMES, OK, STALE, WARN, LayoutError, make_status, qos_latched,
                          qos_signals, window_from_msg)

    class DiagnosticNode(Node):
        def __init__(self):
            super().__init__(NODE_NAME)
            defaults = dict(DEFAULTS, **system_defaults(), **method_defaults())
            self.cfg, self.system, self.method = validate(declare_parameters(self, defaults))
            c = self.cfg
            self.hardware_id = drive_hardware_id(self, c["hardware_id"])
            self.classes = tuple(self.system.grid.inertia_classes_kgm2)
            self.nominal = float(self.system.motor.nominal_inertia_kgm2)
            self.diag = DiagnosticsPublisher(self)
            self.pub_estimate = self.create_publisher(Float64, "inertia_estimate", qos_latched())
            self.bag = None
            self.bag_topics = {}
            self.windows_seen = 0
            self.last_estimate = None
            self._stale_reported_at = None
            self._start_recording()
            self.library, self.library_error = None, None
            if c["image_method"]:
                self._load_library()
            if self.library is not None:
                self.classes = tuple(self.library.classes_kgm2)
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
            if self.bag is not None:  # a chunk never waits long in memory, even when messages pause
                from rclpy.clock import Clock, ClockType
                self.flush_timer = self.create_timer(0.5, self._flush_bag, clock=Clock(clock_type=ClockType.STEADY_TIME))
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
            self.library_path = path = library_path(c, self.system, self.method)
            log = self.get_logger()
            try:
                self.library = PatternLibrary.load(path, self.system, self.method)
                log.info(f"pattern library {path}")
                return
            except FileNotFoundError as exc:
                if not c["build_if_missing"]:
                    self.library_error = f"pattern library missing: {exc}"
                    log.error(self.library_error)
                    return
            except LibraryMismatch as exc:
                self.library_error = f"pattern library unusable: {exc}"
                log.error(self.library_error)
                return
            log.info(f"pattern library {path} not found: building it ({len(self.classes)} J1 classes x "
                     f"{len(self.system.grid.backlash_widths_m)} widths, a few seconds)")
            t0 = time.perf_counter()

            def progress(k, n):
                log.info(f"building pattern library: signal {k}/{n} done ({time.perf_counter() - t0:.1f} s)")

            try:
                lib = PatternLibrary.build(self.system, self.method, progress=progress)
            except Exception as exc:
                self.library_error = f"pattern library could not be built: {type(exc).__name__}: {exc}"
                log.error(self.library_error)
                return
            try:
                lib.save(path)
                log.info(f"pattern library built in {time.perf_counter() - t0:.1f} s, saved to {path}")
            except OSError as exc:
                log.warning(f"pattern library built but not saved to {path}: {exc}")
            self.library = lib

        def _publish_library_error(self):
            try:
                self._publish_status(make_status(STATUS_NAME, ERROR, self.library_error, self.hardware_id,
                                                 [("pattern_library", str(self.library_path)),
                                                  ("windows_seen", self.windows_seen)]))
            except Exception as exc:
                self.get_logger().error(f"status failed: {type(exc).__name__}: {exc}", once=True)

        # ----------------------------------------------------------------- recording
        def _start_recording(self):
            rd = self.cfg["record_dir"]
            if not rd:
                return
            try:
                from ..recording import BagWriter
            except ImportError as exc:
                self.get_logger().warning(f"record_dir is set but MCAP logging is unavailable "
                                          f"(jident_ros.recording: {exc}); logging disabled")
                return
            try:
                self.bag = BagWriter(str(Path(rd).expanduser()))
                topics = [("drive/window", "std_msgs/msg/Float64MultiArray", qos_latched(self.cfg["window_queue_depth"])),
                          ("inertia_estimate", "std_msgs/msg/Float64", qos_latched()),
                          ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", self.diag.pub.qos_profile)]
                if self.cfg["record_signals"]:
                    topics += [("drive/signals", "std_msgs/msg/Float64MultiArray",
                                qos_signals(self.cfg["signals_queue_depth"])),
                               ("drive/backlash_width", "std_msgs/msg/Float64", qos_latched()),
                               ("drive/true_inertia", "std_msgs/msg/Float64", qos_latched()),
                               ("drive/case", "std_msgs/msg/Float64MultiArray", qos_latched())]
                for name, typ, qos in topics:
                    full = self.resolve_topic_name(name)
                    self.bag.add_topic(full, typ, qos)
                    self.bag_topics[name] = full
                self.get_logger().info(f"recording to {rd}")
            except Exception as exc:
                self.get_logger().error(f"recording to {rd} failed: {type(exc).__name__}: {exc}; logging disabled")
                self._close_bag()

        def _record(self, name, msg):
            if self.bag is None:
                return
            try:
                self.bag.write(self.bag_topics[name], msg, self.get_clock().now().nanoseconds)
            except Exception as exc:
                self.get_logger().error(f"recording failed: {type(exc).__name__}: {exc}; logging disabled")
                self._close_bag()

        def _flush_bag(self):
            if self.bag is not None:
                try:
                    self.bag.maybe_flush()
                except Exception as exc:
                    self.get_logger().error(f"recording failed: {type(exc).__name__}: {exc}; logging disabled")
                    self._close_bag()

        def _close_bag(self):
            bag, self.bag = self.bag, None
            if bag is not None:
                try:
                    bag.close()
                except Exception as exc:
                    self.get_logger().error(f"closing the recording failed: {type(exc).__name__}: {exc}")

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
            data = win.as_dict()
            vals = [("window_id", win.window_id), ("entry_time_s", win.entry_time_s),
                    ("backlash_width_m", win.backlash_width_m), ("p", c["p"])]
            problems = []
            # 1. the gap: fast, published first
            gap = None
            if c["gap_method"] != "off":
                try:
                    gap = estimate_inertia(data, win.entry_index, win.backlash_width_m, win.wheel_radius_m,
                                           win.sample_period_s,
                                           method=None if c["gap_method"] == "auto" else c["gap_method"],
                                           bearing_friction_nms_per_rad=self.system.motor.bearing_friction_nms_per_rad)
                except NoGapError as exc:
                    problems.append(f"gap: {exc}")
                if gap is not None:
                    self._publish_estimate(gap.inertia_kgm2)
                    latency = (time.perf_counter() - t_recv) * 1e3
                    vals += [("gap_j1_kgm2", gap.inertia_kgm2), ("gap_ci95_kgm2", list(gap.ci95_kgm2)),
                             ("gap_std_error_kgm2", gap.std_error_kgm2), ("gap_samples", gap.n_samples),
                             ("gap_fit", gap.method), ("gap_interval", gap.interval),
                             ("gap_residual_rms", gap.residual_rms)]
            # 2. the image method
            idn = None
            if c["image_method"]:
                if self.library is None:
                    problems.append(self.library_error or "no pattern library")
                else:
                    signals = [s for s in SIGNALS if s in data]
                    if not signals:
                        problems.append(f"image method: the window has none of {', '.join(SIGNALS)}")
                    else:
                        try:
                            idn = identify_window(data, win.entry_index, win.backlash_width_m, self.library,
                                                  self.method, c["p"], signals=signals)
                        except Exception as exc:
                            problems.append(f"image method: {type(exc).__name__}: {exc}")
            if idn is not None:
                vals += [("fused_class_kgm2", idn.fused_inertia_kgm2), ("fused_margin", idn.fused_margin),
                         ("library_width_m", self.library.widths_m[idn.width_index])]
                for s, a in idn.answers.items():
                    vals += [(f"j1.{s}", a.inertia_kgm2), (f"h.{s}", a.h), (f"margin.{s}", a.margin)]
            # 3. the answer
            if gap is not None:
                j1, source = gap.inertia_kgm2, "gap"
                cls = self.classes[nearest_class(j1, self.classes)]
            elif idn is not None:
                j1, source, cls = idn.fused_inertia_kgm2, "image", idn.fused_inertia_kgm2
                self._publish_estimate(j1)
                latency = (time.perf_counter() - t_recv) * 1e3
            else:
                text = "window could not be diagnosed: " + "; ".join(problems)
                self.get_logger().error(text)
                self._publish_status(make_status(STATUS_NAME, ERROR, text, self.hardware_id, vals))
                return
            deviation = (cls - self.nominal) / self.nominal * 100.0
            if self.library_error and c["image_method"]:
                level = ERROR
                text = f"J1 = {j1:.5g} kg m^2 (from the gap only): {self.library_error}"
            elif cls == self.nominal:
                level, text = OK, f"J1 = {j1:.5g} kg m^2: nominal class {cls:g}"
            else:
                level = WARN
                text = f"J1 = {j1:.5g} kg m^2: class {cls:g} deviates from the nominal {self.nominal:g} by {deviation:+.1f} %"
            vals = [("identified_class_kgm2", cls), ("inertia_estimate_kgm2", j1), ("estimate_source", source),
                    ("nominal_kgm2", self.nominal), ("deviation_percent", deviation)] + vals
            vals += [("estimate_latency_ms", latency),
                     ("processing_ms", (time.perf_counter() - t_recv) * 1e3)]
            if problems:
                vals.append(("problems", "; ".join(problems)))
            self.get_logger().info(f"window {win.window_id} (entry t = {win.entry_time_s:.4f} s): {text} "
                                   f"[{LEVEL_NAMES[level]}]")
            self._publish_status(make_status(STATUS_NAME, level, text, self.hardware_id, vals))

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
