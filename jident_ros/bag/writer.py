"""The bag writer: rosbag2-compatible MCAP bags written with ``mcap``'s Writer.  No ROS needed; never imports
rclpy.  Reading: :mod:`jident_ros.bag.reader`; salvage: :mod:`jident_ros.bag.salvage`.

What :class:`BagWriter` produces is what ``ros2 bag record -s mcap`` produces: a bag directory
``<name>/`` holding ``<name>_0.mcap`` (and ``<name>_1.mcap`` ... after :meth:`BagWriter.split`) and
``metadata.yaml``.  Each MCAP file has profile ``ros2``; one schema per message type (encoding ``ros2msg``,
the definition text rosbags generates), messages ``cdr`` (rosbags' codec, :mod:`jident_ros.bag.messages`);
every channel carries the metadata ``offered_qos_profiles`` (YAML, rosbag2 metadata-version-9 spelling) and
``topic_type_hash`` (REP-2011 ``RIHS01_``, rosbags' hash); a ``rosbag2`` metadata record holds the
serialised bag metadata, as the rosbag2 MCAP plugin writes it.

API::

    with BagWriter("out/run1") as bag:
        bag.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray")
        bag.add_topic("/inertia_estimate", "std_msgs/msg/Float64", qos="transient_local")
        bag.write("/drive/signals", msg, log_time_ns)       # rclpy/rosbags message, dict or CDR bytes

Crash behaviour: messages collect in the mcap Writer's open chunk.  A finished chunk (with its message
indexes) goes to the file in ONE ``os.write`` -- no user-space buffer outlives the call -- when it
reaches ``chunk_size``, on :meth:`BagWriter.flush`, and at most ``flush_age_s`` (default 0.5 s) after
its first message (checked on each write; call :meth:`BagWriter.maybe_flush` from a timer when messages
can pause).  A SIGKILL therefore loses only the open chunk; :func:`jident_ros.bag.salvage.salvage` (and
:func:`jident_ros.bag.reader.read_bag`, on the fly) recovers the rest.  A failed write (disk full: ENOSPC)
cuts the file back to its last complete chunk and finalises it there (summary, metadata.yaml) when the disk
leaves room for that; the messages of the failed chunk are counted in :attr:`BagWriter.messages_lost`.
:meth:`BagWriter.close` (also run by ``with``, at interpreter exit and by the handlers of
:func:`jident_ros.bag.close_on_signal.install_signal_handlers`) writes the summary and ``metadata.yaml``; it
is idempotent.
"""
from __future__ import annotations

import atexit
import errno
import hashlib
import os
import threading
import time
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from mcap import writer as mcap_writer

from jident_ros.bag.chunk_file import ChunkFile
from jident_ros.bag.close_on_signal import _chain_signal
from jident_ros.bag.errors import RecordingError
from jident_ros.bag.messages import (
    QOS_PRESETS,
    canonical_type,
    message_definition,
    qos_dicts,
    qos_profiles,
    serialize,
)
from jident_ros.bag.messages import type_hash as hash_of_type
from jident_ros.bag.metadata_yaml import ROSBAG2_METADATA_VERSION, dump_yaml, wrapped_metadata_yaml

__all__ = ["DEFAULT_CHUNK_SIZE", "DEFAULT_FLUSH_AGE_S", "BagWriter"]

DEFAULT_CHUNK_SIZE = 768 * 1024  # the MCAP C++ writer's (and so rosbag2's) default
DEFAULT_FLUSH_AGE_S = 0.5


@dataclass(slots=True)
class _Topic:
    name: str
    msg_type: str
    schema_encoding: str
    schema_text: bytes
    qos: Any
    qos_text: str
    type_hash: str
    fmt: str
    encodable: bool
    count: int = 0
    sequence: int = 0
    schema_key: tuple = field(init=False)

    def __post_init__(self):
        self.schema_key = (self.msg_type, self.schema_encoding, hashlib.sha1(self.schema_text).hexdigest())


class _File:
    """One MCAP file of a bag and its bookkeeping."""

    def __init__(self, path: Path, chunk_size: int, compression):
        self.path = path
        self.out = ChunkFile(path)
        try:
            self.w = mcap_writer.Writer(self.out, chunk_size=chunk_size, compression=compression,
                                        enable_crcs=True)
            self.w.start(profile="ros2", library=f"jident_ros; {mcap_writer.LIBRARY_IDENTIFIER}")
            self.out.commit()
        except BaseException:
            self.out.close()
            raise
        self.schemas: dict[tuple, int] = {}
        self.channels: dict[str, int] = {}
        self.count = 0
        self.t_min: int | None = None
        self.t_max: int | None = None
        self.open_chunk: dict[str, int] = {}   # topic -> messages in the chunk not yet on disk
        self.chunk_opened_at: float | None = None
        self.chunks = 0
        self.opened_at = time.monotonic()
        self.finalised = False

    def meta(self) -> dict:
        start = self.t_min or 0
        return {"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": (self.t_max - self.t_min) if self.t_min is not None else 0},
                "message_count": self.count}


def _forget_lost_chunk(w, committed_end: int, lost: dict[int, int]) -> None:
    """Make the mcap Writer's summary match a file cut back to ``committed_end``: drop the chunk indexes
    and message statistics of the chunk whose write failed (mcap keeps them in name-mangled attributes;
    an AttributeError here means a changed mcap, and the file is then left for salvage)."""
    indexes = w._Writer__chunk_indices
    stats = w._Writer__statistics
    while indexes and indexes[-1].chunk_start_offset >= committed_end:
        indexes.pop()
        stats.chunk_count -= 1
    for channel_id, n in lost.items():
        stats.channel_message_counts[channel_id] -= n
        stats.message_count -= n
    stats.message_start_time = min((c.message_start_time for c in indexes), default=0)
    stats.message_end_time = max((c.message_end_time for c in indexes), default=0)


class BagWriter:
    """Write a rosbag2-compatible MCAP bag directory (see the module docstring).

    ``bag_dir`` must not exist or be empty; it receives ``<name>_0.mcap`` (``<name>_1.mcap`` ... after
    :meth:`split`) and ``metadata.yaml``.  ``chunk_size``: bytes of messages per chunk before it is
    written; ``flush_age_s``: the longest time a message waits in the open chunk (``None``: only size and
    explicit flushes); ``compression``: ``"zstd"``, ``"lz4"`` or ``None`` (per chunk); ``fsync``: also
    fsync each written chunk (power loss, not just process death); ``custom_data``: str->str for
    ``metadata.yaml``.

    After a failed write (:attr:`error` is set; ENOSPC: :attr:`disk_full`) the bag is finalised as far
    as it got and every further :meth:`write` raises RecordingError.  Thread-safe.
    """

    def __init__(self, bag_dir: str | os.PathLike, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_age_s: float | None = DEFAULT_FLUSH_AGE_S, compression: str | None = "zstd", *,
                 fsync: bool = False, custom_data: Mapping[str, str] | None = None, **deprecated):
        if "flush_every_s" in deprecated:  # the former name
            flush_age_s = deprecated.pop("flush_every_s")
        if deprecated:
            raise TypeError(f"unexpected argument(s) {sorted(deprecated)}")
        comp = {"zstd": mcap_writer.CompressionType.ZSTD, "lz4": mcap_writer.CompressionType.LZ4,
                None: mcap_writer.CompressionType.NONE, "none": mcap_writer.CompressionType.NONE,
                "": mcap_writer.CompressionType.NONE}
        if compression not in comp:
            raise ValueError(f"compression={compression!r}; expected 'zstd', 'lz4' or None")
        if not isinstance(chunk_size, int) or chunk_size < 1:
            raise ValueError(f"chunk_size={chunk_size!r}; expected an integer >= 1")
        if flush_age_s is not None and not flush_age_s > 0:
            raise ValueError(f"flush_age_s={flush_age_s!r}; expected a number > 0 or None")
        if custom_data is not None and not all(isinstance(k, str) and isinstance(v, str)
                                               for k, v in custom_data.items()):
            raise ValueError("custom_data must map str to str")
        self.bag_dir = Path(bag_dir)
        if self.bag_dir.exists() and (not self.bag_dir.is_dir() or any(self.bag_dir.iterdir())):
            raise FileExistsError(f"{self.bag_dir}: already exists and is not an empty directory")
        self.bag_dir.mkdir(parents=True, exist_ok=True)
        self.metadata_path = self.bag_dir / "metadata.yaml"
        self._name = self.bag_dir.resolve().name
        self._chunk_size, self._compression = chunk_size, comp[compression]
        self._flush_age_s = flush_age_s
        self._fsync = fsync
        self._custom_data = dict(custom_data) if custom_data else None
        self._lock = threading.RLock()
        self._busy = None                  # thread id inside a writer operation
        self._pending_signal = None        # (signum, previous handler) deferred by a handler
        self._closed = False
        self._topics: dict[str, _Topic] = {}
        self._files: list[_File] = []
        self.error: str | None = None      # why the bag stopped (a failed write), else None
        self.disk_full = False
        self.messages_lost = 0             # messages of a chunk whose write failed
        self._reserve_fd, self._reserved = -1, 0
        self._last_record = None           # (metadata, its YAML) of the last file's rosbag2 record
        self._file = self._open_file()
        self._ensure_reserve()
        ref = weakref.ref(self)
        self._atexit = lambda: (ref() is not None and ref().close())
        atexit.register(self._atexit)

    # ---- files ----
    def _open_file(self) -> _File:
        f = _File(self.bag_dir / f"{self._name}_{len(self._files)}.mcap", self._chunk_size, self._compression)
        self._files.append(f)
        return f

    @property
    def mcap_path(self) -> Path:
        """The MCAP file being written (the last one after close)."""
        return self._file.path

    @property
    def file_paths(self) -> list[Path]:
        return [f.path for f in self._files]

    @property
    def bytes_written(self) -> int:
        """Bytes handed to the OS over all files of the bag."""
        return sum(f.out.committed for f in self._files)

    @property
    def file_bytes(self) -> int:
        """Bytes of the open file so far (what a size limit compares)."""
        return self._file.out.committed

    @property
    def file_age_s(self) -> float:
        return time.monotonic() - self._file.opened_at

    @property
    def file_message_count(self) -> int:
        return self._file.count

    # ---- context manager ----
    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @contextmanager
    def _op(self):
        """Lock + mark this thread busy, so that a signal handler running in this thread (Python runs
        them between bytecodes of the main thread) defers closing to the end of the operation instead of
        closing a half-written chunk."""
        outer = 0
        try:
            with self._lock:
                outer = self._busy
                self._busy = threading.get_ident()
                try:
                    yield
                finally:
                    self._busy = outer
        finally:
            if outer is None and self._pending_signal is not None:
                signum, previous = self._pending_signal
                self._pending_signal = None
                self.close()
                _chain_signal(signum, previous)

    def _check_open(self) -> None:
        if self.error is not None:
            raise RecordingError(f"{self.mcap_path}: recording stopped: {self.error}")
        if self._closed:
            raise RecordingError(f"{self.mcap_path}: writer is closed")

    # ---- topics ----
    def add_topic(self, topic: str, msg_type: str, qos: Any = None, *, msgdef: str | bytes | None = None,
                  type_hash: str | None = None, schema_encoding: str = "ros2msg",
                  message_encoding: str = "cdr") -> None:
        """Declare a topic before writing to it (again with the same type: no-op).

        ``msg_type``: e.g. ``std_msgs/msg/Float64MultiArray``; a type of rosbags' Jazzy type store needs
        nothing else; other types need ``msgdef`` (the schema text) and ``type_hash`` and are written as
        CDR bytes.  ``qos``: see :func:`jident_ros.bag.messages.qos_profiles`, or the YAML text of a
        recorded ``offered_qos_profiles`` (copied as is)."""
        if not isinstance(topic, str) or not topic:
            raise ValueError(f"topic must be a non-empty string, got {topic!r}")
        if msgdef is None:
            name = canonical_type(msg_type)
            text = message_definition(name).encode("utf-8")
            thash = type_hash if type_hash is not None else hash_of_type(name)
            encodable = True
        else:
            name = msg_type
            text = msgdef.encode("utf-8") if isinstance(msgdef, str) else bytes(msgdef)
            thash = type_hash or ""
            encodable = False
        if isinstance(qos, str) and qos not in QOS_PRESETS:
            qos_text = qos
            try:
                profiles = qos_profiles(qos)
            except (ValueError, TypeError):
                profiles = []
        else:
            profiles = qos_profiles(qos)
            qos_text = dump_yaml(qos_dicts(profiles)).rstrip("\n") if profiles else ""
        with self._op():
            self._check_open()
            existing = self._topics.get(topic)
            if existing is not None:
                if existing.msg_type != name:
                    raise ValueError(f"{topic}: already added with type {existing.msg_type}, not {name}")
                return
            t = _Topic(topic, name, schema_encoding, text, profiles, qos_text, thash, message_encoding,
                       encodable)
            self._topics[topic] = t
            self._register(self._file, t)

    def _register(self, f: _File, t: _Topic) -> None:
        schema_id = f.schemas.get(t.schema_key)
        if schema_id is None:
            schema_id = f.schemas[t.schema_key] = f.w.register_schema(
                name=t.msg_type, encoding=t.schema_encoding, data=t.schema_text)
        f.channels[t.name] = f.w.register_channel(
            topic=t.name, message_encoding=t.fmt, schema_id=schema_id,
            metadata={"offered_qos_profiles": t.qos_text, "topic_type_hash": t.type_hash})

    # ---- messages ----
    def write(self, topic: str, message: Any, log_time_ns: int, publish_time_ns: int | None = None,
              sequence: int | None = None) -> None:
        """Record one message: an rclpy or rosbags message, a dict of fields, or CDR bytes.
        ``log_time_ns``: receive time (the bag's timestamp); ``publish_time_ns`` defaults to it;
        ``sequence`` to a per-topic counter."""
        log_time = _as_time(log_time_ns, "log_time_ns")
        publish_time = log_time if publish_time_ns is None else _as_time(publish_time_ns, "publish_time_ns")
        with self._op():  # serialising inside: a signal handler then closes after this message
            self._check_open()
            t = self._topics.get(topic)
            if t is None:
                raise RecordingError(f"{topic}: not added; call add_topic({topic!r}, <type>) first")
            if isinstance(message, (bytes, bytearray, memoryview)):
                data = message if type(message) is bytes else bytes(message)
                if t.fmt == "cdr" and (len(data) < 4 or data[0] != 0 or data[1] not in (0, 1)):
                    raise ValueError(f"{topic}: bytes given but not a CDR payload")
            elif not t.encodable:
                raise RecordingError(f"{topic}: {t.msg_type} is not in the type store; write CDR bytes")
            else:
                data = serialize(t.msg_type, message)
            f = self._file
            seq = t.sequence if sequence is None else int(sequence)
            f.w.add_message(channel_id=f.channels[topic], log_time=log_time, data=data,
                            publish_time=publish_time, sequence=seq & 0xFFFFFFFF)
            t.sequence = seq + 1
            t.count += 1
            f.count += 1
            f.t_min = log_time if f.t_min is None else min(f.t_min, log_time)
            f.t_max = log_time if f.t_max is None else max(f.t_max, log_time)
            f.open_chunk[topic] = f.open_chunk.get(topic, 0) + 1
            now = time.monotonic()
            if f.chunk_opened_at is None:
                f.chunk_opened_at = now
            if f.out.pending:           # the Writer finished a chunk (chunk_size reached)
                self._commit(f)
            elif self._flush_age_s is not None and now - f.chunk_opened_at >= self._flush_age_s:
                self._flush(f)

    def _commit(self, f: _File) -> None:
        try:
            f.out.commit()
        except OSError as exc:
            self._fail(f, exc)
            raise RecordingError(f"{f.path}: {self.error}") from None
        if self._fsync:
            f.out.fsync()
        f.open_chunk = {}
        f.chunk_opened_at = None
        f.chunks += 1
        self._ensure_reserve()

    # ---- room to finalise on a full disk ----
    _RESERVE_NAME = ".jident_reserve"
    _RESERVE_STEP = 64 * 1024

    def _ensure_reserve(self) -> None:
        """Keep disk space allocated (a hidden file in the bag directory, removed at close) for what
        closing needs: the summary (about 200 bytes per chunk), the rosbag2 metadata record and
        metadata.yaml.  Freed when a write fails, so that a full disk still gets a finalised bag."""
        need = self._RESERVE_STEP + 256 * self._file.chunks + 2048 * len(self._topics)
        if need <= self._reserved:
            return
        need = -(-need // self._RESERVE_STEP) * self._RESERVE_STEP
        try:
            if self._reserve_fd < 0:
                self._reserve_fd = os.open(self.bag_dir / self._RESERVE_NAME, os.O_WRONLY | os.O_CREAT, 0o600)
            os.posix_fallocate(self._reserve_fd, 0, need)
            self._reserved = need
        except OSError:
            pass  # nearly full already: the next failed write releases what is reserved

    def _release_reserve(self) -> None:
        if self._reserve_fd >= 0:
            fd, self._reserve_fd = self._reserve_fd, -1
            os.close(fd)
        (self.bag_dir / self._RESERVE_NAME).unlink(missing_ok=True)
        self._reserved = 0

    def _flush(self, f: _File) -> None:
        f.w.flush()
        self._commit(f)

    def maybe_flush(self) -> None:
        """Flush if the open chunk is older than ``flush_age_s`` (for a timer)."""
        with self._op():
            f = self._file
            if (not self._closed and self.error is None and self._flush_age_s is not None
                    and f.chunk_opened_at is not None
                    and time.monotonic() - f.chunk_opened_at >= self._flush_age_s):
                self._flush(f)

    def flush(self) -> None:
        """Close the open chunk and hand it to the OS (a chunk boundary)."""
        with self._op():
            self._check_open()
            self._flush(self._file)

    def split(self) -> Path:
        """Finalise the open file and continue in ``<name>_<k+1>.mcap`` (as ``ros2 bag record
        --max-bag-size`` does); metadata.yaml is rewritten to list the finished files.  Returns the new
        file's path."""
        with self._op():
            self._check_open()
            self._finish(self._file)
            if self.error is not None:
                raise RecordingError(f"{self._file.path}: {self.error}")
            self._write_metadata()
            f = self._file = self._open_file()
            self._ensure_reserve()
            for t in self._topics.values():
                self._register(f, t)
            return f.path

    # ---- metadata ----
    def bag_metadata(self, finishing: _File | None = None) -> dict:
        """The ``rosbag2_bagfile_information`` content for the messages so far: the finalised files (and
        ``finishing``, the one being finalised)."""
        files = [f for f in self._files if f.finalised or f is finishing]
        started = [f for f in files if f.t_min is not None]
        start = min((f.t_min for f in started), default=0)
        end = max((f.t_max for f in started), default=0)
        topics = [{"topic_metadata": {"name": t.name, "type": t.msg_type, "serialization_format": t.fmt,
                                      "offered_qos_profiles": qos_dicts(t.qos),
                                      "type_description_hash": t.type_hash},
                   "message_count": t.count} for t in self._topics.values()]
        return {
            "version": ROSBAG2_METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": end - start if started else 0},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(f.count for f in files),
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [f.path.name for f in files],
            "files": [f.meta() for f in files],
            "custom_data": self._custom_data,
            "ros_distro": os.environ.get("ROS_DISTRO", ""),
        }

    def _write_metadata(self) -> None:
        tmp = self.metadata_path.with_suffix(".yaml.tmp")
        try:
            tmp.write_text(wrapped_metadata_yaml(self.bag_metadata(), self._last_record), encoding="utf-8")
            os.replace(tmp, self.metadata_path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            self._note_error(f"metadata.yaml not written ({exc.strerror or exc})", exc)

    def _note_error(self, text: str, exc: BaseException | None = None) -> None:
        if self.error is None:
            self.error = text
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            self.disk_full = True

    # ---- failure and close ----
    def _fail(self, f: _File, exc: OSError) -> None:
        """A write failed (the file is already cut back to its last complete chunk): count the messages
        of the failed chunk as lost and finalise the file where it ends, if the disk lets us."""
        lost = sum(f.open_chunk.values())
        self.messages_lost += lost
        for topic, n in f.open_chunk.items():
            self._topics[topic].count -= n
        f.count -= lost
        reason = "disk full (ENOSPC)" if exc.errno == errno.ENOSPC else f"write failed ({exc.strerror or exc})"
        self._note_error(f"{reason}; {lost} message(s) of the unwritten chunk lost", exc)
        self._release_reserve()
        try:
            _forget_lost_chunk(f.w, f.out.committed, {f.channels[t]: n for t, n in f.open_chunk.items()})
            f.open_chunk = {}
            times = [(c.message_start_time, c.message_end_time) for c in f.w._Writer__chunk_indices]
            f.t_min = min((a for a, _ in times), default=None)
            f.t_max = max((b for _, b in times), default=None)
            self._finish(f)
        except AttributeError:  # pragma: no cover - a changed mcap: leave the file for salvage
            self.error += "; file left without summary (recover it with `jident salvage`)"
        self._closed = True
        try:
            atexit.unregister(self._atexit)
        except Exception:  # pragma: no cover
            pass
        if f.finalised:
            self._write_metadata()

    def _finish(self, f: _File) -> None:
        """Last chunk, rosbag2 metadata record, summary and footer of one file; closes it."""
        if f.finalised:
            return
        try:
            if self.error is None:
                f.w.flush()
                f.out.commit()
            md = self.bag_metadata(f)
            self._last_record = (md, dump_yaml(md))
            f.w.add_metadata("rosbag2", {"serialized_metadata": self._last_record[1]})
            f.w.finish()
            f.out.commit()
            if self._fsync:
                f.out.fsync()
            f.finalised = True
        except OSError as exc:
            # no room even for the summary: the file ends on its last complete chunk, salvageable
            self._note_error(f"{f.path.name} not finalised ({exc.strerror or exc}); "
                             f"recover it with `jident salvage`", exc)
        finally:
            f.out.close()

    def close(self, timeout_s: float = 10.0) -> bool:
        """Finish the MCAP file (last chunk, summary, rosbag2 metadata record) and write
        ``metadata.yaml``.  Idempotent; safe from a signal handler (deferred to the end of a write the
        signal interrupted) and at interpreter exit.  Waits at most ``timeout_s`` for a write in another
        thread; returns False when it could not close (the bag then stays recoverable by salvage)."""
        if self._closed:
            return True
        if self._busy == threading.get_ident():
            # re-entered from a signal handler in the middle of an operation: finish when it ends
            self._pending_signal = self._pending_signal or (None, None)
            return False
        if not self._lock.acquire(timeout=timeout_s):
            return False
        try:
            if self._closed:
                return True
            self._closed = True
            try:
                atexit.unregister(self._atexit)
            except Exception:  # pragma: no cover
                pass
            self._release_reserve()
            self._finish(self._file)
            self._write_metadata()
            return True
        finally:
            self._lock.release()


def _as_time(value: Any, name: str) -> int:
    if type(value) is not int:      # a plain int (the common case) needs no conversion
        if isinstance(value, (bool, float)) or not hasattr(value, "__index__"):
            raise TypeError(f"{name} must be an integer number of nanoseconds, got {value!r}")
        value = int(value)
    if not 0 <= value < 2**64:
        raise ValueError(f"{name}={value} is outside 0 .. 2**64-1")
    return value
