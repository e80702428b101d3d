"""The bag reader: the messages of a rosbag2 MCAP recording (a bag directory, also a split one, or an .mcap
file), read with ``mcap`` and decoded with ``rosbags``; a file its writer never finalised is read by
scanning it (:class:`StreamScan`, also what :mod:`jident_ros.bag.salvage` recovers from).  No ROS.

    for topic, msg_type, log_time_ns, msg in read_bag("out/run1"):
        ...
"""
from __future__ import annotations

import heapq
import os
from collections import namedtuple
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.typesys import get_types_from_idl, get_types_from_msg
from rosbags.typesys.store import Typestore

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.messages import canonical_type, deserialize_with
from jident_ros.bag.metadata_yaml import read_metadata

__all__ = ["BagMessage", "StreamScan", "bag_files", "check_magic", "describe_error", "in_publish_order", "is_finalised",
           "read_bag", "read_metadata", "recorded_topics", "schema_problem", "skipped_topics_line", "TopicInfo"]

class BagMessage(namedtuple("BagMessage", "topic msg_type log_time_ns message")):
    """One recorded message: topic, type name, receive time (ns) and the message (decoded by rosbags: fields
    are attributes, numeric arrays numpy; or CDR ``bytes`` with ``raw=True``).  ``publish_time_ns``: the
    MCAP publish time -- the publisher's send time (DDS source timestamp) in bags that rosbag2 (Iron on) or our
    recorder wrote, else the receive time."""

    def __new__(cls, topic, msg_type, log_time_ns, message, publish_time_ns=None):
        self = super().__new__(cls, topic, msg_type, log_time_ns, message)
        self.publish_time_ns = log_time_ns if publish_time_ns is None else publish_time_ns
        return self


def in_publish_order(messages: Iterable[BagMessage], horizon_ns: int = 10_000_000_000) -> Iterator[BagMessage]:
    """``messages`` (in receive-time order) in the order they were published (stable), e.g. a drive's
    K2 message after the signal batches the drive sent before it, although a recorder received it earlier.
    A message is held until one received ``horizon_ns`` later arrives: nothing is sent longer than that after
    it was published (a bag without publish times comes out unchanged)."""
    heap: list = []
    for k, m in enumerate(messages):
        heapq.heappush(heap, (m.publish_time_ns, k, m))
        while heap and heap[0][0] < m.log_time_ns - horizon_ns:
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]


def _split_index(p: Path) -> tuple:
    stem = p.stem
    tail = stem.rsplit("_", 1)[-1]
    return (int(tail), stem) if tail.isdigit() else (1 << 62, stem)


def bag_files(path: str | os.PathLike) -> list[Path]:
    """The MCAP files of a recording in order: the file itself, or a bag directory's files (those named in
    metadata.yaml, then any other ``*.mcap`` of the directory -- a file still open when the recorder
    died -- by split index; such a file shorter than the MCAP magic, e.g. zero bytes, holds nothing and is
    left out)."""
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
    # an unlisted file shorter than the MCAP magic holds nothing: a split begun when the recorder died
    files += sorted((p for p in path.glob("*.mcap") if p.name not in listed and _holds_data(p)), key=_split_index)
    if not files:
        raise RecordingError(f"{path}: no metadata.yaml and no .mcap file")
    return files


def _holds_data(path: Path) -> bool:
    try:
        return path.stat().st_size >= 8
    except OSError:
        return False


def check_magic(path: Path) -> None:
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head != b"\x89MCAP0\r\n":
        raise RecordingError(f"{path}: not an MCAP file (bad magic)")


def is_finalised(path: str | os.PathLike) -> bool:
    """True when an MCAP file has its summary and footer (its writer closed it)."""
    check_magic(Path(path))
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


TopicInfo = namedtuple("TopicInfo", "topic msg_type problem")
TopicInfo.__doc__ = """A recorded topic: name, type name and why its schema cannot be parsed ("" when it can)."""


def _schemas_and_channels(path: Path) -> tuple[dict, dict]:
    """({schema id: Schema}, {channel id: Channel}) of one MCAP file: from its summary, or by scanning it."""
    if is_finalised(path):
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return dict(summary.schemas), dict(summary.channels)
    scan = StreamScan(path)
    for _ in scan.records():
        pass
    return scan.schemas, scan.channels


def schema_problem(schema) -> str:
    """Why rosbags cannot build a type from a recorded schema ("" when it can)."""
    if schema is None:
        return "no schema"
    try:
        _store_for(schema)
    except Exception as exc:  # rosbags' parse errors (TypesysError, lark's), a bad encoding, bad UTF-8
        return f"{type(exc).__name__}: {' '.join(str(exc).split())[:120]}"
    return ""


def recorded_topics(path: str | os.PathLike) -> list[TopicInfo]:
    """Every topic of a recording (an .mcap file or a bag directory) with its type, and whether its schema
    can be parsed -- read from the MCAP summaries without decoding a message, so a bag that also holds types
    nobody here can parse (``ros2 bag record -a`` on Jazzy: the ``_service_event`` topics of service
    introspection) can still be read for the topics it is asked for."""
    seen: dict[str, TopicInfo] = {}
    for p in bag_files(path):
        check_magic(p)
        schemas, channels = _schemas_and_channels(p)
        for ch in channels.values():
            if ch.topic not in seen:
                schema = schemas.get(ch.schema_id)
                seen[ch.topic] = TopicInfo(ch.topic, schema.name if schema is not None else "", schema_problem(schema))
    return [seen[t] for t in sorted(seen)]


def skipped_topics_line(path, topics: Iterable[TopicInfo]) -> str:
    """One line naming the topics of a recording whose types cannot be parsed ("" when there are none)."""
    bad = [t for t in topics if t.problem]
    if not bad:
        return ""
    names = ", ".join(f"{t.topic} ({t.msg_type or 'no type'})" for t in bad[:6])
    more = f" and {len(bad) - 6} more" if len(bad) > 6 else ""
    return f"{path}: skipped {len(bad)} topic(s) whose type cannot be parsed: {names}{more}"


def describe_error(exc: BaseException) -> str:
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
        check_magic(p)
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
        return BagMessage(channel.topic, msg_type, message.log_time, message.data, message.publish_time)
    if schema is None or channel.message_encoding != "cdr":
        raise RecordingError(f"{path}: topic {channel.topic}: cannot decode {channel.message_encoding!r} "
                             f"messages (read with raw=True or select other topics)")
    try:
        decoded = deserialize_with(_store_for(schema), message.data, schema.name)
    except Exception as exc:  # rosbags: SerdeError, TypesysError, parse errors
        raise RecordingError(f"{path}: topic {channel.topic} at {message.log_time}: cannot decode "
                             f"{schema.name} ({type(exc).__name__}: {exc})") from None
    return BagMessage(channel.topic, msg_type, message.log_time, decoded, message.publish_time)


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
            raise RecordingError(f"{path}: damaged ({describe_error(exc)}); recover the readable part with "
                                 f"`jident salvage {path} <out_dir>`") from None


def _iter_salvaged(path: Path, selected, raw: bool, on_salvage) -> Iterator[BagMessage]:
    scan = StreamScan(path)
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


class StreamScan:
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
        return f"damaged record at offset {self.good_end}: {describe_error(exc)}"
