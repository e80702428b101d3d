"""Salvage: every complete chunk of a cut-off or damaged MCAP recording into a new, finalised bag
(``jident salvage``, :mod:`jident_ros.cli.salvage`).  No ROS.

    report = salvage("killed/killed_0.mcap", "recovered")
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

from jident_ros.bag.errors import RecordingError, SalvageError
from jident_ros.bag.reader import StreamScan, bag_files, check_magic
from jident_ros.bag.writer import BagWriter

__all__ = ["salvage", "salvage_report_line"]


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
            check_magic(p)
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
            scan = StreamScan(p)
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
