"""The diagnostic node's recorder: timestamped rosbag2 bags under a root, split by size and duration,
old bags deleted by a retention limit, every failure counted and reported.  No ROS; never imports rclpy.

    rec = Recorder("~/.local/share/jident_ros/bags", max_bag_duration_s=3600, retention_max_total_bytes=20e9)
    rec.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray", qos)
    rec.write("/drive/signals", "std_msgs/msg/Float64MultiArray", cdr_bytes)   # never raises
    rec.status()   # {"state": "recording", "bag": ..., "bytes_written": ..., "messages_dropped": ...}
    rec.close()    # idempotent; from a signal handler or atexit too

* **Where**: ``<root>/rosbag2_YYYY_MM_DD-HH_MM_SS/`` (local time at start, as ``ros2 bag record`` names
  its bags; ``_1``, ``_2`` ... appended when two recorders start in the same second), holding
  ``<name>_0.mcap``, ``<name>_1.mcap`` ... and ``metadata.yaml`` (:class:`~jident_ros.bag.writer.BagWriter`).
  The root: the argument, else ``$JIDENT_DATA_DIR/bags``, else ``$XDG_DATA_HOME/jident_ros/bags``, else
  ``~/.local/share/jident_ros/bags`` (:func:`default_record_root`).
* **Time stamps**: a message's log and publish time is the wall clock (``time.time_ns()``, system time)
  when :meth:`Recorder.write` is called -- never a ROS clock, so another drive's ``/clock`` cannot move
  it.  The drive's own time is in the data (the ``t`` column of ``drive/signals``).
* **Split**: the open file is finalised and ``<name>_<k+1>.mcap`` begun when it holds
  ``max_bag_size_bytes`` or is ``max_bag_duration_s`` old (0: no limit), as ``ros2 bag record
  --max-bag-size / --max-bag-duration`` do; metadata.yaml lists the finished files after each split.
* **Retention**: after each split and at start, the oldest of *this recorder's own* bags under the root are
  deleted while they together exceed ``retention_max_total_bytes`` or a bag's newest file is older than
  ``retention_max_age_s`` (0: no limit).  Ours = named in the root's manifest ``.jident_ros_bags`` (a line
  appended, under an ``flock``, when a recorder claims a bag directory) **and** marked in its metadata.yaml
  (``custom_data: recorded_by: jident_ros.bag.rotating_recorder``).  The root is never scanned: a directory that
  is not in the manifest (a user's own bag, another tool's) is never looked at, never counted, never
  deleted.  Never deleted either: the open bag, a bag another recorder is writing (the writer keeps an
  ``flock`` on its open file), and a bag that was not finalised (a crash or kill cut it: a file without
  its summary, or no metadata.yaml) -- salvage it first (``jident salvage``), or opt in with
  ``retention_delete_unfinalised``.  With ``bag_dir`` (the node's deprecated ``record_dir``) there is no
  root of ours: retention is off (said once in the log), the parent folder is never swept.
* **Failures**: an unusable root or bag directory raises :class:`RecorderError` with the reason (the node
  turns it into an ERROR status).  A failed write (disk full) finalises what was written, and from then on
  every message is counted as dropped with the reason; :meth:`status` reports it.
"""
from __future__ import annotations

import atexit
import fcntl
import os
import shutil
import threading
import time
import weakref
from pathlib import Path
from typing import Any, Callable, Mapping

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.metadata_yaml import read_metadata
from jident_ros.bag.reader import is_finalised
from jident_ros.bag.writer import DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_AGE_S, BagWriter

__all__ = ["MANIFEST", "RECORDED_BY", "Recorder", "RecorderError", "bag_name", "default_record_root", "our_bags"]

#: The root's manifest: the names of the bag directories the recorders claimed under it, one a line.
MANIFEST = ".jident_ros_bags"
#: The marker in each bag's metadata.yaml (``custom_data``): retention deletes only bags that carry it.
RECORDED_BY = ("recorded_by", "jident_ros.bag.rotating_recorder")


class RecorderError(RecordingError):
    """The recorder cannot record (unusable root or bag directory); the message says why."""


def default_record_root() -> Path:
    """``$JIDENT_DATA_DIR/bags``, else ``$XDG_DATA_HOME/jident_ros/bags``, else ``~/.local/share/jident_ros/bags``."""
    if os.environ.get("JIDENT_DATA_DIR"):
        return Path(os.environ["JIDENT_DATA_DIR"]).expanduser() / "bags"
    base = os.environ.get("XDG_DATA_HOME") or "~/.local/share"
    return Path(base).expanduser() / "jident_ros" / "bags"


def bag_name(t: float | None = None) -> str:
    """rosbag2's default bag name for local time ``t`` (default now): ``rosbag2_YYYY_MM_DD-HH_MM_SS``."""
    return time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S", time.localtime(time.time() if t is None else t))


def _usable_dir(path: Path, what: str) -> None:
    """Create ``path`` (and parents) or raise RecorderError saying why it cannot hold recordings."""
    if path.exists() and not path.is_dir():
        raise RecorderError(f"{what} {path}: is a file, not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RecorderError(f"{what} {path}: cannot create it ({exc.strerror or exc})") from None
    probe = path / f".jident_write_test_{os.getpid()}_{threading.get_ident()}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise RecorderError(f"{what} {path}: not writable ({exc.strerror or exc})") from None


def _bag_in_use(bag: Path) -> bool:
    """True when a process holds an .mcap file of ``bag`` open for writing (its flock)."""
    for p in bag.glob("*.mcap"):
        try:
            fd = os.open(p, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            return True
        finally:
            os.close(fd)
    return False


def _bag_size(bag: Path) -> int:
    total = 0
    for p in bag.iterdir():
        try:
            total += p.stat().st_size
        except OSError:
            pass
    return total


def _newest_mtime(bag: Path) -> float:
    times = []
    for p in [bag, *bag.iterdir()]:
        try:
            times.append(p.stat().st_mtime)
        except OSError:
            pass
    return max(times, default=0.0)


def _manifest_names(root: Path) -> list[str]:
    """The bag names in ``root``'s manifest (none when there is none); only plain names of subdirectories."""
    try:
        text = (root / MANIFEST).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    out = []
    for line in text.splitlines():
        name = line.strip()
        if name and name not in out and "/" not in name and name not in (".", "..") and not name.startswith("."):
            out.append(name)
    return out


def _edit_manifest(root: Path, add: str | None = None, remove: set | None = None) -> None:
    """Append ``add`` to / drop ``remove`` from the manifest, under an exclusive flock (two recorders on
    one root).  Raises OSError."""
    fd = os.open(root / MANIFEST, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        if add is not None:
            os.lseek(fd, 0, os.SEEK_END)
            os.write(fd, (add + "\n").encode())
        if remove:
            keep = [n for n in _manifest_names(root) if n not in remove]
            data = "".join(n + "\n" for n in keep).encode()
            os.lseek(fd, 0, os.SEEK_SET)
            os.ftruncate(fd, 0)
            os.write(fd, data)
    finally:
        os.close(fd)


def _bag_state(bag: Path) -> str:
    """``ours`` (metadata.yaml marked by a recorder, every .mcap file finalised), ``unfinalised`` (no
    metadata.yaml, a file named in it missing, or a file without its summary: a crash or kill cut it),
    ``foreign`` (metadata.yaml without our marker)."""
    try:
        meta = read_metadata(bag)
    except (RecordingError, OSError, ValueError):
        return "unfinalised" if (not (bag / "metadata.yaml").exists()) else "foreign"
    custom = meta.get("custom_data") if isinstance(meta, dict) else None
    if not isinstance(custom, dict) or custom.get(RECORDED_BY[0]) != RECORDED_BY[1]:
        return "foreign"
    listed = meta.get("relative_file_paths") or []
    files = sorted(set(bag.glob("*.mcap")) | {bag / str(p) for p in listed})
    for f in files:
        try:
            if not f.is_file() or not is_finalised(f):
                return "unfinalised"
        except (RecordingError, OSError):
            return "unfinalised"
    return "ours"


def our_bags(root: str | os.PathLike) -> list[Path]:
    """The bag directories under ``root`` that its manifest names and that exist (ours, in any state)."""
    root = Path(root)
    return [root / n for n in _manifest_names(root) if (root / n).is_dir() and not (root / n).is_symlink()]


class Recorder:
    """Records topics into timestamped, split, retention-limited bags under ``root`` (module docstring).

    Parameters
    ----------
    root : directory of the bags ("" or None: :func:`default_record_root`)
    bag_dir : record into exactly this bag directory instead (must not exist or be empty; the node's
        deprecated ``record_dir``); retention is then off (its parent is never swept)
    max_bag_size_bytes, max_bag_duration_s : split limits of one .mcap file (0: none)
    retention_max_total_bytes, retention_max_age_s : retention limits over this recorder's bags under the
        root (0: none)
    retention_delete_unfinalised : let retention delete our bags that were not finalised (default: kept
        for ``jident salvage``)
    chunk_size, flush_age_s, compression : of the :class:`~jident_ros.bag.writer.BagWriter`
    custom_data : str -> str for metadata.yaml (e.g. the node's namespace; the marker ``recorded_by`` is added)
    clock : ns since the epoch for a message's time stamp when :meth:`write` gets none (default: wall clock)
    log : gets one line for each split, retention deletion and failure

    Raises :class:`RecorderError` (the reason in one line) when the root or bag directory is unusable.
    """

    def __init__(self, root: str | os.PathLike | None = None, *, bag_dir: str | os.PathLike | None = None,
                 max_bag_size_bytes: int = 0, max_bag_duration_s: float = 0.0,
                 retention_max_total_bytes: int = 0, retention_max_age_s: float = 0.0,
                 retention_delete_unfinalised: bool = False,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, flush_age_s: float | None = DEFAULT_FLUSH_AGE_S,
                 compression: str | None = "zstd", custom_data: Mapping[str, str] | None = None,
                 clock: Callable[[], int] = time.time_ns, log: Callable[[str], Any] = lambda text: None):
        for name, value in (("max_bag_size_bytes", max_bag_size_bytes), ("max_bag_duration_s", max_bag_duration_s),
                            ("retention_max_total_bytes", retention_max_total_bytes),
                            ("retention_max_age_s", retention_max_age_s)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
                raise ValueError(f"{name}: expected a number >= 0 (0 = no limit), got {value!r}")
        self.max_bag_size_bytes = int(max_bag_size_bytes)
        self.max_bag_duration_s = float(max_bag_duration_s)
        self.retention_max_total_bytes = int(retention_max_total_bytes)
        self.retention_max_age_s = float(retention_max_age_s)
        self.retention_delete_unfinalised = bool(retention_delete_unfinalised)
        self.retention_on = True
        self.bags_kept_unfinalised = 0
        self._kept_logged: set = set()
        self._clock, self._log = clock, log
        self._lock = threading.RLock()
        self._topics: dict[str, tuple] = {}
        self.messages_written = 0
        self.messages_dropped = 0
        self.drop_reasons: dict[str, int] = {}
        self.bags_deleted = 0
        self.bytes_deleted = 0
        self.splits = 0
        self.last_error: str | None = None
        self._closed = False
        if bag_dir:
            self.bag_dir = Path(bag_dir).expanduser()
            self.root = self.bag_dir.parent
            _usable_dir(self.root, "record root")
            if self.bag_dir.exists() and (not self.bag_dir.is_dir() or any(self.bag_dir.iterdir())):
                kind = "a file" if not self.bag_dir.is_dir() else "a non-empty directory"
                raise RecorderError(f"bag directory {self.bag_dir}: is {kind} (give a new or empty one)")
            self.retention_on = False   # one bag where the user put it: its parent is not ours to sweep
            if self.retention_max_total_bytes or self.retention_max_age_s:
                log(f"retention off: recording into the given bag directory {self.bag_dir}; retention applies "
                    "only to the bags a recorder made under record_root, never to a parent folder")
        else:
            self.root = Path(root).expanduser() if root else default_record_root()
            _usable_dir(self.root, "record root")
            self.bag_dir = self._claim_bag_dir()
        try:
            marked = {**dict(custom_data or {}), RECORDED_BY[0]: RECORDED_BY[1]}
            self.bag_writer: BagWriter | None = BagWriter(self.bag_dir, chunk_size=chunk_size,
                                                          flush_age_s=flush_age_s, compression=compression,
                                                          custom_data=marked)
        except (OSError, ValueError) as exc:
            raise RecorderError(f"bag directory {self.bag_dir}: cannot start recording "
                                f"({getattr(exc, 'strerror', None) or exc})") from None
        ref = weakref.ref(self)
        self._atexit = lambda: (ref() is not None and ref().close())
        atexit.register(self._atexit)
        self.apply_retention()

    def _claim_bag_dir(self) -> Path:
        name = bag_name()
        for k in range(1000):
            candidate = self.root / (name if k == 0 else f"{name}_{k}")
            try:
                candidate.mkdir()  # atomic: two recorders never share a bag
            except FileExistsError:
                continue
            except OSError as exc:
                raise RecorderError(f"record root {self.root}: cannot create a bag directory "
                                    f"({exc.strerror or exc})") from None
            try:
                _edit_manifest(self.root, add=candidate.name)   # ours: the only bags retention may delete
            except OSError as exc:
                try:
                    candidate.rmdir()
                except OSError:
                    pass
                raise RecorderError(f"record root {self.root}: cannot write its manifest {MANIFEST} "
                                    f"({exc.strerror or exc})") from None
            return candidate
        raise RecorderError(f"record root {self.root}: 1000 bags named {name}* already")

    # ------------------------------------------------------------------ writing
    def add_topic(self, topic: str, msg_type: str, qos: Any = None) -> None:
        """Declare a topic with its offered QoS (optional: :meth:`write` adds unknown topics with the
        default QoS).  A bad type or QoS raises ValueError."""
        with self._lock:
            self._topics[topic] = (msg_type, qos)
            if self.bag_writer is not None and self.bag_writer.error is None and not self._closed:
                self.bag_writer.add_topic(topic, msg_type, qos)

    def write(self, topic: str, msg_type: str, message: Any, t_ns: int | None = None,
              publish_time_ns: int | None = None) -> bool:
        """Record one message (CDR bytes, an rclpy or rosbags message, or a dict of fields) stamped with
        ``t_ns`` (default: the wall clock now); ``publish_time_ns``: the publisher's send time (the DDS source
        timestamp, as rosbag2 records it; default ``t_ns``).  Never raises: a message that cannot be recorded is
        counted in :attr:`messages_dropped` under its reason.  Returns True when it was recorded."""
        t = self._clock() if t_ns is None else t_ns
        with self._lock:
            bag = self.bag_writer
            if bag is not None and bag.closed and bag.error is None:
                self._closed = True  # closed by a signal handler through the writer
            if bag is not None and bag.error is not None:   # also after close: a failure's drops keep its reason
                return self._drop(self._stopped_reason())
            if self._closed or bag is None:
                return self._drop("recorder closed" if self._closed else "recorder stopped")
            if bag.error is not None:
                return self._drop(self._stopped_reason())
            accepted = bag.message_count + bag.messages_lost
            try:
                if topic not in self._topics:
                    self.add_topic(topic, msg_type)
                self._maybe_split(bag)
                bag.write(topic, message, t, publish_time_ns)
            except (ValueError, TypeError) as exc:  # this message only
                self.last_error = f"{topic}: {exc}"
                return self._drop("unrecordable message")
            except (RecordingError, OSError) as exc:   # the bag: disk full, I/O error
                in_lost_chunk = bag.message_count + bag.messages_lost > accepted
                self._failed(bag, exc)
                return False if in_lost_chunk else self._drop(self._stopped_reason())
            self.messages_written += 1
            return True

    def _failed(self, bag: BagWriter, exc: BaseException) -> None:
        """The bag stopped (the writer finalised what it could): the messages of the chunk that never
        reached the disk are dropped (reason "lost in the unwritten chunk"); keep the reason."""
        key = "lost in the unwritten chunk"
        lost = bag.messages_lost - self.drop_reasons.get(key, 0)
        if lost > 0:
            self.drop_reasons[key] = bag.messages_lost
            self.messages_dropped += lost
            self.messages_written = bag.message_count
        self._fail(str(exc))

    def _stopped_reason(self) -> str:
        bag = self.bag_writer
        return "disk full" if bag is not None and bag.disk_full else "recording failed"

    def _drop(self, reason: str) -> bool:
        self.messages_dropped += 1
        self.drop_reasons[reason] = self.drop_reasons.get(reason, 0) + 1
        return False

    def _fail(self, text: str) -> None:
        if self.last_error != text:
            self.last_error = text
            self._log(f"recording stopped: {text}")

    def _maybe_split(self, bag: BagWriter) -> None:
        if bag.file_message_count == 0:
            return
        why = None
        if self.max_bag_size_bytes and bag.file_bytes >= self.max_bag_size_bytes:
            why = f"{bag.file_bytes} bytes >= max_bag_size_bytes {self.max_bag_size_bytes}"
        elif self.max_bag_duration_s and bag.file_age_s >= self.max_bag_duration_s:
            why = f"{bag.file_age_s:.1f} s >= max_bag_duration_s {self.max_bag_duration_s:g}"
        if why is None:
            return
        path = bag.split()
        self.splits += 1
        self._log(f"split ({why}): now writing {path}")
        self.apply_retention()

    def flush(self) -> None:
        """Hand the open chunk to the OS (errors are reported by :meth:`status`)."""
        self._guarded(lambda b: b.flush())

    def maybe_flush(self) -> None:
        """For a timer: flush the open chunk if it is older than ``flush_age_s``, and split on duration
        even while no message arrives."""
        def tick(b: BagWriter) -> None:
            b.maybe_flush()
            self._maybe_split(b)
        self._guarded(tick)

    def _guarded(self, op) -> None:
        with self._lock:
            bag = self.bag_writer
            if self._closed or bag is None or bag.error is not None:
                return
            try:
                op(bag)
            except (RecordingError, OSError) as exc:
                self._failed(bag, exc)

    # ------------------------------------------------------------------ retention
    def _bags(self) -> list[Path]:
        """This recorder family's bags under the root (the manifest's names that exist); never a scan."""
        return our_bags(self.root) if self.retention_on else []

    def apply_retention(self) -> list[Path]:
        """Delete the oldest of our finalised bags under the root while the limits are exceeded (module
        docstring); returns the deleted directories."""
        if not self.retention_on or not (self.retention_max_total_bytes or self.retention_max_age_s):
            return []
        deleted = []
        with self._lock:
            bags = self._bags()
            sizes = {b: _bag_size(b) for b in bags}
            total = sum(sizes.values())
            now = time.time()
            mine = self.bag_dir.resolve()
            candidates = sorted((b for b in bags if b.resolve() != mine),
                                key=lambda b: (_newest_mtime(b), b.name))
            for b in candidates:
                too_big = self.retention_max_total_bytes and total > self.retention_max_total_bytes
                too_old = self.retention_max_age_s and now - _newest_mtime(b) > self.retention_max_age_s
                if not (too_big or too_old):
                    continue
                if _bag_in_use(b):
                    continue
                state = _bag_state(b)
                if state == "foreign":   # named in the manifest but not marked: not ours after all
                    continue
                if state == "unfinalised" and not self.retention_delete_unfinalised:
                    if b.name not in self._kept_logged:
                        self._kept_logged.add(b.name)
                        self.bags_kept_unfinalised += 1
                        self._log(f"retention: kept {b}: not finalised (a crash or kill cut it); recover it "
                                  "with `jident salvage`, then delete it (or set retention_delete_unfinalised)")
                    continue
                try:
                    shutil.rmtree(b)
                except OSError as exc:
                    self._fail(f"retention could not delete {b} ({exc.strerror or exc})")
                    continue
                total -= sizes[b]
                self.bags_deleted += 1
                self.bytes_deleted += sizes[b]
                deleted.append(b)
                why = (f"our bags over retention_max_total_bytes {self.retention_max_total_bytes}" if too_big
                       else f"older than retention_max_age_s {self.retention_max_age_s:g}")
                self._log(f"retention: deleted {b} ({sizes[b]} bytes; {why})")
            gone = {b.name for b in deleted}
            if gone:
                try:
                    _edit_manifest(self.root, remove=gone)
                except OSError:
                    pass   # a stale name is harmless: a missing directory is skipped
        return deleted

    # ------------------------------------------------------------------ status and close
    @property
    def ok(self) -> bool:
        bag = self.bag_writer
        return bag is not None and bag.error is None and self.last_error is None

    def status(self) -> dict:
        """What a periodic status reports: ``state`` (recording | error | closed), ``bag``, ``file``,
        ``files``, ``bytes_written``, ``messages_written``, ``messages_dropped`` and ``drop_reasons``,
        ``splits``, ``bags_deleted``, ``bytes_deleted``, ``error`` (the first failure, or "")."""
        with self._lock:
            bag = self.bag_writer
            error = (bag.error if bag is not None and bag.error else None) or self.last_error or ""
            state = "error" if error else "closed" if self._closed else "recording"
            return {"state": state, "bag": str(self.bag_dir),
                    "file": str(bag.mcap_path) if bag is not None else "",
                    "files": len(bag.file_paths) if bag is not None else 0,
                    "bytes_written": bag.bytes_written if bag is not None else 0,
                    "messages_written": self.messages_written, "messages_dropped": self.messages_dropped,
                    "drop_reasons": dict(self.drop_reasons), "splits": self.splits,
                    "bags_deleted": self.bags_deleted, "bytes_deleted": self.bytes_deleted,
                    "bags_kept_unfinalised": self.bags_kept_unfinalised, "error": error}

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> bool:
        """Finalise the bag (last chunk, summary, metadata.yaml).  Idempotent; safe from a signal handler
        (a write the signal interrupted finishes first) and at interpreter exit.  Returns False when the
        bag could not be finalised now (it stays recoverable by ``jident salvage``)."""
        if self._closed:
            return True
        bag = self.bag_writer
        if bag is not None and bag._busy == threading.get_ident():
            return bag.close()  # deferred by the writer to the end of the interrupted write
        if not self._lock.acquire(timeout=10.0):
            return False
        try:
            if self._closed:
                return True
            done = bag.close() if bag is not None else True
            if done:
                self._closed = True
                try:
                    atexit.unregister(self._atexit)
                except Exception:  # pragma: no cover
                    pass
            if bag is not None and bag.error and not self.last_error:
                self.last_error = bag.error
            return done
        finally:
            self._lock.release()

