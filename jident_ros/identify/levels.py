"""Status levels of a diagnosis: diagnostic_msgs/DiagnosticStatus (REP 107) levels, as plain ints
(the message field is a byte), so the core can grade a window without ROS."""

#: diagnostic_msgs/DiagnosticStatus levels (the message field is a byte).
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}
