"""Close a bag writer or recorder on SIGINT/SIGTERM, then stop the process as without it.  No ROS."""
from __future__ import annotations

import os
import signal
import threading
from typing import Any, Iterable

__all__ = ["install_signal_handlers"]


def _chain_signal(signum: int | None, previous: Any) -> None:
    """After closing on a signal, stop the process: call the previous Python handler (SIGINT:
    KeyboardInterrupt), else raise KeyboardInterrupt for SIGINT and die of any other signal.

    A signal that was *ignored* before our handler was installed stops the process too.  A background
    job of a non-interactive shell (``cmd &``, nohup, many CI runners) inherits SIGINT ignored, so
    Python installs no KeyboardInterrupt handler; returning here would leave a process that runs on
    with a closed writer, dropping every later message (the child of the SIGINT tests then spun at
    full CPU until killed)."""
    if signum is None:
        return
    if callable(previous):
        previous(signum, None)
    elif signum == signal.SIGINT:  # SIG_IGN, SIG_DFL or a handler installed outside Python
        raise KeyboardInterrupt
    else:  # die of the signal
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)


def install_signal_handlers(writer, signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> dict:
    """Close ``writer`` (a BagWriter or a Recorder) on SIGINT/SIGTERM, then stop as without the
    recorder (the previous Python handler; KeyboardInterrupt for SIGINT, death by the signal for
    SIGTERM) -- also when the signal was ignored before (SIGINT of a background job): a caught signal
    always ends the recording *and* the process, never one without the other.

    For processes that do not run rclpy.  Must be called from the main thread.  Returns the previous
    handlers (for ``signal.signal`` to restore)."""
    previous: dict[int, Any] = {}
    bag = getattr(writer, "bag_writer", writer)

    def handler(signum, frame):
        prev = previous.get(signum)
        target = getattr(writer, "bag_writer", bag)
        if target is not None and target._busy == threading.get_ident():
            target._pending_signal = (signum, prev)
            return
        writer.close()
        _chain_signal(signum, prev)

    for s in signals:
        previous[s] = signal.signal(s, handler)
    return previous
