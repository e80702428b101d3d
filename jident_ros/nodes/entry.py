"""The node executables' entry points (setup.py console_scripts; what ``ros2 run jident_ros <node>`` starts).

Importing a node takes seconds (rclpy, numpy, scipy, the method).  ``ros2 launch`` stops every node with SIGINT
as soon as one exits -- also while the others are still importing.  Python's default SIGINT handler then
printed a KeyboardInterrupt traceback.  Here, SIGINT or SIGTERM before the node's own handlers are installed
(:class:`jident_ros.nodes.runtime.StopFlag`, at the start of its ``main``) ends the process quietly with status 0:
nothing had started, so there is nothing to finish.  Only the standard library is imported before the handlers.
"""
import signal
from importlib import import_module


def _stop_before_start(signum, frame):
    raise SystemExit(0)


def _run(name: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop_before_start)
    return import_module(f"jident_ros.nodes.{name}").main()


def simulator() -> int:
    return _run("simulator")


def windowing() -> int:
    return _run("windowing")


def diagnostic() -> int:
    return _run("diagnostic")


def replay() -> int:
    return _run("replay")
