"""A node that refuses its parameters in its constructor is destroyed before rcl shuts down
(nodes/runtime._half_built_node): left to the garbage collector after rclpy.shutdown, such a node can hang the
interpreter's exit (ros2/launch#124); a simulator refusing ``batch_size:=fifty`` hung 180 s once on a loaded machine."""
from __future__ import annotations

import pytest


@pytest.mark.ros
def test_a_node_refusing_its_parameters_is_destroyed_before_shutdown(capsys):
    from rclpy.node import Node

    from jident_ros.nodes import runtime
    from jident_ros.nodes.params import ParameterError
    seen = {}

    class Refusing(Node):
        def __init__(self):
            super().__init__("jident_refusing_test")
            self.helper = object()
            raise ParameterError("parameter batch_size: must be an integer, got 'fifty'")

        def destroy_node(self):
            import rclpy
            seen["context_ok"] = rclpy.ok()           # destroyed while rcl is still up
            return super().destroy_node()

    code = runtime.main(lambda argv: Refusing(), "refusing", ["refusing"])
    assert code == runtime.EXIT_BAD_PARAMETER
    assert seen == {"context_ok": True}
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["refusing: parameter batch_size: must be an integer, got 'fifty'"], err


def test_the_half_built_node_is_found_in_the_traceback_not_elsewhere():
    pytest.importorskip("rclpy")
    from jident_ros.nodes.runtime import _half_built_node

    def build():
        x = object()  # noqa: F841 (a frame without a node)
        raise ValueError("no node here")
    try:
        build()
    except ValueError as exc:
        assert _half_built_node(exc) is None


def test_the_entry_point_leaves_a_refused_start_with_the_bad_parameter_status(monkeypatch):
    """A node that refused its parameters ends its process at once with status 2 (nodes/entry.py: no interpreter
    finalisation after rcl shut down); the light module's copy of the status is the runtime's."""
    import types

    from jident_ros.nodes import entry
    # _run installs its handlers and leaves both signals ignored as the interpreter exits: not in this process
    monkeypatch.setattr(entry.signal, "signal", lambda sig, handler: None)
    from jident_ros.nodes.params import EXIT_BAD_PARAMETER
    assert entry.EXIT_BAD_PARAMETER == EXIT_BAD_PARAMETER
    exits = []

    def fake_exit(code):
        exits.append(code)
        raise SystemExit(code)
    monkeypatch.setattr(entry.os, "_exit", fake_exit)
    monkeypatch.setattr(entry.importlib, "import_module", lambda name: types.SimpleNamespace(main=lambda: 2))
    with pytest.raises(SystemExit):
        entry._run("jident_ros.nodes.replay", "replay")
    assert exits == [2]
    monkeypatch.setattr(entry.importlib, "import_module", lambda name: types.SimpleNamespace(main=lambda: 0))
    assert entry._run("jident_ros.nodes.replay", "replay") == 0 and exits == [2]


@pytest.mark.ros
def test_a_refused_start_in_its_own_process_leaves_before_any_teardown(capsys, monkeypatch):
    """Started by its entry point (its own process: nodes/entry.leaves_at_once), a node that refuses its parameters
    prints its one line and leaves at once with status 2: no half-built node destroyed, no rcl shutdown (where 10 nodes
    refusing at once on a loaded machine died by SIGSEGV after their line, stops 33 and 34).  In a caller's process the
    teardown runs (the test above)."""
    import rclpy
    from rclpy.node import Node

    from jident_ros.nodes import runtime
    from jident_ros.nodes.params import ParameterError
    seen = []

    class Refusing(Node):
        def __init__(self):
            super().__init__("jident_refusing_at_once_test")
            raise ParameterError("parameter real_time_factor: must be >= 0 and <= 1000, got -2.0")

        def destroy_node(self):
            seen.append("destroyed")
            return super().destroy_node()

    def fake_exit(code):
        seen.append(("exit", code))
        raise SystemExit(code)
    monkeypatch.setattr(runtime, "leaves_at_once", lambda: True)
    monkeypatch.setattr(runtime.os, "_exit", fake_exit)
    try:
        with pytest.raises(SystemExit):
            runtime.main(lambda argv: Refusing(), "refusing", ["refusing"])
        # leaves before any destroy or shutdown (the real os._exit does not return; this one's SystemExit lets the
        # finally run after it)
        assert seen[0] == ("exit", runtime.EXIT_BAD_PARAMETER)
        assert capsys.readouterr().err.strip().splitlines() == [
            "refusing: parameter real_time_factor: must be >= 0 and <= 1000, got -2.0"]
    finally:
        rclpy.try_shutdown()                     # this process goes on (the test run): what os._exit would have left


def test_only_an_entry_point_start_leaves_at_once(monkeypatch):
    import types

    from jident_ros.nodes import entry
    assert entry.leaves_at_once() is False
    monkeypatch.setattr(entry.signal, "signal", lambda sig, handler: None)
    during = []
    monkeypatch.setattr(entry.importlib, "import_module",
                        lambda name: types.SimpleNamespace(main=lambda: during.append(entry.leaves_at_once()) or 0))
    assert entry._run("jident_ros.nodes.replay", "replay") == 0
    assert during == [True] and entry.leaves_at_once() is False
