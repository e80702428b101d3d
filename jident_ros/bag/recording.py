"""Rosbag2-compatible MCAP bags -- written with ``mcap``'s Writer, read with ``mcap`` + ``rosbags``,
salvaged with ``mcap``'s StreamReader.  No ROS needed; never imports rclpy.

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

    for topic, msg_type, log_time_ns, msg in read_bag("out/run1"):
        ...

    report = salvage("killed/killed_0.mcap", "recovered")  # every complete chunk

Crash behaviour: messages collect in the mcap Writer's open chunk.  A finished chunk (with its message
indexes) goes to the file in ONE ``os.write`` -- no user-space buffer outlives the call -- when it
reaches ``chunk_size``, on :meth:`BagWriter.flush`, and at most ``flush_age_s`` (default 0.5 s) after
its first message (checked on each write; call :meth:`BagWriter.maybe_flush` from a timer when messages
can pause).  A SIGKILL therefore loses only the open chunk; :func:`salvage` (and :func:`read_bag`, on
the fly) recovers the rest.  A failed write (disk full: ENOSPC) cuts the file back to its last complete
chunk and finalises it there (summary, metadata.yaml) when the disk leaves room for that; the messages
of the failed chunk are counted in :attr:`BagWriter.messages_lost`.  :meth:`BagWriter.close` (also run
by ``with``, at interpreter exit and by the handlers of :func:`install_signal_handlers`) writes the
summary and ``metadata.yaml``; it is idempotent.
"""
from __future__ import annotations

import argparse
import atexit
import errno
import fcntl
import hashlib
import os
import signal
import sys
import threading
import time
import weakref
from collections import namedtuple
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

import yaml
from mcap import writer as mcap_writer
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.typesys import get_types_from_idl, get_types_from_msg
from rosbags.typesys.store import Typestore

from jident_ros.bag.messages import (
    QOS_PRESETS,
    canonical_type,
    deserialize,
    deserialize_with,
    message_definition,
    message_to_dict,
    qos_dicts,
    qos_profiles,
    serialize,
    type_hash,
)

__all__ = [
    "QOS_PRESETS", "BagMessage", "BagWriter", "RecordingError", "SalvageError", "bag_files",
    "canonical_type", "deserialize", "install_signal_handlers", "is_finalised", "message_definition",
    "message_to_dict", "qos_profiles", "read_bag", "read_metadata", "salvage", "salvage_main",
    "salvage_report_line", "serialize", "type_hash",
]

ROSBAG2_METADATA_VERSION = 9
DEFAULT_CHUNK_SIZE = 768 * 1024  # the MCAP C++ writer's (and so rosbag2's) default
DEFAULT_FLUSH_AGE_S = 0.5


class RecordingError(RuntimeError):
    """A recording cannot be written or read (the message names the file or topic)."""


class SalvageError(RecordingError):
    """The input of :func:`salvage` is missing or is not an MCAP file."""


# ------------------------------------------------------------------------------------------ YAML
class _Dumper(yaml.SafeDumper):
    """Block YAML with indented sequences, as yaml-cpp (rosbag2) writes it."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)


def _dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_Dumper, default_flow_style=False, sort_keys=False, allow_unicode=True,
                     width=1 << 16)


def _wrapped_metadata_yaml(metadata: dict, record: tuple | None = None) -> str:
    """metadata.yaml's text: ``metadata`` under ``rosbag2_bagfile_information``.  When ``record`` = (the same
    metadata, its YAML) -- the rosbag2 record just written to the last file, which for a one-file bag holds the
    same content -- that text is indented instead of dumped again (PyYAML's pure-Python emitter was most of the
    cost of closing a bag; block style nests by indenting every line by 2, the _Dumper's indent)."""
    if record is not None and record[0] == metadata:
        body = record[1]
    else:
        body = _dump_yaml(metadata)
    return "rosbag2_bagfile_information:\n" + "".join("  " + line if line.strip() else line
                                                       for line in body.splitlines(keepends=True))


# ------------------------------------------------------------------------------------------ writing
class _ChunkFile:
    """The mcap Writer's output stream: what the Writer writes is collected and handed to the OS by
    :meth:`commit` in one ``os.write`` (a finished chunk and its message indexes together).  On a failed
    write the file is cut back to the end of the last commit, so it always ends on a complete record.
    The open file is ``flock``-ed: retention (jident_ros.bag.recorder) never deletes a bag in use."""

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


class _Topic:
    __slots__ = ("name", "msg_type", "schema_key", "schema_encoding", "schema_text", "qos", "qos_text",
                 "type_hash", "fmt", "count", "sequence", "encodable")

    def __init__(self, name, msg_type, schema_encoding, schema_text, qos, qos_text, thash, fmt, encodable):
        self.name, self.msg_type, self.fmt = name, msg_type, fmt
        self.schema_encoding, self.schema_text = schema_encoding, schema_text
        self.schema_key = (msg_type, schema_encoding, hashlib.sha1(schema_text).hexdigest())
        self.qos, self.qos_text, self.type_hash = qos, qos_text, thash
        self.count = 0
        self.sequence = 0
        self.encodable = encodable


class _File:
    """One MCAP file of a bag and its bookkeeping."""

    def __init__(self, path: Path, chunk_size: int, compression):
        self.path = path
        self.out = _ChunkFile(path)
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
            thash = type_hash if type_hash is not None else globals()["type_hash"](name)
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
            qos_text = _dump_yaml(qos_dicts(profiles)).rstrip("\n") if profiles else ""
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
            tmp.write_text(_wrapped_metadata_yaml(self.bag_metadata(), self._last_record), encoding="utf-8")
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
            self._last_record = (md, _dump_yaml(md))
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


# ------------------------------------------------------------------------------------------ reading
BagMessage = namedtuple("BagMessage", "topic msg_type log_time_ns message")
BagMessage.__doc__ = """One recorded message: topic, type name, receive time (ns) and the message (decoded
by rosbags: fields are attributes, numeric arrays numpy; or CDR ``bytes`` with ``raw=True``)."""


def read_metadata(bag_dir: str | os.PathLike) -> dict:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory's metadata.yaml."""
    path = Path(bag_dir) / "metadata.yaml"
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        return doc["rosbag2_bagfile_information"]
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except (yaml.YAMLError, TypeError, KeyError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: not rosbag2 metadata ({exc})") from None


def _split_index(p: Path) -> tuple:
    stem = p.stem
    tail = stem.rsplit("_", 1)[-1]
    return (int(tail), stem) if tail.isdigit() else (1 << 62, stem)


def bag_files(path: str | os.PathLike) -> list[Path]:
    """The MCAP files of a recording in order: the file itself, or a bag directory's files (those named in
    metadata.yaml, then any other ``*.mcap`` of the directory -- a file still open when the recorder
    died -- by split index)."""
    path = Path(path)
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise RecordingError(f"{path}: no such file or directory")
    files: list[Path] = []
    if (path / "metadata.yaml").is_file():
        meta = read_metadata(path)
        if meta.get("storage_identifier") != "mcap":
            raise RecordingError(f"{path}: storage {meta.get('storage_identifier')!r} is not mcap")
        files = [path / Path(p).name for p in meta.get("relative_file_paths") or []]
        missing = [str(p) for p in files if not p.is_file()]
        if missing:
            raise RecordingError(f"{path}: files named in metadata.yaml are missing: {missing}")
    listed = {p.name for p in files}
    files += sorted((p for p in path.glob("*.mcap") if p.name not in listed), key=_split_index)
    if not files:
        raise RecordingError(f"{path}: no metadata.yaml and no .mcap file")
    return files


def _check_magic(path: Path) -> None:
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head != b"\x89MCAP0\r\n":
        raise RecordingError(f"{path}: not an MCAP file (bad magic)")


def is_finalised(path: str | os.PathLike) -> bool:
    """True when an MCAP file has its summary and footer (its writer closed it)."""
    _check_magic(Path(path))
    try:
        with open(path, "rb") as f:
            return make_reader(f).get_summary() is not None
    except Exception:  # mcap raises McapError, EndOfFile, struct.error, ValueError ... on a cut file
        return False


_STORES: dict[tuple, Typestore] = {}


def _store_for(schema) -> Typestore:
    """A rosbags type store holding the types of one recorded schema (cached by its text)."""
    key = (schema.name, schema.encoding, schema.data)
    store = _STORES.get(key)
    if store is None:
        text = schema.data.decode("utf-8")
        if schema.encoding == "ros2msg":
            types = get_types_from_msg(text, schema.name)
        elif schema.encoding == "ros2idl":
            types = get_types_from_idl(text)
        else:
            raise ValueError(f"schema encoding {schema.encoding!r} is not ros2msg or ros2idl")
        store = Typestore()
        store.register(types)
        _STORES[key] = store
    return store


def _describe(exc: BaseException) -> str:
    name = type(exc).__name__
    if "crc" in str(exc).lower():
        return f"CRC mismatch ({exc})"
    if "zstd" in name.lower() or "lz4" in name.lower() or "decompress" in str(exc).lower():
        return f"cannot decompress ({name}: {exc})"
    return f"{name}: {exc}" if str(exc) else name


def read_bag(path: str | os.PathLike, topics: str | Iterable[str] | None = None, *, raw: bool = False,
             on_salvage: Callable[[str], Any] | None = None) -> Iterator[BagMessage]:
    """Iterate over the messages of a recording (bag directory -- also split into several files -- or an
    .mcap file) as :class:`BagMessage` ``(topic, msg_type, log_time_ns, message)``: file after file, each
    finalised file in receive-time order.

    A file without summary (its writer was killed) is read by salvaging it on the fly (every complete
    chunk, in file order); ``on_salvage`` gets one line saying so (without it: RecordingError pointing
    to ``jident salvage``).  A damaged finalised file raises RecordingError naming the file and the
    damage when the reader reaches it."""
    files = bag_files(path)
    selected = None if topics is None else ({topics} if isinstance(topics, str) else set(topics))
    for p in files:
        _check_magic(p)
    return _iter_files(files, selected, raw, on_salvage)


def _iter_files(files, selected, raw, on_salvage) -> Iterator[BagMessage]:
    for p in files:
        if is_finalised(p):
            yield from _iter_finalised(p, selected, raw)
        elif on_salvage is None:
            raise RecordingError(f"{p}: not finalised (no summary; was the recorder killed?) -- "
                                 f"recover it with `jident salvage {p} <out_dir>`")
        else:
            yield from _iter_salvaged(p, selected, raw, on_salvage)


def _decoded(path, schema, channel, message, raw) -> BagMessage:
    msg_type = schema.name if schema is not None else ""
    try:
        msg_type = canonical_type(msg_type)
    except ValueError:
        pass  # not a ROS type name; reported as found
    if raw:
        return BagMessage(channel.topic, msg_type, message.log_time, message.data)
    if schema is None or channel.message_encoding != "cdr":
        raise RecordingError(f"{path}: topic {channel.topic}: cannot decode {channel.message_encoding!r} "
                             f"messages (read with raw=True or select other topics)")
    try:
        decoded = deserialize_with(_store_for(schema), message.data, schema.name)
    except Exception as exc:  # rosbags: SerdeError, TypesysError, parse errors
        raise RecordingError(f"{path}: topic {channel.topic} at {message.log_time}: cannot decode "
                             f"{schema.name} ({type(exc).__name__}: {exc})") from None
    return BagMessage(channel.topic, msg_type, message.log_time, decoded)


def _iter_finalised(path: Path, selected, raw: bool) -> Iterator[BagMessage]:
    with open(path, "rb") as f:
        try:
            reader = make_reader(f, validate_crcs=True)
            items = reader.iter_messages(topics=selected, log_time_order=True)
            while True:
                try:
                    schema, channel, message = next(items)
                except StopIteration:
                    return
                yield _decoded(path, schema, channel, message, raw)
        except RecordingError:
            raise
        except Exception as exc:  # a damaged chunk: zstd/lz4 errors, CRC, struct, McapError ...
            raise RecordingError(f"{path}: damaged ({_describe(exc)}); recover the readable part with "
                                 f"`jident salvage {path} <out_dir>`") from None


def _iter_salvaged(path: Path, selected, raw: bool, on_salvage) -> Iterator[BagMessage]:
    scan = _Scan(path)
    n = 0
    for kind, item in scan.records():
        if kind != "message":
            continue
        channel = scan.channels.get(item.channel_id)
        if channel is None or (selected is not None and channel.topic not in selected):
            continue
        n += 1
        yield _decoded(path, scan.schemas.get(channel.schema_id), channel, item, raw)
    on_salvage(f"{path}: not finalised (was the recorder killed?); read by salvaging it: {n} message(s) "
               f"of {scan.chunks} complete chunk(s), {scan.bytes_lost} of {scan.size} bytes lost "
               f"({scan.reason})")


# ------------------------------------------------------------------------------------------ salvage
class _Scan:
    """A sequential read (mcap's StreamReader) of a possibly cut or damaged MCAP file: yields every
    schema, channel and message up to the first incomplete or damaged record, keeping where it stopped."""

    def __init__(self, path: Path):
        self.path = path
        self.size = path.stat().st_size
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.chunks = 0
        self.good_end = 8
        self.data_end = False
        self.reason = ""

    @property
    def bytes_lost(self) -> int:
        # after a complete data section only the (regenerated) summary follows
        return 0 if self.data_end else max(0, self.size - self.good_end)

    def records(self) -> Iterator[tuple[str, Any]]:
        with open(self.path, "rb") as f:
            reader = StreamReader(f, skip_magic=False, emit_chunks=True, validate_crcs=True,
                                  record_size_limit=max(self.size, 1 << 16))
            it = iter(reader.records)
            while True:
                try:
                    record = next(it)
                    inner = (breakup_chunk(record, validate_crc=True) if isinstance(record, Chunk)
                             else [record])
                except StopIteration:
                    self.reason = "file ends after the last complete record"
                    return
                except Exception as exc:  # EndOfFile, struct.error, zstd, CRCValidationError ...
                    self.reason = self._stop_reason(f, exc)
                    return
                if isinstance(record, (DataEnd, Footer)):
                    self.good_end = f.tell()
                    self.data_end = True
                    self.reason = "complete data section"
                    return
                if isinstance(record, Chunk):
                    self.chunks += 1
                for r in inner:
                    if isinstance(r, Schema):
                        self.schemas[r.id] = r
                    elif isinstance(r, Channel):
                        self.channels[r.id] = r
                        yield "channel", r
                    elif isinstance(r, Message):
                        yield "message", r
                self.good_end = f.tell()

    def _stop_reason(self, f, exc: BaseException) -> str:
        """Cut off (the record at good_end reaches past the end of the file) or damaged."""
        if self.good_end >= self.size:
            return "file ends after the last complete record"
        f.seek(self.good_end)
        head = f.read(9)  # opcode (1 byte) + record length (uint64 LE), MCAP's record framing
        if len(head) < 9 or self.good_end + 9 + int.from_bytes(head[1:], "little") > self.size:
            return f"file ends inside the record at offset {self.good_end}"
        return f"damaged record at offset {self.good_end}: {_describe(exc)}"


def _salvage_sources(src: Path) -> list[Path]:
    if src.is_dir():
        try:
            return bag_files(src)
        except RecordingError as exc:
            raise SalvageError(str(exc)) from None
    if not src.exists():
        raise SalvageError(f"{src}: no such file")
    if not src.is_file():
        raise SalvageError(f"{src}: not a regular file")
    return [src]


def salvage(source: str | os.PathLike, out_bag_dir: str | os.PathLike, *,
            compression: str | None = "zstd") -> dict:
    """Recover every complete chunk (and unchunked record) of a cut-off or damaged recording into a new
    bag directory with a summary and metadata.yaml.

    ``source``: an .mcap file, or a bag directory (also one split into several files: each becomes one
    file of the new bag).  Returns a report: ``messages_recovered``, ``chunks_recovered``,
    ``bytes_total``, ``bytes_recovered``, ``bytes_lost`` (after the last intact record),
    ``data_section_complete``, ``stop_reason`` (of the first file that was not complete), ``topics``
    (topic -> messages), ``files`` (one report per source file), ``source``, ``output``.  Raises
    :class:`SalvageError` naming the file if it is missing or not MCAP."""
    src = Path(source)
    sources = _salvage_sources(src)
    for p in sources:
        try:
            _check_magic(p)
        except RecordingError as exc:
            raise SalvageError(str(exc)) from None
    out = Path(out_bag_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SalvageError(f"{out}: already exists and is not an empty directory")
    topics: dict[str, int] = {}
    lost = 0
    per_file = []
    with BagWriter(out, compression=compression, flush_age_s=None,
                   custom_data={"salvaged_from": str(src)}) as writer:
        for k, p in enumerate(sources):
            if k:
                writer.split()
            scan = _Scan(p)
            by_channel: dict[int, str] = {}
            n_file = 0
            for kind, item in scan.records():
                if kind == "channel":
                    if item.topic not in topics:
                        schema = scan.schemas.get(item.schema_id)
                        writer.add_topic(item.topic, schema.name if schema else "",
                                         item.metadata.get("offered_qos_profiles", ""),
                                         msgdef=schema.data if schema else b"",
                                         type_hash=item.metadata.get("topic_type_hash", ""),
                                         schema_encoding=schema.encoding if schema else "",
                                         message_encoding=item.message_encoding)
                        topics[item.topic] = 0
                    by_channel[item.id] = item.topic
                    continue
                topic = by_channel.get(item.channel_id)
                if topic is None:
                    lost += 1
                    continue
                writer.write(topic, item.data, item.log_time, item.publish_time, item.sequence)
                topics[topic] += 1
                n_file += 1
            per_file.append({"source": str(p), "messages_recovered": n_file, "chunks_recovered": scan.chunks,
                             "bytes_total": scan.size, "bytes_recovered": scan.good_end,
                             "bytes_lost": scan.bytes_lost, "data_section_complete": scan.data_end,
                             "stop_reason": scan.reason})
    first_bad = next((r for r in per_file if not r["data_section_complete"]), per_file[-1])
    return {
        "source": str(src) if len(sources) > 1 else str(sources[0]),
        "output": str(out),
        "files": per_file,
        "chunks_recovered": sum(r["chunks_recovered"] for r in per_file),
        "messages_recovered": sum(topics.values()),
        "messages_unusable": lost,
        "bytes_total": sum(r["bytes_total"] for r in per_file),
        "bytes_recovered": sum(r["bytes_recovered"] for r in per_file),
        "bytes_lost": sum(r["bytes_lost"] for r in per_file),
        "data_section_complete": all(r["data_section_complete"] for r in per_file),
        "stop_reason": first_bad["stop_reason"],
        "topics": topics,
    }


def salvage_report_line(report: Mapping[str, Any]) -> str:
    """The one-line summary ``jident salvage`` prints."""
    files = report.get("files") or []
    where = f" ({len(files)} files)" if len(files) > 1 else ""
    return (f"salvaged {report['source']}{where}: {report['messages_recovered']} messages in "
            f"{report['chunks_recovered']} complete chunks -> {report['output']}; "
            f"{report['bytes_lost']} of {report['bytes_total']} bytes lost ({report['stop_reason']})")


def salvage_main(argv: list[str] | None = None) -> int:
    """``jident salvage <recording> <out_dir>``: prints one line and returns 0 (the readable part was
    written: how much was lost and why is on that line), or prints a one-line error naming the file and
    returns 2."""

    class _Parser(argparse.ArgumentParser):
        def error(self, message):
            raise SalvageError(message)

    parser = _Parser(prog="jident salvage",
                     description="Recover every complete chunk of a cut-off or damaged MCAP recording "
                                 "(an .mcap file or a bag directory, also a split one) into a new bag directory.")
    parser.add_argument("source", help="the .mcap file or bag directory")
    parser.add_argument("out_dir", help="new bag directory to write (must not exist)")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    try:
        args = parser.parse_args(argv)
        report = salvage(args.source, args.out_dir,
                         compression=None if args.compression == "none" else args.compression)
    except (RecordingError, OSError, McapError) as exc:
        print(f"jident salvage: error: {exc}", file=sys.stderr)
        return 2
    print(salvage_report_line(report))
    return 0
