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
node reads: a ``fast_sleep_s`` pause per batch and at most ``max_lead_s`` drive seconds ahead of its
``drive/progress``, :class:`jident_ros.nodes.ProgressGate`).

    ros2 run jident_ros simulator --ros-args -p inertias_kgm2:="[1.16, 1.073]" -p real_time_factor:=0.0
"""
from __future__ import annotations

import time

import numpy as np

from jident_ros.nodes.params import (
    ParameterError,
    checked,
    declare_parameters,
    require,
    system_config,
    system_defaults,
)
from jident_ros.nodes.ros_io import clock_msg, multiarray_from_array, qos_clock, qos_latched, qos_signals
from jident_ros.nodes.runtime import ProgressGate, spin
from jident_ros.nodes.runtime import main as run_main
from jident_ros.parameters import SIMULATOR
from jident_ros.sim import Case, check_stable, paper_grid_cases, simulate_grid
from jident_ros.stream.detector import embed_windows
from jident_ros.stream.layout import DEFAULT_CHANNELS

NODE_NAME = "jident_simulator"
#: Wall-clock pause after announcing a case whose backlash width differs from the previous one, s.
CASE_SETTLE_S = 0.05
CASE_LABEL = "case_index,inertia_kgm2,backlash_width_m,consistency_pa_sn,entry_time_s"

DEFAULTS = SIMULATOR


def build_cases(cfg: dict, system) -> list:
    """The Case list of the ``cases`` mode (ParameterError on a bad combination)."""
    mode = cfg["cases"]
    j, w, e = cfg["inertias_kgm2"], cfg["backlash_widths_m"], cfg["consistencies_pa_sn"]
    if mode == "grid":
        return paper_grid_cases(system)
    for name in ("inertias_kgm2", "backlash_widths_m", "consistencies_pa_sn"):
        vals = cfg[name]
        require(name, vals, len(vals) > 0, "a non-empty list")
        for i, v in enumerate(vals):
            require(f"{name}[{i}]", v, v > 0, "a number > 0")
    if mode == "product":
        return [Case(a, b, c) for a in j for b in w for c in e]
    n = max(len(j), len(w), len(e))
    for name, vals in (("inertias_kgm2", j), ("backlash_widths_m", w), ("consistencies_pa_sn", e)):
        require(name, vals, len(vals) in (1, n), f"of length 1 or {n} (cases: zip)")
    pick = lambda vals, i: vals[0] if len(vals) == 1 else vals[i]  # noqa: E731
    return [Case(pick(j, i), pick(w, i), pick(e, i)) for i in range(n)]


def validate(values: dict):
    cfg = checked(values, DEFAULTS, DEFAULTS)
    require("cases", cfg["cases"], cfg["cases"] in ("product", "zip", "grid"), "one of product, zip, grid")
    require("gap_samples", cfg["gap_samples"], cfg["gap_samples"] >= 0, "an integer >= 0")
    require("batch_size", cfg["batch_size"], cfg["batch_size"] >= 1, "an integer >= 1")
    require("real_time_factor", cfg["real_time_factor"], cfg["real_time_factor"] >= 0,
            "a number >= 0 (0 = as fast as possible)")
    require("fast_sleep_s", cfg["fast_sleep_s"], 0 <= cfg["fast_sleep_s"] <= 1, "a number in [0, 1]")
    require("max_lead_s", cfg["max_lead_s"], cfg["max_lead_s"] >= 0, "a number >= 0 (0 = no back-pressure)")
    require("progress_timeout_s", cfg["progress_timeout_s"], cfg["progress_timeout_s"] > 0, "a number > 0")
    require("start_time_s", cfg["start_time_s"], cfg["start_time_s"] >= 0, "a number >= 0")
    require("repeat", cfg["repeat"], cfg["repeat"] >= 0, "an integer >= 0 (0 = forever)")
    require("wait_for_subscribers", cfg["wait_for_subscribers"], cfg["wait_for_subscribers"] >= 0,
            "an integer >= 0")
    require("wait_timeout_s", cfg["wait_timeout_s"], cfg["wait_timeout_s"] > 0, "a number > 0")
    require("signals_queue_depth", cfg["signals_queue_depth"], cfg["signals_queue_depth"] >= 1,
            "an integer >= 1")
    system = system_config(values)
    cases = build_cases(cfg, system)
    try:  # inputs the simulation cannot integrate (an overload, a step too coarse for J1): one line, not NaN batches
        check_stable(system, cases)
    except ValueError as exc:
        raise ParameterError(f"model parameters: {exc}") from None
    return cfg, system, cases


def _node_class():
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64, Float64MultiArray


    class SimulatorNode(Node):
        def __init__(self):
            super().__init__(NODE_NAME)
            defaults = dict(DEFAULTS, **system_defaults())
            self.cfg, self.system, self.cases = validate(declare_parameters(self, defaults))
            self.exit_code = 0
            c = self.cfg
            self.pub_signals = self.create_publisher(Float64MultiArray, "drive/signals",
                                                     qos_signals(c["signals_queue_depth"]))
            self.pub_clock = self.create_publisher(Clock, "/clock", qos_clock()) if c["publish_clock"] else None
            self.pub_inertia = self.create_publisher(Float64, "drive/true_inertia", qos_latched())
            self.pub_width = self.create_publisher(Float64, "drive/backlash_width", qos_latched())
            # every case stays available to late subscribers while the node lives
            self.pub_case = self.create_publisher(Float64MultiArray, "drive/case",
                                                  qos_latched(min(len(self.cases), 1000)))
            t0 = time.perf_counter()
            self.windows = simulate_grid(self.system, self.cases)
            self.stream, self.entry_rows = embed_windows(self.windows, c["gap_samples"], 0.0, DEFAULT_CHANNELS)
            self.per_case = c["gap_samples"] + len(self.windows.t)
            self.ts = self.windows.sample_period_s
            self.get_logger().info(
                f"simulated {len(self.cases)} case(s) in {time.perf_counter() - t0:.2f} s; publishing "
                f"{c['batch_size']}-sample batches at real-time factor {c['real_time_factor']:g} "
                f"on {self.resolve_topic_name('drive/signals')}")
            self._multiarray = multiarray_from_array

        # ----------------------------------------------------------------- main loop
        def run(self):
            c = self.cfg
            if not self._wait_for_subscribers():
                return
            n_rows = self.stream.shape[0]
            # back-pressure from the windowing node at real_time_factor 0
            gate = (ProgressGate(self, c["max_lead_s"], c["progress_timeout_s"])
                    if c["real_time_factor"] == 0 and c["max_lead_s"] > 0 else None)
            try:
                self._stream(n_rows, gate)
            finally:
                if gate is not None:
                    gate.close()
            if not self.context.ok():
                return
            self._drain()
            if not c["exit_when_done"]:
                spin(self)

        def _stream(self, n_rows: int, gate) -> None:
            c = self.cfg
            wall0 = time.monotonic()
            passes = 0
            sample0 = 0  # running sample number of the drive clock
            while self.context.ok() and (c["repeat"] == 0 or passes < c["repeat"]):
                for i, case in enumerate(self.cases):
                    if not self.context.ok():
                        return
                    base = sample0 + i * self.per_case
                    entry_t = c["start_time_s"] + (base + c["gap_samples"] + self.windows.entry_index) * self.ts
                    self._publish_case(i, case, entry_t)
                    if i > 0 and case.backlash_width_m != self.cases[i - 1].backlash_width_m:
                        # the windowing node must hear the new K2 (drive/backlash_width, another topic:
                        # no ordering with drive/signals) before this case's samples: the simulated
                        # stream jumps between cases, and with the old K2 that jump could look like an entry
                        time.sleep(CASE_SETTLE_S)
                    rows = self.stream[i * self.per_case:(i + 1) * self.per_case].copy()
                    rows[:, 0] = c["start_time_s"] + (base + np.arange(rows.shape[0])) * self.ts
                    for s in range(0, rows.shape[0], c["batch_size"]):
                        batch = rows[s:s + c["batch_size"]]
                        t_last = float(batch[-1, 0])
                        if c["real_time_factor"] > 0:
                            delay = wall0 + (t_last - c["start_time_s"]) / c["real_time_factor"] - time.monotonic()
                            if delay > 0:
                                time.sleep(delay)
                        else:
                            if c["fast_sleep_s"] > 0:
                                time.sleep(c["fast_sleep_s"])
                            if gate is not None:
                                gate.wait(t_last)
                        if not self.context.ok():
                            return
                        self.pub_signals.publish(self._multiarray(batch, self.stream_channels))
                        if self.pub_clock is not None:
                            self._publish_clock(t_last)
                sample0 += n_rows
                passes += 1
            waited = (f"; waited {gate.waited_s:.2f} s for the windowing node (back-pressure)"
                      if gate is not None and gate.waited_s else "")
            self.get_logger().info(f"done: {passes} pass(es) over {len(self.cases)} case(s){waited}")

        stream_channels = DEFAULT_CHANNELS

        def _wait_for_subscribers(self) -> bool:
            want = self.cfg["wait_for_subscribers"]
            if want <= 0:
                return True
            topic = self.resolve_topic_name("drive/signals")
            self.get_logger().info(f"waiting for {want} subscriber(s) of {topic}")
            deadline = time.monotonic() + self.cfg["wait_timeout_s"]
            while self.context.ok() and self.pub_signals.get_subscription_count() < want:
                if time.monotonic() > deadline:
                    self.get_logger().error(f"no {want} subscriber(s) of {topic} after "
                                            f"{self.cfg['wait_timeout_s']:g} s; giving up")
                    self.exit_code = 1
                    return False
                time.sleep(0.05)
            time.sleep(0.2)  # let the reliable reader finish matching
            return self.context.ok()

        def _publish_case(self, i, case, entry_t):
            self.pub_inertia.publish(Float64(data=case.inertia_kgm2))
            self.pub_width.publish(Float64(data=case.backlash_width_m))
            row = np.array([[i, case.inertia_kgm2, case.backlash_width_m, case.consistency_pa_sn, entry_t]])
            self.pub_case.publish(self._multiarray(row, CASE_LABEL.split(",")))
            self.get_logger().info(f"case {i + 1}/{len(self.cases)}: J1 = {case.inertia_kgm2:g} kg m^2, "
                                   f"K2 = {case.backlash_width_m:g} m, eta_k = {case.consistency_pa_sn:g} "
                                   f"Pa s^n (entry at t = {entry_t:.4f} s)")

        def _publish_clock(self, t: float):
            self.pub_clock.publish(clock_msg(t))

        def _drain(self):
            """Give reliable readers the last batches before the node goes away."""
            from rclpy.duration import Duration
            try:
                for pub in (self.pub_signals, self.pub_case, self.pub_inertia, self.pub_width):
                    pub.wait_for_all_acked(Duration(seconds=5.0))
            except Exception:  # not supported by every rmw
                time.sleep(0.5)

    return SimulatorNode


def main(args=None) -> int:
    return run_main(lambda: _node_class()(), NODE_NAME, args)


if __name__ == "__main__":
    raise SystemExit(main())
