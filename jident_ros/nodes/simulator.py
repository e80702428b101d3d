"""simulator node: runs the motor-load model case after case and publishes the drive's signals.

Publishes (topic names relative, see docs/interfaces.md):

* ``drive/signals`` (std_msgs/Float64MultiArray): batches of ``batch_size`` samples, channels
  ``t,alpha1,alpha2,omega2,a1,m_el,omega1,a2,v2``;
* ``/clock`` (rosgraph_msgs/Clock): the drive clock, after every batch (t of its last sample);
* ``drive/true_inertia``, ``drive/backlash_width`` (std_msgs/Float64, transient local) and
  ``drive/case`` (Float64MultiArray, one row ``case_index,inertia_kgm2,backlash_width_m,
  consistency_pa_sn,entry_time_s``, transient local) before each case's first sample.

Every case is preceded by ``gap_samples`` steady-state samples; the drive clock runs on without a
break.  ``real_time_factor`` paces the drive clock against the wall clock (0 = as fast as the windowing
node reads: at most ``RATE0_BATCHES_PER_TICK`` batches per ``fast_sleep_s`` and at most ``max_lead_s`` drive seconds ahead of its
``drive/progress``, :class:`jident_ros.nodes.runtime.ProgressGate`), from a timer: parameter requests
are answered while it streams.

    ros2 run jident_ros simulator --ros-args -p inertias_kgm2:="[1.16, 1.073]" -p real_time_factor:=0.0
"""
from __future__ import annotations

import time

import numpy as np
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, Float64MultiArray

from jident_ros.nodes import params as node_params
from jident_ros.nodes.params import ParameterError
from jident_ros.nodes.ros_io import clock_msg, multiarray_from_array, qos_clock, qos_latched, qos_signals
from jident_ros.nodes.runtime import ProgressGate, RunnableNode, drain, tick
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import SIMULATOR, SIMULATOR_PARAMS
from jident_ros.sim import Case, check_stable, paper_grid_cases, simulate_grid
from jident_ros.stream.detector import embed_windows
from jident_ros.stream.layout import CASE_LABEL, DEFAULT_CHANNELS

NODE_NAME = "jident_simulator"
#: At real_time_factor 0, at most this many batches per tick of ``fast_sleep_s`` (while the windowing node's
#: progress allows them): one per tick capped the stream at 1 batch / fast_sleep_s = 25x at 1 ms (issue 25).
RATE0_BATCHES_PER_TICK = 4
#: Wall-clock pause after announcing a case whose backlash width differs from the previous one, s.
CASE_SETTLE_S = 0.05

DEFAULTS = SIMULATOR


def build_cases(cfg: dict, system) -> list:
    """The Case list of the ``cases`` mode (ParameterError on a bad combination)."""
    mode = cfg["cases"]
    j, w, e = cfg["inertias_kgm2"], cfg["backlash_widths_m"], cfg["consistencies_pa_sn"]
    if mode == "grid":
        return paper_grid_cases(system)
    for name in ("inertias_kgm2", "backlash_widths_m", "consistencies_pa_sn"):
        vals = cfg[name]
        node_params.require(name, vals, len(vals) > 0, "a non-empty list")
        for i, v in enumerate(vals):
            node_params.require(f"{name}[{i}]", v, v > 0, "a number > 0")
    if mode == "product":
        return [Case(a, b, c) for a in j for b in w for c in e]
    n = max(len(j), len(w), len(e))
    for name, vals in (("inertias_kgm2", j), ("backlash_widths_m", w), ("consistencies_pa_sn", e)):
        node_params.require(name, vals, len(vals) in (1, n), f"of length 1 or {n} (cases: zip)")
    pick = lambda vals, i: vals[0] if len(vals) == 1 else vals[i]  # noqa: E731
    return [Case(pick(j, i), pick(w, i), pick(e, i)) for i in range(n)]


def validate(values: dict):
    cfg = node_params.checked(values, DEFAULTS, DEFAULTS)
    # each parameter's type, range and choices are the schema's, checked before (nodes.params.coerce)
    system = node_params.system_config(values)
    cases = build_cases(cfg, system)
    try:  # inputs the simulation cannot integrate (an overload, a step too coarse for J1): one line, not NaN batches
        check_stable(system, cases)
    except ValueError as exc:  # name what the user sets: the case lists (or the model sections)
        raise ParameterError(f"parameter consistencies_pa_sn, inertias_kgm2, backlash_widths_m (the cases) with "
                             f"the model: {exc}") from None
    return cfg, system, cases


def schema() -> dict:
    """Every parameter of the node: its own (jident_ros/parameters.py) and the model's (system.yaml)."""
    return node_params.node_schema(SIMULATOR_PARAMS)


class SimulatorNode(RunnableNode, Node):
    """The simulator node (composable: keyword arguments go to rclpy's Node).

    Streams from a timer (never a blocking loop: parameter requests are answered while it streams): a
    state machine WAITING (for ``wait_for_subscribers``) -> STREAMING -> DONE; at real_time_factor > 0
    every tick publishes the batches due by the wall clock, at 0 up to RATE0_BATCHES_PER_TICK per tick of ``fast_sleep_s``
    when the windowing node's progress allows it (:class:`ProgressGate`)."""

    def __init__(self, **kwargs):
        super().__init__(kwargs.pop("node_name", NODE_NAME), **node_params.node_options(kwargs))
        self.schema = schema()
        values = node_params.declare_parameters(self, self.schema, validate)
        self.cfg, self.system, self.cases = validate(values)
        self.exit_code = 0
        self.done = False
        c = self.cfg
        self.pub_signals = self.create_publisher(Float64MultiArray, "drive/signals",
                                                 qos_signals(c["signals_queue_depth"]))
        self.pub_clock = self.create_publisher(Clock, "/clock", qos_clock()) if c["publish_clock"] else None
        # every case stays available to late subscribers while the node lives: a recorder whose subscription was
        # matched after case 2 began (a loaded machine) still records case 1's K2 and J1, with their publish times
        # (with keep-last 1 it got case 2's K2 alone, and the replay diagnosed case 1 with it: replay != live)
        latched_cases = qos_latched(min(len(self.cases), 1000))
        self.pub_inertia = self.create_publisher(Float64, "drive/true_inertia", latched_cases)
        self.pub_width = self.create_publisher(Float64, "drive/backlash_width", latched_cases)
        self.pub_case = self.create_publisher(Float64MultiArray, "drive/case", latched_cases)
        t0 = time.perf_counter()
        try:
            self.windows = simulate_grid(self.system, self.cases)
        except ValueError as exc:  # the model cannot run these cases (e.g. an overload): one line
            raise ParameterError(f"parameter consistencies_pa_sn/inertias_kgm2/backlash_widths_m: {exc}") from None
        self.stream, self.entry_rows = embed_windows(self.windows, c["gap_samples"], 0.0, DEFAULT_CHANNELS)
        self.per_case = c["gap_samples"] + len(self.windows.t)
        self.ts = self.windows.sample_period_s
        self.get_logger().info(
            f"simulated {len(self.cases)} case(s) in {time.perf_counter() - t0:.2f} s; publishing "
            f"{c['batch_size']}-sample batches at real-time factor {c['real_time_factor']:g} "
            f"on {self.resolve_topic_name('drive/signals')}")
        self.gate = None
        self.batches = self._batches()
        self.pending = None          # the next batch (t_last, kind, payload) not yet published
        self.passes = 0
        self.state = "waiting"
        self.wait_deadline = time.monotonic() + c["wait_timeout_s"]
        self.settle_until = 0.0
        self.wall0 = None
        steady = RosClock(clock_type=ClockType.STEADY_TIME)
        period = c["fast_sleep_s"] if c["real_time_factor"] == 0 else min(0.01, c["batch_size"] * self.ts /
                                                                            max(c["real_time_factor"], 1e-9))
        self.timer = self.create_timer(max(period, 1e-4), self.on_tick, clock=steady)
        if c["wait_for_subscribers"] > 0:
            self.get_logger().info(f"waiting for {c['wait_for_subscribers']} subscriber(s) of "
                                   f"{self.resolve_topic_name('drive/signals')}" +
                                   (f", one of them the node {c['wait_for_node']!r}" if c["wait_for_node"] else ""))

    # ----------------------------------------------------------------- streaming (timer)
    def _batches(self):
        """(kind, payload) items in order: ('case', (i, case, entry_t)), ('settle', None), ('batch', rows)."""
        c = self.cfg
        sample0 = 0
        n_rows = self.stream.shape[0]
        while c["repeat"] == 0 or self.passes < c["repeat"]:
            for i, case in enumerate(self.cases):
                base = sample0 + i * self.per_case
                entry_t = c["start_time_s"] + (base + c["gap_samples"] + self.windows.entry_index) * self.ts
                yield "case", (i, case, entry_t)
                if i > 0 and case.backlash_width_m != self.cases[i - 1].backlash_width_m:
                    # the windowing node must hear the new K2 (drive/backlash_width, another topic:
                    # no ordering with drive/signals) before this case's samples: the simulated
                    # stream jumps between cases, and with the old K2 that jump could look like an entry
                    yield "settle", None
                rows = self.stream[i * self.per_case:(i + 1) * self.per_case].copy()
                rows[:, 0] = c["start_time_s"] + (base + np.arange(rows.shape[0])) * self.ts
                for s in range(0, rows.shape[0], c["batch_size"]):
                    yield "batch", rows[s:s + c["batch_size"]]
            sample0 += n_rows
            self.passes += 1

    def on_tick(self):
        tick(self.state, {"waiting": self._tick_waiting, "streaming": self._tick_streaming}, self._failed)

    def _tick_waiting(self):
        c = self.cfg
        want = c["wait_for_subscribers"]
        have = self.pub_signals.get_subscription_count()
        missing_node = want > 0 and have >= want and not self._named_subscriber()
        if want > 0 and (have < want or missing_node):
            if time.monotonic() > self.wait_deadline:
                topic = self.resolve_topic_name('drive/signals')
                if missing_node or (c["wait_for_node"] and not self._named_subscriber()):
                    what = (f"no subscription of {topic} by a node named {c['wait_for_node']!r} ({have} "
                            f"subscriber(s) of other nodes; parameters wait_for_node, wait_for_subscribers {want})")
                else:
                    what = f"{have} of {want} subscriber(s) of {topic}"
                self.get_logger().error(f"{what} after {c['wait_timeout_s']:g} s; giving up")
                self.exit_code = 1
                self.state = "done"
                self.done = True
            return
        if have == 0:
            self.get_logger().warning(f"starting without any subscriber of {self.resolve_topic_name('drive/signals')}"
                                      " (wait_for_subscribers is 0): the first batches may be lost")
        self.state = "streaming"
        self.settle_until = time.monotonic() + (0.2 if want > 0 else 0.0)  # let the reliable reader finish matching
        if c["real_time_factor"] == 0 and c["max_lead_s"] > 0:
            self.gate = ProgressGate(self, c["max_lead_s"], c["progress_timeout_s"])

    def _named_subscriber(self) -> bool:
        """True when wait_for_node is empty or a node of that name subscribes to drive/signals (the graph
        names each subscription's node: the diagnostic node's recorder is not the windowing node)."""
        name = self.cfg["wait_for_node"]
        if not name:
            return True
        infos = self.get_subscriptions_info_by_topic(self.resolve_topic_name("drive/signals"))
        return any(i.node_name == name for i in infos)

    def _tick_streaming(self):
        c = self.cfg
        now = time.monotonic()
        if now < self.settle_until:
            return
        rt = c["real_time_factor"]
        burst = 0
        while True:
            if self.pending is None:
                self.pending = next(self.batches, None)
                if self.pending is None:
                    self._finish_streaming()
                    return
            kind, payload = self.pending
            if kind == "case":
                self._publish_case(*payload)
            elif kind == "settle":
                self.pending = None
                self.settle_until = time.monotonic() + CASE_SETTLE_S
                return
            else:
                t_last = float(payload[-1, 0])
                if rt > 0:
                    if self.wall0 is None:
                        self.wall0 = now - (t_last - c["start_time_s"]) / rt
                    if self.wall0 + (t_last - c["start_time_s"]) / rt > now:
                        return                       # not due yet
                elif self.gate is not None and not self.gate.allows(t_last):
                    return                           # the windowing node is behind: next tick
                self.pub_signals.publish(multiarray_from_array(payload, DEFAULT_CHANNELS))
                if self.pub_clock is not None:
                    self.pub_clock.publish(clock_msg(t_last))
                self.pending = None
                if rt == 0:
                    burst += 1
                    if burst >= RATE0_BATCHES_PER_TICK:
                        return                       # at most this many batches per tick of fast_sleep_s
                continue
            self.pending = None

    def _failed(self, exc: Exception) -> None:
        """A failure while streaming: one line, exit status 1, stop."""
        self.get_logger().error(f"streaming failed: {type(exc).__name__}: {exc}")
        self.exit_code = 1
        self._finish_streaming()

    def _finish_streaming(self):
        self.timer.cancel()
        gate, self.gate = self.gate, None
        waited = ""
        if gate is not None:
            waited = (f"; waited {gate.waited_s:.2f} s for the downstream nodes (back-pressure)"
                      if gate.waited_s else "")
            if gate.openings:
                waited += f"; back-pressure off {gate.openings} time(s) after progress_timeout_s without progress"
            gate.close()
        self.get_logger().info(f"done: {self.passes} pass(es) over {len(self.cases)} case(s){waited}")
        self.state = "done"
        if self.cfg["exit_when_done"]:
            self.done = True

    def finish(self, stopping) -> None:
        """After the spin (the cases are done): give reliable readers the last batches (runtime.drain: a WARN names
        a topic not acknowledged in time)."""
        if self.exit_code == 0:
            drain((self.pub_signals, self.pub_case, self.pub_inertia, self.pub_width), self.get_logger(), stopping)

    def _publish_case(self, i, case, entry_t):
        self.pub_inertia.publish(Float64(data=case.inertia_kgm2))
        self.pub_width.publish(Float64(data=case.backlash_width_m))
        row = np.array([[i, case.inertia_kgm2, case.backlash_width_m, case.consistency_pa_sn, entry_t]])
        self.pub_case.publish(multiarray_from_array(row, CASE_LABEL.split(",")))
        self.get_logger().info(f"case {i + 1}/{len(self.cases)}: J1 = {case.inertia_kgm2:g} kg m^2, "
                               f"K2 = {case.backlash_width_m:g} m, eta_k = {case.consistency_pa_sn:g} "
                               f"Pa s^n (entry at t = {entry_t:.4f} s)")


def main(args=None) -> int:
    return run_main(lambda argv: SimulatorNode(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
