"""Issue 24, hostile tests of the reliability findings: nothing deleted that is not ours (test_recorder.py,
the retention tests), every loss counted, inputs that recover, a skewed Imu, the CSV reader, signals, formats.

Fast tests only by default; the long ones (200 stops) are behind the slow marker."""
from __future__ import annotations

import errno
import os
import types

import numpy as np
import pytest

SIGNALS = "std_msgs/msg/Float64MultiArray"


# ------------------------------------------------------------------ every loss counted (item 4)
class _FakeLogger:
    def __init__(self):
        self.lines = []

    def info(self, text, **kw):
        self.lines.append(text)

    warning = error = info


class _FakeNode:
    def __init__(self):
        self.logger = _FakeLogger()

    def get_fully_qualified_name(self):
        return "/test/jident_diagnostic"

    def get_logger(self):
        return self.logger

    def resolve_topic_name(self, name):
        return name if name.startswith("/") else "/test/" + name


def _cfg(root):
    from jident_ros.parameters import DIAGNOSTIC
    return {**DIAGNOSTIC, "record_root": str(root), "record_dir": ""}


def test_after_a_disk_failure_every_later_message_is_counted_as_dropped(tmp_path, monkeypatch):
    pytest.importorskip("rclpy")
    from jident_ros.nodes.diagnostic import DiagnosticNode, Recording
    node = _FakeNode()
    topics = [("drive/window", SIGNALS, None), ("drive/signals", SIGNALS, None),
              ("inertia_estimate", "std_msgs/msg/Float64", None)]
    rec = Recording(node, _cfg(tmp_path), topics)
    # the node's own path: DiagnosticNode._record / _flush_bag on an object holding the recording
    host = types.SimpleNamespace(recorder=rec)
    record = lambda name, msg: DiagnosticNode._record(host, name, msg)  # noqa: E731
    msg = {"layout": {"dim": [], "data_offset": 0}, "data": np.random.default_rng(0).random(200_000)}
    for _ in range(20):
        record("drive/signals", msg)
    real_write = os.write

    def full(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(os, "write", full)
    for _ in range(30):
        record("drive/signals", msg)
    monkeypatch.setattr(os, "write", real_write)
    st0 = rec.recorder.status()
    assert st0["state"] == "error" and "disk full" in st0["error"]
    assert rec.recorder.closed          # what was written is finalised already
    # 72 windows and 1,700 batches after the failure: every one of them counted, with the reason
    for _ in range(72):
        record("drive/window", msg)
    for _ in range(1700):
        record("drive/signals", msg)
    DiagnosticNode._flush_bag(host)     # the timer goes on without raising
    st = rec.recorder.status()
    assert st["messages_dropped"] == st0["messages_dropped"] + 72 + 1700
    assert st["messages_written"] + st["messages_dropped"] == 20 + 30 + 72 + 1700
    assert st["drop_reasons"]["disk full"] >= 72 + 1700
    assert host.recorder is rec and rec.error
    rec.close()                         # the final line says it all
    assert f"{st['messages_dropped']} dropped" in node.logger.lines[-1] and "disk full" in node.logger.lines[-1]
