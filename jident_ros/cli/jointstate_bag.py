"""JointState bags (``ros2 bag record`` of ``joint_states`` and ``imu``) -> the sample batches that ``jident
diagnose`` feeds its detector (:func:`jident_ros.cli.offline.diagnose_samples`).  An MCAP bag is read with
:mod:`jident_ros.bag.reader`, which decodes only these topics (a foreign bag's unparsable types are skipped with one
line); other storage (sqlite3) with rosbags' AnyReader.  Errors: :class:`~jident_ros.stream.inputs.InputError`,
one line naming the recording."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Optional

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.reader import read_bag, recorded_topics, skipped_topics_line
from jident_ros.stream.inputs import InputError, JointStateAdapter
from jident_ros.stream.layout import topic_matches as _matches

try:  # reading a `ros2 bag record` of /joint_states (any storage, any distro) needs rosbags
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
except ImportError:  # pragma: no cover - the drive/signals path does not need it
    AnyReader = None

__all__ = ["jointstate_batches"]


def jointstate_batches(path, sample_period_s: float, motor_joint: str = "motor", load_joint: str = "load",
                       imu_axis: str = "x", topic: Optional[str] = None, batch_size: int = 50,
                       log: Callable[[str], Any] = lambda text: None):
    """(adapter, batch iterator, joint_states topic) of a `ros2 bag record` bag holding sensor_msgs/JointState
    (topic ending in ``joint_states``, any namespace) and optionally sensor_msgs/Imu (ending in ``imu``); the
    header stamps give t.  An MCAP bag is read with :mod:`jident_ros.bag.reader`, which decodes only these
    topics: topics of types that cannot be parsed (``_service_event`` topics of ``ros2 bag record -a`` on
    Jazzy) are skipped, and ``log`` gets one line naming them.  Other storage (sqlite3) is read with
    rosbags' AnyReader."""
    path = Path(path)
    try:
        infos = recorded_topics(path)
    except RecordingError:
        infos = None                       # not an MCAP recording: rosbags' AnyReader (sqlite3 bags)
    if infos is None:
        return _jointstate_batches_anyreader(path, sample_period_s, motor_joint, load_joint, imu_axis, topic,
                                             batch_size)
    conns = [(t.topic, t.msg_type) for t in infos if not t.problem]
    js, imu = _jointstate_topics(path, conns, topic)
    line = skipped_topics_line(path, infos)
    if line:
        log(line)
    adapter = JointStateAdapter(sample_period_s, motor_joint, load_joint, batch_size=batch_size,
                                use_imu=bool(imu), imu_axis=imu_axis, channels="auto")

    def batches():
        try:
            for m in read_bag(path, [t for t, _ in js + imu]):
                yield from _push_jointstate(adapter, m.msg_type, m.message)
        except RecordingError as exc:
            raise InputError(f"recording {exc}") from None
        yield from adapter.flush()
    return adapter, batches(), js[0][0]


def _jointstate_topics(path, conns, topic):
    """([(joint_states topic, type)], [(imu topic, type)]) among ``conns`` (topic, type), or InputError."""
    js = [c for c in conns if c[1] == "sensor_msgs/msg/JointState" and _matches(c[0], "joint_states")]
    topics = sorted({c[0] for c in js})
    if topic is not None:
        js = [c for c in js if c[0] == topic]
        if not js:
            raise InputError(f"joint_states topic {topic!r}: not in recording {path} (found: {', '.join(topics) or 'none'})")
    elif len(topics) > 1:
        raise InputError(f"recording {path}: several joint_states topics ({', '.join(topics)}); choose one with --topic")
    if not js:
        raise InputError(f"recording {path}: no drive/signals topic and no sensor_msgs/JointState topic ending in "
                           f"joint_states "
                           f"(topics: {', '.join(sorted({c[0] for c in conns})) or 'none'})")
    prefix = js[0][0][:-len("joint_states")]
    imu = [c for c in conns if c[1] == "sensor_msgs/msg/Imu" and c[0] == prefix + "imu"]
    return js, imu


def _push_jointstate(adapter, msg_type: str, msg):
    stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    if msg_type.endswith("Imu"):
        return adapter.push_imu(stamp, msg.linear_acceleration)
    return adapter.push(stamp, msg.name, msg.position, msg.velocity, msg.effort)


def _jointstate_batches_anyreader(path, sample_period_s, motor_joint, load_joint, imu_axis, topic, batch_size):
    if AnyReader is None:
        raise InputError("reading JointState bags needs the rosbags package (pip install rosbags)")
    reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    try:
        reader.open()
    except Exception as exc:
        raise InputError(f"recording {path}: cannot be read as a rosbag2 bag ({type(exc).__name__}: {exc})") from None
    js, imu = _jointstate_topics(path, [(c.topic, c.msgtype) for c in reader.connections], topic)
    wanted = {t for t, _ in js + imu}
    adapter = JointStateAdapter(sample_period_s, motor_joint, load_joint, batch_size=batch_size,
                                use_imu=bool(imu), imu_axis=imu_axis, channels="auto")

    def batches():
        try:
            for conn, _, raw in reader.messages(connections=[c for c in reader.connections if c.topic in wanted]):
                yield from _push_jointstate(adapter, conn.msgtype, reader.deserialize(raw, conn.msgtype))
            yield from adapter.flush()
        finally:
            reader.close()
    return adapter, batches(), js[0][0]
