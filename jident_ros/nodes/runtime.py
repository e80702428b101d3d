"""Running a node: init, build, spin, close (Ctrl-C and SIGTERM end it cleanly), and the back-pressure
gate of the streaming nodes."""
from __future__ import annotations

import math
import sys
import time
from typing import Any, Callable

from jident_ros.nodes.params import EXIT_BAD_PARAMETER, ParameterError
from jident_ros.nodes.ros_io import qos_signals


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
