"""Parameters of the nodes: declared in ONE place from a dict of defaults, validated at start.

The model and method sections of ``config/system.yaml`` and ``config/method.yaml`` are declared as dotted
parameters (``load.wheel_radius_m``, ``method.p_values``, ...) with the package's files as defaults, so the
same files serve as ``--params-file`` for the nodes and as configuration of the ``jident`` CLI.  Every value
is validated at start; a bad one raises :class:`ParameterError` whose text is one line naming the parameter
and the value (:func:`jident_ros.nodes.runtime.main` prints it and exits with status 2).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

from jident_ros.config import (
    ConfigError,
    config_to_dict,
    load_method_config,
    load_system_config,
    method_config_from_dict,
    system_config_from_dict,
)

#: Sections of the shared configuration files (config/system.yaml, config/method.yaml).
SYSTEM_SECTIONS = ("motor", "load", "sampling", "grid")
METHOD_SECTIONS = ("method",)
SHARED_SECTIONS = SYSTEM_SECTIONS + METHOD_SECTIONS
#: Exit status of a node stopped by a bad parameter.
EXIT_BAD_PARAMETER = 2


class ParameterError(Exception):
    """A parameter value is invalid; the message is one line naming the parameter and the value."""


# --------------------------------------------------------------------------- defaults


def flatten(d: Mapping, prefix: str = "") -> dict:
    """Nested mapping -> {dotted name: value} (lists stay values)."""
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, name + "."))
        else:
            out[name] = v
    return out


def nest(flat: Mapping) -> dict:
    """{dotted name: value} -> nested dict."""
    out: dict = {}
    for name, v in flat.items():
        parts = name.split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


def _ros_value(v):
    return [_ros_value(x) for x in v] if isinstance(v, (list, tuple)) else v


def system_defaults() -> dict:
    """Dotted parameters of config/system.yaml (the package's file) with their values."""
    return {k: _ros_value(v) for k, v in flatten(config_to_dict(load_system_config())).items()}


def method_defaults() -> dict:
    """Dotted parameters of config/method.yaml; ``method.wavelets`` becomes ``method.wavelets.<signal>``."""
    cfg = load_method_config()
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if f.name == "wavelets":
            for sig, w in v:
                out[f"method.wavelets.{sig}"] = w
        else:
            out[f"method.{f.name}"] = _ros_value(v)
    return out


# --------------------------------------------------------------------------- declaration


def declare_parameters(node, defaults: Mapping[str, Any]) -> dict:
    """Declare every parameter of ``defaults`` (dynamically typed: validation is ours) and return
    {name: value}.  An override naming no parameter of this node is refused (a typo), unless it
    belongs to a shared configuration section this node does not use."""
    from rcl_interfaces.msg import ParameterDescriptor
    node.declare_parameters("", [(name, _ros_value(v), ParameterDescriptor(dynamic_typing=True))
                                 for name, v in defaults.items()])
    values = {name: node.get_parameter(name).value for name in defaults}
    used = {name.split(".")[0] for name in defaults}
    for name, param in sorted(getattr(node, "_parameter_overrides", {}).items()):
        if name in defaults or name == "use_sim_time" or name.startswith("qos_overrides."):
            continue
        section = name.split(".")[0]
        if section in SHARED_SECTIONS and section not in used:
            continue  # e.g. method.yaml given to every node of a launch file
        raise ParameterError(f"parameter {name}: unknown parameter of node {node.get_name()} "
                             f"(value {param.value!r})")
    return values


def check(name: str, value: Any, default: Any) -> Any:
    """Value coerced to the type of its default; ParameterError naming it otherwise."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ParameterError(f"parameter {name}: expected true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"parameter {name}: expected an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ParameterError(f"parameter {name}: expected a finite number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ParameterError(f"parameter {name}: expected a string, got {value!r}")
        return value
    if isinstance(default, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            raise ParameterError(f"parameter {name}: expected a list, got {value!r}")
        value = list(value)
        if default and isinstance(default[0], str):
            if not all(isinstance(x, str) for x in value):
                raise ParameterError(f"parameter {name}: expected a list of strings, got {value!r}")
            return value
        if default and isinstance(default[0], (int, float)):
            for i, x in enumerate(value):
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise ParameterError(f"parameter {name}[{i}]: expected a finite number, got {x!r}")
            return [float(x) for x in value]
        return value
    return value


def require(name: str, value: Any, ok: bool, what: str) -> Any:
    """ParameterError 'parameter <name>: must be <what>, got <value>' unless ok."""
    if not ok:
        raise ParameterError(f"parameter {name}: must be {what}, got {value!r}")
    return value


def checked(values: Mapping[str, Any], defaults: Mapping[str, Any], names) -> dict:
    """check() every name of ``names``."""
    return {n: check(n, values[n], defaults[n]) for n in names}


def system_config(values: Mapping[str, Any]):
    """SystemConfig from the declared dotted parameters (ParameterError on a bad value)."""
    sub = {k: v for k, v in values.items() if k.split(".")[0] in SYSTEM_SECTIONS}
    try:
        return system_config_from_dict(nest(sub))
    except ConfigError as exc:
        raise ParameterError(f"parameter {exc}") from None


def method_config(values: Mapping[str, Any]):
    """MethodConfig from the declared ``method.*`` parameters (ParameterError on a bad value)."""
    sub = {k: v for k, v in values.items() if k.split(".")[0] in METHOD_SECTIONS}
    try:
        return method_config_from_dict(nest(sub))
    except ConfigError as exc:
        raise ParameterError(f"parameter {exc}") from None
