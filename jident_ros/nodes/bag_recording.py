"""The diagnostic node's recorder behind one seam (:class:`Recording`): a rosbag2 MCAP bag of its topics
(docs/recording.md).  Used by :mod:`jident_ros.nodes.diagnostic`."""
from __future__ import annotations

from jident_ros.nodes.recorded_qos import offered_qos

try:  # the recorder needs mcap and rosbags: without them the node runs on and says so
    from jident_ros.bag.rotating_recorder import Recorder, RecorderError
    _BAG_IMPORT_ERROR = None
except ImportError as _exc:  # pragma: no cover - both are install requirements
    Recorder, RecorderError, _BAG_IMPORT_ERROR = None, RuntimeError, _exc


def serialize_message(msg) -> bytes:
    from rclpy.serialization import serialize_message as _serialize
    return _serialize(msg)


class Recording:
    """The node's recorder behind one seam: ``write(name, msg)``, ``flush()``, ``close()`` (idempotent,
    finalises the bag), ``status()``, over :class:`jident_ros.bag.rotating_recorder.Recorder` (rosbag2-named bags
    under ``record_root``, split by size / duration, retention, wall-clock stamps that no /clock can move).
    A failure (disk full) finalises what was written; ``error`` says it and further writes are counted as
    dropped."""

    def __init__(self, node, cfg: dict, topics):
        if Recorder is None:
            raise RuntimeError(f"MCAP recording is unavailable here (jident_ros.bag.rotating_recorder: {_BAG_IMPORT_ERROR})")
        self.node = node
        self.recorder = Recorder(
            cfg["record_root"] or None, bag_dir=cfg["record_dir"] or None,
            max_bag_size_bytes=cfg["max_bag_size_bytes"], max_bag_duration_s=cfg["max_bag_duration_s"],
            retention_max_total_bytes=cfg["retention_max_total_bytes"],
            retention_max_age_s=cfg["retention_max_age_s"],
            retention_delete_unfinalised=cfg["retention_delete_unfinalised"],
            custom_data={"node": node.get_fully_qualified_name()}, log=node.get_logger().info)
        self.bag_dir = str(self.recorder.bag_dir)
        self._summarised = False
        self.topics = {}
        self.offered = {}   # topics of other nodes: added at their first message, with the QoS their publishers offer
        try:
            for name, typ, qos, *subscribed in topics:
                full = node.resolve_topic_name(name)
                if subscribed and subscribed[0]:
                    self.offered[name] = qos
                else:
                    self.recorder.add_topic(full, typ, qos)
                self.topics[name] = (full, typ)
        except Exception:
            self.close()
            raise

    @property
    def open(self) -> bool:
        return not self.recorder.closed

    @property
    def error(self):
        """The recorder's first failure, or None; asked after every write, so read directly (as
        ``Recorder.status()["error"]``) without building the whole status."""
        rec = self.recorder
        bag = rec.bag_writer
        return (bag.error if bag is not None and bag.error else None) or rec.last_error or None

    def write(self, name: str, msg, publish_time_ns: int | None = None) -> None:
        if name in self.topics:   # never raises: drops are counted by reason
            if name in self.offered:
                full, typ = self.topics[name]
                try:
                    self.recorder.add_topic(full, typ, offered_qos(self.node, full, self.offered.pop(name)))
                except ValueError:
                    pass   # a QoS the bag cannot hold: the recorder adds the topic with the default one
            if hasattr(msg, "get_fields_and_field_types"):
                # an rclpy message: rclpy's C serialiser, 20-50x faster than converting it for rosbags' (a
                # DiagnosticArray 2 ms -> 0.05 ms; bench/bench_ros.py --profile, issue 25); same CDR
                try:
                    msg = serialize_message(msg)
                except Exception:  # the recorder's own path then counts it as unrecordable (never raises)
                    pass
            self.recorder.write(*self.topics[name], msg, publish_time_ns=publish_time_ns)

    def flush(self) -> None:
        self.recorder.maybe_flush()

    def close(self) -> None:
        """Finalise the bag and say in one line what it holds (also what was dropped, by reason).  After a
        failure (:meth:`finalise_failed`) it only says the final counts."""
        if self.recorder.closed:
            if not self._summarised:
                self._summarised = True
                self._summary(True)
            return
        self._summarised = True
        self._summary(self.recorder.close())

    def finalise_failed(self) -> None:
        """After a failure (disk full): finalise what was written now, but stay the node's recorder, so that
        every later message is still counted as dropped with the failure's reason (issue 24 item 5)."""
        if not self.recorder.closed:
            self.recorder.close()

    def _summary(self, done: bool) -> None:
        st = self.recorder.status()
        drops = ", ".join(f"{n} {why}" for why, n in sorted(st["drop_reasons"].items()))
        self.node.get_logger().info(
            f"recording {'finalised' if done else 'NOT finalised (recover it with `jident salvage`)'}: "
            f"{st['bag']}: {st['messages_written']} message(s) written, {st['messages_dropped']} dropped"
            + (f" ({drops})" if drops else ""))

    def status(self) -> dict:
        st = self.recorder.status()
        out = {k: st[k] for k in ("state", "bag", "file", "files", "bytes_written", "messages_written",
                                  "messages_dropped", "splits", "bags_deleted", "bytes_deleted",
                                  "bags_kept_unfinalised")}
        out.update({f"dropped: {k}": v for k, v in st["drop_reasons"].items()})
        return out


__all__ = ["Recording", "Recorder", "RecorderError"]
