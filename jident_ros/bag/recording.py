"""Rosbag2-compatible MCAP recording, reading and salvage -- no ROS needed.

What :class:`BagWriter` produces is what ``ros2 bag record -s mcap`` produces: a bag
directory ``<dir>/`` holding ``<dir>_0.mcap`` and ``metadata.yaml``.  The MCAP file has
profile ``ros2``; one schema per message type with encoding ``ros2msg`` whose text is
the type's ``.msg`` file followed by every dependency, concatenated exactly as
rosbag2's message-definition cache does (80 ``=``, ``MSG: pkg/Type``); messages are
``cdr``; every channel carries the metadata ``offered_qos_profiles`` (YAML, rosbag2
metadata version 9 spelling) and ``topic_type_hash`` (the REP-2011 ``RIHS01_...`` hash,
computed here from the definitions); a ``rosbag2`` metadata record holds the serialised
bag metadata, as the rosbag2 MCAP plugin writes it.

The ``.msg`` texts of the few types the nodes use are shipped in :data:`MSG_FILES`
(byte-exact copies of the ROS 2 interface packages), and the CDR codec below is driven
by those definitions, so writing, reading and salvaging work without a ROS install.
The codec is ours rather than ``mcap-ros2-support``'s because that one converts every
float of a ``float64[]`` in Python (about 5 ms to encode and 3 ms to decode a
1000-sample x 9-channel batch, ~200x slower than numpy); the tests check our bytes
against ``mcap-ros2-support``, against ``rclpy.serialization`` and by decoding with the
independent ``rosbags`` library.

API::

    with BagWriter("out/run1", flush_every_s=1.0) as bag:
        bag.add_topic("/drive/signals", "std_msgs/msg/Float64MultiArray")
        bag.add_topic("/inertia_estimate", "std_msgs/msg/Float64", qos="transient_local")
        bag.write("/drive/signals", msg, log_time_ns)       # rclpy message, dict or CDR bytes

    for topic, msg_type, log_time_ns, msg in read_bag("out/run1"):
        ...

    report = salvage("killed/killed_0.mcap", "recovered")  # every complete chunk

Crash behaviour: messages are collected in an in-memory chunk; a chunk is written to the
file (one ``os.write``, no user-space buffer) when it reaches ``chunk_size``, on
:meth:`BagWriter.flush` and at most ``flush_every_s`` after its first message (checked
on each write; call :meth:`BagWriter.maybe_flush` from a timer when messages can pause).
A SIGKILL therefore loses only the open chunk; :func:`salvage` recovers the rest.
:meth:`BagWriter.close` (also run by ``with``, at interpreter exit, and by the handlers
of :func:`install_signal_handlers`) writes the summary and ``metadata.yaml``.
This module never imports rclpy.
"""
from __future__ import annotations

import argparse
import atexit
import hashlib
import io
import json
import os
import re
import signal
import struct
import sys
import threading
import time
import weakref
import zlib
from collections import namedtuple
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Iterable, Iterator, Mapping

import numpy as np
import yaml

__all__ = [
    "MSG_FILES",
    "QOS_PRESETS",
    "canonical_type",
    "salvage_report_line",
    "BagMessage",
    "BagWriter",
    "DecodedMessage",
    "RecordingError",
    "SalvageError",
    "install_signal_handlers",
    "message_definition",
    "message_to_dict",
    "qos_profiles",
    "read_bag",
    "read_metadata",
    "salvage",
    "salvage_main",
    "serialize",
    "deserialize",
    "type_hash",
]

ROSBAG2_METADATA_VERSION = 9
DEFAULT_CHUNK_SIZE = 768 * 1024  # the MCAP C++ writer's (and so rosbag2's) default
_MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(RuntimeError):
    """A recording cannot be written or read (message names the file or topic)."""


class SalvageError(RecordingError):
    """The input of :func:`salvage` is missing or is not an MCAP file."""


# --------------------------------------------------------------------------------------
# Message definitions: byte-exact copies of the .msg files of the ROS 2 interface
# packages (std_msgs 5.5.1, builtin_interfaces 2.3.0, rosgraph_msgs 2.3.0,
# diagnostic_msgs 5.5.1).  test_recording.py compares them with the installed ones.
# --------------------------------------------------------------------------------------
MSG_FILES: dict[str, str] = {
    "builtin_interfaces/msg/Time": """\
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 1e9).
uint32 nanosec
""",
    "std_msgs/msg/Header": """\
# Standard metadata for higher-level stamped data types.
# This is generally used to communicate timestamped data
# in a particular coordinate frame.

# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
""",
    "std_msgs/msg/Float64": """\
# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.

float64 data
""",
    "std_msgs/msg/MultiArrayDimension": """\
# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.

string label   # label of given dimension
uint32 size    # size of given dimension (in type units)
uint32 stride  # stride of given dimension
""",
    "std_msgs/msg/MultiArrayLayout": """\
# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.

# The multiarray declares a generic multi-dimensional array of a
# particular data type.  Dimensions are ordered from outer most
# to inner most.
#
# Accessors should ALWAYS be written in terms of dimension stride
# and specified outer-most dimension first.
#
# multiarray(i,j,k) = data[data_offset + dim_stride[1]*i + dim_stride[2]*j + k]
#
# A standard, 3-channel 640x480 image with interleaved color channels
# would be specified as:
#
# dim[0].label  = "height"
# dim[0].size   = 480
# dim[0].stride = 3*640*480 = 921600  (note dim[0] stride is just size of image)
# dim[1].label  = "width"
# dim[1].size   = 640
# dim[1].stride = 3*640 = 1920
# dim[2].label  = "channel"
# dim[2].size   = 3
# dim[2].stride = 3
#
# multiarray(i,j,k) refers to the ith row, jth column, and kth channel.

MultiArrayDimension[] dim # Array of dimension properties
uint32 data_offset        # padding bytes at front of data
""",
    "std_msgs/msg/Float64MultiArray": """\
# This was originally provided as an example message.
# It is deprecated as of Foxy
# It is recommended to create your own semantically meaningful message.
# However if you would like to continue using this please use the equivalent in example_msgs.

# Please look at the MultiArrayLayout message definition for
# documentation on all multiarrays.

MultiArrayLayout  layout        # specification of data layout
float64[]         data          # array of data
""",
    "rosgraph_msgs/msg/Clock": """\
# This message communicates the current time.
#
# For more information, see https://design.ros2.org/articles/clock_and_time.html.
builtin_interfaces/Time clock
""",
    "diagnostic_msgs/msg/KeyValue": """\
# What to label this value when viewing.
string key
# A value to track over time.
string value
""",
    "diagnostic_msgs/msg/DiagnosticStatus": """\
# This message holds the status of an individual component of the robot.

# Possible levels of operations.
byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3

# Level of operation enumerated above.
byte level
# A description of the test/component reporting.
string name
# A description of the status.
string message
# A hardware unique string.
string hardware_id
# An array of values associated with the status.
KeyValue[] values

""",
    "diagnostic_msgs/msg/DiagnosticArray": """\
# This message is used to send diagnostic information about the state of the robot.
std_msgs/Header header # for timestamp
DiagnosticStatus[] status # an array of components being reported on
""",
}


# --------------------------------------------------------------------------------------
# .msg parsing, rosbag2 concatenated definitions, REP-2011 type hashes
# --------------------------------------------------------------------------------------
# msg primitive -> (struct code, size, numpy dtype, REP-2011 FieldType id)
_PRIMITIVES: dict[str, tuple[str, int, str, int]] = {
    "bool": ("?", 1, "?", 15),
    "byte": ("B", 1, "u1", 16),   # IDL octet
    "char": ("B", 1, "u1", 3),    # IDL uint8
    "int8": ("b", 1, "i1", 2),
    "uint8": ("B", 1, "u1", 3),
    "int16": ("h", 2, "i2", 4),
    "uint16": ("H", 2, "u2", 5),
    "int32": ("i", 4, "i4", 6),
    "uint32": ("I", 4, "u4", 7),
    "int64": ("q", 8, "i8", 8),
    "uint64": ("Q", 8, "u8", 9),
    "float32": ("f", 4, "f4", 10),
    "float64": ("d", 8, "f8", 11),
}
_STRING_ID, _BOUNDED_STRING_ID, _NESTED_ID = 17, 21, 1

# kind: "" scalar, "fixed" T[N], "bounded" T[<=N], "seq" T[]
_Field = namedtuple("_Field", "name base kind size string_bound default")

_FIELD_RE = re.compile(
    r"^(?P<type>[A-Za-z][A-Za-z0-9_/]*)(?:<=(?P<sbound>\d+))?"
    r"(?:\[(?P<bounded><=)?(?P<size>\d*)\])?\s+(?P<name>[A-Za-z][A-Za-z0-9_]*)"
    r"(?P<rest>.*)$"
)


def canonical_type(msg_type: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    parts = msg_type.strip().split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and all(parts):
        return msg_type.strip()
    raise ValueError(f"not a ROS 2 message type name: {msg_type!r} (expected pkg/msg/Type)")


def _strip_comment(line: str) -> str:
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
    return line


def _parse_default(base: str, kind: str, text: str) -> Any:
    text = text.strip()
    if not text:
        return None
    if kind:
        items = [t.strip() for t in text.strip()[1:-1].split(",") if t.strip()]
        return [_parse_default(base, "", t) for t in items]
    if base == "string":
        return text[1:-1] if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'" else text
    if base == "bool":
        return text.lower() in ("true", "1")
    if base in ("float32", "float64"):
        return float(text)
    return int(text, 0)


def _parse_msg(pkg: str, text: str, type_name: str) -> list[_Field]:
    """Fields of one .msg text (constants are skipped, as REP 2011 does)."""
    fields = []
    for raw in text.splitlines():
        line = _strip_comment(raw).strip()
        if not line:
            continue
        m = _FIELD_RE.match(line)
        if m is None:
            raise ValueError(f"{type_name}: cannot parse definition line {raw.strip()!r}")
        rest = m.group("rest")
        if rest.lstrip().startswith("="):
            continue  # a constant
        base = m.group("type")
        if base in _PRIMITIVES or base == "string":
            pass
        elif base in ("wstring", "time", "duration"):
            raise ValueError(f"{type_name}: field type {base!r} is not supported")
        else:
            parts = base.split("/")
            if len(parts) == 1:
                base = f"{pkg}/msg/{base}"
            else:
                base = canonical_type(base)
        if m.group("sbound") and base != "string":
            raise ValueError(f"{type_name}: bound on non-string type in {raw.strip()!r}")
        if m.group("size") is None:
            kind, size = "", 0
        elif m.group("bounded"):
            kind, size = "bounded", int(m.group("size"))
        elif m.group("size"):
            kind, size = "fixed", int(m.group("size"))
        else:
            kind, size = "seq", 0
        sbound = int(m.group("sbound")) if m.group("sbound") else 0
        fields.append(_Field(m.group("name"), base, kind, size, sbound,
                             _parse_default(base, kind, rest)))
    return fields


class _Registry(dict):
    """type name (pkg/msg/Type) -> list of fields."""

    def fields(self, msg_type: str) -> list[_Field]:
        try:
            return self[msg_type]
        except KeyError:
            raise ValueError(f"no message definition for {msg_type}") from None


_EMBEDDED: _Registry | None = None


def _embedded() -> _Registry:
    global _EMBEDDED
    if _EMBEDDED is None:
        reg = _Registry()
        for name, text in MSG_FILES.items():
            reg[name] = _parse_msg(name.split("/")[0], text, name)
        _EMBEDDED = reg
    return _EMBEDDED


def _parse_concatenated(root_type: str, text: str) -> _Registry:
    """Registry from a rosbag2/ros2msg concatenated definition (root first)."""
    reg = _Registry()
    name = canonical_type(root_type)
    for i, section in enumerate(re.split(r"^={3,}[ \t]*$", text, flags=re.MULTILINE)):
        lines = section.strip("\n").splitlines()
        if i == 0 and not section.strip():
            continue  # no root text before the first separator
        if i > 0:
            while lines and not lines[0].strip():
                lines.pop(0)
            if not lines or not lines[0].startswith("MSG:"):
                raise ValueError(f"{root_type}: definition section without 'MSG:' line")
            name = canonical_type(lines.pop(0)[4:].strip())
        reg[name] = _parse_msg(name.split("/")[0], "\n".join(lines), name)
    # some writers leave builtin_interfaces out of the concatenated text
    time_fields = _embedded()["builtin_interfaces/msg/Time"]
    reg.setdefault("builtin_interfaces/msg/Time", time_fields)
    reg.setdefault("builtin_interfaces/msg/Duration", time_fields)  # same layout
    return reg


# rosbag2_storage_mcap message_definition_cache.cpp, same regex and order
_DEP_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_DEF_PRIMITIVES = set(_PRIMITIVES) | {"string"}


def message_definition(msg_type: str) -> str:
    """The ``ros2msg`` schema text rosbag2 writes for a built-in type: its .msg text,
    then for each dependency (sorted, depth first, each once) a line of 80 ``=``,
    ``MSG: <name as written>`` and that type's .msg text."""
    seen: set[str] = set()

    def text_of(name: str) -> tuple[str, str]:
        full = canonical_type(name)
        try:
            return full.split("/")[0], MSG_FILES[full]
        except KeyError:
            raise ValueError(f"no built-in .msg definition for {name}") from None

    def rec(name: str, depth: int) -> str:
        if depth <= 0:
            raise ValueError(f"definition of {msg_type} nests too deeply")
        pkg, text = text_of(name)
        deps = set()
        for m in _DEP_RE.finditer(text):
            t = m.group(1)
            if t not in _DEF_PRIMITIVES:
                deps.add(t if "/" in t else f"{pkg}/{t}")
        out = text
        for dep in sorted(deps):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + "=" * 80 + "\nMSG: " + dep + "\n" + rec(dep, depth - 1)
        return out

    return rec(canonical_type(msg_type), 50)


def _field_type_description(f: _Field) -> dict:
    if f.base in _PRIMITIVES:
        tid = _PRIMITIVES[f.base][3]
    elif f.base == "string":
        tid = _BOUNDED_STRING_ID if f.string_bound else _STRING_ID
    else:
        tid = _NESTED_ID
    tid += {"": 0, "fixed": 48, "bounded": 96, "seq": 144}[f.kind]
    return {
        "type_id": tid,
        "capacity": f.size if f.kind in ("fixed", "bounded") else 0,
        "string_capacity": f.string_bound,
        "nested_type_name": "" if (f.base in _PRIMITIVES or f.base == "string") else f.base,
    }


def _type_description_entry(reg: _Registry, name: str) -> dict:
    fields = reg.fields(name) or [_Field("structure_needs_at_least_one_member", "uint8", "", 0, 0, None)]
    return {"type_name": name,
            "fields": [{"name": f.name, "type": _field_type_description(f)} for f in fields]}


def type_hash(msg_type: str, registry: Mapping[str, list] | None = None) -> str:
    """REP-2011 ``RIHS01_<sha256>`` of a type (default: the built-in definitions).

    sha256 over the JSON of ``{type_description, referenced_type_descriptions}`` with
    default values removed, separators ``", "``/``": "``, references sorted by name --
    what rosidl_generator_type_description computes at build time."""
    reg = registry if registry is not None else _embedded()
    root = canonical_type(msg_type)
    refs: set[str] = set()
    stack = [root]
    while stack:
        for f in reg.fields(stack.pop()):
            if f.base not in _PRIMITIVES and f.base != "string" and f.base not in refs:
                refs.add(f.base)
                stack.append(f.base)
    doc = {"type_description": _type_description_entry(reg, root),
           "referenced_type_descriptions": [_type_description_entry(reg, r) for r in sorted(refs)]}
    text = json.dumps(doc, ensure_ascii=True, allow_nan=False, separators=(", ", ": "))
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------
# CDR (XCDR1, as rmw_fastrtps serialises ROS 2 messages) driven by the definitions
# --------------------------------------------------------------------------------------
class DecodedMessage(SimpleNamespace):
    """A message read from a recording: fields are attributes, like an rclpy message.

    Nested messages are DecodedMessage, numeric arrays are numpy arrays, ``string`` is
    ``str``, ``byte``/``char`` are ``int``.  The ROS type name is ``type(m).msg_type``."""

    msg_type = ""


_MISSING = object()


def _object_msg_type(obj: Any) -> str | None:
    cls = type(obj)
    t = getattr(cls, "msg_type", None) if isinstance(obj, DecodedMessage) else None
    if t:
        return t
    mod = cls.__module__.split(".")
    if len(mod) >= 2 and mod[1] == "msg":
        return f"{mod[0]}/msg/{cls.__name__}"
    return None


class _Codec:
    """Encode/decode one message type (and its nested types) from a registry."""

    def __init__(self, registry: _Registry, msg_type: str):
        self.reg = registry
        self.msg_type = canonical_type(msg_type)
        registry.fields(self.msg_type)  # fail early
        self._classes: dict[str, type] = {}

    # ---- encode ----
    def encode(self, msg: Any) -> bytes:
        out = bytearray(b"\x00\x01\x00\x00")
        self._enc_struct(self.msg_type, msg, out, self.msg_type)
        return bytes(out)

    @staticmethod
    def _align(out: bytearray, n: int) -> None:
        pad = -(len(out) - 4) % n
        if pad:
            out += bytes(pad)

    def _enc_struct(self, name: str, msg: Any, out: bytearray, path: str) -> None:
        fields = self.reg.fields(name)
        if isinstance(msg, Mapping):
            unknown = set(msg) - {f.name for f in fields}
            if unknown:
                raise ValueError(f"{path}: unknown field(s) {sorted(unknown)} for {name}")
            get = lambda f: msg.get(f.name, _MISSING)  # noqa: E731
        else:
            t = _object_msg_type(msg)
            if t is not None and t != name:
                raise TypeError(f"{path}: got a {t} message where {name} is expected")
            get = lambda f: getattr(msg, f.name, _MISSING)  # noqa: E731
        if not fields:
            out += b"\x00"  # structure_needs_at_least_one_member
        for f in fields:
            value = get(f)
            fpath = f"{path}.{f.name}"
            if value is _MISSING:
                if not isinstance(msg, Mapping):
                    raise ValueError(f"{fpath}: missing field of {name}")
                value = self._default(f)
            try:
                self._enc_field(f, value, out, fpath)
            except (struct.error, OverflowError, TypeError, ValueError) as exc:
                if isinstance(exc, (TypeError, ValueError)) and str(exc).startswith(fpath):
                    raise
                raise ValueError(f"{fpath}: cannot encode {type(value).__name__} as "
                                 f"{f.base}{'[]' if f.kind else ''}: {exc}") from None

    def _default(self, f: _Field) -> Any:
        if f.default is not None:
            return f.default
        if f.kind == "fixed":
            return [self._scalar_default(f)] * f.size if f.base not in _PRIMITIVES else np.zeros(
                f.size, dtype=_PRIMITIVES[f.base][2])
        if f.kind:
            return []
        return self._scalar_default(f)

    def _scalar_default(self, f: _Field) -> Any:
        if f.base == "string":
            return ""
        if f.base in _PRIMITIVES:
            return False if f.base == "bool" else 0
        return {}

    def _enc_scalar(self, base: str, value: Any, out: bytearray, path: str) -> None:
        if base == "string":
            if not isinstance(value, str):
                raise ValueError(f"{path}: expected str, got {type(value).__name__}")
            b = value.encode("utf-8")
            self._align(out, 4)
            out += struct.pack("<I", len(b) + 1)
            out += b
            out += b"\x00"
        elif base in _PRIMITIVES:
            code, size, _, _ = _PRIMITIVES[base]
            if isinstance(value, (bytes, bytearray)) and len(value) == 1 and code == "B":
                value = value[0]  # rclpy represents ``byte`` as a 1-byte bytes object
            elif code in "fd" and isinstance(value, (bool, np.bool_)):
                raise ValueError(f"{path}: bool given for {base}")
            self._align(out, size)
            out += struct.pack("<" + code, value)
        else:
            self._enc_struct(base, value, out, path)

    def _enc_field(self, f: _Field, value: Any, out: bytearray, path: str) -> None:
        if not f.kind:
            if f.base == "string" and f.string_bound and len(value) > f.string_bound:
                raise ValueError(f"{path}: string longer than its bound {f.string_bound}")
            self._enc_scalar(f.base, value, out, path)
            return
        if f.base in _PRIMITIVES:
            code, size, dtype, _ = _PRIMITIVES[f.base]
            if isinstance(value, (bytes, bytearray, memoryview)) and size == 1:
                arr = np.frombuffer(value, dtype=dtype)
            else:
                arr = np.asarray(value)
                if arr.dtype.kind in "fc" and dtype[0] in "iub?" and arr.size:
                    raise ValueError(f"{path}: float values for {f.base}[]")
                arr = arr.astype("<" + dtype if size > 1 else dtype, copy=False).reshape(-1)
            n = arr.size
        else:
            value = list(value)
            n = len(value)
        if f.kind == "fixed" and n != f.size:
            raise ValueError(f"{path}: {n} elements for a {f.base}[{f.size}]")
        if f.kind == "bounded" and n > f.size:
            raise ValueError(f"{path}: {n} elements for a {f.base}[<={f.size}]")
        if f.kind != "fixed":
            self._align(out, 4)
            out += struct.pack("<I", n)
        if f.base in _PRIMITIVES:
            if n:
                self._align(out, size)
                out += arr.tobytes()
        else:
            for i, item in enumerate(value):
                if f.base == "string" and f.string_bound and len(item) > f.string_bound:
                    raise ValueError(f"{path}[{i}]: string longer than its bound {f.string_bound}")
                self._enc_scalar(f.base, item, out, f"{path}[{i}]")

    # ---- decode ----
    def decode(self, data: bytes | memoryview) -> DecodedMessage:
        buf = memoryview(data)
        if len(buf) < 4 or buf[0] != 0 or buf[1] not in (0, 1):
            raise ValueError(f"{self.msg_type}: not a CDR payload (header {bytes(buf[:4])!r})")
        self._end = "<" if buf[1] == 1 else ">"
        msg, pos = self._dec_struct(self.msg_type, buf, 4)
        return msg

    def _cls(self, name: str) -> type:
        cls = self._classes.get(name)
        if cls is None:
            cls = type(name.split("/")[-1], (DecodedMessage,), {"msg_type": name, "__slots__": ()})
            self._classes[name] = cls
        return cls

    def _unpack(self, code: str, size: int, buf: memoryview, pos: int) -> tuple[Any, int]:
        pos += -(pos - 4) % size
        if pos + size > len(buf):
            raise ValueError(f"{self.msg_type}: CDR payload is truncated")
        return struct.unpack_from(self._end + code, buf, pos)[0], pos + size

    def _dec_scalar(self, base: str, buf: memoryview, pos: int) -> tuple[Any, int]:
        if base == "string":
            n, pos = self._unpack("I", 4, buf, pos)
            if n == 0 or pos + n > len(buf):
                raise ValueError(f"{self.msg_type}: bad string in CDR payload")
            return bytes(buf[pos:pos + n - 1]).decode("utf-8"), pos + n
        if base in _PRIMITIVES:
            code, size, _, _ = _PRIMITIVES[base]
            return self._unpack(code, size, buf, pos)
        return self._dec_struct(base, buf, pos)

    def _dec_struct(self, name: str, buf: memoryview, pos: int) -> tuple[Any, int]:
        fields = self.reg.fields(name)
        values = {}
        if not fields:
            pos += 1
        for f in fields:
            if not f.kind:
                values[f.name], pos = self._dec_scalar(f.base, buf, pos)
                continue
            if f.kind == "fixed":
                n = f.size
            else:
                n, pos = self._unpack("I", 4, buf, pos)
            if f.base in _PRIMITIVES:
                _, size, dtype, _ = _PRIMITIVES[f.base]
                if n:
                    pos += -(pos - 4) % size
                if pos + n * size > len(buf):
                    raise ValueError(f"{self.msg_type}: CDR payload is truncated")
                dt = np.dtype(self._end + dtype if size > 1 else dtype)
                values[f.name] = np.frombuffer(buf, dtype=dt, count=n, offset=pos).astype(
                    dt.newbyteorder("="), copy=True)
                pos += n * size
            else:
                items = []
                for _ in range(n):
                    item, pos = self._dec_scalar(f.base, buf, pos)
                    items.append(item)
                values[f.name] = items
        return self._cls(name)(**values), pos


_CODECS: dict[str, _Codec] = {}


def _builtin_codec(msg_type: str) -> _Codec:
    name = canonical_type(msg_type)
    codec = _CODECS.get(name)
    if codec is None:
        if name not in MSG_FILES:
            raise ValueError(f"no built-in definition for {msg_type}; known: {sorted(MSG_FILES)}")
        codec = _CODECS[name] = _Codec(_embedded(), name)
    return codec


def serialize(msg_type: str, message: Any) -> bytes:
    """CDR bytes of a built-in type from an rclpy message, a DecodedMessage or a dict
    (missing keys take the field's default; unknown keys are an error)."""
    return _builtin_codec(msg_type).encode(message)


def deserialize(msg_type: str, data: bytes) -> DecodedMessage:
    """Decode CDR bytes of a built-in type."""
    return _builtin_codec(msg_type).decode(data)


def message_to_dict(msg: Any) -> Any:
    """Plain dict/list/float/int/str form of a decoded (or rclpy) message."""
    if isinstance(msg, DecodedMessage):
        return {k: message_to_dict(v) for k, v in vars(msg).items()}
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: message_to_dict(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [message_to_dict(v) for v in msg]
    return msg


# --------------------------------------------------------------------------------------
# QoS profiles (rosbag2 metadata version 9 spelling)
# --------------------------------------------------------------------------------------
_INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE
_QOS_KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan",
             "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions")
_QOS_ENUMS = {
    "history": {"system_default", "keep_last", "keep_all", "unknown"},
    "reliability": {"system_default", "reliable", "best_effort", "unknown", "best_available"},
    "durability": {"system_default", "transient_local", "volatile", "unknown", "best_available"},
    "liveliness": {"system_default", "automatic", "manual_by_topic", "unknown", "best_available"},
}
QOS_PRESETS: dict[str, dict] = {
    "default": {"history": "keep_last", "depth": 10, "reliability": "reliable",
                "durability": "volatile"},
    "transient_local": {"history": "keep_last", "depth": 1, "reliability": "reliable",
                        "durability": "transient_local"},
    "best_effort": {"history": "keep_last", "depth": 10, "reliability": "best_effort",
                    "durability": "volatile"},
    "sensor_data": {"history": "keep_last", "depth": 5, "reliability": "best_effort",
                    "durability": "volatile"},
}


def _full_profile(values: Mapping[str, Any]) -> dict:
    unknown = set(values) - set(_QOS_KEYS)
    if unknown:
        raise ValueError(f"unknown QoS key(s) {sorted(unknown)}; known: {list(_QOS_KEYS)}")
    # what a publisher with these settings offers once the RMW resolved its defaults
    p = {"history": "keep_last", "depth": 10, "reliability": "reliable",
         "durability": "volatile", "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE),
         "liveliness": "automatic", "liveliness_lease_duration": dict(_INFINITE),
         "avoid_ros_namespace_conventions": False}
    p.update(values)
    for key, allowed in _QOS_ENUMS.items():
        if not isinstance(p[key], str) or p[key].lower() not in allowed:
            raise ValueError(f"QoS {key}={p[key]!r}; expected one of {sorted(allowed)}")
        p[key] = p[key].lower()
    for key in ("deadline", "lifespan", "liveliness_lease_duration"):
        v = p[key]
        if not (isinstance(v, Mapping) and set(v) == {"sec", "nsec"}):
            raise ValueError(f"QoS {key}={v!r}; expected {{sec: ..., nsec: ...}}")
        p[key] = {"sec": int(v["sec"]), "nsec": int(v["nsec"])}
    if isinstance(p["depth"], bool) or not isinstance(p["depth"], int) or p["depth"] < 0:
        raise ValueError(f"QoS depth={p['depth']!r}; expected an integer >= 0")
    p["avoid_ros_namespace_conventions"] = bool(p["avoid_ros_namespace_conventions"])
    return {k: p[k] for k in _QOS_KEYS}


def _from_rclpy_profile(q: Any) -> dict:
    def dur(d: Any) -> dict:
        ns = int(getattr(d, "nanoseconds", 0))
        return {"sec": ns // 10**9, "nsec": ns % 10**9}
    return _full_profile({
        "history": q.history.name.lower(), "depth": int(q.depth),
        "reliability": q.reliability.name.lower(), "durability": q.durability.name.lower(),
        "deadline": dur(q.deadline), "lifespan": dur(q.lifespan),
        "liveliness": q.liveliness.name.lower(),
        "liveliness_lease_duration": dur(q.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": q.avoid_ros_namespace_conventions,
    })


def qos_profiles(qos: Any = None) -> list[dict]:
    """The offered QoS profile list recorded for a topic.

    ``qos``: None (reliable, volatile, keep_last 10), a preset name from
    :data:`QOS_PRESETS`, a dict of overrides, an ``rclpy.qos.QoSProfile``, a list of
    those, or a YAML string as found in a recording (``offered_qos_profiles``)."""
    if qos is None:
        return [_full_profile({})]
    if isinstance(qos, str):
        if qos in QOS_PRESETS:
            return [_full_profile(QOS_PRESETS[qos])]
        if not qos.strip():
            return []
        try:
            loaded = yaml.safe_load(qos)
        except yaml.YAMLError as exc:
            raise ValueError(f"QoS {qos!r} is neither a preset {sorted(QOS_PRESETS)} "
                             f"nor YAML: {exc}") from None
        if not isinstance(loaded, (list, dict)):
            raise ValueError(f"QoS {qos!r} is neither a preset {sorted(QOS_PRESETS)} "
                             "nor a YAML profile list")
        return qos_profiles(loaded)
    if isinstance(qos, Mapping):
        return [_full_profile(qos)]
    if isinstance(qos, (list, tuple)):
        return [p for q in qos for p in qos_profiles(q)]
    if all(hasattr(qos, a) for a in ("history", "depth", "reliability", "durability")):
        return [_from_rclpy_profile(qos)]
    raise TypeError(f"cannot make a QoS profile from {type(qos).__name__}")


class _Dumper(yaml.SafeDumper):
    """Block YAML with indented sequences, as yaml-cpp (rosbag2) writes it."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)


def _dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_Dumper, default_flow_style=False, sort_keys=False,
                     allow_unicode=True, width=1 << 16)


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------
def _mcap_writer_module():
    try:
        from mcap import writer as mcap_writer
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RecordingError("MCAP recording needs the 'mcap' package "
                             "(pip install 'jident_ros[mcap]')") from exc
    return mcap_writer


class _DirectFile:
    """Unbuffered append-only file for the mcap Writer: every ``write`` goes to the OS
    at once, so a completed chunk survives SIGKILL of the writing process."""

    def __init__(self, path: Path):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        n = len(view)
        while view:
            written = os.write(self._fd, view)
            view = view[written:]
        self._pos += n
        return n

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


class _Topic:
    __slots__ = ("name", "msg_type", "channel_id", "codec", "qos", "type_hash", "fmt",
                 "count", "sequence")

    def __init__(self, name, msg_type, channel_id, codec, qos, type_hash, fmt="cdr"):
        self.name, self.msg_type, self.channel_id = name, msg_type, channel_id
        self.codec, self.qos, self.type_hash, self.fmt = codec, qos, type_hash, fmt
        self.count = 0
        self.sequence = 0


def _ros_distro() -> str:
    return os.environ.get("ROS_DISTRO", "")


class BagWriter:
    """Write a rosbag2-compatible MCAP bag directory (see the module docstring).

    ``bag_dir`` must not exist or be empty; it receives ``<name>_0.mcap`` and, on
    :meth:`close`, ``metadata.yaml``.  ``chunk_size``: bytes of messages per chunk
    before it is written; ``flush_every_s``: the longest time a message waits in the
    open chunk (``None``: only size and explicit flushes); ``compression``: ``"zstd"``,
    ``"lz4"`` or ``None`` (per chunk); ``fsync``: also fsync each written chunk (power
    loss, not just process death); ``custom_data``: str->str for ``metadata.yaml``.

    Thread-safe.  Use as a context manager or call :meth:`close`.
    """

    def __init__(self, bag_dir: str | os.PathLike, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_every_s: float | None = 1.0, compression: str | None = "zstd", *,
                 fsync: bool = False, custom_data: Mapping[str, str] | None = None):
        mw = _mcap_writer_module()
        comp = {"zstd": mw.CompressionType.ZSTD, "lz4": mw.CompressionType.LZ4,
                None: mw.CompressionType.NONE, "none": mw.CompressionType.NONE,
                "": mw.CompressionType.NONE}
        if compression not in comp:
            raise ValueError(f"compression={compression!r}; expected 'zstd', 'lz4' or None")
        if not isinstance(chunk_size, int) or chunk_size < 1:
            raise ValueError(f"chunk_size={chunk_size!r}; expected an integer >= 1")
        if flush_every_s is not None and not flush_every_s > 0:
            raise ValueError(f"flush_every_s={flush_every_s!r}; expected a number > 0 or None")
        if custom_data is not None and not all(isinstance(k, str) and isinstance(v, str)
                                               for k, v in custom_data.items()):
            raise ValueError("custom_data must map str to str")
        self.bag_dir = Path(bag_dir)
        if self.bag_dir.exists() and (not self.bag_dir.is_dir() or any(self.bag_dir.iterdir())):
            raise FileExistsError(f"{self.bag_dir}: already exists and is not an empty directory")
        self.bag_dir.mkdir(parents=True, exist_ok=True)
        self.mcap_path = self.bag_dir / f"{self.bag_dir.resolve().name}_0.mcap"
        self.metadata_path = self.bag_dir / "metadata.yaml"
        self._flush_every_s = flush_every_s
        self._fsync = fsync
        self._custom_data = dict(custom_data) if custom_data else None
        self._lock = threading.RLock()
        self._busy = None                  # thread id inside a writer operation
        self._pending_signal = None        # (signum, previous handler) deferred by a handler
        self._closed = False
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self._count = 0
        self._t_min: int | None = None
        self._t_max: int | None = None
        self._chunk_opened_at: float | None = None
        self._file = _DirectFile(self.mcap_path)
        try:
            self._w = mw.Writer(self._file, chunk_size=chunk_size, compression=comp[compression],
                                enable_crcs=True)
            self._w.start(profile="ros2", library=f"jident_ros; {mw.LIBRARY_IDENTIFIER}")
        except BaseException:
            self._file.close()
            raise
        ref = weakref.ref(self)
        self._atexit = lambda: (ref() is not None and ref().close())
        atexit.register(self._atexit)

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
        return self._count

    @contextmanager
    def _op(self):
        """Lock + mark this thread busy, so that a signal handler running in this
        thread (Python runs them between bytecodes of the main thread) defers closing
        to the end of the operation instead of closing a half-written chunk."""
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
        if self._closed:
            raise RecordingError(f"{self.mcap_path}: writer is closed")

    def add_topic(self, topic: str, msg_type: str, qos: Any = None, *,
                  msgdef: str | None = None, type_hash: str | None = None) -> None:
        """Declare a topic before writing to it (again with the same type: no-op).

        ``msg_type``: e.g. ``std_msgs/msg/Float64MultiArray``; built-in types
        (:data:`MSG_FILES`) need nothing else, other types need ``msgdef`` (the
        concatenated ``ros2msg`` text) and then accept dicts too if it parses, raw CDR
        bytes otherwise.  ``qos``: see :func:`qos_profiles`.  ``type_hash``: the
        RIHS01 string, computed from the definition when omitted."""
        if not isinstance(topic, str) or not topic:
            raise ValueError(f"topic must be a non-empty string, got {topic!r}")
        name = canonical_type(msg_type)
        profiles = qos_profiles(qos)
        with self._op():
            self._check_open()
            existing = self._topics.get(topic)
            if existing is not None:
                if existing.msg_type != name:
                    raise ValueError(f"{topic}: already added with type {existing.msg_type}, "
                                     f"not {name}")
                return
            if msgdef is None:
                codec = _builtin_codec(name)
                text = message_definition(name)
                thash = type_hash if type_hash is not None else globals()["type_hash"](name)
            else:
                text = msgdef
                try:
                    reg = _parse_concatenated(name, msgdef)
                    codec = _Codec(reg, name)
                except ValueError:
                    codec, reg = None, None
                if type_hash is not None:
                    thash = type_hash
                else:
                    try:
                        thash = globals()["type_hash"](name, reg) if reg is not None else ""
                    except ValueError:
                        thash = ""
            schema_id = self._schemas.get(name)
            if schema_id is None:
                schema_id = self._w.register_schema(name=name, encoding="ros2msg",
                                                    data=text.encode("utf-8"))
                self._schemas[name] = schema_id
            qos_text = _dump_yaml(profiles).rstrip("\n") if profiles else ""
            channel_id = self._w.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema_id,
                metadata={"offered_qos_profiles": qos_text, "topic_type_hash": thash})
            self._topics[topic] = _Topic(topic, name, channel_id, codec, profiles, thash)

    def _add_raw_topic(self, topic: str, schema_name: str, schema_encoding: str,
                       schema_data: bytes, message_encoding: str,
                       metadata: Mapping[str, str]) -> None:
        """Copy a channel as found in another MCAP file (used by salvage)."""
        with self._op():
            self._check_open()
            key = f"{schema_encoding}\0{schema_name}\0{hashlib.sha1(schema_data).hexdigest()}"
            schema_id = self._schemas.get(key)
            if schema_id is None:
                schema_id = self._w.register_schema(name=schema_name, encoding=schema_encoding,
                                                    data=schema_data)
                self._schemas[key] = schema_id
            channel_id = self._w.register_channel(topic=topic, message_encoding=message_encoding,
                                                  schema_id=schema_id, metadata=dict(metadata))
            try:
                profiles = qos_profiles(metadata.get("offered_qos_profiles", ""))
            except (ValueError, TypeError):
                profiles = []
            self._topics[topic] = _Topic(topic, schema_name, channel_id, None, profiles,
                                         metadata.get("topic_type_hash", ""), message_encoding)

    def write(self, topic: str, message: Any, log_time_ns: int,
              publish_time_ns: int | None = None, sequence: int | None = None) -> None:
        """Record one message: an rclpy message, a :class:`DecodedMessage`, a dict of
        fields, or already serialised CDR bytes.  ``log_time_ns``: receive time (the
        bag's timestamp); ``publish_time_ns`` defaults to it; ``sequence`` defaults to a
        per-topic counter."""
        log_time = _as_time(log_time_ns, "log_time_ns")
        publish_time = log_time if publish_time_ns is None else _as_time(publish_time_ns,
                                                                         "publish_time_ns")
        with self._op():
            self._check_open()
            t = self._topics.get(topic)
            if t is None:
                raise RecordingError(f"{topic}: not added; call add_topic({topic!r}, <type>) first")
            if isinstance(message, (bytes, bytearray, memoryview)):
                data = bytes(message)
                if t.fmt == "cdr" and (len(data) < 4 or data[0] != 0 or data[1] not in (0, 1)):
                    raise ValueError(f"{topic}: bytes given but not a CDR payload")
            elif t.codec is None:
                raise RecordingError(f"{topic}: no usable definition of {t.msg_type}; "
                                     "write serialised CDR bytes")
            else:
                data = t.codec.encode(message)
            seq = t.sequence if sequence is None else int(sequence)
            self._w.add_message(channel_id=t.channel_id, log_time=log_time, data=data,
                                publish_time=publish_time, sequence=seq & 0xFFFFFFFF)
            t.sequence = seq + 1
            t.count += 1
            self._count += 1
            self._t_min = log_time if self._t_min is None else min(self._t_min, log_time)
            self._t_max = log_time if self._t_max is None else max(self._t_max, log_time)
            now = time.monotonic()
            if self._chunk_opened_at is None:
                self._chunk_opened_at = now
            self._maybe_flush(now)

    def _maybe_flush(self, now: float) -> None:
        if (self._flush_every_s is not None and self._chunk_opened_at is not None
                and now - self._chunk_opened_at >= self._flush_every_s):
            self._flush()

    def maybe_flush(self) -> None:
        """Flush if the open chunk is older than ``flush_every_s`` (for a timer)."""
        with self._op():
            if not self._closed:
                self._maybe_flush(time.monotonic())

    def _flush(self) -> None:
        self._w.flush()
        if self._fsync:
            self._file.fsync()
        self._chunk_opened_at = None

    def flush(self) -> None:
        """Close the open chunk and hand it to the OS (a chunk boundary)."""
        with self._op():
            self._check_open()
            self._flush()

    def bag_metadata(self) -> dict:
        """The ``rosbag2_bagfile_information`` content for the messages so far."""
        start = self._t_min if self._t_min is not None else 0
        duration = (self._t_max - self._t_min) if self._t_min is not None else 0
        rel = self.mcap_path.name
        topics = []
        for t in self._topics.values():
            topics.append({
                "topic_metadata": {
                    "name": t.name,
                    "type": t.msg_type,
                    "serialization_format": t.fmt,
                    "offered_qos_profiles": t.qos,
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            })
        return {
            "version": ROSBAG2_METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self._count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [rel],
            "files": [{"path": rel, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": self._count}],
            "custom_data": self._custom_data,
            "ros_distro": _ros_distro(),
        }

    def close(self) -> None:
        """Finish the MCAP file (last chunk, summary, rosbag2 metadata record) and write
        ``metadata.yaml``.  Idempotent; called by ``with``, at interpreter exit and by the
        handlers of :func:`install_signal_handlers` (deferred to the end of a write
        that the signal interrupted)."""
        with self._lock:
            if self._closed:
                return
            if self._busy == threading.get_ident():
                # re-entered from a signal handler in the middle of an operation:
                # finish when that operation ends (see _op)
                self._pending_signal = self._pending_signal or (None, None)
                return
            self._closed = True
            try:
                atexit.unregister(self._atexit)
            except Exception:  # pragma: no cover
                pass
            meta = self.bag_metadata()
            try:
                self._w.flush()
                self._w.add_metadata("rosbag2", {"serialized_metadata": _dump_yaml(meta)})
                self._w.finish()
                if self._fsync:
                    self._file.fsync()
            finally:
                self._file.close()
            tmp = self.metadata_path.with_suffix(".yaml.tmp")
            tmp.write_text(_dump_yaml({"rosbag2_bagfile_information": meta}), encoding="utf-8")
            os.replace(tmp, self.metadata_path)


def _as_time(value: Any, name: str) -> int:
    if isinstance(value, (bool, float, np.floating)) or not hasattr(value, "__index__"):
        raise TypeError(f"{name} must be an integer number of nanoseconds, got {value!r}")
    v = int(value)
    if not 0 <= v < 2**64:
        raise ValueError(f"{name}={v} is outside 0 .. 2**64-1")
    return v


def _chain_signal(signum: int | None, previous: Any) -> None:
    """After closing on a signal, do what would have happened without our handler."""
    if signum is None:
        return
    if callable(previous):
        previous(signum, None)
    elif previous == signal.SIG_IGN:
        return
    else:  # SIG_DFL (or a handler installed outside Python): die of the signal
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)


def install_signal_handlers(writer: BagWriter,
                            signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> dict:
    """Close ``writer`` on SIGINT/SIGTERM, then continue as before (KeyboardInterrupt
    for SIGINT, death by the signal for SIGTERM, or the previous Python handler).

    For processes that do not run rclpy.  rclpy installs its own SIGINT/SIGTERM
    handling (the executor stops, ``spin`` raises); a node should call
    ``writer.close()`` in the ``finally`` after ``spin`` instead.  Must be called from
    the main thread.  Returns the previous handlers (for ``signal.signal`` to restore)."""
    previous: dict[int, Any] = {}

    def handler(signum, frame):
        prev = previous.get(signum)
        if writer._busy == threading.get_ident():
            writer._pending_signal = (signum, prev)
            return
        writer.close()
        _chain_signal(signum, prev)

    for s in signals:
        previous[s] = signal.signal(s, handler)
    return previous


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
BagMessage = namedtuple("BagMessage", "topic msg_type log_time_ns message")
BagMessage.__doc__ = """One recorded message: topic, type name, receive time (ns) and the
message (a :class:`DecodedMessage`, or CDR ``bytes`` with ``raw=True``)."""


def read_metadata(bag_dir: str | os.PathLike) -> dict:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory's metadata.yaml."""
    path = Path(bag_dir) / "metadata.yaml"
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        return doc["rosbag2_bagfile_information"]
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except (yaml.YAMLError, TypeError, KeyError) as exc:
        raise RecordingError(f"{path}: not rosbag2 metadata ({exc})") from None


def _bag_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise RecordingError(f"{path}: no such file or directory")
    if (path / "metadata.yaml").is_file():
        meta = read_metadata(path)
        if meta.get("storage_identifier") != "mcap":
            raise RecordingError(f"{path}: storage {meta.get('storage_identifier')!r} is not mcap")
        files = [path / Path(p).name for p in meta.get("relative_file_paths") or []]
        missing = [str(p) for p in files if not p.is_file()]
        if missing:
            raise RecordingError(f"{path}: files named in metadata.yaml are missing: {missing}")
        return files
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise RecordingError(f"{path}: no metadata.yaml and no .mcap file")
    return files


def read_bag(path: str | os.PathLike, topics: str | Iterable[str] | None = None, *,
             raw: bool = False) -> Iterator[BagMessage]:
    """Iterate over the messages of a bag directory or an .mcap file in receive-time
    order, as :class:`BagMessage` ``(topic, msg_type, log_time_ns, message)``.

    Reads any finalised ros2 MCAP file whose schemas are ``ros2msg`` (our recordings,
    ``ros2 bag record -s mcap``).  A file without a summary (its writer was killed)
    raises :class:`RecordingError` pointing to :func:`salvage`."""
    files = _bag_files(Path(path))
    selected = None if topics is None else ({topics} if isinstance(topics, str) else set(topics))
    return _iter_files(files, selected, raw)


def _iter_files(files, selected, raw) -> Iterator[BagMessage]:
    for p in files:
        yield from _iter_mcap(p, selected, raw)


def _iter_mcap(path: Path, selected, raw: bool) -> Iterator[BagMessage]:
    try:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader
    except ImportError as exc:  # pragma: no cover
        raise RecordingError("reading MCAP needs the 'mcap' package") from exc
    with open(path, "rb") as f:
        head = f.read(8)
        if head != _MCAP_MAGIC:
            raise RecordingError(f"{path}: not an MCAP file (bad magic)")
        size = f.seek(0, io.SEEK_END)
        tail = b""
        if size >= 8 + _FOOTER_RECORD_SIZE + 8:
            f.seek(size - _FOOTER_RECORD_SIZE - 8)
            tail = f.read()
        if tail[:1] != bytes([_OP_FOOTER]) or tail[-8:] != _MCAP_MAGIC:
            raise RecordingError(
                f"{path}: not finalised (no footer; was the recorder killed?) -- "
                f"recover it with `jident salvage {path} <out_dir>`")
        f.seek(0)
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
        except (McapError, struct.error, ValueError, EOFError, OSError) as exc:
            raise RecordingError(f"{path}: not a readable MCAP file ({exc})") from None
        if summary is None:
            raise RecordingError(f"{path}: MCAP file without a summary section; "
                                 f"rewrite it with `jident salvage {path} <out_dir>`")
        codecs: dict[int, _Codec] = {}
        for schema, channel, message in reader.iter_messages(topics=selected,
                                                             log_time_order=True):
            msg_type = schema.name if schema is not None else ""
            try:
                msg_type = canonical_type(msg_type)
            except ValueError:
                pass  # not a ROS type name; reported as found
            if raw:
                yield BagMessage(channel.topic, msg_type, message.log_time, message.data)
                continue
            codec = codecs.get(channel.id)
            if codec is None:
                if schema is None or schema.encoding != "ros2msg" or \
                        channel.message_encoding != "cdr":
                    raise RecordingError(
                        f"{path}: topic {channel.topic}: cannot decode "
                        f"{channel.message_encoding!r} messages with schema encoding "
                        f"{getattr(schema, 'encoding', None)!r} (read with raw=True or "
                        "select other topics)")
                try:
                    codec = _Codec(_parse_concatenated(schema.name, schema.data.decode("utf-8")),
                                   schema.name)
                except ValueError as exc:
                    raise RecordingError(f"{path}: topic {channel.topic}: {exc}") from None
                codecs[channel.id] = codec
            try:
                decoded = codec.decode(message.data)
            except ValueError as exc:
                raise RecordingError(f"{path}: topic {channel.topic} at {message.log_time}: "
                                     f"{exc}") from None
            yield BagMessage(channel.topic, msg_type, message.log_time, decoded)


# --------------------------------------------------------------------------------------
# Salvage
# --------------------------------------------------------------------------------------
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F
_FOOTER_RECORD_SIZE = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, crc
_OP_NAMES = {1: "header", 2: "footer", 3: "schema", 4: "channel", 5: "message", 6: "chunk",
             7: "message index", 8: "chunk index", 9: "attachment", 0x0A: "attachment index",
             0x0B: "statistics", 0x0C: "metadata", 0x0D: "metadata index",
             0x0E: "summary offset", 0x0F: "data end"}


class _Reader:
    """Bounds-checked little-endian reads of one record body."""

    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise ValueError("record body too short")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def u(self, fmt: str) -> int:
        size = struct.calcsize("<" + fmt)
        return struct.unpack("<" + fmt, self.take(size))[0]

    def string(self) -> str:
        return self.take(self.u("I")).decode("utf-8")

    def str_map(self) -> dict:
        sub = _Reader(self.take(self.u("I")))
        out = {}
        while sub.pos < len(sub.data):
            k = sub.string()
            out[k] = sub.string()
        return out


def _parse_schema(body: bytes):
    r = _Reader(body)
    sid, name, enc = r.u("H"), r.string(), r.string()
    return SimpleNamespace(id=sid, name=name, encoding=enc, data=r.take(r.u("I")))


def _parse_channel(body: bytes):
    r = _Reader(body)
    return SimpleNamespace(id=r.u("H"), schema_id=r.u("H"), topic=r.string(),
                           message_encoding=r.string(), metadata=r.str_map())


def _parse_message(body: bytes):
    r = _Reader(body)
    return SimpleNamespace(channel_id=r.u("H"), sequence=r.u("I"), log_time=r.u("Q"),
                           publish_time=r.u("Q"), data=body[r.pos:])


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame
        return lz4.frame.decompress(data)
    raise ValueError(f"unsupported chunk compression {compression!r}")


def _records(buf, start: int, end: int) -> Iterator[tuple[int, int, int]]:
    """(opcode, body_start, body_end) of each record; stops before an incomplete one."""
    pos = start
    while pos + 9 <= end:
        opcode, length = struct.unpack_from("<BQ", buf, pos)
        body = pos + 9
        if length > end - body:
            return
        yield opcode, body, body + length
        pos = body + length


class _Scan:
    """What a sequential scan of a (possibly truncated) MCAP file could recover."""

    def __init__(self, buf):
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, Any] = {}
        self.items: list[tuple[str, Any]] = []   # ("channel", ch) / ("message", msg)
        self.chunks = 0
        self.good_end = 8
        self.data_end = False
        self.reason = ""
        size = len(buf)
        for opcode, b0, rec_end in _records(buf, 8, size):
            b1 = rec_end
            try:
                if opcode == 0 or 0x10 <= opcode < 0x80:
                    self.reason = f"invalid record opcode 0x{opcode:02x} at offset {b0 - 9}"
                    return
                if opcode == _OP_DATA_END or opcode == _OP_FOOTER:
                    self.good_end = rec_end
                    self.data_end = True
                    self.reason = "complete data section"
                    return
                if opcode == _OP_CHUNK:
                    self._chunk(bytes(buf[b0:b1]))
                    self.chunks += 1
                elif opcode in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
                    self._record(opcode, bytes(buf[b0:b1]), self.items)
            except Exception as exc:  # a damaged record ends the recoverable part
                self.reason = (f"damaged {_OP_NAMES.get(opcode, 'record')} at offset {b0 - 9}: "
                               f"{exc}")
                return
            self.good_end = rec_end
        self.reason = (f"file ends inside the record at offset {self.good_end}"
                       if self.good_end < size else "file ends after the last complete record")

    def _record(self, opcode: int, body: bytes, items: list) -> None:
        if opcode == _OP_SCHEMA:
            s = _parse_schema(body)
            self.schemas[s.id] = s
        elif opcode == _OP_CHANNEL:
            c = _parse_channel(body)
            self.channels[c.id] = c
            items.append(("channel", c))
        else:
            items.append(("message", _parse_message(body)))

    def _chunk(self, body: bytes) -> None:
        r = _Reader(body)
        r.take(16)  # message start / end time
        usize, crc, compression = r.u("Q"), r.u("I"), r.string()
        data = _decompress(compression, r.take(r.u("Q")), usize)
        if len(data) != usize:
            raise ValueError(f"uncompressed size {len(data)} != {usize}")
        if crc and zlib.crc32(data) != crc:
            raise ValueError("CRC mismatch")
        items: list = []
        saved = dict(self.schemas), dict(self.channels)
        try:
            end = 0
            for opcode, b0, b1 in _records(data, 0, len(data)):
                if opcode in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
                    self._record(opcode, data[b0:b1], items)
                end = b1
            if end != len(data):
                raise ValueError("chunk records overrun the chunk")
        except BaseException:
            self.schemas, self.channels = saved
            raise
        self.items.extend(items)


def salvage(source: str | os.PathLike, out_bag_dir: str | os.PathLike, *,
            compression: str | None = "zstd") -> dict:
    """Recover every complete chunk (and unchunked record) of a truncated or damaged
    MCAP file into a new bag directory with a summary and metadata.yaml.

    ``source``: an .mcap file or a bag directory holding one.  Returns a report:
    ``messages_recovered``, ``chunks_recovered``, ``bytes_total``, ``bytes_recovered``,
    ``bytes_lost`` (after the last intact record), ``data_section_complete``,
    ``stop_reason``, ``topics`` (topic -> messages), ``source``, ``output``.
    Raises :class:`SalvageError` naming the file if it is missing or not MCAP."""
    src = Path(source)
    if src.is_dir():
        found = sorted(src.glob("*.mcap"))
        if len(found) != 1:
            raise SalvageError(f"{src}: expected one .mcap file in the directory, "
                               f"found {len(found)}")
        src = found[0]
    if not src.exists():
        raise SalvageError(f"{src}: no such file")
    if not src.is_file():
        raise SalvageError(f"{src}: not a regular file")
    out = Path(out_bag_dir)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SalvageError(f"{out}: already exists and is not an empty directory")
    try:
        with open(src, "rb") as f:
            buf = f.read()
    except OSError as exc:
        raise SalvageError(f"{src}: cannot read ({exc.strerror or exc})") from None
    if len(buf) < 8 or buf[:8] != _MCAP_MAGIC:
        raise SalvageError(f"{src}: not an MCAP file (bad magic)")
    scan = _Scan(memoryview(buf))
    del buf

    topics: dict[str, int] = {}
    by_channel: dict[int, str] = {}
    lost = 0
    with BagWriter(out, compression=compression, flush_every_s=None,
                   custom_data={"salvaged_from": str(src)}) as writer:
        for kind, item in scan.items:
            if kind == "channel":
                if item.topic not in topics:
                    schema = scan.schemas.get(item.schema_id)
                    writer._add_raw_topic(
                        item.topic,
                        schema.name if schema else "", schema.encoding if schema else "",
                        schema.data if schema else b"", item.message_encoding, item.metadata)
                    topics[item.topic] = 0
                by_channel[item.id] = item.topic
                continue
            topic = by_channel.get(item.channel_id)
            if topic is None:
                lost += 1
                continue
            try:
                writer.write(topic, item.data, item.log_time, item.publish_time, item.sequence)
            except ValueError:
                lost += 1
                continue
            topics[topic] += 1
    total = src.stat().st_size
    return {
        "source": str(src),
        "output": str(out),
        "chunks_recovered": scan.chunks,
        "messages_recovered": sum(topics.values()),
        "messages_unusable": lost,
        "bytes_total": total,
        "bytes_recovered": scan.good_end,
        # after a complete data section only the (regenerated) summary follows
        "bytes_lost": 0 if scan.data_end else max(0, total - scan.good_end),
        "data_section_complete": scan.data_end,
        "stop_reason": scan.reason,
        "topics": topics,
    }


def salvage_report_line(report: Mapping[str, Any]) -> str:
    """The one-line summary ``jident salvage`` prints."""
    return (f"salvaged {report['source']}: {report['messages_recovered']} messages in "
            f"{report['chunks_recovered']} complete chunks -> {report['output']}; "
            f"{report['bytes_lost']} of {report['bytes_total']} bytes lost "
            f"({report['stop_reason']})")


def salvage_main(argv: list[str] | None = None) -> int:
    """``jident salvage <truncated.mcap> <out_dir>``: prints one line, returns 0, or
    prints a one-line error naming the file and returns 2."""

    class _Parser(argparse.ArgumentParser):
        def error(self, message):
            raise SalvageError(message)

    parser = _Parser(prog="jident salvage",
                     description="Recover every complete chunk of a truncated MCAP recording "
                                 "into a new bag directory.")
    parser.add_argument("source", help="the .mcap file (or a bag directory holding one)")
    parser.add_argument("out_dir", help="new bag directory to write (must not exist)")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    try:
        args = parser.parse_args(argv)
        report = salvage(args.source, args.out_dir,
                         compression=None if args.compression == "none" else args.compression)
    except (SalvageError, OSError) as exc:
        print(f"jident salvage: error: {exc}", file=sys.stderr)
        return 2
    print(salvage_report_line(report))
    return 0
