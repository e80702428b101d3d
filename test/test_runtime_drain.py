"""runtime.drain: a node that ends by itself waits for its reliable readers, at most DRAIN_TIMEOUT_S in all, and names
in one WARN the topics whose readers had not acknowledged the last messages (it waited 5 s per publisher and said
nothing: a test lost 9 of 98 batches that way on a loaded machine)."""
from __future__ import annotations

import pytest


class _Pub:
    def __init__(self, topic, acked_after, readers=1):
        self.topic_name, self.calls, self.acked_after, self.readers = topic, 0, acked_after, readers

    def wait_for_all_acked(self, timeout):
        self.calls += 1
        return self.acked_after is not None and self.calls >= self.acked_after

    def get_subscription_count(self):
        return self.readers


class _Log:
    def __init__(self):
        self.warnings = []

    def warning(self, text):
        self.warnings.append(text)


@pytest.mark.ros
def test_drain_waits_for_slow_readers_and_names_the_late_ones():
    from jident_ros.nodes.runtime import DRAIN_TIMEOUT_S, drain
    assert DRAIN_TIMEOUT_S >= 10.0
    slow, never, quick = _Pub("/a/drive/signals", 3), _Pub("/a/drive/case", None, readers=2), _Pub("/a/x", 1)
    log = _Log()
    late = drain([slow, never, quick], log, timeout_s=1.2)
    assert slow.calls == 3 and quick.calls == 1          # a slow reader is waited for, not given up after one slice
    assert late == ["/a/drive/case"]
    assert len(log.warnings) == 1 and "/a/drive/case (2 reader(s))" in log.warnings[0], log.warnings
    assert "/a/drive/signals" not in log.warnings[0]


@pytest.mark.ros
def test_drain_stops_waiting_when_the_node_is_stopped():
    from jident_ros.nodes.runtime import drain
    never = _Pub("/b/drive/signals", None)
    log = _Log()
    assert drain([never], log, stopping=lambda: True, timeout_s=60.0) == ["/b/drive/signals"]
    assert never.calls == 1 and len(log.warnings) == 1


@pytest.mark.ros
def test_drain_says_nothing_when_every_reader_acknowledged():
    from jident_ros.nodes.runtime import drain
    log = _Log()
    assert drain([_Pub("/c/t", 1), _Pub("/c/u", 2)], log, timeout_s=5.0) == [] and log.warnings == []
