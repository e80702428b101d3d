"""The node executables' entry points (setup.py console_scripts ``simulator``, ``windowing``, ``diagnostic``,
``replay``): the SIGINT/SIGTERM handlers go in before any heavy import.

Importing a node module takes about a second (rclpy, numpy, scipy, the message packages); with the handlers
installed only in :func:`jident_ros.nodes.runtime.main`, a Ctrl-C in that second ended the process with a
KeyboardInterrupt traceback and status -2 (issue 24; ``ros2 launch`` sends SIGINT to every node as soon as one
exits, also to those still importing: issue 22).  Here this light module (standard library only)
installs a :class:`StopFlag` first, then imports the node module, and :func:`jident_ros.nodes.runtime.main`
takes that flag over (:func:`take_early_flag`): a signal at any moment of a node's life -- the imports, rcl's
start, the node's construction, the spin, the teardown -- ends it by the one shutdown path, status 0, no
traceback.  After the node's main returns, both signals are ignored while the interpreter exits.
"""
from __future__ import annotations

import importlib
import os
import signal
import sys
from typing import Optional

__all__ = ["StopFlag", "diagnostic", "replay", "simulator", "take_early_flag", "windowing"]


class StopFlag:
    """SIGINT/SIGTERM handlers that only record the signal (the spin loop acts on it)."""

    def __init__(self):
        self.signum = None
        self._previous = {}

    def install(self) -> "StopFlag":
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handler)
        return self

    def _handler(self, signum, frame):
        if self.signum is None:
            self.signum = signum

    @property
    def set(self) -> bool:
        return self.signum is not None

    def restore(self) -> None:
        for sig, prev in self._previous.items():
            signal.signal(sig, prev)
        self._previous.clear()


_early: Optional[StopFlag] = None
#: True while a node started by an entry point below runs (:func:`leaves_at_once`)
_from_entry = False

#: jident_ros.nodes.params.EXIT_BAD_PARAMETER (not imported: this module stays light, standard library only)
EXIT_BAD_PARAMETER = 2


def leaves_at_once() -> bool:
    """Whether a start refused for its parameters leaves the process at once (jident_ros.nodes.runtime): only a node
    started by an entry point below (its own process), never one run in a caller's process (the tests)."""
    return _from_entry


def take_early_flag() -> Optional[StopFlag]:
    """The flag an entry point installed before the imports (once; None when the node was not started by one)."""
    global _early
    flag, _early = _early, None
    return flag


def _run(module: str, prog: str) -> int:
    global _early, _from_entry
    _early = flag = StopFlag().install()
    _from_entry = True
    try:
        try:
            mod = importlib.import_module(module)
        except Exception as exc:   # e.g. rclpy missing: one line, not a traceback
            print(f"{prog}: cannot start: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
            return 1
        if flag.set:               # stopped while importing: nothing started, nothing to finalise
            return 0
        code = int(mod.main() or 0)
        if code == EXIT_BAD_PARAMETER:
            # the node refused its parameters: nothing was built, nothing recorded, rcl already shut down (main's
            # finally).  Leave without the interpreter's finalisation, where rclpy's and the message packages' C
            # objects are torn down in no set order: a clean clone's test run (stop 33, 10 nodes refusing at once on
            # the loaded 2-core machine) saw the replay node print its one line and then die by SIGSEGV (status -11)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        return code
    finally:
        _early, _from_entry = None, False
        for sig in (signal.SIGINT, signal.SIGTERM):   # the interpreter exits: a late signal changes nothing
            signal.signal(sig, signal.SIG_IGN)


def simulator() -> int:
    return _run("jident_ros.nodes.simulator", "simulator")


def windowing() -> int:
    return _run("jident_ros.nodes.windowing", "windowing")


def diagnostic() -> int:
    return _run("jident_ros.nodes.diagnostic", "diagnostic")


def replay() -> int:
    return _run("jident_ros.nodes.replay", "replay")


if __name__ == "__main__":   # python -m jident_ros.nodes.entry <node> [args]: a checkout without install
    if len(sys.argv) < 2 or sys.argv[1] not in ("simulator", "windowing", "diagnostic", "replay"):
        print("usage: python -m jident_ros.nodes.entry simulator|windowing|diagnostic|replay [args]", file=sys.stderr)
        raise SystemExit(2)
    _name = sys.argv.pop(1)
    raise SystemExit(_run(f"jident_ros.nodes.{_name}", _name))
