"""Parameters of the nodes: declared in ONE place from the schema (jident_ros/parameters.py), typed and
described (ParameterDescriptor), validated at start and at every change at run time.

The model and method sections of ``config/system.yaml`` and ``config/method.yaml`` are declared as dotted
parameters (``load.wheel_radius_m``, ``method.p_values``, ...) with the package's files as defaults, so the
same files serve as ``--params-file`` for the nodes and as configuration of the ``jident`` CLI.  Every value
is validated at start; a bad one raises :class:`ParameterError` whose text is one line naming the parameter
and the value (:func:`jident_ros.nodes.runtime.main` prints it and exits with status 2).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import re
from typing import Any, Callable, Mapping

from jident_ros.config import (
    ConfigError,
    config_to_dict,
    load_method_config,
    load_system_config,
    method_config_from_dict,
    system_config_from_dict,
)
from jident_ros.method.pipeline import MATCHED_SENSOR_FIELDS, MethodConfig
from jident_ros.parameters import UNIT_SUFFIXES, Param
from jident_ros.sim.params import GridParams, LoadParams, MotorParams, SamplingParams

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
    """Dotted parameters of config/method.yaml; ``method.wavelets`` becomes ``method.wavelets.<signal>``,
    ``method.matched_sensors`` ``method.matched_sensors.<SensorSpec field>`` (every field)."""
    cfg = load_method_config()
    out = {}
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if f.name == "wavelets":
            for sig, w in v:
                out[f"method.wavelets.{sig}"] = w
        elif f.name == "matched_sensors":   # every sensor field, at the configured set's value
            spec = cfg.sensor_spec()
            for name in MATCHED_SENSOR_FIELDS:
                out[f"method.matched_sensors.{name}"] = getattr(spec, name)
        else:
            out[f"method.{f.name}"] = _ros_value(v)
    return out


# --------------------------------------------------------------------------- schema

def _attribute_docs(cls) -> dict:
    """{field: its description's first sentence} from the ``Attributes`` section of a config dataclass's
    docstring (numpydoc ``name : type`` then indented text): the one place the model's and the method's fields
    are described."""
    out, current, lines = {}, None, (cls.__doc__ or "").splitlines()
    for line in lines[next((i for i, t in enumerate(lines) if t.strip() == "Attributes"), len(lines)):]:
        head = re.match(r"^    (\w+(?:, \w+)*) : ", line)
        if head:
            current = [n.strip() for n in head.group(1).split(",")]
            for n in current:
                out[n] = ""
        elif current and line.startswith("        ") and line.strip():
            for n in current:
                out[n] = f"{out[n]} {line.strip()}".strip()
        elif not line.strip():
            current = None
    return {n: re.split(r"(?<=\.)\s", text, maxsplit=1)[0] for n, text in out.items() if text}


@functools.lru_cache(maxsize=None)
def field_docs() -> dict:
    """{dotted parameter: description} of the model's (system.yaml) and the method's (method.yaml) fields."""
    sections = {"motor": MotorParams, "load": LoadParams, "sampling": SamplingParams, "grid": GridParams,
                "method": MethodConfig}
    return {f"{sec}.{n}": text for sec, cls in sections.items() for n, text in _attribute_docs(cls).items()}


def describe_field(name: str) -> str:
    """One-line description of a dotted model/method parameter: its dataclass docstring's, else from its field
    name and unit suffix: ``load.wheel_radius_m`` -> ``load: wheel radius, m (config/system.yaml; fixed at
    start)``."""
    section, _, field = name.partition(".")
    source = "config/method.yaml" if section in METHOD_SECTIONS else "config/system.yaml"
    doc = field_docs().get(name)
    if doc:
        return f"{section}: {doc.rstrip('.')} ({source}; fixed at start)"
    unit = ""
    for suffix, u in UNIT_SUFFIXES:
        if field.endswith(suffix):
            field, unit = field[: -len(suffix)], u
            break
    text = f"{section}: {field.replace('.', ' ').replace('_', ' ')}" + (f", {unit}" if unit else "")
    return f"{text} ({source}; fixed at start)"


def model_schema(values: Mapping[str, Any]) -> dict:
    """Params of the dotted model/method parameters (read-only, described from their names)."""
    return {name: Param(v, describe_field(name)) for name, v in values.items()}


def node_schema(own: Mapping[str, Param], *, method: bool = False) -> dict:
    """Every parameter of a node: its ``own`` (jident_ros/parameters.py) and the model's (system.yaml),
    with ``method`` the method's (method.yaml) too."""
    shared = dict(system_defaults(), **(method_defaults() if method else {}))
    return dict(own, **model_schema(shared))


def parameter_type(default: Any) -> int:
    """rcl_interfaces ParameterType of a default value."""
    from rcl_interfaces.msg import ParameterType as T
    if isinstance(default, bool):
        return T.PARAMETER_BOOL
    if isinstance(default, int):
        return T.PARAMETER_INTEGER
    if isinstance(default, float):
        return T.PARAMETER_DOUBLE
    if isinstance(default, str):
        return T.PARAMETER_STRING
    if isinstance(default, (list, tuple)):
        first = default[0] if default else 0.0
        if isinstance(first, str):
            return T.PARAMETER_STRING_ARRAY
        if isinstance(first, bool):
            return T.PARAMETER_BOOL_ARRAY
        if isinstance(first, int) and all(isinstance(x, int) for x in default):
            return T.PARAMETER_INTEGER_ARRAY
        return T.PARAMETER_DOUBLE_ARRAY
    raise TypeError(f"no ROS parameter type for {default!r}")


def descriptor(name: str, param: Param):
    """rcl_interfaces/ParameterDescriptor of a schema entry: type, description, range, read_only."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    from rcl_interfaces.msg import ParameterType as T
    typ = parameter_type(param.default)
    constraints = param.range_text()
    d = ParameterDescriptor(name=name, type=typ, description=param.description, read_only=param.read_only,
                            additional_constraints=constraints)
    if param.min is not None or param.max is not None:
        lo = -math.inf if param.min is None else param.min
        hi = math.inf if param.max is None else param.max
        # an exclusive end as the nearest value inside: the range `ros2 param describe` shows is exactly the
        # values the validation accepts, at both ends (issue 24)
        if typ == T.PARAMETER_DOUBLE:
            lo = math.nextafter(lo, math.inf) if param.min_exclusive else lo
            hi = math.nextafter(hi, -math.inf) if param.max_exclusive else hi
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        elif typ == T.PARAMETER_INTEGER:
            big = 2 ** 63 - 1
            lo = lo + 1 if param.min_exclusive else lo
            hi = hi - 1 if param.max_exclusive else hi
            d.integer_range = [IntegerRange(from_value=int(max(lo, -big)), to_value=int(min(hi, big)), step=1)]
    return d


# --------------------------------------------------------------------------- declaration

#: Parameters rclpy and its helpers declare on every node (not ours, never refused).
BUILTIN_PARAMETERS = ("use_sim_time", "start_type_description_service")
BUILTIN_PREFIXES = ("qos_overrides.", "diagnostic_updater.")


def node_options(kwargs: dict) -> dict:
    """Node keyword arguments of a jident node: the parameter overrides (command line, params files,
    ``parameter_overrides=``) are declared as given, so :func:`declare_parameters` can read them
    through the public API, check them and declare them again with their types and descriptors."""
    kwargs = dict(kwargs)
    kwargs["automatically_declare_parameters_from_overrides"] = True
    kwargs.setdefault("allow_undeclared_parameters", False)
    return kwargs


def coerce(name: str, value: Any, param: Param) -> Any:
    """A given value in the type of its default (ParameterError naming it otherwise).  ``gap_method``:
    a command line reads ``off`` as YAML false; false means ``off`` there."""
    if name == "gap_method" and value is False:
        value = "off"
    value = check(name, value, param.default)
    what = param.range_text()
    if param.choices and value not in param.choices:
        raise ParameterError(f"parameter {name}: must be {what}, got {value!r}")
    if param.min is not None or param.max is not None:
        for i, x in enumerate(value if isinstance(value, list) else [value]):
            low = param.min is not None and (x <= param.min if param.min_exclusive else x < param.min)
            high = param.max is not None and (x >= param.max if param.max_exclusive else x > param.max)
            if low or high or (param.nonzero and x == 0):
                where = f"{name}[{i}]" if isinstance(value, list) else name
                raise ParameterError(f"parameter {where}: must be {what}, got {x!r}")
    return value


def declare_parameters(node, schema: Mapping[str, Param], validate: Callable[[dict], Any] | None = None) -> dict:
    """Read the given values of every parameter of ``schema`` (defaults for those not given), coerce
    them to their types, ``validate`` them, then declare each with its typed descriptor; return
    {name: value}.

    The node must have been built with :func:`node_options` (overrides declared as given).  A given
    parameter that names no parameter of this node is refused (a typo), unless it belongs to a shared
    configuration section this node does not use (then it is undeclared: it has no effect here)."""
    given = {name: node.get_parameter(name).value for name in node.list_parameters([], 0).names}
    used = {name.split(".")[0] for name in schema}
    for name in sorted(given):
        if name in schema or name in BUILTIN_PARAMETERS or name.startswith(BUILTIN_PREFIXES):
            continue
        section = name.split(".")[0]
        if section in SHARED_SECTIONS and section not in used:
            node.undeclare_parameter(name)  # e.g. method.yaml given to every node of a launch file
            continue
        raise ParameterError(f"parameter {name}: unknown parameter of node {node.get_name()} "
                             f"(value {given[name]!r})")
    values = {name: coerce(name, given.get(name, p.default), p) for name, p in schema.items()}
    if validate is not None:
        validate(values)
    for name, p in schema.items():
        if node.has_parameter(name):
            node.undeclare_parameter(name)
        node.declare_parameter(name, _ros_value(values[name]), descriptor(name, p), ignore_override=True)
    return values


class RuntimeParameters:
    """Changes of a running node's parameters, after rclpy's parameter callbacks:

    * pre-set: coerce what a command line gives (an integer for a float, ``gap_method:=off`` read as
      false) to the declared type;
    * on-set: check the types and ``validate`` the whole set of values with the change (the same checks
      as at start); a bad value is refused with the one-line reason (SetParametersResult);
    * post-set: ``apply`` the accepted changes ({name: value}) to the running node.

    Read-only parameters (a change could not take effect) are refused by rclpy before these run."""

    def __init__(self, node, schema: Mapping[str, Param], values: dict, validate: Callable[[dict], Any],
                 apply: Callable[[dict], None]):
        self.node, self.schema, self.values = node, schema, dict(values)
        self.validate, self.apply = validate, apply
        node.add_pre_set_parameters_callback(self._pre_set)
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)

    def _pre_set(self, parameters):
        from rclpy.parameter import Parameter
        out = []
        for prm in parameters:
            p = self.schema.get(prm.name)
            if p is not None and not p.read_only:
                try:
                    v = coerce(prm.name, prm.value, p)
                    prm = Parameter(prm.name, value=_ros_value(v))
                except ParameterError:
                    pass  # refused with the reason by _on_set
            out.append(prm)
        return out

    def _on_set(self, parameters):
        from rcl_interfaces.msg import SetParametersResult
        candidate = dict(self.values)
        try:
            for prm in parameters:
                if prm.name in self.schema:
                    candidate[prm.name] = coerce(prm.name, prm.value, self.schema[prm.name])
            self.validate(candidate)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _post_set(self, parameters):
        changed = {prm.name: coerce(prm.name, prm.value, self.schema[prm.name])
                   for prm in parameters if prm.name in self.schema}
        self.values.update(changed)
        if changed:
            try:
                self.apply(changed)
            except Exception as exc:  # never die on a parameter change: say so
                self.node.get_logger().error(f"applying {sorted(changed)} failed: {type(exc).__name__}: {exc}")


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


def _sections_config(values: Mapping[str, Any], sections, from_dict):
    """``from_dict`` of the declared dotted parameters of ``sections`` (ParameterError on a bad value)."""
    sub = {k: v for k, v in values.items() if k.split(".")[0] in sections}
    try:
        return from_dict(nest(sub))
    except ConfigError as exc:
        raise ParameterError(f"parameter {exc}") from None


def system_config(values: Mapping[str, Any]):
    """SystemConfig from the declared dotted parameters (ParameterError on a bad value)."""
    return _sections_config(values, SYSTEM_SECTIONS, system_config_from_dict)


def method_config(values: Mapping[str, Any]):
    """MethodConfig from the declared ``method.*`` parameters (ParameterError on a bad value)."""
    return _sections_config(values, METHOD_SECTIONS, method_config_from_dict)
