"""The diagnostic node's recorder behind one seam (:class:`Recording`): a rosbag2 MCAP bag of its topics
(docs/recording.md).  Used by :mod:`jident_ros.nodes.diagnostic`."""
from __future__ import annotations

try:  # the recorder needs mcap and rosbags: without them the node runs on and says so
    from jident_ros.bag.rotating_recorder import Recorder, RecorderError
    _BAG_IMPORT_ERROR = None
except ImportError as _exc:  # pragma: no cover - both are install requirements
    Recorder, RecorderError, _BAG_IMPORT_ERROR = None, RuntimeError, _exc


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
            custom_data={"node": node.get_fully_qualified_name()}, log=node.get_logger().info)
        self.bag_dir = str(self.recorder.bag_dir)
        self.topics = {}
        try:
            for name, typ, qos in topics:
                full = node.resolve_topic_name(name)
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
        st = self.recorder.status()
        return st["error"] or None

    def write(self, name: str, msg) -> None:
        if name in self.topics:
            self.recorder.write(*self.topics[name], msg)   # never raises: drops are counted by reason

    def flush(self) -> None:
        self.recorder.maybe_flush()

    def close(self) -> None:
        """Finalise the bag and say in one line what it holds (also what was dropped, by reason)."""
        if self.recorder.closed:
            return
        done = self.recorder.close()
        st = self.recorder.status()
        drops = ", ".join(f"{n} {why}" for why, n in sorted(st["drop_reasons"].items()))
        self.node.get_logger().info(
            f"recording {'finalised' if done else 'NOT finalised (recover it with `jident salvage`)'}: "
            f"{st['bag']}: {st['messages_written']} message(s) written, {st['messages_dropped']} dropped"
            + (f" ({drops})" if drops else ""))

    def status(self) -> dict:
        st = self.recorder.status()
        out = {k: st[k] for k in ("state", "bag", "file", "files", "bytes_written", "messages_written",
                                  "messages_dropped", "splits", "bags_deleted", "bytes_deleted")}
        out.update({f"dropped: {k}": v for k, v in st["drop_reasons"].items()})
        return out


__all__ = ["Recording", "Recorder", "RecorderError"]
