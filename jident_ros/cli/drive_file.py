"""A drive file: one ROS 2 params file that describes a drive to the CLI and to the nodes (docs/your_drive.md).

Its ``/**`` section is the system configuration (motor, load, sampling, grid: :func:`jident_ros.config.load_system_config`);
its ``/**/jident_diagnostic`` and ``/**/jident_windowing`` sections are those nodes' parameters, which ROS applies
when the file is given as ``--params-file``.  ``jident diagnose --config FILE`` and ``jident trend --config FILE``
read the same sections, so the drive's declaration (torque accuracy, friction bands, gear ratio, joint names) is
written once:

* ``jident_diagnostic``: the publishing policy (``parameters.POLICY_CLI_FLAGS``), ``p`` and ``gap_method``;
* ``jident_windowing``: ``gear_ratio``, ``motor_joint``, ``load_joint``, ``imu_axis``, ``detector``.

A flag on the command line overrides the file; the file overrides the node's default.  Each value is checked
against the node's parameter schema (type, range, choices: :func:`jident_ros.nodes.params.coerce`); a parameter
the node does not have is refused with one line naming it, the node's other parameters (``record_dir``, ...) are
the node's alone and left to it.  Plain numpy-free; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

from jident_ros.config import ConfigError, node_parameters, resolve_config_path
from jident_ros.nodes.params import ParameterError, coerce
from jident_ros.parameters import DIAGNOSTIC_PARAMS, POLICY_CLI_FLAGS, WINDOWING_PARAMS

DIAGNOSTIC_NODE = "jident_diagnostic"
WINDOWING_NODE = "jident_windowing"
#: The diagnostic node's parameters the CLI takes from a drive file (besides the policy's).
DIAGNOSTIC_KEYS = tuple(POLICY_CLI_FLAGS) + ("p", "gap_method")
#: The windowing node's parameters the CLI takes from a drive file.
WINDOWING_KEYS = ("gear_ratio", "motor_joint", "load_joint", "imu_axis", "detector")


@dataclass(frozen=True)
class DriveFile:
    """What a drive file declares for the CLI: ``diagnostic`` ({name: value} of :data:`DIAGNOSTIC_KEYS`),
    ``windowing`` (of :data:`WINDOWING_KEYS`), ``path`` (the file, '' for none)."""

    diagnostic: dict = field(default_factory=dict)
    windowing: dict = field(default_factory=dict)
    path: str = ""

    def policy(self) -> dict:
        """The publishing policy's values the file sets."""
        return {k: v for k, v in self.diagnostic.items() if k in POLICY_CLI_FLAGS}

    def lines(self) -> list:
        """One line per node section, for `jident info` (empty for a file without node sections)."""
        out = []
        for node, values in ((DIAGNOSTIC_NODE, self.diagnostic), (WINDOWING_NODE, self.windowing)):
            if values:
                out.append(f"  {node}: " + ", ".join(f"{k} {v!r}" for k, v in values.items()))
        return out


def _section(config, node: str, schema: dict, keys: tuple) -> dict:
    out = {}
    where = f"{resolve_config_path(config)}: /**/{node}"
    for name, value in node_parameters(config, node).items():
        if name not in schema:
            raise ConfigError(f"{where}: {name}: not a parameter of {node} (docs/interfaces.md lists them)")
        if name not in keys:
            continue
        try:
            out[name] = coerce(name, value, schema[name])
        except ParameterError as exc:
            raise ConfigError(f"{where}: {str(exc).removeprefix('parameter ')}") from None
    return out


def read_drive_file(config: Optional[Any]) -> DriveFile:
    """The node sections of ``--config`` (a file or a profile name; None: the default configuration, which has
    none).  ConfigError with one line naming the file, the section and the parameter."""
    if config is None or str(config) == "":
        return DriveFile()
    diagnostic = _section(config, DIAGNOSTIC_NODE, DIAGNOSTIC_PARAMS, DIAGNOSTIC_KEYS)
    windowing = _section(config, WINDOWING_NODE, WINDOWING_PARAMS, WINDOWING_KEYS)
    if diagnostic.get("gap_method") is False:
        diagnostic["gap_method"] = "off"
    return DriveFile(diagnostic, windowing, str(resolve_config_path(config)))


def resolve(given: Any, drive_file: DriveFile, name: str) -> Any:
    """A setting: the flag when given (not None), else the drive file's, else the node's default."""
    if given is not None:
        return given
    for values in (drive_file.diagnostic, drive_file.windowing):
        if name in values:
            return values[name]
    schema = DIAGNOSTIC_PARAMS if name in DIAGNOSTIC_PARAMS else WINDOWING_PARAMS
    return schema[name].default


__all__ = ["DIAGNOSTIC_KEYS", "DIAGNOSTIC_NODE", "DriveFile", "WINDOWING_KEYS", "WINDOWING_NODE", "read_drive_file",
           "resolve"]
