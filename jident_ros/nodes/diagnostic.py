"""diagnostic node: identifies J1 from every window on ``drive/window``.

A thin ROS adapter over :class:`jident_ros.identify.monitor.DriveMonitor` and
:class:`jident_ros.identify.diagnosis.Diagnoser` (the same per-window diagnosis
``jident diagnose`` runs offline on a recording).  For each window:

1. the gap estimate (:func:`jident_ros.identify.gap.estimate_inertia`: J1 by least squares over the
   samples inside the backlash zone) -- when there is one it is published at once on
   ``inertia_estimate`` (std_msgs/Float64, kg m^2, transient local): the best continuous J1;
2. the paper's image method (:func:`jident_ros.method.patterns.identify_window`, KHM exponent ``p``)
   against the pattern library; when the window has no usable gap, the fused verdict's class J1
   (the margin-weighted vote of the five signals, :mod:`jident_ros.identify.fusion`) is what goes
   out on ``inertia_estimate``;
3. one DiagnosticStatus "<ns>/jident_diagnostic: inertia" on ``/diagnostics`` (REP 107) per window: OK when the verdict's
   class is the nominal J1; WARN when it deviates, lies between classes, or the image method's vote
   disagrees with the gap; ERROR when the window could not be diagnosed (unreadable, or its length, sample
   period or wheel radius differ from the configuration).

Besides, once a second (steady clock), one status per task (:class:`jident_ros.nodes.diagnostics.Updater`):
"jident_diagnostic: diagnosis" (windows seen/lost/mismatched; STALE when the input stopped),
"jident_diagnostic: library" (ERROR naming the file and the problem when the pattern library is unusable;
the gap estimates go on), "jident_diagnostic: recorder" (the bag, its files, bytes, messages written and
dropped by reason; ERROR with the reason when recording failed), "jident_diagnostic: trend" (with
``trend_enabled``: the trend of J1 and of the backlash width K2, :mod:`jident_ros.identify.trend`).

The trend: every diagnosed window updates a :class:`~jident_ros.identify.trend.TrendTracker` with its entry
time, the published J1 when it is the gap estimate (with its standard error) and the backlash width estimate
(with its standard uncertainty): the flank detector's flank-to-flank K2 when the window carries one (window
format 2, ``detector: flank`` in the windowing node), else the gap estimator's width at re-contact; the status
says which (``width_source``, and the counts of each) (:func:`jident_ros.identify.trend_status.trend_inputs`).
The smoothed J1 goes
out on ``inertia_trend`` and the width's regression line on ``backlash_width_trend`` (std_msgs/Float64,
kg m^2 and m, transient local) once known.  With ``trend_state_file`` the tracker's state is written
atomically after each update and read at start (a corrupt file: ERROR status, moved aside, a fresh start).

A managed (lifecycle) node: parameters are declared and checked in the constructor; ``configure`` loads the
pattern library, opens the recording and creates the topics; ``activate`` starts diagnosing; ``deactivate``
ignores windows (counted); ``cleanup``/``shutdown`` finalise the recording.  ``ros2 run jident_ros
diagnostic`` configures and activates it at once (autostart).

With ``record`` (the default), the windows (and with ``record_signals`` the drive's signals), the
estimates, the trend and the statuses are logged to a rosbag2 MCAP bag under ``record_root``
(``self.recorder``, :class:`Recording` over :class:`jident_ros.bag.rotating_recorder.Recorder`) finalised on
shutdown before the ROS context goes down (:mod:`jident_ros.nodes.runtime`).

    ros2 run jident_ros diagnostic --ros-args -p record_root:=out/bags
"""
from __future__ import annotations

import math
import time
from pathlib import Path

from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from std_msgs.msg import Float64, Float64MultiArray

from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig
from jident_ros.identify.levels import ERROR, LEVEL_NAMES, OK, STALE, WARN
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.monitor import DriveMonitor
from jident_ros.identify.trend import TrendConfig
from jident_ros.identify.trend_status import WIDTH_SOURCES
from jident_ros.identify.verdict import VerdictPolicy
from jident_ros.nodes.bag_recording import RecorderError, Recording
from jident_ros.nodes.diagnostic_trend import TrendTask
from jident_ros.nodes.diagnostics import DiagnosticsPublisher, drive_hardware_id, make_updater, status_name
from jident_ros.nodes.estimate_out import TOPICS as STAMPED_TOPIC_TYPES
from jident_ros.nodes.estimate_out import StampedEstimate
from jident_ros.nodes.params import (
    ParameterError,
    RuntimeParameters,
    checked,
    declare_parameters,
    method_config,
    node_options,
    node_schema,
    require,
    system_config,
)
from jident_ros.nodes.ros_io import (
    LayoutError,
    WithMessageInfo,
    make_status,
    qos_latched,
    qos_signals,
    window_from_msg,
)
from jident_ros.nodes.runtime import DIAGNOSED_PROGRESS_TOPIC, RunnableNode, events_executor
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import DIAGNOSTIC, DIAGNOSTIC_PARAMS, gap_method_problem
from jident_ros.stream.layout import RAW_ANGLE_DETECTORS
from jident_ros.stream.text import plain_numbers

NODE_NAME = "jident_diagnostic"
#: Each window's result.
STAMPED_TOPICS = tuple(topic for topic, _ in STAMPED_TOPIC_TYPES)
CASE_QUEUE_DEPTH = 100   # drive/case, drive/true_inertia, drive/backlash_width: subscribed and recorded with it
STATUS_TASK = "inertia"   # event status "<ns>/jident_diagnostic: inertia", one per window
#: Periodic tasks (status names "jident_diagnostic: <task>").
TASKS = ("diagnosis", "library", "recorder", "trend")
#: Period of the task statuses, s (steady clock).
TASK_PERIOD_S = 1.0
#: Lost window ids kept for the status (the count is complete).
LOST_IDS_SHOWN = 20

DEFAULTS = DIAGNOSTIC


def validate(values: dict):
    """The rules across parameters (each parameter's type, range and choices are the schema's, checked before:
    :func:`jident_ros.nodes.params.coerce`)."""
    cfg = checked(values, DEFAULTS, DEFAULTS)
    system = system_config(values)
    method = method_config(values)
    require("p", cfg["p"], cfg["p"] in [float(p) for p in method.p_values],
            f"one of method.p_values {list(method.p_values)}")
    problem = gap_method_problem(cfg["gap_method"], cfg["image_method"])
    if problem is not None:
        require(problem[0], cfg[problem[0]], False, problem[1])
    for name, what in VerdictPolicy.from_params(cfg).problems():
        require(name, cfg[name], False, what)
    try:
        TrendConfig.from_parameters(cfg)
    except ValueError as exc:  # names the trend_* parameter and its value
        raise ParameterError(f"parameter {exc}") from None
    return cfg, system, method


def schema() -> dict:
    """Every parameter of the node: its own, the model's (system.yaml) and the method's (method.yaml)."""
    return node_schema(DIAGNOSTIC_PARAMS, method=True)


def library_path(cfg, system, method) -> Path:
    if cfg["pattern_library"]:
        return Path(cfg["pattern_library"]).expanduser()
    return default_library_path(system, method)


def id_ranges(ids) -> str:
    """[3, 4, 5, 9] -> '3-5 9'."""
    out, ids = [], sorted(ids)
    i = 0
    while i < len(ids):
        j = i
        while j + 1 < len(ids) and ids[j + 1] == ids[j] + 1:
            j += 1
        out.append(str(ids[i]) if i == j else f"{ids[i]}-{ids[j]}")
        i = j + 1
    return " ".join(out)


class DiagnosticNode(TrendTask, RunnableNode, LifecycleNode):
    """The diagnostic node (composable: keyword arguments go to rclpy's LifecycleNode)."""

    def __init__(self, **kwargs):
        super().__init__(kwargs.pop("node_name", NODE_NAME), **node_options(kwargs))
        self.schema = schema()
        values = declare_parameters(self, self.schema, validate)
        self.cfg, self.system, self.method = validate(values)
        c = self.cfg
        self.policy = VerdictPolicy.from_params(c)   # what may be published (identify/verdict.py)
        self.hardware_id = drive_hardware_id(self, c["hardware_id"])
        self.nominal = float(self.system.motor.nominal_inertia_kgm2)
        s = self.system.sampling
        self.window_length = s.samples_before_entry + s.samples_from_entry
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        # state
        self.active = False
        self.recorder = None
        self.recorder_error = None
        self.library, self.library_error, self.library_path = None, None, None
        self.pub_estimate = None
        self.subs = []
        self.windows_seen = self.windows_diagnosed = self.windows_mismatched = self.windows_inactive = 0
        self.raw_windows = 0
        self.windows_lost = 0
        self.lost_ids = []                 # the last LOST_IDS_SHOWN lost ids
        self.lost_in_period = 0
        self.last_window_id = None
        self.window_id_restarts = 0
        self.last_estimate = None
        self.published_j1 = None       # J1 sent on inertia_estimate for the window being diagnosed
        self.last_message = ""
        self.last_input = None             # steady time (s) of the last drive/window or drive/progress
        self.started = time.monotonic()
        # the chain: the diagnosis (rebuilt when a parameter or the library changes) and the trend's tracker
        self.monitor = DriveMonitor(None, self._diagnoser())   # .tracker: TrendTracker (trend_enabled, configured)
        self.trend_update = None           # its last TrendUpdate
        self.trend_error = None            # why the trend's state file was not used (ERROR), one line
        self.trend_state_refused = False   # trend_state_file is not a regular file: never read nor written
        self.trend_save_error = None       # the last failure to write the state file (ERROR), one line
        self.trend_windows_without_estimate = 0
        self.trend_width_source = ""        # where the last window's width came from: flank, gap or none
        self.trend_width_sources = dict.fromkeys(WIDTH_SOURCES, 0)
        self.trend_saves = 0
        self.pub_inertia_trend = self.pub_width_trend = None
        # /diagnostics: event statuses and the periodic tasks
        self.diag = DiagnosticsPublisher(self)
        self.diag.listeners.append(lambda msg: self._record("/diagnostics", msg))
        self.updater = make_updater(self, TASK_PERIOD_S, self.diag)
        self.updater.setHardwareID(self.hardware_id)
        self.updater.add("diagnosis", self.diagnosis_status)
        self.updater.add("library", self.library_status)
        self.updater.add("recorder", self.recorder_status)
        self.updater.add("trend", self.trend_task_status)
        self.parameters = RuntimeParameters(self, self.schema, values, validate, self.on_parameters)

    # ----------------------------------------------------------------- lifecycle
    def make_executor(self):
        """The EventsExecutor of rclpy, as the other nodes (before Jazzy: SingleThreadedExecutor, which rebuilds its
        wait set in Python for every callback: at 10x it cost this node more CPU than its windows, most of it per
        recorded drive/signals batch; bench/bench_ros.py --profile, issue 25).  The recorder's subscriptions take
        the message info (the publish time) through :class:`~jident_ros.nodes.ros_io.WithMessageInfo`, which
        also works with rclpy 9.1's EventsExecutor."""
        from rclpy.executors import SingleThreadedExecutor
        return events_executor(self) or SingleThreadedExecutor(context=self.context)

    def autostart(self) -> None:
        """Configure + activate (``ros2 run``, the launch file): the node works as an unmanaged one."""
        self.trigger_configure()
        self.trigger_activate()

    def on_configure(self, state):
        c = self.cfg
        self._start_recording()
        if c["image_method"]:
            self._load_library()
        self.pub_estimate = self.create_lifecycle_publisher(Float64, "inertia_estimate", qos_latched())
        self.stamped = StampedEstimate(self, qos_latched())      # inertia_estimate/stamped and /detail
        if c["trend_enabled"]:
            self._start_trend()
            self.pub_inertia_trend = self.create_lifecycle_publisher(Float64, "inertia_trend", qos_latched())
            self.pub_width_trend = self.create_lifecycle_publisher(Float64, "backlash_width_trend", qos_latched())
        self.subs.append(self.create_subscription(Float64MultiArray, "drive/window", self.on_window,
                                                  qos_latched(c["window_queue_depth"])))
        # the windowing node's drive/progress: evidence that input flows between windows (STALE); echoed on
        # drive/diagnosed_progress once every window before it has been handled (back-pressure, ProgressGate)
        self.pub_diagnosed_progress = self.create_publisher(Float64, DIAGNOSED_PROGRESS_TOPIC, qos_signals(10))
        self.subs.append(self.create_subscription(Float64, "drive/progress", self.on_progress, qos_signals(10)))
        if self.recorder is not None and c["record_signals"]:
            sq = qos_signals(c["signals_queue_depth"])
            # raw: the CDR bytes go to the recording as received, never decoded here
            # each callback also takes the message info: its source timestamp is recorded as the publish time
            # (as rosbag2 does), so a reader can restore the order the drive sent its topics in (replay = live)
            self.subs.append(self.create_subscription(
                Float64MultiArray, "drive/signals", WithMessageInfo(lambda m, i: self._record("drive/signals", m, i)),
                sq, raw=True))
            deep = qos_latched(CASE_QUEUE_DEPTH)  # keep every case message while a window is being diagnosed
            for name in ("drive/backlash_width", "drive/true_inertia"):
                self.subs.append(self.create_subscription(
                    Float64, name, WithMessageInfo(lambda m, i, n=name: self._record(n, m, i)), deep))
            self.subs.append(self.create_subscription(
                Float64MultiArray, "drive/case", WithMessageInfo(lambda m, i: self._record("drive/case", m, i)), deep))
        if self.recorder is not None:  # a chunk never waits long in memory (flush age 0.5 s), even when messages pause
            self.flush_timer = self.create_timer(0.25, self._flush_bag, clock=self.steady)
        self.updater.force_update()
        self.get_logger().info(
            f"ready: windows from {self.resolve_topic_name('drive/window')}, J1 on "
            f"{self.resolve_topic_name('inertia_estimate')} (p = {c['p']:g}, gap method {c['gap_method']}, "
            f"image method {'on' if c['image_method'] else 'off'})")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        self.active = True
        return super().on_activate(state)

    def on_deactivate(self, state):
        self.active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        self.active = False
        for sub in self.subs:
            self.destroy_subscription(sub)
        self.subs = []
        for name in ("pub_estimate", "pub_inertia_trend", "pub_width_trend"):
            pub = getattr(self, name)
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
                setattr(self, name, None)
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state):
        self.active = False
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Finalise the recording (idempotent; the runtime calls it before the context goes down)."""
        rec, self.recorder = self.recorder, None
        if rec is not None:
            rec.close()
            self.recorder_error = rec.error or self.recorder_error
            self._closed_recorder = rec

    # ----------------------------------------------------------------- parameters at run time
    def on_parameters(self, changed: dict) -> None:
        """Apply accepted changes: p, gap_method, image_method (loads the library when switched on),
        stale_after_s, hardware_id and the settable trend_* parameters (the tracker keeps its state under
        the new configuration: :meth:`TrendTracker.reconfigure`) take effect with the next window / status."""
        self.cfg.update(changed)
        self.policy = VerdictPolicy.from_params(self.cfg)
        self.monitor.diagnoser = self._diagnoser()
        if "hardware_id" in changed:
            self.hardware_id = drive_hardware_id(self, changed["hardware_id"])
            self.updater.setHardwareID(self.hardware_id)
        if changed.get("image_method") and self.library is None and self.library_error is None:
            self._load_library()
        if self.trend is not None and any(k.startswith("trend_") for k in changed):
            # the read-only trend parameters (given baselines, regression length, file) never get here
            self.trend = self.trend.reconfigure(TrendConfig.from_parameters(self.cfg))
        self.get_logger().info("parameters changed: " + ", ".join(f"{k} = {v!r}" for k, v in sorted(changed.items())))

    # ----------------------------------------------------------------- library
    def _load_library(self):
        c = self.cfg
        self.library_path = library_path(c, self.system, self.method)
        log = self.get_logger()
        self.library, self.library_error = load_pattern_library(
            self.library_path, self.system, self.method, c["build_if_missing"], log=log.info, warn=log.warning)
        if self.library_error:
            log.error(self.library_error)
        self.monitor.diagnoser = self._diagnoser()

    def _diagnoser(self) -> Diagnoser:
        """The per-window diagnosis of the current parameters and library."""
        c = self.cfg
        config = DiagnosisConfig.from_parameters(c, self.nominal)
        return Diagnoser(self.system, self.method, config, self.policy,
                         self.library if c["image_method"] else None, self.library_error or "")

    @property
    def trend(self):
        """The trend's :class:`~jident_ros.identify.trend.TrendTracker` (None: trend off or not configured)."""
        return self.monitor.tracker

    @trend.setter
    def trend(self, tracker) -> None:
        self.monitor.tracker = tracker

    def library_status(self, stat):
        if not self.cfg["image_method"]:
            stat.summary(OK, "image method off: no pattern library used")
        elif self.library_error:
            stat.summary(ERROR, self.library_error + " (gap estimates go on)")
        elif self.library is None:
            stat.summary(OK, "pattern library not loaded yet (node not configured)")
        else:
            lib = self.library
            stat.summary(OK, f"pattern library {self.library_path}: {len(lib.classes_kgm2)} J1 classes x "
                         f"{len(lib.widths_m)} widths x p {list(lib.p_values)}")
        stat.add("pattern_library", str(self.library_path or ""))
        stat.add("image_method", self.cfg["image_method"])
        return stat

    # ----------------------------------------------------------------- recording
    def _start_recording(self):
        c = self.cfg
        if not c["record"]:
            return
        if c["record_dir"]:
            self.get_logger().warning("record_dir is deprecated: use record_root (bags get rosbag2 names under it)")
        # True: another node's topic, recorded with the QoS its publishers offer (nodes/recorded_qos.py)
        topics = [("drive/window", "std_msgs/msg/Float64MultiArray", qos_latched(self.cfg["window_queue_depth"]), True),
                  ("inertia_estimate", "std_msgs/msg/Float64", qos_latched()),
                  *((topic, typ, qos_latched()) for topic, typ in STAMPED_TOPIC_TYPES),
                  ("inertia_trend", "std_msgs/msg/Float64", qos_latched()),
                  ("backlash_width_trend", "std_msgs/msg/Float64", qos_latched()),
                  ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", self.diag.pub.qos_profile)]
        if self.cfg["record_signals"]:
            topics += [("drive/signals", "std_msgs/msg/Float64MultiArray",
                        qos_signals(self.cfg["signals_queue_depth"]), True),
                       ("drive/backlash_width", "std_msgs/msg/Float64", qos_latched(CASE_QUEUE_DEPTH), True),
                       ("drive/true_inertia", "std_msgs/msg/Float64", qos_latched(CASE_QUEUE_DEPTH), True),
                       ("drive/case", "std_msgs/msg/Float64MultiArray", qos_latched(CASE_QUEUE_DEPTH), True)]
        try:
            self.recorder = Recording(self, c, topics)
            self.get_logger().info(f"recording to {self.recorder.bag_dir}")
        except (RecorderError, RuntimeError, ValueError, OSError) as exc:
            self.recorder_error = f"not recording: {exc}"
            self.get_logger().error(self.recorder_error)

    def _record(self, name, msg, info=None):
        if self.recorder is not None:
            sent = (info or {}).get("source_timestamp") or None    # rclpy's MessageInfo; 0: not known
            # after a failure: counted as dropped, by reason
            self.recorder.write(name, msg, sent if sent is None or 0 < sent < 2**63 else None)
            if self.recorder.error:
                self.recorder.finalise_failed()

    def _flush_bag(self):
        if self.recorder is not None and self.recorder.open:
            self.recorder.flush()
            if self.recorder.error:
                self.recorder.finalise_failed()

    def recorder_status(self, stat):
        rec = self.recorder or getattr(self, "_closed_recorder", None)
        if self.recorder_error:
            stat.summary(ERROR, self.recorder_error)
        elif not self.cfg["record"]:
            stat.summary(OK, "not recording (record is false)")
        elif self.recorder is not None and self.recorder.error:
            st = self.recorder.status()
            stat.summary(ERROR, f"recording stopped: {self.recorder.error}; {st['messages_dropped']} message(s) "
                         "dropped since (by reason in the values)")
        elif self.recorder is not None:
            stat.summary(OK, f"recording to {self.recorder.bag_dir}")
        else:
            stat.summary(OK, "recording closed")
        if rec is not None:
            for k, v in rec.status().items():
                stat.add(k, v)
        return stat

    # ----------------------------------------------------------------- windows
    def on_progress(self, msg):
        """drive/progress: input flows (STALE), and its echo on drive/diagnosed_progress. The executor hands
        this node its callbacks in arrival order, so the echo of a progress message goes out only after every
        window that arrived before it was diagnosed: a streaming node's ProgressGate waits for the slower of
        the windowing and the diagnostic node, and no window piles up in this node's queue."""
        self.last_input = time.monotonic()
        self.pub_diagnosed_progress.publish(msg)

    def on_window(self, msg):
        t_recv = time.perf_counter()
        self.last_input = time.monotonic()
        try:
            self._record("drive/window", msg)
            if not self.active:
                # ignored, not lost: its id moves on, so the next diagnosed window sees no gap
                self.windows_inactive += 1
                try:
                    self.last_window_id = int(window_from_msg(msg).window_id)
                except (LayoutError, ValueError):
                    pass
                return
            self.windows_seen += 1
            self._diagnose(msg, t_recv)
        except Exception as exc:  # never die on a window: report, go on
            text = plain_numbers(f"window could not be diagnosed: internal error {type(exc).__name__}: {exc}")
            self.get_logger().error(text)
            try:
                self.diag.publish(make_status(status_name(self, STATUS_TASK), ERROR, text, self.hardware_id))
            except Exception:
                pass

    def _publish_estimate(self, j1):
        self.published_j1 = float(j1)
        m = Float64(data=float(j1))
        self.pub_estimate.publish(m)
        self._record("inertia_estimate", m)
        self.last_estimate = float(j1)

    def _count_window_id(self, window_id: int) -> None:
        """Lost windows: a jump of window_id (the windowing node numbers its windows from 1); a smaller id
        is a restart of the windowing node (counted, not a loss)."""
        last = self.last_window_id
        if last is not None and window_id > last + 1:
            lost = range(last + 1, window_id)
            self.windows_lost += len(lost)
            self.lost_in_period += len(lost)
            self.lost_ids = (self.lost_ids + list(lost)[-LOST_IDS_SHOWN:])[-LOST_IDS_SHOWN:]
            self.get_logger().warning(f"{len(lost)} window(s) lost before window {window_id} (ids "
                                      f"{id_ranges(list(lost)[-LOST_IDS_SHOWN:])})", throttle_duration_sec=1.0)
        elif last is not None and window_id <= last:
            self.window_id_restarts += 1
        self.last_window_id = window_id

    def check_window(self, win) -> tuple[list, list]:
        """(errors, warnings) of a window against the configuration: its length, its header's sample
        period and wheel radius (errors: the diagnosis would be wrong), its K2 (a warning when it lies
        outside the library's widths and the image method is on)."""
        errors, warnings = [], []
        if len(win) != self.window_length:
            errors.append(f"length {len(win)} samples, configuration {self.window_length} "
                          "(sampling.samples_before_entry + samples_from_entry)")
        ts = self.system.sampling.sample_period_s
        if not (math.isfinite(win.sample_period_s) and abs(win.sample_period_s - ts) <= 1e-9 * ts):
            errors.append(f"sample period {win.sample_period_s!r} s, configuration {ts!r} s (sampling.sample_period_s)")
        r = self.system.load.wheel_radius_m
        if not (math.isfinite(win.wheel_radius_m) and abs(win.wheel_radius_m - r) <= 1e-9 * r):
            errors.append(f"wheel radius {win.wheel_radius_m!r} m, configuration {r!r} m (load.wheel_radius_m)")
        widths = self.system.grid.backlash_widths_m
        k2 = win.backlash_width_m
        if win.detector == "dynamics" and math.isnan(k2):
            pass   # no load encoder: K2 unknown (the Diagnoser runs the gap fit without it, no image method)
        elif not (math.isfinite(k2) and k2 > 0):
            errors.append(f"backlash width K2 {k2!r} m: not a width")
        elif self.cfg["image_method"] and not (min(widths) * (1 - 1e-9) <= k2 <= max(widths) * (1 + 1e-9)):
            warnings.append(f"K2 {k2:g} m outside the library's widths {min(widths):g} .. {max(widths):g} m "
                            "(grid.backlash_widths_m): the image method uses the nearest")
        return errors, warnings

    def _diagnose(self, msg, t_recv):
        try:
            win = window_from_msg(msg)
        except LayoutError as exc:
            text = f"window could not be diagnosed: unreadable drive/window message: {exc}"
            self.get_logger().error(text)
            self.diag.publish(make_status(status_name(self, STATUS_TASK), ERROR, text, self.hardware_id))
            return
        self._count_window_id(int(win.window_id))
        self.raw_windows += win.detector in RAW_ANGLE_DETECTORS     # a real drive's recording
        errors, warnings = self.check_window(win)
        if errors:
            self.windows_mismatched += 1
            text = plain_numbers(f"window {win.window_id} not diagnosed: it does not match the configuration: "
                                 + "; ".join(errors))
            self.get_logger().error(text, throttle_duration_sec=1.0)
            self.last_message = text
            self.diag.publish(make_status(status_name(self, STATUS_TASK), ERROR, text, self.hardware_id,
                                          [("window_id", win.window_id), ("entry_time_s", win.entry_time_s),
                                           ("mismatch", "; ".join(errors))]))
            return
        # the gap estimate goes out on inertia_estimate (on_estimate) before the image method runs
        self.published_j1 = None
        result = self.monitor.window(win, on_estimate=self._publish_estimate, started_at=t_recv)
        d = result.diagnosis
        level, message, values = d.level, plain_numbers(d.message), list(d.values)
        if warnings:
            self.windows_mismatched += 1
            level = max(level, WARN)
            message = f"{message}; {'; '.join(warnings)}"
            values.append(("mismatch", "; ".join(warnings)))
        if d.diagnosed:
            self.windows_diagnosed += 1
            self.get_logger().info(f"window {win.window_id} (entry t = {win.entry_time_s:.4f} s): {message} "
                                   f"[{LEVEL_NAMES[level]}]")
        else:
            self.get_logger().error(message)
        self.last_message = message
        self.diag.publish(make_status(status_name(self, STATUS_TASK), level, message, self.hardware_id, values))
        if self.published_j1 is not None:
            for topic, msg in zip(STAMPED_TOPICS, self.stamped.publish(win.window_id, win.entry_time_s,
                                                                        self.published_j1, values, level)):
                self._record(topic, msg)
        if self.trend is not None:
            self._update_trend(win, result)

    # ----------------------------------------------------------------- periodic status
    def diagnosis_status(self, stat):
        """"jident_diagnostic: diagnosis": STALE when no drive/window and no drive/progress arrived for
        stale_after_s (steady clock: the input stopped, REP 107), WARN when windows were lost (window_id
        gaps) in the period, else OK."""
        now = time.monotonic()
        stale = self.cfg["stale_after_s"]
        age = now - (self.last_input if self.last_input is not None else self.started)
        undeclared = self.policy.undeclared_note(self.system.motor.bearing_friction_nms_per_rad)
        if not self.active:
            stat.summary(OK, "inactive (lifecycle): windows are not diagnosed")
        elif stale > 0 and age >= stale:
            stat.summary(STALE, "no input received yet (no drive/window, no drive/progress)" if self.last_input is None
                         else f"no input for {age:.1f} s (no drive/window, no drive/progress)")
        elif self.lost_in_period:
            stat.summary(WARN, f"{self.lost_in_period} window(s) lost in the last period (window_id gaps; "
                         f"{self.windows_lost} in all, last ids {id_ranges(self.lost_ids)})")
        else:
            stat.summary(OK, f"{self.windows_diagnosed} window(s) diagnosed" +
                         (f"; {undeclared}" if undeclared and self.raw_windows else "") +
                         (f"; last: {self.last_message}" if self.last_message else ""))
        self.lost_in_period = 0
        for k, v in (("windows_seen", self.windows_seen), ("windows_diagnosed", self.windows_diagnosed),
                     ("windows_lost", self.windows_lost), ("lost_window_ids", id_ranges(self.lost_ids)),
                     ("windows_mismatched", self.windows_mismatched),
                     ("windows_ignored_inactive", self.windows_inactive),
                     ("window_id_restarts", self.window_id_restarts),
                     ("last_window_id", -1 if self.last_window_id is None else self.last_window_id),
                     ("input_age_s", age), ("stale_after_s", stale), ("p", self.cfg["p"]),
                     ("gap_method", self.cfg["gap_method"]), ("image_method", self.cfg["image_method"]),
                     ("drive_model_declared", not undeclared)):
            stat.add(k, v)
        if self.last_estimate is not None:
            stat.add("last_estimate_kgm2", self.last_estimate)
        return stat


def main(args=None) -> int:
    return run_main(lambda argv: DiagnosticNode(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
