"""/diagnostics of the nodes (REP 107): event statuses and periodic task statuses.

* :class:`DiagnosticsPublisher` publishes event statuses as they happen (a dropped window, each
  window's result "<ns>/jident_diagnostic: inertia"), stamped with the node's clock.
* Status names: ``"<namespace>/<node name>: <task>"`` (:func:`status_name`), e.g. ``press3/jident_diagnostic:
  inertia``, ``jident_windowing: rate`` in the root namespace: the node and the task, and unique per drive --
  diagnostic_aggregator keys its items by name, so two drives in two namespaces no longer overwrite each other
  (config/analyzers.yaml groups them; docs/interfaces.md).
* :class:`Updater` runs periodic *tasks* — ``add(name, callback)``, ``period`` — the API of ROS's
  ``diagnostic_updater.Updater``: every ``period`` it calls each task's callback with a
  :class:`DiagnosticStatusWrapper` (``summary(level, message)``, ``add(key, value)``) and publishes
  the results in one DiagnosticArray.  diagnostic_updater names them ``"<node name>: <task>"`` without the
  namespace, which is not unique per drive; this Updater (always used) names them by :func:`status_name`, and
  its timer runs on the node's *steady* clock: with ``use_sim_time`` a stopped (or foreign) /clock cannot stop
  the statuses.
"""
from __future__ import annotations

from jident_ros.identify.levels import ERROR, LEVEL_NAMES, OK, STALE, WARN  # noqa: F401  (re-exported)
from jident_ros.nodes.ros_io import format_value, make_diagnostic_array, qos_diagnostics

#: The periodic statuses come from this module's Updater, never from a distribution's diagnostic_updater
#: (its names lack the namespace: two drives would share them).
USING_DIAGNOSTIC_UPDATER = False


def status_name(node, task: str) -> str:
    """``"<namespace>/<node name>: <task>"`` (no leading slash; the root namespace adds nothing)."""
    return f"{node.get_fully_qualified_name().lstrip('/')}: {task}"


def status_task(name: str) -> str:
    """``"<node name>: <task>"`` of a status name (its namespace removed): what one drive's statuses share
    with another's."""
    node, sep, task = name.partition(": ")
    return f"{node.rsplit('/', 1)[-1]}{sep}{task}"


def drive_hardware_id(node, given: str = "") -> str:
    """hardware_id for /diagnostics: the parameter when set, else the resolved namespace of the
    drive topics (``/drive``, ``/press3/drive``): Float64MultiArray has no header to carry one."""
    return given or node.resolve_topic_name("drive")


class DiagnosticsPublisher:
    """Publishes DiagnosticArrays on /diagnostics stamped with the node's clock; remembers the last."""

    def __init__(self, node, topic: str = "/diagnostics"):
        from diagnostic_msgs.msg import DiagnosticArray
        self.node = node
        self.pub = node.create_publisher(DiagnosticArray, topic, qos_diagnostics())
        self.last = None
        self.listeners = []  # callables(msg): e.g. the recorder

    def publish(self, *statuses):
        msg = make_diagnostic_array(self.node.get_clock().now().to_msg(), statuses)
        self.pub.publish(msg)
        self.last = msg
        for listen in self.listeners:
            listen(msg)
        return msg


def _status_type():
    from diagnostic_msgs.msg import DiagnosticStatus
    return DiagnosticStatus


class DiagnosticStatusWrapper:
    """diagnostic_updater's DiagnosticStatusWrapper: a DiagnosticStatus being filled by a task."""

    def __init__(self, name: str = "", hardware_id: str = ""):
        self.name, self.hardware_id = name, hardware_id
        self.level, self.message = ERROR, "No message was set"
        self.values = []

    def summary(self, level: int, message: str) -> None:
        self.level, self.message = int(level), str(message)

    def mergeSummary(self, level: int, message: str) -> None:  # noqa: N802  (diagnostic_updater's name)
        """Keep the worse level; append the message."""
        level = int(level)
        if (level > 0) == (self.level > 0) and self.message and level != STALE:
            self.message = f"{self.message}; {message}"
        elif level > self.level:
            self.message = message
        self.level = max(self.level, level)

    def add(self, key: str, value) -> None:
        self.values.append((str(key), value))

    def to_msg(self):
        from diagnostic_msgs.msg import KeyValue
        st = _status_type()()
        st.level = bytes([self.level])
        st.name, st.message, st.hardware_id = self.name, self.message, self.hardware_id
        st.values = [KeyValue(key=k, value=format_value(v)) for k, v in self.values]
        return st


class _Task:
    def __init__(self, name, fn):
        self.name, self.fn = name, fn


class JidentUpdater:
    """diagnostic_updater.Updater's API over :class:`DiagnosticsPublisher`, on the steady clock.

    ``Updater(node, period=1.0)``; ``add(name, fn)`` (``fn(stat) -> stat``); ``setHardwareID``;
    ``force_update()``; ``broadcast(level, message)``.  A task that raises gives an ERROR status
    naming the exception (the others still go out)."""

    def __init__(self, node, period: float = 1.0, publisher: DiagnosticsPublisher | None = None):
        from rclpy.clock import Clock, ClockType
        self.node = node
        self.period = float(period)
        self.publisher = publisher or DiagnosticsPublisher(node)
        self.tasks = []
        self.hwid = ""
        self.timer = (node.create_timer(self.period, self.update, clock=Clock(clock_type=ClockType.STEADY_TIME))
                      if self.period > 0 else None)

    def setHardwareID(self, hwid: str) -> None:  # noqa: N802  (diagnostic_updater's name)
        self.hwid = str(hwid)

    def add(self, name: str, fn) -> None:
        self.tasks.append(_Task(name, fn))

    def removeByName(self, name: str) -> bool:  # noqa: N802
        n = len(self.tasks)
        self.tasks = [t for t in self.tasks if t.name != name]
        return len(self.tasks) < n

    def _name(self, task_name: str) -> str:
        return status_name(self.node, task_name)

    def update(self) -> None:
        self.force_update()

    def force_update(self):
        statuses = []
        for task in self.tasks:
            stat = DiagnosticStatusWrapper(self._name(task.name), self.hwid)
            try:
                stat = task.fn(stat) or stat
            except Exception as exc:  # a failing task is a status, never a dead timer
                stat.summary(ERROR, f"status task failed: {type(exc).__name__}: {exc}")
            stat.name = self._name(task.name)
            statuses.append(stat.to_msg())
        if statuses:
            return self.publisher.publish(*statuses)
        return None

    def broadcast(self, level: int, message: str):
        statuses = []
        for task in self.tasks:
            stat = DiagnosticStatusWrapper(self._name(task.name), self.hwid)
            stat.summary(level, message)
            statuses.append(stat.to_msg())
        return self.publisher.publish(*statuses) if statuses else None

    def destroy(self) -> None:
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None


def make_updater(node, period: float, publisher: DiagnosticsPublisher):
    """The periodic-status Updater of a node (:class:`JidentUpdater`: diagnostic_updater.Updater's API --
    ``add``, ``setHardwareID``, ``force_update`` -- with names unique per drive, on the steady clock)."""
    return JidentUpdater(node, period, publisher)


#: The Updater of the plain venv (diagnostic_updater.Updater's API); nodes get theirs from make_updater.
Updater = JidentUpdater
