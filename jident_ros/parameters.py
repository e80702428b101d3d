"""The parameters of the four nodes besides the model and method sections (config/system.yaml,
config/method.yaml): one schema for the nodes, the CLI, the docs and the tests.

Each entry is a :class:`Param`: its default (whose Python type is the ROS parameter type), a one-line
description, its range (``min``/``max``, inclusive; ``min_exclusive`` when the bound itself is refused),
its allowed values (``choices``) and whether a change at run time can take effect (``read_only``).  The
nodes declare every parameter with a ``rcl_interfaces/ParameterDescriptor`` built from it
(:func:`jident_ros.nodes.params.descriptor`), so ``ros2 param describe`` (the ``describe_parameters``
service) tells the type, the description and the range.  ``SIMULATOR``, ``WINDOWING``, ``DIAGNOSTIC``,
``REPLAY`` are the plain {name: default} dicts derived from the schemas; config/nodes.yaml holds the
same defaults in the ROS 2 params-file format (a test keeps the two equal).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Param:
    """One node parameter: default, description, inclusive range [min, max], choices, read_only."""

    default: Any
    description: str
    min: float | None = None
    max: float | None = None
    read_only: bool = True
    choices: tuple = ()
    min_exclusive: bool = False   # the range is (min, max]: min itself is refused

    def range_text(self) -> str:
        """The range as the docs and the one-line errors say it ("" when there is none)."""
        if self.choices:
            return "one of " + ", ".join(str(c) for c in self.choices)
        lo = "" if self.min is None else (f"> {self.min:g}" if self.min_exclusive else f">= {self.min:g}")
        hi = "" if self.max is None else f"<= {self.max:g}"
        return " and ".join(x for x in (lo, hi) if x)


def defaults(schema: dict) -> dict:
    """{name: default} of a schema."""
    return {name: p.default for name, p in schema.items()}


#: Upper bound of the queue depths (a keep-last history of more is a memory leak in disguise).
MAX_DEPTH = 100_000

#: The simulator node (besides the model sections of config/system.yaml).  Everything is fixed at start
#: (the cases are simulated before the first batch): read-only.
SIMULATOR_PARAMS = {
    "cases": Param("product", "how the case lists combine: product (every combination), zip (element-wise), "
                   "grid (the paper's 168 cases of system.yaml)", choices=("product", "zip", "grid")),
    "inertias_kgm2": Param([1.16, 1.073, 1.218], "J1 of the simulated cases, kg m^2 (each > 0)", min=0.0,
                           min_exclusive=True),
    "backlash_widths_m": Param([0.005], "backlash width K2 of the simulated cases, m (each > 0)", min=0.0,
                               min_exclusive=True),
    "consistencies_pa_sn": Param([0.025], "consistency index eta_k of the simulated cases, Pa s^n (each > 0)",
                                 min=0.0, min_exclusive=True),
    "gap_samples": Param(400, "steady-state samples before each case", min=0, max=1_000_000),
    "batch_size": Param(50, "samples per drive/signals message", min=1, max=MAX_DEPTH),
    "real_time_factor": Param(1.0, "drive seconds per wall second; 0 = as fast as the windowing node reads "
                              "(back-pressure by drive/progress)", min=0.0, max=1000.0),
    "fast_sleep_s": Param(0.001, "timer period per batch when real_time_factor = 0, s", min=0.0, max=1.0),
    "max_lead_s": Param(2.0, "real_time_factor 0: at most this many drive seconds ahead of the windowing "
                        "node's drive/progress; 0 = no back-pressure", min=0.0, max=3600.0),
    "progress_timeout_s": Param(2.0, "no drive/progress for this long while waiting: back-pressure off "
                                "(warning), s", min=0.0, max=3600.0, min_exclusive=True),
    "start_time_s": Param(1.0, "drive clock of the first sample, s", min=0.0, max=1e9),
    "repeat": Param(1, "passes through the case list; 0 = forever", min=0, max=1_000_000),
    "publish_clock": Param(True, "publish the drive clock on /clock (the other nodes may use_sim_time; the launch "
                           "file remaps it into a namespaced drive)"),
    "wait_for_subscribers": Param(1, "wait until drive/signals has this many subscribers (1: the windowing "
                                  "node) before the first case; 0 = start at once (warned when nobody listens)",
                                  min=0, max=1000),
    "wait_timeout_s": Param(30.0, "give up (exit status 1) when the subscribers are not there after this "
                            "long, s", min=0.0, max=86400.0, min_exclusive=True),
    "exit_when_done": Param(True, "exit after the last case (else stay up, idle)"),
    "signals_queue_depth": Param(1000, "keep-last depth of the drive/signals publisher", min=1, max=MAX_DEPTH),
}

#: The windowing node (besides the model sections of config/system.yaml).
WINDOWING_PARAMS = {
    "backlash_width_m": Param(0.005, "K2 of inequality (1) |alpha1 - alpha2| < K2/r, m (settable at run "
                              "time: a window in progress keeps its K2)", min=0.0, max=1.0, min_exclusive=True,
                              read_only=False),
    "backlash_width_from_topic": Param(False, "follow drive/backlash_width (simulator, replay) when published"),
    "channels": Param(["alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2"],
                      "channels captured besides t (must hold alpha1 and alpha2)"),
    "gap_tolerance": Param(1.5, "a step of t above this many sample periods is a gap (samples lost)",
                           min=1.0, max=1000.0, min_exclusive=True, read_only=False),
    "signals_queue_depth": Param(1000, "keep-last depth of the drive/signals subscription", min=1, max=MAX_DEPTH),
    "window_queue_depth": Param(50, "keep-last depth of the drive/window publisher (transient local)",
                                min=1, max=MAX_DEPTH),
    "hardware_id": Param("", "hardware_id of the /diagnostics statuses; empty = the resolved drive "
                         "namespace, e.g. /drive", read_only=False),
    "diagnostics_period_s": Param(1.0, "period of the rate status on /diagnostics, s (steady clock); "
                                  "0 = only the event statuses", min=0.0, max=3600.0),
    "progress_every_batches": Param(10, "publish drive/progress (drive time read) every this many batches; "
                                    "0 = off", min=0, max=MAX_DEPTH),
}

#: The gap method values of the diagnostic node; ``none`` is the preferred spelling of "no gap estimate",
#: ``off`` (which a command line reads as YAML false) is still accepted.
GAP_METHOD_CHOICES = ("auto", "acceleration", "anchored", "angle", "speed", "none", "off")

#: The diagnostic node (besides config/system.yaml and config/method.yaml).
DIAGNOSTIC_PARAMS = {
    "pattern_library": Param("", "pattern library .npz; empty = ~/.cache/jident_ros/patterns-<hash>.npz "
                             "(as `jident build-patterns`)"),
    "build_if_missing": Param(True, "build (and save) the pattern library when the file does not exist"),
    "p": Param(2.0, "KHM exponent p of the image method, one of method.p_values", min=1.0, max=100.0,
               read_only=False),
    "image_method": Param(True, "run the paper's image method on every window", read_only=False),
    "gap_method": Param("auto", "J1 from the backlash gap: auto | acceleration | anchored | angle | speed | "
                        "none (off is accepted)", choices=GAP_METHOD_CHOICES, read_only=False),
    "hardware_id": Param("", "hardware_id of the /diagnostics statuses; empty = the resolved drive namespace",
                         read_only=False),
    "stale_after_s": Param(5.0, "STALE when no drive/window arrived for this long (steady clock), s; "
                           "0 = never", min=0.0, max=86400.0, read_only=False),
    "record_dir": Param("", "MCAP recording (bag directory); empty = no recording"),
    "record_signals": Param(True, "also record drive/signals, drive/backlash_width, drive/true_inertia, "
                            "drive/case (replayable)"),
    "window_queue_depth": Param(50, "keep-last depth of the drive/window subscription", min=1, max=MAX_DEPTH),
    "signals_queue_depth": Param(1000, "keep-last depth of the recorder's drive/signals subscription",
                                 min=1, max=MAX_DEPTH),
}

#: The replay node.  Everything is fixed at start: read-only.
REPLAY_PARAMS = {
    "bag": Param("", "bag directory or .mcap file (or the first command-line argument)"),
    "rate": Param(1.0, "playback speed factor; 0 = as fast as the windowing node reads", min=0.0, max=1000.0),
    "fast_sleep_s": Param(0.001, "timer period per message when rate = 0, s", min=0.0, max=1.0),
    "max_lead_s": Param(2.0, "rate 0: at most this many drive seconds ahead of drive/progress; 0 = off",
                        min=0.0, max=3600.0),
    "progress_timeout_s": Param(2.0, "no drive/progress for this long while waiting: back-pressure off, s",
                                min=0.0, max=3600.0, min_exclusive=True),
    "publish_clock": Param(True, "publish /clock from the t column of drive/signals (remap it per drive)"),
    "topics": Param(["drive/signals", "drive/backlash_width", "drive/true_inertia", "drive/case"],
                    "relative names of the recorded topics to republish"),
    "wait_for_subscribers": Param(0, "wait until drive/signals has this many subscribers", min=0, max=1000),
    "wait_timeout_s": Param(30.0, "give up when the subscribers are not there after this long, s",
                            min=0.0, max=86400.0, min_exclusive=True),
}

SIMULATOR = defaults(SIMULATOR_PARAMS)
WINDOWING = defaults(WINDOWING_PARAMS)
DIAGNOSTIC = defaults(DIAGNOSTIC_PARAMS)
REPLAY = defaults(REPLAY_PARAMS)


_TYPE_NAMES = {bool: "bool", int: "integer", float: "double", str: "string"}


def _type_name(default) -> str:
    if isinstance(default, list):
        return ("string" if default and isinstance(default[0], str) else "double") + "[]"
    return _TYPE_NAMES[type(default)]


def markdown_table(schema: dict) -> str:
    """The declared parameters of a node as a Markdown table (docs/interfaces.md holds these, a test
    keeps them equal): name, type, default, range, whether a change at run time takes effect, description."""
    rows = ["| parameter | type | default | range | at run time | description |", "|---|---|---|---|---|---|"]
    for name, p in schema.items():
        default = f"`{p.default!r}`" if p.default != "" else '`""`'
        rows.append(f"| `{name}` | {_type_name(p.default)} | {default} | {p.range_text() or '—'} | "
                    f"{'read-only' if p.read_only else 'settable'} | {p.description} |")
    return "\n".join(rows)
