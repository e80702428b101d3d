"""The file a bag writer's chunks go to: one ``os.write`` per finished chunk, cut back to the last
complete chunk when a write fails, ``flock``-ed while open.  No ROS."""
from __future__ import annotations

import fcntl
import os
from pathlib import Path

__all__ = ["ChunkFile"]


class ChunkFile:
    """The mcap Writer's output stream: what the Writer writes is collected and handed to the OS by
    :meth:`commit` in one ``os.write`` (a finished chunk and its message indexes together).  On a failed
    write the file is cut back to the end of the last commit, so it always ends on a complete record.
    The open file is ``flock``-ed: retention (jident_ros.bag.rotating_recorder) never deletes a bag in use."""

    def __init__(self, path: Path):
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        self._buf = bytearray()
        self.committed = 0

    def write(self, data) -> int:
        self._buf += data
        return len(data)

    def tell(self) -> int:
        return self.committed + len(self._buf)

    def flush(self) -> None:
        pass  # commit() is the flush

    @property
    def pending(self) -> int:
        return len(self._buf)

    def commit(self) -> int:
        """Write what is pending in one ``os.write`` (repeated only if the OS takes part of it); on an
        OSError cut the file back to the last commit and re-raise.  Returns the bytes written."""
        if not self._buf:
            return 0
        view = memoryview(self._buf)
        try:
            done = 0
            while done < len(view):
                done += os.write(self._fd, view[done:])
        except OSError:
            view.release()
            self.discard()
            raise
        view.release()
        self.committed += done
        self._buf = bytearray()  # a fresh buffer: a huge chunk's memory goes back at once
        return done

    def discard(self) -> None:
        """Forget what is pending and cut the file back to the last commit."""
        self._buf = bytearray()
        try:
            os.ftruncate(self._fd, self.committed)
            os.lseek(self._fd, self.committed, os.SEEK_SET)
        except OSError:
            pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)  # also releases the flock

