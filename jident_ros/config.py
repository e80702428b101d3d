"""One parameter schema for the CLI, the nodes and the tests.

Configuration files live in ``config/`` in the ROS 2 params-file format::

    /**:
      ros__parameters:
        motor:
          stator_resistance_pu: 0.059
          ...

The keys under ``ros__parameters`` are exactly the field names of the
dataclasses in :mod:`jident_ros.sim.params` (nested per section), so a ROS node
can declare them as dotted parameters (``motor.stator_resistance_pu``) and the
CLI reads the same file.  Every value is validated here; a bad one raises
:class:`ConfigError` with one line naming the field and the value.
"""
from __future__ import annotations

import dataclasses
import dataclasses as dc
import math
from pathlib import Path
from typing import Any, Mapping, Optional

import pywt
import yaml

from jident_ros.resources import default_config_path
from jident_ros.sim.params import GridParams, LoadParams, MotorParams, SamplingParams, SystemConfig

SECTIONS = {"motor": MotorParams, "load": LoadParams, "sampling": SamplingParams, "grid": GridParams}


class ConfigError(ValueError):
    """A configuration value is missing, unknown or out of range."""


# field -> (predicate, description) for values that need more than "finite > 0"
_RULES = {
    "motor.pole_pairs": (lambda v: isinstance(v, int) and v >= 1, "an integer >= 1"),
    "motor.bearing_friction_nms_per_rad": (lambda v: v >= 0, "a number >= 0"),
    "load.process_force_n": (lambda v: v >= 0, "a number >= 0"),
    "load.clutch_damping_nms_per_rad": (lambda v: v >= 0, "a number >= 0"),
    "load.line_damping_ns_per_m": (lambda v: v >= 0, "a number >= 0"),
    "load.flow_index": (lambda v: 0 < v <= 2, "a number in (0, 2]"),
    "sampling.samples_before_entry": (lambda v: isinstance(v, int) and v >= 0, "an integer >= 0"),
    "sampling.samples_from_entry": (lambda v: isinstance(v, int) and v >= 2, "an integer >= 2"),
    "sampling.integration_substeps": (lambda v: isinstance(v, int) and v >= 1, "an integer >= 1"),
    "method.p_values": (lambda v: True, ""),
    "method.khm_tol": (lambda v: v >= 0, "a number >= 0"),
}


def _yaml11_number(v: Any) -> Any:
    """PyYAML (YAML 1.1) reads ``2.0e4`` as a string; ROS's parser reads a double."""
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


def _check_number(name: str, v: Any) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{name}: expected a finite number, got {v!r}")


def _coerce(name: str, default: Any, v: Any) -> Any:
    """Type-check v against the dataclass default's type and apply range rules."""
    if isinstance(default, tuple):
        if not isinstance(v, (list, tuple)) or not v:
            raise ConfigError(f"{name}: expected a non-empty list of numbers, got {v!r}")
        v = [_yaml11_number(x) for x in v]
        for i, x in enumerate(v):
            _check_number(f"{name}[{i}]", x)
            if x <= 0:
                raise ConfigError(f"{name}[{i}]: must be > 0, got {x!r}")
        return tuple(float(x) for x in v)
    v = _yaml11_number(v)
    _check_number(name, v)
    if isinstance(default, int) and not isinstance(default, bool):
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        if not isinstance(v, int):
            raise ConfigError(f"{name}: expected an integer, got {v!r}")
    else:
        v = float(v)
    pred, what = _RULES.get(name, (lambda x: x > 0, "a number > 0"))
    if not pred(v):
        raise ConfigError(f"{name}: must be {what}, got {v!r}")
    return v


#: The section of a params file that holds the system configuration when the file has node sections too.
ALL_NODES_SECTION = "/**"


def _ros_sections(data) -> Optional[dict]:
    """{section name: its ros__parameters} when ``data`` is a ROS 2 params file (every top-level value a mapping
    with ``ros__parameters``), else None."""
    if not isinstance(data, Mapping) or not data:
        return None
    if not all(isinstance(v, Mapping) and "ros__parameters" in v for v in data.values()):
        return None
    return {str(k): (v["ros__parameters"] or {}) for k, v in data.items()}


def strip_ros_wrapper(data: Mapping) -> Mapping:
    """Return the ``ros__parameters`` mapping of a params file (or data itself).  A file with several sections
    (a drive file: ``/**`` for the system configuration, ``/**/jident_diagnostic`` and ``/**/jident_windowing``
    for the nodes, docs/your_drive.md) gives its ``/**`` section; the node sections are read by
    :func:`node_parameters`."""
    sections = _ros_sections(data)
    if sections is None:
        return data
    if len(sections) == 1:
        return next(iter(sections.values()))
    return sections.get(ALL_NODES_SECTION, {})


def node_parameters(path_or_profile: str | Path | None, node: str) -> dict:
    """The parameters a params file (``--config``: a file or a profile name) sets for the node named ``node``
    (e.g. ``jident_diagnostic``): its sections ``/**/<node>``, ``<node>`` and ``/<node>``, merged in file order.
    {} for a file without such a section (a plain system configuration)."""
    if path_or_profile is None or str(path_or_profile) == "":
        return {}
    target = resolve_config_path(path_or_profile)
    sections = _ros_sections(load_yaml(target)) or {}
    out: dict = {}
    for name, values in sections.items():
        if name in (f"/**/{node}", node, f"/{node}"):
            if not isinstance(values, Mapping):
                raise ConfigError(f"{target}: section {name}: expected a mapping of parameters, got {values!r}")
            out.update(values)
    return out


def system_config_from_dict(data: Mapping | None) -> SystemConfig:
    """Build and validate a SystemConfig; missing fields take the defaults."""
    data = strip_ros_wrapper(data or {})
    if not isinstance(data, Mapping):
        raise ConfigError(f"configuration: expected a mapping of sections, got {type(data).__name__}")
    parts = {}
    for key in data:
        if key not in SECTIONS and key not in _FOREIGN_SECTIONS:
            raise ConfigError(f"{key}: unknown section (known: {', '.join(SECTIONS)}; a node's parameter goes in "
                              f"the node's own section, e.g. /**/jident_diagnostic: ros__parameters: "
                              f"{{{key}: ...}}, docs/your_drive.md)")
    for section, cls in SECTIONS.items():
        given = data.get(section) or {}
        if not isinstance(given, Mapping):
            raise ConfigError(f"{section}: expected a mapping, got {given!r}")
        defaults = cls()
        names = {f.name for f in dataclasses.fields(cls)}
        for k in given:
            if k not in names:
                raise ConfigError(f"{section}.{k}: unknown parameter (known: {', '.join(sorted(names))})")
        values = {k: _coerce(f"{section}.{k}", getattr(defaults, k), v) for k, v in given.items()}
        parts[section] = dataclasses.replace(defaults, **values)
    m = parts["motor"]
    if m.magnetizing_reactance_pu >= min(m.stator_reactance_pu, m.rotor_reactance_pu):
        raise ConfigError(f"motor.magnetizing_reactance_pu: must be below x_s and x_w, "
                          f"got {m.magnetizing_reactance_pu!r}")
    g = parts["grid"]
    if g.pattern_consistency_pa_sn not in g.consistency_indices_pa_sn:
        raise ConfigError(f"grid.pattern_consistency_pa_sn: must be one of "
                          f"grid.consistency_indices_pa_sn {list(g.consistency_indices_pa_sn)}, "
                          f"got {g.pattern_consistency_pa_sn!r}")
    return SystemConfig(**parts)


#: Sections other modules own in the same file (validated there).
_FOREIGN_SECTIONS = {"method", "nodes"}


def load_yaml(path: str | Path) -> Mapping:
    """Read a YAML file; errors name the file."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config file: no such file {str(p)!r}")
    try:
        with open(p, encoding="utf-8") as f:
            return yaml.safe_load(f) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"config file {str(p)!r}: not valid YAML ({exc.__class__.__name__})") from None


def default_system_config_path() -> Path:
    return default_config_path("system.yaml")


#: Folder of the named drive profiles inside the config folder (``config/profiles/<name>.yaml``).
PROFILES_DIR = "profiles"


def profile_names() -> list[str]:
    """Names of the drive profiles shipped in ``config/profiles/`` (wherever the config folder is)."""
    try:
        folder = default_config_path(PROFILES_DIR + "/heavy_film.yaml").parent
    except FileNotFoundError:
        return []
    return sorted(p.stem for p in folder.glob("*.yaml"))


def resolve_config_path(path_or_profile: str | Path | None) -> Path:
    """The system configuration file meant by ``--config``: an existing file, else a profile name
    (``heavy_film`` -> ``config/profiles/heavy_film.yaml``, found as :func:`default_config_path` finds the
    default configuration: checkout, ament share dir, pip share dir); None -> ``config/system.yaml``."""
    if path_or_profile is None or str(path_or_profile) == "":
        return default_system_config_path()
    p = Path(path_or_profile)
    if p.is_file():
        return p
    name = str(path_or_profile)
    if "/" not in name and "\\" not in name and not name.endswith((".yaml", ".yml")):
        try:
            return default_config_path(f"{PROFILES_DIR}/{name}.yaml")
        except FileNotFoundError:
            known = ", ".join(profile_names()) or "none found"
            raise ConfigError(f"config: {name!r} is neither a file nor a drive profile (profiles: {known})") from None
    raise ConfigError(f"config file: no such file {name!r}")


def load_system_config(path: str | Path | None = None) -> SystemConfig:
    """Load ``config/system.yaml``, the given file or the named profile (:func:`resolve_config_path`).

    A profile file may give only the fields it changes; the others are those of ``config/system.yaml``
    (not the dataclass defaults), so a profile is "the default drive except ...". """
    target = resolve_config_path(path)
    data = strip_ros_wrapper(load_yaml(target))
    base = default_system_config_path()
    if _is_profile(target) and target.resolve() != base.resolve():
        merged = {k: dict(v) if isinstance(v, Mapping) else v for k, v in strip_ros_wrapper(load_yaml(base)).items()}
        for section, values in (data or {}).items():
            if isinstance(values, Mapping) and isinstance(merged.get(section), Mapping):
                merged[section].update(values)
            else:
                merged[section] = values
        data = merged
    return system_config_from_dict(data)


def _is_profile(path: Path) -> bool:
    return path.parent.name == PROFILES_DIR


def __getattr__(name: str):
    """``config_hash``/``config_to_dict`` (now in method.patterns) stay importable from here, loaded on first
    use: method.patterns imports the method pipeline and scipy.fft (~0.4 s), which `jident simulate`/`info`
    do not need (issue 23; test_layers.LAZY)."""
    if name in ("config_hash", "config_to_dict"):
        from jident_ros.method import patterns
        return getattr(patterns, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def method_config_from_dict(data: Mapping | None):
    """Build and validate a MethodConfig from the ``method`` section."""
    # imported here, not at the top: the method pipeline imports scipy.fft & co. (~0.4 s), and `jident
    # simulate`/`info` read the system config only (issue 23; test_layers.LAZY)
    from jident_ros.method.pipeline import MethodConfig
    data = strip_ros_wrapper(data or {})
    sec = data.get("method", data) if isinstance(data, Mapping) else data
    if not isinstance(sec, Mapping):
        raise ConfigError(f"method: expected a mapping, got {sec!r}")
    defaults = MethodConfig()
    names = {f.name for f in dc.fields(MethodConfig)}
    values = {}
    for k, v in sec.items():
        if k not in names:
            raise ConfigError(f"method.{k}: unknown parameter (known: {', '.join(sorted(names))})")
        d = getattr(defaults, k)
        if k == "wavelets":
            if not isinstance(v, Mapping):
                raise ConfigError(f"method.wavelets: expected a mapping signal -> wavelet, got {v!r}")
            for sig, w in v.items():
                if w not in pywt.wavelist(kind="discrete"):
                    raise ConfigError(f"method.wavelets.{sig}: unknown discrete wavelet {w!r}")
            values[k] = tuple((str(a), str(b)) for a, b in v.items())
        elif k == "matched_sensors":
            if not isinstance(v, Mapping):
                raise ConfigError(f"method.matched_sensors: expected a mapping sensor field -> number, got {v!r}")
            pairs = tuple((str(a), _yaml11_number(b)) for a, b in v.items())
            for name, x in pairs:
                _check_number(f"method.matched_sensors.{name}", x)
            values[k] = tuple((a, float(b)) for a, b in pairs)
        elif isinstance(d, str):
            if not isinstance(v, str):
                raise ConfigError(f"method.{k}: expected a string, got {v!r}")
            values[k] = v
        else:
            values[k] = _coerce(f"method.{k}", d, v)
    try:
        return dc.replace(defaults, **values)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def load_method_config(path: str | Path | None = None):
    """Load ``config/method.yaml`` (or the given file) into a MethodConfig."""
    if path is None:
        path = default_config_path("method.yaml")
    return method_config_from_dict(load_yaml(path))
