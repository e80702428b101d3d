"""The replay node's pacing (issue 25, item 3): lossless at any rate -- when the downstream falls behind at
rate > 0 the replay pauses (back-pressure), counts the pauses and says so in a WARN; never a silent loss.
Deterministic: a scripted gate and a fake clock, no timing."""
from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from jident_ros.nodes.replay import RatePacer  # noqa: E402


class ScriptedGate:
    """ProgressGate's interface: allows(t_last) answers from ``self.open``."""

    def __init__(self):
        self.open = True
        self.progress_t = 1.0
        self.progress_wall = 0.0     # a windowing node has reported progress
        self.max_lead_s = 2.0
        self.waited_s = 0.0
        self.asked = []

    def allows(self, t_last):
        self.asked.append(t_last)
        return self.open


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_pause_warns_once_per_episode_with_the_count():
    gate, clock, warnings = ScriptedGate(), Clock(), []
    p = RatePacer(10.0, gate, warnings.append, clock)
    assert p.due(0, 1.0)                      # first message: at once
    gate.open = False
    for _ in range(3):                        # behind for three ticks: one pause, one WARN
        assert not p.due(1_000_000_000, 4.0)
    assert p.pauses == 1 and len(warnings) == 1
    assert "downstream behind at rate 10" in warnings[0] and "1 pause(s)" in warnings[0]
    assert "t = 1.000 s" in warnings[0] and "t = 4.000 s" in warnings[0]
    gate.open = True
    assert p.due(1_000_000_000, 4.0)          # after the pause: the schedule restarts here, no wait
    gate.open = False
    assert not p.due(2_000_000_000, 5.0)      # a second episode: counted, warned again
    assert p.pauses == 2 and len(warnings) == 2 and "2 pause(s)" in warnings[1]
    gate.waited_s = 1.5
    assert "fell behind rate 10 2 time(s)" in p.summary() and "paused 1.50 s" in p.summary()


def test_schedule_at_rate_and_restart_after_a_pause():
    gate, clock = ScriptedGate(), Clock()
    p = RatePacer(10.0, gate, None, clock)
    assert p.due(0, 1.0)
    assert not p.due(1_000_000_000, 2.0)      # 1 s recorded at rate 10: due 0.1 s later
    clock.now += 0.1
    assert p.due(1_000_000_000, 2.0)
    gate.open = False
    assert not p.due(2_000_000_000, 3.0)
    clock.now += 5.0                          # a long pause
    gate.open = True
    assert p.due(2_000_000_000, 3.0)          # restart: this one at once ...
    assert not p.due(3_000_000_000, 4.0)      # ... the next one 0.1 s later, not a burst to catch up
    clock.now += 0.1
    assert p.due(3_000_000_000, 4.0)


def test_rate_zero_back_pressure_is_not_a_warning():
    gate, warnings = ScriptedGate(), []
    p = RatePacer(0.0, gate, warnings.append, Clock())
    gate.open = False
    assert not p.due(0, 1.0)
    gate.open = True
    assert p.due(0, 1.0)
    assert warnings == [] and p.pauses == 0 and p.summary() == ""


def test_messages_without_drive_time_are_not_gated():
    gate, warnings = ScriptedGate(), []
    gate.open = False
    p = RatePacer(10.0, gate, warnings.append, Clock())
    assert p.due(0, None)                     # drive/case, drive/backlash_width: no t, never held back
    assert gate.asked == [] and warnings == []


def test_no_gate_paces_by_the_clock_only():
    clock = Clock()
    p = RatePacer(2.0, None, None, clock)
    assert p.due(0, 1.0)
    assert not p.due(1_000_000_000, 2.0)
    clock.now += 0.5
    assert p.due(1_000_000_000, 2.0)
    assert p.summary() == ""


def test_no_windowing_node_yet_is_counted_not_warned_here():
    """No drive/progress ever: the pause is counted; the gate's own WARN (back-pressure off after
    progress_timeout_s) explains it, not 'downstream behind'."""
    gate, warnings = ScriptedGate(), []
    gate.progress_wall = None
    gate.open = False
    p = RatePacer(10.0, gate, warnings.append, Clock())
    assert not p.due(0, 5.0)
    assert p.pauses == 1 and warnings == []
