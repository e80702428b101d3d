"""A per-sample view of a recording for plotting against drive time (Foxglove, PlotJuggler).

``drive/signals`` carries batches (50 samples x 9 channels per message), which a plot panel cannot lay out on a
time axis.  :func:`write_per_sample` writes a new bag with one message per sample on ``/drive/sample``
(std_msgs/Float64MultiArray in the drive/signals layout with one row, so the channel names travel with it), whose
log and publish time are the sample's **drive time** ``t``; the drive's ``drive/case``, ``drive/backlash_width``
and ``drive/true_inertia`` go along on ``/drive/...`` at the drive time of the batch that follows them (publish
order, :func:`~jident_ros.bag.reader.in_publish_order`).  config/foxglove_layout.json plots its channels.
No ROS.
"""
from __future__ import annotations

from pathlib import Path

from jident_ros.bag.drive_replay import in_sample_time_order, read_drive_messages
from jident_ros.bag.errors import RecordingError
from jident_ros.bag.messages import deserialize
from jident_ros.bag.writer import BagWriter
from jident_ros.stream.layout import DRIVE_TOPICS, SIGNALS_TOPIC, LayoutError, pack, topic_matches, unpack

SAMPLE_TOPIC = "/drive/sample"


def _relative(topic: str) -> str | None:
    return next((rel for rel in DRIVE_TOPICS if topic_matches(topic, rel)), None)


def write_per_sample(recording, out_dir, note=lambda text: None) -> dict:
    """Write ``out_dir`` (a new bag) from ``recording``; returns {topic: messages written}."""
    messages, _ = read_drive_messages(recording, RecordingError, note)
    signals = [t for t, _, _ in messages if _relative(t) == SIGNALS_TOPIC]
    if not signals:
        raise RecordingError(f"{recording}: no drive/signals topic")
    ordered = in_sample_time_order(messages, signals[0])
    counts: dict = {}
    pending = []          # case/K2/truth messages waiting for the drive time of the next batch
    with BagWriter(Path(out_dir), custom_data={"per_sample_of": str(recording)}) as bag:
        bag.add_topic(SAMPLE_TOPIC, "std_msgs/msg/Float64MultiArray")
        for topic, msg_type, raw in ordered:
            rel = _relative(topic)
            if rel != SIGNALS_TOPIC:
                pending.append(("/" + rel, msg_type, raw))
                continue
            msg = deserialize(msg_type, raw)
            try:
                arr, channels, _ = unpack(msg.data, msg.layout.dim, msg.layout.data_offset)
            except LayoutError as exc:
                note(f"{topic}: batch skipped: {exc}")
                continue
            if not arr.shape[0] or "t" not in channels:
                continue
            t_col = channels.index("t")
            t0 = max(0, int(round(arr[0, t_col] * 1e9)))
            for name, typ, data in pending:
                bag.add_topic(name, typ, qos="transient_local")
                bag.write(name, data, t0)
                counts[name] = counts.get(name, 0) + 1
            pending = []
            for row in arr:
                flat, dims, offset = pack(row[None, :], channels)
                t_ns = max(0, int(round(row[t_col] * 1e9)))
                bag.write(SAMPLE_TOPIC, {"layout": {"dim": [{"label": d[0], "size": d[1], "stride": d[2]} for d in dims],
                                                    "data_offset": offset}, "data": flat}, t_ns)
                counts[SAMPLE_TOPIC] = counts.get(SAMPLE_TOPIC, 0) + 1
    return counts
