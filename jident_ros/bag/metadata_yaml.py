"""rosbag2's ``metadata.yaml``: written as yaml-cpp (rosbag2) writes it, read back as a mapping.  No ROS."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from jident_ros.bag.errors import RecordingError

__all__ = ["ROSBAG2_METADATA_VERSION", "dump_yaml", "read_metadata", "wrapped_metadata_yaml"]

ROSBAG2_METADATA_VERSION = 9


class _Dumper(yaml.SafeDumper):
    """Block YAML with indented sequences, as yaml-cpp (rosbag2) writes it."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)


def dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_Dumper, default_flow_style=False, sort_keys=False, allow_unicode=True,
                     width=1 << 16)


def wrapped_metadata_yaml(metadata: dict, record: tuple | None = None) -> str:
    """metadata.yaml's text: ``metadata`` under ``rosbag2_bagfile_information``.  When ``record`` = (the same
    metadata, its YAML) -- the rosbag2 record just written to the last file, which for a one-file bag holds the
    same content -- that text is indented instead of dumped again (PyYAML's pure-Python emitter was most of the
    cost of closing a bag; block style nests by indenting every line by 2, the _Dumper's indent)."""
    if record is not None and record[0] == metadata:
        body = record[1]
    else:
        body = dump_yaml(metadata)
    return "rosbag2_bagfile_information:\n" + "".join("  " + line if line.strip() else line
                                                       for line in body.splitlines(keepends=True))



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
