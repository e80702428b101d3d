"""ROS 2 messages without ROS: CDR, definitions, type hashes and QoS profiles -- all from ``rosbags``.

* :data:`TYPESTORE` is rosbags' Jazzy type store (``get_typestore(Stores.ROS2_JAZZY)``): every message
  type of the ROS 2 core interface packages, with rosbags' CDR codec (``serialize_cdr`` /
  ``deserialize_cdr``), its REP-2011 ``RIHS01_`` hash (``hash_rihs01``) and its ``ros2msg`` definition
  text (``generate_msgdef``).  The hashes of the types we record equal those installed with the ROS 2
  interface packages (test_recording.py compares them with ``share/<pkg>/msg/<Type>.json``).
* :func:`to_store_message` turns what a caller has -- a dict of fields, an rclpy message, a message
  decoded from another bag -- into the store's message class, naming the field path of anything that does
  not fit.  That is the only code here that looks at fields; the bytes are rosbags'.
* QoS profiles are rosbags' :class:`rosbags.interfaces.Qos`, written in the rosbag2 metadata-version-9
  spelling by ``rosbags.rosbag2.metadata.dump_qos_v9`` and read back by ``parse_qos``.

Never imports rclpy.
"""
from __future__ import annotations

import functools
from typing import Any, Mapping

import numpy as np
from rosbags.interfaces import (
    Nodetype,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import dump_qos_v9, parse_qos
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.msg import normalize_msgtype

__all__ = ["TYPESTORE", "QOS_PRESETS", "canonical_type", "deserialize", "deserialize_with", "message_definition",
           "message_to_dict", "qos_dicts", "qos_profiles", "serialize", "to_store_message", "type_hash"]

#: rosbags' type store of ROS 2 Jazzy (the same definitions and hashes as Kilted for the types we record).
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

# primitive msg type -> numpy dtype of its arrays
_DTYPES = {"bool": "?", "byte": "u1", "char": "u1", "octet": "u1", "int8": "i1", "uint8": "u1",
           "int16": "<i2", "uint16": "<u2", "int32": "<i4", "uint32": "<u4", "int64": "<i8", "uint64": "<u8",
           "float32": "<f4", "float64": "<f8"}


def canonical_type(msg_type: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    return _canonical(str(msg_type).strip())


@functools.lru_cache(maxsize=1024)
def _canonical(name: str) -> str:
    """canonical_type of a stripped name, memoised: serialising a message looks up the name of every
    nested type, and rosbags' normalize_msgtype (pathlib underneath) was a third of a dict's
    serialisation time (cProfile of bench/bench_bag.py's writes).  An invalid name is not cached."""
    parts = name.split("/")
    if len(parts) in (2, 3) and all(parts):
        return normalize_msgtype(name)
    raise ValueError(f"not a ROS 2 message type name: {name!r} (expected pkg/msg/Type)")


@functools.lru_cache(maxsize=256)
def _known(msg_type: str) -> str:
    name = canonical_type(msg_type)
    if name not in TYPESTORE.fielddefs:
        raise ValueError(f"no definition of {msg_type} in rosbags' ROS 2 Jazzy type store")
    return name


def message_definition(msg_type: str) -> str:
    """The ``ros2msg`` schema text of a type and its dependencies (rosbags' ``generate_msgdef``)."""
    return TYPESTORE.generate_msgdef(_known(msg_type), ros_version=2)[0]


def type_hash(msg_type: str) -> str:
    """The REP-2011 ``RIHS01_<sha256>`` hash of a type (rosbags' ``hash_rihs01``)."""
    return TYPESTORE.hash_rihs01(_known(msg_type))


# --------------------------------------------------------------------------------------------- messages
def _rclpy_type(obj: Any) -> str | None:
    """``pkg/msg/Type`` of an rclpy message object (its class lives in ``pkg.msg``), else None."""
    mod = type(obj).__module__.split(".")
    if len(mod) >= 2 and mod[1] == "msg" and hasattr(obj, "get_fields_and_field_types"):
        return f"{mod[0]}/msg/{type(obj).__name__}"
    return None


def _scalar(base: str, value: Any, path: str) -> Any:
    if base == "string":
        if not isinstance(value, str):
            raise ValueError(f"{path}: expected str, got {type(value).__name__} {value!r}")
        return value
    if isinstance(value, (bytes, bytearray)) and len(value) == 1 and _DTYPES.get(base) == "u1":
        return value[0]  # rclpy represents ``byte`` as a 1-byte bytes object
    if base == "bool":
        if not isinstance(value, (bool, np.bool_, int, np.integer)):
            raise ValueError(f"{path}: expected bool, got {type(value).__name__} {value!r}")
        return bool(value)
    if base in ("float32", "float64"):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"{path}: expected a number for {base}, got {type(value).__name__} {value!r}")
        return float(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{path}: expected an integer for {base}, got {type(value).__name__} {value!r}")
    info = np.iinfo(_DTYPES[base])
    if not info.min <= int(value) <= info.max:
        raise ValueError(f"{path}: {value} is outside the range of {base} [{info.min}, {info.max}]")
    return int(value)


def _array(base: str, value: Any, path: str) -> np.ndarray:
    if isinstance(value, (bytes, bytearray, memoryview)) and _DTYPES[base] == "u1":
        return np.frombuffer(value, dtype="u1").copy()
    arr = np.asarray(value)
    if arr.size and arr.dtype.kind not in "biuf":
        raise ValueError(f"{path}: expected numbers for {base}[], got {arr.dtype}")
    if arr.size and arr.dtype.kind == "f" and np.dtype(_DTYPES[base]).kind in "biu":
        raise ValueError(f"{path}: float values for {base}[]")
    return np.ascontiguousarray(arr.reshape(-1), dtype=_DTYPES[base])


def _default(desc) -> Any:
    kind, arg = desc
    if kind == Nodetype.BASE:
        base = arg[0]
        return "" if base == "string" else False if base == "bool" else 0.0 if base.startswith("float") else 0
    if kind == Nodetype.NAME:
        return {}
    (sub_kind, sub_arg), size = arg
    if kind == Nodetype.ARRAY:
        if sub_kind == Nodetype.BASE and sub_arg[0] != "string":
            return np.zeros(size, dtype=_DTYPES[sub_arg[0]])
        return [_default((sub_kind, sub_arg))] * size
    return []


def _field(desc, value: Any, path: str) -> Any:
    kind, arg = desc
    if kind == Nodetype.BASE:
        return _scalar(arg[0], value, path)
    if kind == Nodetype.NAME:
        return to_store_message(arg, value, path)
    (sub_kind, sub_arg), size = arg
    if sub_kind == Nodetype.BASE and sub_arg[0] != "string":
        items = _array(sub_arg[0], value, path)
        n = items.size
    else:
        if isinstance(value, (str, bytes, Mapping)):
            raise ValueError(f"{path}: expected a sequence, got {type(value).__name__}")
        items = [_field((sub_kind, sub_arg), v, f"{path}[{i}]") for i, v in enumerate(value)]
        n = len(items)
    if kind == Nodetype.ARRAY and n != size:
        raise ValueError(f"{path}: {n} elements for an array of {size}")
    if kind == Nodetype.SEQUENCE and size and n > size:
        raise ValueError(f"{path}: {n} elements for a sequence of at most {size}")
    return items


def to_store_message(msg_type: str, message: Any, path: str | None = None) -> Any:
    """``message`` as an instance of :data:`TYPESTORE`'s class for ``msg_type``.

    ``message``: a dict of fields (missing keys take the field's zero value, unknown keys are an error),
    an rclpy message, or any object with the type's fields as attributes (a message decoded by rosbags or
    by :func:`deserialize`).  A value that does not fit raises ValueError naming the field path, e.g.
    ``diagnostic_msgs/msg/DiagnosticArray.status[0].level``."""
    name = _known(msg_type)
    path = path or name
    cls = TYPESTORE.types[name]
    if type(message) is cls:
        return message
    fields = TYPESTORE.fielddefs[name][1]
    if isinstance(message, Mapping):
        unknown = set(message) - {f for f, _ in fields}
        if unknown:
            raise ValueError(f"{path}: unknown field(s) {sorted(unknown)} for {name}")
        values = {f: _field(d, message[f] if f in message else _default(d), f"{path}.{f}")
                  for f, d in fields}
    else:
        other = _rclpy_type(message) or getattr(message, "__msgtype__", None)
        if other is not None and canonical_type(other) != name:
            raise TypeError(f"{path}: got a {other} message where {name} is expected")
        values = {}
        for f, d in fields:
            if not hasattr(message, f):
                raise ValueError(f"{path}.{f}: missing field of {name} in a {type(message).__name__}")
            values[f] = _field(d, getattr(message, f), f"{path}.{f}")
    return cls(**values)


def serialize(msg_type: str, message: Any) -> bytes:
    """Little-endian CDR bytes of ``message`` (see :func:`to_store_message`), by rosbags."""
    name = _known(msg_type)
    obj = to_store_message(name, message)
    try:
        return bytes(TYPESTORE.serialize_cdr(obj, name))
    except (SerdeError, ValueError, TypeError, OverflowError) as exc:  # a value rosbags cannot pack
        raise ValueError(f"{name}: cannot serialise: {exc}") from None


def deserialize_with(store, data: bytes | memoryview, msg_type: str) -> Any:
    """``store.deserialize_cdr(data, msg_type)``, also for a payload that ends in more than 3 bytes of
    alignment padding: rmw_fastrtps pads e.g. an empty ``float64[]`` to 8 bytes, where rosbags allows 3
    trailing bytes.  Then the padding (at most 7 bytes) is dropped and the decode retried."""
    try:
        return store.deserialize_cdr(data, msg_type)
    except SerdeError as exc:
        if "size mismatch" not in str(exc):
            raise
        view = memoryview(data)
        for cut in (4, 7):
            if len(view) - cut >= 4:
                try:
                    return store.deserialize_cdr(view[:len(view) - cut], msg_type)
                except SerdeError:
                    continue
        raise


def deserialize(msg_type: str, data: bytes | memoryview) -> Any:
    """Decode CDR bytes of a type of :data:`TYPESTORE` (rosbags' ``deserialize_cdr``): fields are
    attributes, numeric arrays numpy arrays (read-only views of ``data``).  Raises ValueError."""
    name = _known(msg_type)
    try:
        return deserialize_with(TYPESTORE, data, name)
    except (SerdeError, ValueError, IndexError) as exc:
        raise ValueError(f"{name}: undecodable CDR payload ({exc})") from None


def message_to_dict(msg: Any) -> Any:
    """Plain dict/list/float/int/str form of a decoded (rosbags or rclpy) message."""
    msgtype = getattr(msg, "__msgtype__", None)
    if msgtype is not None and not isinstance(msg, type):
        defs = TYPESTORE.fielddefs.get(msgtype)
        names = [f for f, _ in defs[1]] if defs else [k for k in vars(msg) if not k.startswith("_")]
        return {k: message_to_dict(getattr(msg, k)) for k in names}
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: message_to_dict(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [message_to_dict(v) for v in msg]
    return msg


# --------------------------------------------------------------------------------------------- QoS
_INFINITE = QosTime(9223372036, 854775807)  # RMW_DURATION_INFINITE as rosbag2 writes it
_ENUMS = {"history": QosHistory, "reliability": QosReliability, "durability": QosDurability,
          "liveliness": QosLiveliness}
_QOS_KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
             "liveliness_lease_duration", "avoid_ros_namespace_conventions")
#: Named QoS profiles accepted by :func:`qos_profiles` (overrides of the default profile).
QOS_PRESETS: dict[str, dict] = {
    "default": {},
    "transient_local": {"depth": 1, "durability": "transient_local"},
    "best_effort": {"reliability": "best_effort"},
    "sensor_data": {"depth": 5, "reliability": "best_effort"},
}


def _qos_from_dict(values: Mapping[str, Any]) -> Qos:
    unknown = set(values) - set(_QOS_KEYS)
    if unknown:
        raise ValueError(f"unknown QoS key(s) {sorted(unknown)}; known: {list(_QOS_KEYS)}")
    # what a publisher with these settings offers once the RMW resolved its defaults
    full = {"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
            "deadline": _INFINITE, "lifespan": _INFINITE, "liveliness": "automatic",
            "liveliness_lease_duration": _INFINITE, "avoid_ros_namespace_conventions": False, **values}
    for key, enum in _ENUMS.items():
        v = full[key]
        if not isinstance(v, enum):
            if not isinstance(v, str) or v.upper() not in enum.__members__:
                raise ValueError(f"QoS {key}={v!r}; expected one of {[m.lower() for m in enum.__members__]}")
            full[key] = enum.__members__[v.upper()]
    for key in ("deadline", "lifespan", "liveliness_lease_duration"):
        v = full[key]
        if isinstance(v, Mapping) and set(v) == {"sec", "nsec"}:
            full[key] = QosTime(int(v["sec"]), int(v["nsec"]))
        elif not isinstance(v, QosTime):
            raise ValueError(f"QoS {key}={v!r}; expected {{sec: ..., nsec: ...}}")
    if isinstance(full["depth"], bool) or not isinstance(full["depth"], int) or full["depth"] < 0:
        raise ValueError(f"QoS depth={full['depth']!r}; expected an integer >= 0")
    return Qos(*(full[k] for k in _QOS_KEYS[:8]), bool(full["avoid_ros_namespace_conventions"]))


def _qos_from_rclpy(q: Any) -> Qos:
    def dur(d: Any) -> QosTime:
        ns = int(getattr(d, "nanoseconds", 0))
        return QosTime(ns // 10**9, ns % 10**9)
    return _qos_from_dict({
        "history": q.history.name.lower(), "depth": int(q.depth), "reliability": q.reliability.name.lower(),
        "durability": q.durability.name.lower(), "deadline": dur(q.deadline), "lifespan": dur(q.lifespan),
        "liveliness": q.liveliness.name.lower(), "liveliness_lease_duration": dur(q.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions)})


def qos_profiles(qos: Any = None) -> list[Qos]:
    """The offered QoS profiles recorded for a topic, as rosbags ``Qos``.

    ``qos``: None (reliable, volatile, keep_last 10), a preset name of :data:`QOS_PRESETS`, a dict of
    overrides, an ``rclpy.qos.QoSProfile``, a rosbags ``Qos``, a list of those, or the YAML text of a
    recording's ``offered_qos_profiles`` (read by rosbags' ``parse_qos``)."""
    if qos is None:
        return [_qos_from_dict({})]
    if isinstance(qos, Qos):
        return [qos]
    if isinstance(qos, str):
        if qos in QOS_PRESETS:
            return [_qos_from_dict(QOS_PRESETS[qos])]
        if not qos.strip():
            return []
        try:
            return parse_qos(qos)
        except Exception as exc:  # rosbags raises ReaderError, KeyError, TypeError on odd YAML
            raise ValueError(f"QoS {qos!r} is neither a preset {sorted(QOS_PRESETS)} nor a profile "
                             f"list ({type(exc).__name__}: {exc})") from None
    if isinstance(qos, Mapping):
        return [_qos_from_dict(qos)]
    if isinstance(qos, (list, tuple)):
        return [p for q in qos for p in qos_profiles(q)]
    if all(hasattr(qos, a) for a in ("history", "depth", "reliability", "durability")):
        return [_qos_from_rclpy(qos)]
    raise TypeError(f"cannot make a QoS profile from {type(qos).__name__}")


def qos_dicts(profiles: list[Qos]) -> list[dict]:
    """rosbag2 metadata-version-9 form of QoS profiles (rosbags' ``dump_qos_v9``)."""
    return [dict(d) for d in dump_qos_v9(list(profiles))]
