"""Running a node: init, build, spin, stop — the shutdown path — and the back-pressure gate of the
streaming nodes.

The shutdown path (issue 15, item 1).  rclpy's own signal handling shuts the ROS context down from the
signal handler, while the executor may still be waiting on it: under load that race crashed a recording
node (SIGSEGV in ``rcl_trigger_guard_condition``) before the recording was finalised.  Here rclpy is
initialised with ``SignalHandlerOptions.NO``; SIGINT and SIGTERM only set a flag (:class:`StopFlag`), the
spin loop wakes at least every ``SPIN_PERIOD_S`` and sees it, and then, in this order and in the main
thread: ``node.close()`` (finalises the recording), ``node.destroy_node()``, the executor's and the
context's shutdown.  Whatever signal arrives and whenever (during start-up, the library build, a
window's diagnosis or the teardown itself), nothing is torn down under a running callback.
"""
from __future__ import annotations

import math
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import yaml

from jident_ros.nodes.entry import StopFlag, leaves_at_once, take_early_flag
from jident_ros.nodes.params import EXIT_BAD_PARAMETER, ParameterError
from jident_ros.nodes.ros_io import qos_signals

#: The spin loop looks at the stop flag at least this often, s.
SPIN_PERIOD_S = 0.1


#: The diagnostic node's echo of drive/progress, sent once the windows before it have been diagnosed.
DIAGNOSED_PROGRESS_TOPIC = "drive/diagnosed_progress"


class ProgressGate:
    """Back-pressure for a node that streams ``drive/signals`` as fast as it can (simulator and replay
    at rate 0): a batch ending at drive time t may go out only when the windowing node has reported,
    on ``drive/progress``, that it has read up to t - ``max_lead_s`` -- and, once a diagnostic node has been
    heard on ``drive/diagnosed_progress``, when it too has diagnosed every window up to there (the slower of
    the two sets the pace: at rate 0 the windows otherwise piled up in the diagnostic node's queue and the
    oldest were dropped, 31 of 140 in bench_ros at 3d6fb4b).

    Non-blocking: the streaming timer asks :meth:`allows` and publishes nothing on that tick when the
    answer is no (the node keeps spinning: progress messages and parameter requests are served).  The
    first batch's time is the baseline (nothing read yet).  With no progress for ``timeout_s`` while waiting
    (no windowing node, one without progress, or a downstream node that stalls), the gate opens and says so in
    the log: the stream never stalls for ever.  It closes again at the next progress (a stall of a second or
    two in the diagnostic node must not leave the rest of the stream unpaced: at 3d6fb4b, opened for good, it
    lost 14 of 140 windows after one 2 s stall); ``openings`` counts the timeouts.
    """

    def __init__(self, node, max_lead_s: float, timeout_s: float):
        from std_msgs.msg import Float64

        self.node, self.max_lead_s, self.timeout_s = node, float(max_lead_s), float(timeout_s)
        self.progress_t = None          # drive time read by the windowing node
        self.progress_wall = None       # monotonic time of the last progress message
        self.waited_s = 0.0
        self.active = True
        self.openings = 0               # timeouts that opened the gate (until the next progress)
        self._wait_start = None         # monotonic start of the current wait
        self.read_t = None              # drive time read by the windowing node (drive/progress)
        self.diagnosed_t = None         # ... and diagnosed (drive/diagnosed_progress), once heard
        self.sub = node.create_subscription(Float64, "drive/progress", self._on_progress, qos_signals(10))
        self.sub_diagnosed = node.create_subscription(Float64, DIAGNOSED_PROGRESS_TOPIC, self._on_diagnosed,
                                                      qos_signals(10))

    def _on_progress(self, msg):
        t = float(msg.data)
        if math.isfinite(t) and (self.read_t is None or t > self.read_t):
            self.read_t = t
            self._advance()

    def _on_diagnosed(self, msg):
        t = float(msg.data)
        if math.isfinite(t) and (self.diagnosed_t is None or t > self.diagnosed_t):
            self.diagnosed_t = t
            self._advance()

    def _advance(self) -> None:
        """progress_t: what the slower downstream node has done (the windowing node alone until a diagnostic
        node is heard); progress_wall moves only when progress_t does (the timeout watches the pace)."""
        known = [t for t in (self.read_t, self.diagnosed_t) if t is not None]
        t = min(known)
        if self.progress_t is None or t > self.progress_t:
            self.progress_t = t
            self.progress_wall = time.monotonic()
            if not self.active:
                self.active = True
                self.node.get_logger().info(f"progress again (done up to t = {t:.4f} s): back-pressure on")

    def allows(self, t_last: float) -> bool:
        """True when a batch ending at ``t_last`` may go out now (or the gate has opened for good)."""
        if not self.active:
            return True
        if self.progress_t is None:
            self.progress_t = t_last       # baseline: the stream starts here
        if self.progress_t >= t_last - self.max_lead_s:
            self._end_wait()
            return True
        now = time.monotonic()
        if self._wait_start is None:
            self._wait_start = now
        last = self._wait_start if self.progress_wall is None else max(self.progress_wall, self._wait_start)
        if now - last > self.timeout_s:
            self.node.get_logger().warning(
                f"no progress from the windowing{'' if self.diagnosed_t is None else ' or the diagnostic'} node "
                f"for {self.timeout_s:g} s (done up to t = {self.progress_t:.4f} s, streamed to t = {t_last:.4f} s):"
                " back-pressure off until the next progress, pacing by fast_sleep_s only")
            self.active = False
            self.openings += 1
            self._end_wait()
            return True
        return False

    def _end_wait(self):
        if self._wait_start is not None:
            self.waited_s += time.monotonic() - self._wait_start
            self._wait_start = None

    def close(self) -> None:
        self._end_wait()
        for sub in (self.sub, getattr(self, "sub_diagnosed", None)):
            if sub is not None:
                self.node.destroy_subscription(sub)
        self.sub = self.sub_diagnosed = None


# --------------------------------------------------------------------------- params files

_RCL_LOCATION = re.compile(r",? at /[^,]*\.c:\d+")


class _ParamsFileLoader(yaml.SafeLoader):
    """YAML as rcl's params-file parser reads it: a node's tag does not change what it holds.  launch_ros
    writes the list parameters of a launch file as ``!!python/tuple`` sequences (it dumps tuples with
    ``yaml.dump``) and rcl reads them as arrays; ``yaml.safe_load`` refused them.  Any tag other than
    YAML's own is read by the node's kind (sequence -> list, mapping -> dict, scalar -> its text); nothing
    is ever constructed from a tag."""


def _untagged(loader: yaml.SafeLoader, tag_suffix: str, node: yaml.Node):
    if isinstance(node, yaml.SequenceNode):
        return loader.construct_sequence(node, deep=True)
    if isinstance(node, yaml.MappingNode):
        return loader.construct_mapping(node, deep=True)
    return loader.construct_scalar(node)


_ParamsFileLoader.add_multi_constructor("tag:yaml.org,2002:python/", _untagged)
_ParamsFileLoader.add_multi_constructor("!", _untagged)


def load_params_file(text: str):
    """A params file's YAML as rcl accepts it (``!!python/tuple`` lists included); yaml.YAMLError if not YAML."""
    return yaml.load(text, Loader=_ParamsFileLoader)  # noqa: S506 - a SafeLoader subclass


def check_params_files(args) -> None:
    """ParameterError (one line naming the file and the problem) for a ``--params-file`` that rcl
    would refuse with a multi-line error before any of our code runs: missing, unreadable, not YAML,
    or not the ROS 2 params-file layout (``<node name>: {ros__parameters: {...}}``)."""
    args = list(args or [])
    files = [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--params-file"]
    for f in files:
        path = Path(f)
        try:
            doc = load_params_file(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ParameterError(f"--params-file {f}: cannot read it ({exc.strerror or exc})") from None
        except yaml.YAMLError as exc:
            where = getattr(exc, "problem_mark", None)
            at = f" at line {where.line + 1}" if where is not None else ""
            raise ParameterError(f"--params-file {f}: not YAML{at} ({getattr(exc, 'problem', None) or exc})") \
                from None
        if not isinstance(doc, dict) or not doc:
            raise ParameterError(f"--params-file {f}: not a ROS 2 params file (expected "
                                 "'<node name>: {ros__parameters: {...}}', got "
                                 f"{type(doc).__name__ if doc is not None else 'an empty file'})")
        for key, section in doc.items():
            if not isinstance(section, dict) or "ros__parameters" not in section:
                raise ParameterError(f"--params-file {f}: not a ROS 2 params file (section {key!r} has no "
                                     "ros__parameters)")


def rcl_error_line(exc: Exception) -> str:
    """Rcl's error text on one line, without the C source locations."""
    text = " ".join(str(exc).split())
    return _RCL_LOCATION.sub("", text)


# --------------------------------------------------------------------------- timer-driven nodes


def tick(state: str, handlers: Mapping[str, Callable[[], None]], fail: Callable[[Exception], None]) -> None:
    """One timer tick of a streaming node's state machine (simulator, replay): the handler of ``state``
    (none, e.g. in ``done``: nothing to do); any exception goes to ``fail`` (one line, an exit status,
    the end of the stream): never a traceback from a timer."""
    handler = handlers.get(state)
    if handler is None:
        return
    try:
        handler()
    except Exception as exc:
        fail(exc)


# --------------------------------------------------------------------------- main


class RunnableNode:
    """What :func:`main` and :func:`spin` call on a node, declared (a node class lists it first among its bases,
    e.g. ``class WindowingNode(RunnableNode, Node)``); the defaults do nothing.

    done : the node has ended by itself: the spin stops (simulator, replay at the end of their stream)
    exit_code : the exit status of the process after the spin
    spin_in_periods : spin ``SPIN_PERIOD_S`` at a time instead of one callback at a time (many small messages)
    """

    done: bool = False
    exit_code: int = 0
    spin_in_periods: bool = False

    def make_executor(self):
        """The executor to spin the node with: rclpy's EventsExecutor where there is one (spun a period at a
        time), else None: a SingleThreadedExecutor.  SingleThreadedExecutor rebuilds its wait set in Python for
        every callback: 4-5x the CPU of the callbacks themselves in each node at one batch of 50 samples per
        message (bench/bench_ros.py --profile, issue 25)."""
        return events_executor(self)

    def autostart(self) -> None:
        """Called once after the node is built and added to the executor (a lifecycle node configures and
        activates itself here)."""

    def finish(self, stopping: Callable[[], bool]) -> None:
        """Called after the spin when the node ended by itself (``done``), not after a signal; ``stopping()``
        becomes true when a signal arrives meanwhile (e.g. while waiting for the last batches' acknowledgement)."""

    def close(self) -> None:
        """Called first on the way down (always, also after a signal): finalise what must be (the recording);
        idempotent."""


def events_executor(node):
    """rclpy.experimental.EventsExecutor on the node's context, with ``node.spin_in_periods`` set (a period's
    callbacks per spin call); None when this rclpy has none (before Jazzy)."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return None
    node.spin_in_periods = True
    return EventsExecutor(context=node.context)


def spin(node, executor, stop: StopFlag, period_s: float = SPIN_PERIOD_S) -> None:
    """Spin until a signal arrives, the node is ``done`` or the context is shut down.  A node whose
    ``spin_in_periods`` is true is spun ``period_s`` at a time (every ready callback in that time, then the
    checks) instead of one callback at a time: for many small messages (the windowing node on JointState)."""
    pending = executor.create_future() if node.spin_in_periods else None
    while not stop.set and not node.done and node.context.ok():
        if pending is not None:
            executor.spin_until_future_complete(pending, timeout_sec=period_s)   # never completes: a period
        else:
            executor.spin_once(timeout_sec=period_s)


#: How long a node that ends by itself (simulator, replay) waits for its reliable readers to acknowledge the last
#: messages, s: 5 s per publisher lost a test's last 9 of 98 drive/signals batches on a machine running two test
#: suites at once (test_pipeline_recording_holds_every_message), silently.
DRAIN_TIMEOUT_S = 20.0


def drain(publishers, logger, stopping: Callable[[], bool] = lambda: False, timeout_s: float = DRAIN_TIMEOUT_S) -> list:
    """Wait until every reliable reader of ``publishers`` acknowledged what they sent, at most ``timeout_s`` in all
    (in 0.5 s slices: a stop ends the wait); a publisher still waiting then is named in one WARN (its topic, its
    readers): what a slow reader may not have received.  Returns those topics."""
    from rclpy.duration import Duration
    end = time.monotonic() + float(timeout_s)
    late = []
    for pub in publishers:
        try:
            while not pub.wait_for_all_acked(Duration(seconds=min(0.5, max(end - time.monotonic(), 0.0)))):
                if stopping() or time.monotonic() >= end:
                    late.append(pub)
                    break
        except Exception:  # not supported by every rmw: a pause instead
            time.sleep(0.5)
    if late:
        waited = float(timeout_s) - max(end - time.monotonic(), 0.0)
        logger.warning("not acknowledged after %.1f s: %s: a reader may not have received the last messages"
                       % (waited, ", ".join(f"{p.topic_name} ({p.get_subscription_count()} reader(s))" for p in late)))
    return [p.topic_name for p in late]


def _half_built_node(exc: BaseException):
    """The node whose constructor raised ``exc`` (``self`` of a frame of its traceback), or None.  It is destroyed
    before rcl shuts down: a node left to the garbage collector after rclpy.shutdown can hang the interpreter's exit
    (ros2/launch#124, ros2/rclpy#456); a simulator refusing ``batch_size:=fifty`` hung for 180 s once in ten runs of
    test_nodes' bad-parameter test on a loaded machine."""
    from rclpy.node import Node
    tb = exc.__traceback__
    while tb is not None:
        obj = tb.tb_frame.f_locals.get("self")
        if isinstance(obj, Node):
            return obj
        tb = tb.tb_next
    return None


def _refused(prog: str, line: str, built: bool = False) -> int:
    """A start refused for its parameters: its one line on stderr, then EXIT_BAD_PARAMETER.  A node that was never built
    and runs in its own process (started by its entry point, :func:`jident_ros.nodes.entry.leaves_at_once`) leaves at
    once, before any teardown: the half-built node's destruction and rcl's shutdown are where a clean clone's test run
    saw a node that had printed its line die by SIGSEGV (status -11; stop 33 the replay node, stop 34 the simulator,
    10 nodes refusing at once on the loaded 2-core machine); nothing was built to finalise, the process's exit frees
    what rcl holds.  In a caller's process (the tests) the teardown runs, the half-built node destroyed before rcl's
    shutdown (test_runtime_half_built)."""
    print(f"{prog}: {line}", file=sys.stderr, flush=True)
    if not built and leaves_at_once():
        sys.stdout.flush()
        os._exit(EXIT_BAD_PARAMETER)
    return EXIT_BAD_PARAMETER


def main(factory: Callable[..., Any], prog: str, args=None) -> int:
    """Run a node: init, build (``factory(args)``), spin, stop; returns the exit status.

    * a bad ``--params-file``, a bad argument of rcl, or a ParameterError -> one line on stderr, status 2;
    * SIGINT / SIGTERM at any moment -> the shutdown path of the module docstring, status 0;
    * the node (a :class:`RunnableNode`) may set ``done`` (the spin ends) and ``exit_code``; ``finish()`` runs
      after the spin when the node ended by itself (e.g. waiting for the last batches to be acknowledged).
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    args = sys.argv if args is None else args
    early = take_early_flag()          # installed by the entry point before the heavy imports (nodes/entry.py)
    stop = early or StopFlag().install()
    node = executor = half = None
    code = 0
    try:
        if stop.set:                   # stopped before rcl started: nothing to finalise
            return 0
        try:
            check_params_files(args)
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except ParameterError as exc:
            return _refused(prog, str(exc))
        except Exception as exc:  # RCLError: rcl refused the arguments before our code ran
            return _refused(prog, rcl_error_line(exc))
        try:
            node = factory(args)
            # a node may bring its own executor (the windowing node on JointState: one callback per sample)
            executor = node.make_executor() or SingleThreadedExecutor()
            executor.add_node(node)
            node.autostart()
            spin(node, executor, stop)
            if not stop.set:
                node.finish(lambda: stop.set)
            code = int(node.exit_code or 0)
        except ParameterError as exc:
            code = _refused(prog, str(exc), built=node is not None)
            half = None if node is not None else _half_built_node(exc)
        except Exception as exc:
            if node is None and type(exc).__module__.startswith("rclpy"):  # e.g. a bad remapping
                code = _refused(prog, rcl_error_line(exc), built=False)
                half = _half_built_node(exc)
            else:
                raise
    finally:
        try:
            if node is not None:
                node.close()                # the recording is finalised here, the context still up
        finally:
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            if node is not None:
                node.destroy_node()
            elif half is not None:
                try:
                    half.destroy_node()
                except Exception as exc:  # half-built: what it holds may be incomplete; rcl shuts down anyway
                    print(f"{prog}: destroying the node that refused its parameters: {exc}", file=sys.stderr,
                          flush=True)
            rclpy.try_shutdown()
            if early is None:
                stop.restore()         # the entry point keeps its handlers until the interpreter exits
    return code
