"""ProgressGate (nodes/runtime.py): a streaming node's back-pressure follows the slower of the windowing node
(drive/progress) and, once heard, the diagnostic node (drive/diagnosed_progress)."""
from __future__ import annotations

import types

import pytest

pytest.importorskip("std_msgs")

from jident_ros.nodes.runtime import DIAGNOSED_PROGRESS_TOPIC, ProgressGate  # noqa: E402


class FakeNode:
    def __init__(self):
        self.callbacks, self.warnings = {}, []

    def create_subscription(self, _type, topic, cb, _qos):
        self.callbacks[topic] = cb
        return topic

    def destroy_subscription(self, sub):
        self.callbacks.pop(sub, None)

    def get_logger(self):
        return types.SimpleNamespace(warning=self.warnings.append, info=lambda _text: None)


def msg(t):
    return types.SimpleNamespace(data=t)


def test_the_windowing_node_alone_paces_until_a_diagnostic_node_is_heard():
    node = FakeNode()
    gate = ProgressGate(node, max_lead_s=2.0, timeout_s=60.0)
    assert gate.allows(1.0)                       # the first batch is the baseline
    assert not gate.allows(3.5)                   # 2.5 s ahead of what was read
    node.callbacks["drive/progress"](msg(1.6))
    assert gate.allows(3.5)


def test_a_diagnostic_node_behind_the_windowing_node_holds_the_stream():
    node = FakeNode()
    gate = ProgressGate(node, max_lead_s=2.0, timeout_s=60.0)
    assert gate.allows(1.0)
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(1.0))
    node.callbacks["drive/progress"](msg(10.0))   # the windowing node is far ahead ...
    assert not gate.allows(3.5)                   # ... but the diagnostic node has done only 1.0 s
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(1.6))
    assert gate.allows(3.5)
    assert not gate.allows(12.5)                  # now the windowing node (10.0) is the slower
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(11.0))
    assert not gate.allows(12.5)
    node.callbacks["drive/progress"](msg(10.6))
    assert gate.allows(12.5)


def test_a_stalled_diagnostic_node_opens_the_gate_until_its_next_progress_and_says_so():
    node = FakeNode()
    gate = ProgressGate(node, max_lead_s=1.0, timeout_s=0.5)
    assert gate.allows(1.0)
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(1.0))
    node.callbacks["drive/progress"](msg(5.0))
    assert not gate.allows(5.0)                   # the diagnostic node has done 1.0 s: wait ...
    gate._wait_start -= 1.0                       # ... 1 s with no progress of the slower node
    assert gate.allows(5.0)                       # beyond timeout_s: open for good
    assert not gate.active and "diagnostic" in node.warnings[0] and gate.openings == 1
    assert gate.allows(9.0)                       # open: the stream goes on while nothing progresses ...
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(2.0))
    assert gate.active and not gate.allows(9.0)   # ... and the next progress closes it again
    node.callbacks[DIAGNOSED_PROGRESS_TOPIC](msg(4.9))
    assert gate.allows(5.9) and not gate.allows(6.0)
    gate.close()
    assert not node.callbacks
