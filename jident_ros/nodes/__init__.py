"""ROS 2 nodes of jident_ros: simulator, windowing, diagnostic, replay (docs/interfaces.md).

Shared machinery of the four nodes, in the style of the rclpy examples:

* every node declares its parameters in ONE place, from a dict of defaults
  (:func:`declare_parameters`); the model and method sections of ``config/system.yaml`` and
  ``config/method.yaml`` are declared as dotted parameters (``load.wheel_radius_m``,
  ``method.p_values``, ...) with the package's files as defaults, so the same files serve as
  ``--params-file`` for the nodes and as configuration of the ``jident`` CLI;
* every value is validated at start; a bad one raises :class:`ParameterError` whose text is one
  line naming the parameter and the value, and :func:`main` prints it and exits with status 2;
* Ctrl-C and SIGTERM end the node cleanly (rclpy's signal handlers shut the context down,
  :func:`main` then closes the node: files are finalised in ``close()``).

rclpy is imported inside the functions: importing this package never needs ROS.
"""
from __future__ import annotations

import math
import sys
import time
from typing import Any, Callable, Mapping

#: Sections of the shared configuration files (config/system.yaml, config/method.yaml).
SYSTEM_SECTIONS = ("motor", "load", "sampling", "grid")
METHOD_SECTIONS = ("method",)
SHARED_SECTIONS = SYSTEM_SECTIONS + METHOD_SECTIONS
#: Exit status of a node stopped by a bad parameter.
EXIT_BAD_PARAMETER = 2


class ParameterError(Exception):
    """A parameter value is invalid; the message is one line naming the parameter and the value."""


# --------------------------------------------------------------------------- defaults


def flatten(d: Mapping, prefix: str = "") -> dict:
    """Nested mapping -> {dotted name: value} (lists stay values)."""
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, name + "."))
        else:
            out[name] = v
    return out


def nest(flat: Mapping) -> dict:
    """{dotted name: value} -> nested dict."""
    out: dict = {}
    for name, v in flat.items():
        parts = name.split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


def _ros_value(v):
    return [_ros_value(x) for x in v] if isinstance(v, (list, tuple)) else v


def system_defaults() -> dict:
    """Dotted parameters of config/system.yaml (the package's file) with their values."""
    from ..config import config_to_dict, load_system_config
    return {k: _ros_value(v) for k, v in flatten(config_to_dict(load_system_config())).items()}


def method_defaults() -> dict:
    """Dotted parameters of config/method.yaml; ``method.wavelets`` becomes ``method.wavelets.<signal>``."""
    import dataclasses
    from ..config import load_method_config
    cfg = load_method_config()
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if f.name == "wavelets":
            for sig, w in v:
                out[f"method.wavelets.{sig}"] = w
        else:
            out[f"method.{f.name}"] = _ros_value(v)
    return out


# --------------------------------------------------------------------------- declaration


def declare_parameters(node, defaults: Mapping[str, Any]) -> dict:
    """Declare every parameter of ``defaults`` (dynamically typed: validation is ours) and return
    {name: value}.  An override naming no parameter of this node is refused (a typo), unless it
    belongs to a shared configuration section this node does not use."""
    from rcl_interfaces.msg import ParameterDescriptor
    node.declare_parameters("", [(name, _ros_value(v), ParameterDescriptor(dynamic_typing=True))
                                 for name, v in defaults.items()])
    values = {name: node.get_parameter(name).value for name in defaults}
    used = {name.split(".")[0] for name in defaults}
    for name, param in sorted(getattr(node, "_parameter_overrides", {}).items()):
        if name in defaults or name == "use_sim_time" or name.startswith("qos_overrides."):
            continue
        section = name.split(".")[0]
        if section in SHARED_SECTIONS and section not in used:
            continue  # e.g. method.yaml given to every node of a launch file
        raise ParameterError(f"parameter {name}: unknown parameter of node {node.get_name()} "
                             f"(value {param.value!r})")
    return values


def check(name: str, value: Any, default: Any) -> Any:
    """Value coerced to the type of its default; ParameterError naming it otherwise."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ParameterError(f"parameter {name}: expected true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"parameter {name}: expected an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"parameter {name}: expected a finite number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ParameterError(f"parameter {name}: expected a string, got {value!r}")
        return value
    if isinstance(default, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            raise ParameterError(f"parameter {name}: expected a list, got {value!r}")
        value = list(value)
        if default and isinstance(default[0], str):
            if not all(isinstance(x, str) for x in value):
                raise ParameterError(f"parameter {name}: expected a list of strings, got {value!r}")
            return value
        if default and isinstance(default[0], (int, float)):
            for i, x in enumerate(value):
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise ParameterError(f"parameter {name}[{i}]: expected a finite number, got {x!r}")
            return [float(x) for x in value]
        return value
    return value


def require(name: str, value: Any, ok: bool, what: str) -> Any:
    """ParameterError 'parameter <name>: must be <what>, got <value>' unless ok."""
    if not ok:
        raise ParameterError(f"parameter {name}: must be {what}, got {value!r}")
    return value


def checked(values: Mapping[str, Any], defaults: Mapping[str, Any], names) -> dict:
    """check() every name of ``names``."""
    return {n: check(n, values[n], defaults[n]) for n in names}


def system_config(values: Mapping[str, Any]):
    """SystemConfig from the declared dotted parameters (ParameterError on a bad value)."""
    from ..config import ConfigError, system_config_from_dict
    sub = {k: v for k, v in values.items() if k.split(".")[0] in SYSTEM_SECTIONS}
    try:
        return system_config_from_dict(nest(sub))
    except ConfigError as exc:
        raise ParameterError(f"parameter {exc}") from None


def method_config(values: Mapping[str, Any]):
    """MethodConfig from the declared ``method.*`` parameters (ParameterError on a bad value)."""
    from ..config import ConfigError, method_config_from_dict
    sub = {k: v for k, v in values.items() if k.split(".")[0] in METHOD_SECTIONS}
    try:
        return method_config_from_dict(nest(sub))
    except ConfigError as exc:
        raise ParameterError(f"parameter {exc}") from None


# --------------------------------------------------------------------------- helpers


def drive_hardware_id(node, given: str = "") -> str:
    """hardware_id for /diagnostics: the parameter when set, else the resolved namespace of the
    drive topics (``/drive``, ``/press3/drive``): Float64MultiArray has no header to carry one."""
    return given or node.resolve_topic_name("drive")


class DiagnosticsPublisher:
    """Publishes DiagnosticArrays on /diagnostics stamped with the node's clock; remembers the last."""

    def __init__(self, node, topic: str = "/diagnostics"):
        from ..ros_io import qos_diagnostics
        self.node = node
        self.pub = node.create_publisher(_diagnostic_array_type(), topic, qos_diagnostics())
        self.last = None

    def publish(self, *statuses):
        from ..ros_io import make_diagnostic_array
        msg = make_diagnostic_array(self.node.get_clock().now().to_msg(), statuses)
        self.pub.publish(msg)
        self.last = msg
        return msg


def _diagnostic_array_type():
    from diagnostic_msgs.msg import DiagnosticArray
    return DiagnosticArray


def context_ok(node) -> bool:
    return node.context.ok()


class ProgressGate:
    """Back-pressure for a node that streams ``drive/signals`` as fast as it can (simulator and replay
    at rate 0): it publishes a batch ending at drive time t only when the windowing node has reported,
    on ``drive/progress``, that it has read up to t - ``max_lead_s``.

    The first batch's time is the baseline (nothing read yet).  With no progress message for
    ``timeout_s`` while waiting (no windowing node, or one without progress), the gate opens for good
    and says so once in the log: the stream never stalls for ever.  Call :meth:`close` when done (the
    gate spins the node on an executor of its own while it waits).
    """

    def __init__(self, node, max_lead_s: float, timeout_s: float):
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import Float64

        from ..ros_io import qos_signals
        self.node, self.max_lead_s, self.timeout_s = node, float(max_lead_s), float(timeout_s)
        self.progress_t = None          # drive time read by the windowing node
        self.progress_wall = None       # monotonic time of the last progress message
        self.waited_s = 0.0
        self.active = True
        self.sub = node.create_subscription(Float64, "drive/progress", self._on_progress, qos_signals(10))
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(node)

    def _on_progress(self, msg):
        t = float(msg.data)
        if math.isfinite(t) and (self.progress_t is None or t > self.progress_t):
            self.progress_t = t
            self.progress_wall = time.monotonic()

    def wait(self, t_last: float) -> None:
        """Block until the windowing node has read up to ``t_last - max_lead_s`` (or the gate opened)."""
        if not self.active:
            return
        if self.progress_t is None:
            self.progress_t = t_last       # baseline: the stream starts here
        target = t_last - self.max_lead_s
        if self.progress_t >= target:
            return
        t0 = time.monotonic()
        while self.node.context.ok() and self.progress_t < target:
            try:
                self.executor.spin_once(timeout_sec=0.01)
            except Exception:   # the context went down (Ctrl-C, SIGTERM) during the wait
                return
            last = t0 if self.progress_wall is None else max(self.progress_wall, t0)
            if time.monotonic() - last > self.timeout_s:
                self.node.get_logger().warning(
                    f"no drive/progress from a windowing node for {self.timeout_s:g} s (read up to t = "
                    f"{self.progress_t:.4f} s, streamed to t = {t_last:.4f} s): back-pressure off, pacing by "
                    "fast_sleep_s only")
                self.active = False
                break
        self.waited_s += time.monotonic() - t0

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_subscription(self.sub)


def spin(node, period_s: float = 0.25) -> None:
    """Spin until the context is shut down (Ctrl-C, SIGTERM, rclpy.shutdown).

    Instead of ``rclpy.spin``: a plain wait could, rarely (seen about once in ten SIGTERMs with
    traffic), miss the wake-up of rclpy's signal handling and never return; waking every
    ``period_s`` to look at the context makes the shutdown certain.  A shutdown that races the wait
    ends the loop like any other."""
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok():
            try:
                executor.spin_once(timeout_sec=period_s)
            except Exception:
                # SIGINT/SIGTERM may shut the context down between the check above and the wait
                # inside spin_once (RCLError "the given context is not valid", seen once in CI):
                # that is a clean stop, anything else is not
                if node.context.ok():
                    raise
                break
    finally:
        executor.shutdown(timeout_sec=1.0)


def main(factory: Callable[[], Any], prog: str, args=None) -> int:
    """Run a node: init, build (``factory``), spin (or its ``run()``), close; returns the exit status.

    * ParameterError -> its one line on stderr, status 2;
    * Ctrl-C / SIGTERM -> clean shutdown, status 0 (``node.close()`` runs in every case);
    * the node may set ``exit_code``.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    args = sys.argv if args is None else args
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = factory()
        if hasattr(node, "run"):
            node.run()
        else:
            spin(node)
        code = int(getattr(node, "exit_code", 0) or 0)
    except ParameterError as exc:
        print(f"{prog}: {exc}", file=sys.stderr, flush=True)
        code = EXIT_BAD_PARAMETER
    except (KeyboardInterrupt, ExternalShutdownException):
        code = int(getattr(node, "exit_code", 0) or 0) if node is not None else 0
    finally:
        if node is not None:
            try:
                if hasattr(node, "close"):
                    node.close()
            finally:
                node.destroy_node()
        rclpy.try_shutdown()
    return code
