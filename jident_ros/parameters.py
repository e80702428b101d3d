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
    """One node parameter: default, description, range [min, max] (each end inclusive unless ``min_exclusive`` /
    ``max_exclusive``), choices, read_only (False: a change at run time takes effect), unit ("" = from the name's
    suffix, :func:`unit_of`), and for a parameter that sets a field of a config dataclass that takes None, whether 0
    stands for that None (``zero_is_none``: ROS parameters cannot be None)."""

    default: Any
    description: str
    min: float | None = None
    max: float | None = None
    read_only: bool = True
    choices: tuple = ()
    min_exclusive: bool = False   # the range is (min, max]: min itself is refused
    max_exclusive: bool = False   # the range is [min, max): max itself is refused
    unit: str = ""
    zero_is_none: bool = False
    nonzero: bool = False         # 0 itself is refused (a signed ratio)

    def range_text(self) -> str:
        """The range as the docs and the one-line errors say it ("" when there is none)."""
        if self.choices:
            return "one of " + ", ".join(str(c) for c in self.choices)
        lo = "" if self.min is None else (f"> {self.min:g}" if self.min_exclusive else f">= {self.min:g}")
        hi = "" if self.max is None else (f"< {self.max:g}" if self.max_exclusive else f"<= {self.max:g}")
        return " and ".join(x for x in (lo, hi, "!= 0" if self.nonzero else "") if x)


#: Units of parameter and field names (suffix -> unit, SI, REP 103), longest suffix first.
UNIT_SUFFIXES = (("_nms_per_rad", "N m s/rad"), ("_nm_per_rad", "N m/rad"), ("_ns_per_m", "N s/m"),
                 ("_n_per_m", "N/m"), ("_pa_sn", "Pa s^n"), ("_kgm2", "kg m^2"), ("_m_s", "m/s"), ("_m2", "m^2"),
                 ("_pct_per_window", "% per window"), ("_bytes", "bytes"), ("_rad", "rad"), ("_hz", "Hz"),
                 ("_pu", "per unit"), ("_pct", "%"), ("_sd", "standard deviations"), ("_kg", "kg"), ("_m", "m"),
                 ("_s", "s"), ("_v", "V"), ("_n", "N"))


def unit_of(name: str, param: "Param | None" = None) -> str:
    """The unit of a parameter: its own ``unit``, else the one its name's suffix says ("" when none)."""
    if param is not None and param.unit:
        return param.unit
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def cli_help(name: str, schema: "dict | None" = None, node: str = "diagnostic") -> str:
    """The --help of a CLI flag that mirrors the node parameter ``name``: its description, unit, range and
    default from the schema (argparse's % escaped)."""
    p = (DIAGNOSTIC_PARAMS if schema is None else schema)[name]
    unit, rng = unit_of(name, p), p.range_text()
    facts = "; ".join(x for x in (unit and f"unit {unit}", rng, f"default {p.default!r}") if x)
    return f"{p.description} ({facts}; the {node} node's parameter {name})".replace("%", "%%")


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
    "fast_sleep_s": Param(0.001, "timer period when real_time_factor = 0 (at most 4 batches per tick), s", min=0.0, max=1.0),
    "max_lead_s": Param(2.0, "real_time_factor 0: at most this many drive seconds ahead of the windowing "
                        "node's drive/progress and, once heard, the diagnostic node's drive/diagnosed_progress; "
                        "0 = no back-pressure", min=0.0, max=3600.0),
    "progress_timeout_s": Param(2.0, "no drive/progress for this long while waiting: back-pressure off "
                                "(warning), s", min=0.0, max=3600.0, min_exclusive=True),
    "start_time_s": Param(1.0, "drive clock of the first sample, s", min=0.0, max=1e9),
    "repeat": Param(1, "passes through the case list; 0 = forever", min=0, max=1_000_000),
    "publish_clock": Param(True, "publish the drive clock on /clock (the other nodes may use_sim_time; the launch "
                           "file remaps it into a namespaced drive)"),
    "wait_for_subscribers": Param(1, "wait until drive/signals has this many subscribers (1: the windowing "
                                  "node) before the first case; 0 = start at once (warned when nobody listens)",
                                  min=0, max=1000),
    "wait_for_node": Param("jident_windowing", "with wait_for_subscribers > 0, also wait until a node of this name "
                           "(any namespace) subscribes to drive/signals: the diagnostic node's recorder alone "
                           "does not start the stream; empty = any subscribers"),
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
    "input": Param("signals", "what the drive publishes: signals (drive/signals, std_msgs/Float64MultiArray "
                   "batches) | joint_states (sensor_msgs/JointState, one message per sample)",
                   choices=("signals", "joint_states")),
    "detector": Param("auto", "entry detector: flank (no K2, any encoder offsets) | paper (inequality 1 with "
                      "backlash_width_m, zone-centred angles) | dynamics (no angles: the load-torque step m_el - "
                      "J1_nom dω1/dt, from a1 or the alpha1 encoder) | auto (flank for joint_states, dynamics for "
                      "joint_states whose channels hold no alpha2, paper for signals)",
                      choices=("auto", "flank", "paper", "dynamics")),
    "gear_ratio": Param(1.0, "N in delta = alpha1 - N alpha2: motor turns per load-encoder turn (flank detector); "
                             "negative when the load encoder counts the other way (a reversing gear, an encoder "
                             "mounted facing the motor's)", min=-1000.0, max=1000.0, nonzero=True),
    "motor_joint": Param("motor", "joint_states: the motor joint (position alpha1, velocity omega1, effort m_el)"),
    "load_joint": Param("load", "joint_states: the load joint (position alpha2, velocity omega2)"),
    "use_imu": Param(False, "joint_states: a1 from sensor_msgs/Imu on imu (matched by stamp)"),
    "imu_axis": Param("x", "joint_states: the Imu linear_acceleration axis that is a1", choices=("x", "y", "z")),
    "batch_size": Param(50, "joint_states: samples per batch handed to the detector", min=1, max=MAX_DEPTH),
    "input_reliability": Param("reliable", "QoS reliability of the input subscriptions (drive/signals, joint_states, "
                               "imu): reliable | best_effort (drivers that publish with SensorDataQoS)",
                               choices=("reliable", "best_effort")),
}

#: The gap methods (the one list: the diagnostic node's ``gap_method``, ``jident diagnose --gap-method``, the
#: diagnosis; :func:`jident_ros.identify.gap.estimate_inertia`): ``auto`` (acceleration fit when a1 is there,
#: else angle, else speed), ``acceleration``, ``gap_only``, ``anchored``, ``angle``, ``speed``; ``none`` is the
#: preferred spelling of "no gap estimate", ``off`` (which a command line reads as YAML false) is still accepted.
GAP_METHODS = ("auto", "acceleration", "gap_only", "anchored", "angle", "speed", "none", "off")
#: The gap_method values that mean: no gap estimate.
NO_GAP = ("none", "off")


def gap_method_problem(gap_method, image_method: bool):
    """The rules of the gap method, in one wording: None, or (field, "what is wrong") -- the field's value is
    not one of :data:`GAP_METHODS`, or there is neither a gap estimate nor the image method."""
    if gap_method not in GAP_METHODS:
        return "gap_method", f"expected one of {', '.join(GAP_METHODS)}, got {gap_method!r}"
    if not image_method and gap_method in NO_GAP:
        return "image_method", "must be true when gap_method is none (nothing would be identified)"
    return None

#: Trend of J1 and the backlash width (issue 14), parameters of the diagnostic node: the one schema of the
#: trend's parameters.  ``trend_<field>`` sets the TrendConfig field ``<field>`` (:data:`TREND_FIELDS`;
#: TrendConfig.from_parameters maps them from here), but for :data:`TREND_NODE_ONLY`; ``zero_is_none``: 0 means
#: "not set" where TrendConfig takes None.  A new trend parameter: one entry here and its field in TrendConfig;
#: config/nodes.yaml and docs/interfaces.md follow (tests).
TREND_PARAMS = {
    "trend_enabled": Param(True, 'follow the trend of J1 and K2: inertia_trend, backlash_width_trend and the '
                           '"jident_diagnostic: trend" status'),
    "trend_state_file": Param("", 'tracker state file (JSON, written atomically after each window, read at start) so the '
                              'trend survives a restart; "" = not kept'),
    "trend_commissioning_windows": Param(5, 'windows that give the first baseline', min=2, max=10**9, read_only=False),
    "trend_commissioning_duration_s": Param(0.0, 'instead: learn over this drive time, s (0 = by windows)',
                                            min=0.0, max=1e12, read_only=False, zero_is_none=True),
    "trend_inertia_baseline_kgm2": Param(0.0, 'given J1 baseline, kg m^2 (0 = learn it)', min=0.0, max=1e12, zero_is_none=True),
    "trend_inertia_baseline_se_kgm2": Param(0.0, 'standard error of the given J1 baseline, kg m^2', min=0.0, max=1e12),
    "trend_width_baseline_m": Param(0.0, 'given width baseline, m (0 = learn it)', min=0.0, max=1e12, zero_is_none=True),
    "trend_width_baseline_se_m": Param(0.0, 'standard error of the given width baseline, m', min=0.0, max=1e12),
    "trend_target_arl_windows": Param(300000.0, 'in-control average run length (windows) the two-sided CUSUM threshold is '
                                      'designed for: 1e4 / this = false changes per 10,000 steady windows',
                                      min=1.0, min_exclusive=True, max=1e12, read_only=False),
    "trend_cusum_reference_sd": Param(1.5, 'CUSUM k, standard deviations', min=0.0, min_exclusive=True, max=1e12,
                                      read_only=False),
    "trend_cusum_threshold_sd": Param(0.0, 'CUSUM h (0 = from trend_target_arl_windows)',
                                      min=0.0, max=1e12, read_only=False, zero_is_none=True),
    "trend_innovation_clip_sd": Param(4.5, 'standardised innovations clipped at +- this many standard deviations',
                                      min=0.0, min_exclusive=True, max=1e12, read_only=False),
    "trend_se_scale_from_commissioning": Param(False, 'scale the reported errors by the commissioning scatter', read_only=False),
    "trend_se_scale_max": Param(3.0, 'largest scale of the reported standard errors from the commissioning '
                                'scatter', min=1.0, max=1e12, read_only=False),
    "trend_inertia_process_sd_pct_per_window": Param(0.02, 'J1 random walk, % of the baseline per window',
                                                     min=0.0, max=1e12, read_only=False),
    "trend_relearn_windows": Param(5, 'windows after a change forming the new baseline', min=1, max=10**9, read_only=False),
    "trend_change_hold_windows": Param(24, 'WARN for this many windows after a change', min=0, max=10**9, read_only=False),
    "trend_drift_warn_pct": Param(2.0, 'J1 drift giving WARN, %', min=0.0, min_exclusive=True, max=1e12, read_only=False),
    "trend_drift_alarm_pct": Param(5.0, 'J1 drift giving ERROR, %', min=0.0, min_exclusive=True, max=1e12, read_only=False),
    "trend_width_limit_m": Param(0.012, 'backlash width limit (ERROR), m', min=0.0, min_exclusive=True, max=1e12,
                                 read_only=False),
    "trend_width_warn_m": Param(0.0, 'WARN width, m (0 = 90 % of the limit)', min=0.0, max=1e12, read_only=False, zero_is_none=True),
    "trend_time_to_limit_warn_s": Param(2592000.0, 'WARN when the limit is projected sooner, s (30 days; 0 = off)',
                                        min=0.0, max=1e12, read_only=False, zero_is_none=True),
    "trend_width_regression_windows": Param(50, 'windows of the wear-rate regression', min=3, max=10**9),
    "trend_width_se_floor_m": Param(1.0e-6, 'floor of the width standard error, m', min=0.0, max=1e12, read_only=False),
    "trend_width_change_detection": Param(True, 'change detection (CUSUM) on the width too', read_only=False),
    "trend_wear_significance_sd": Param(1.96, 'wear rate significant above this many standard errors',
                                       min=0.0, min_exclusive=True, max=1e12, read_only=False),
    "trend_max_changes_kept": Param(100, 'change events kept in the state', min=1, max=10**9, read_only=False),
    "trend_baseline_refine_windows": Param(20, 'J1 baseline refined by the monitored windows up to this many windows',
                                           min=0, max=10**9, read_only=False),
    "trend_torque_accuracy_pct": Param(0.0, "the drive's torque accuracy, % (1 sd): widens the absolute J1 only",
                                       min=0.0, max=100.0, read_only=False),
    "trend_se_scale_down": Param(True, "scale the errors down to the refined baseline's scatter when it is "
                                 'significantly smaller (over-reported errors)', read_only=False),
    "trend_se_scale_min": Param(0.25, 'smallest such scale', min=0.0, min_exclusive=True, max=1.0, read_only=False),
    "trend_time_discontinuity_s": Param(604800.0, 'a window this long after the previous one (or before it) starts '
                                        'a new time segment, s', min=0.0, min_exclusive=True, max=1e12, read_only=False),
}
#: The trend parameters that are the node's own, not TrendConfig fields.
TREND_NODE_ONLY = ("trend_enabled", "trend_state_file")
#: parameter name -> the TrendConfig field it sets.
TREND_FIELDS = {name: name[len("trend_"):] for name in TREND_PARAMS if name not in TREND_NODE_ONLY}

#: The diagnostic node (besides config/system.yaml and config/method.yaml).
DIAGNOSTIC_PARAMS = {
    "pattern_library": Param("", "pattern library .npz; empty = ~/.cache/jident_ros/patterns-<hash>.npz "
                             "(as `jident build-patterns`)"),
    "build_if_missing": Param(True, "build (and save) the pattern library when the file does not exist"),
    "p": Param(2.0, "KHM exponent p of the image method, one of method.p_values", min=1.0, max=100.0,
               read_only=False),
    "image_method": Param(True, "run the paper's image method on every window", read_only=False),
    "gap_method": Param("auto", "J1 from the backlash gap: auto | acceleration | gap_only | anchored | angle | speed | "
                        "none (off is accepted)", choices=GAP_METHODS, read_only=False),
    "hardware_id": Param("", "hardware_id of the /diagnostics statuses; empty = the resolved drive namespace",
                         read_only=False),
    "stale_after_s": Param(5.0, "STALE when no drive/window arrived for this long (steady clock), s; "
                           "0 = never", min=0.0, max=86400.0, read_only=False),
    "record": Param(True, "record to a rosbag2 MCAP bag (docs/recording.md)"),
    "record_root": Param("", "bags go to <root>/rosbag2_YYYY_MM_DD-HH_MM_SS; empty = $JIDENT_DATA_DIR/bags, else "
                         "$XDG_DATA_HOME/jident_ros/bags, else ~/.local/share/jident_ros/bags"),
    "record_dir": Param("", "deprecated: this exact bag directory (new or empty) instead of record_root"),
    "max_bag_size_bytes": Param(1073741824, "split the bag's .mcap file at this size, bytes; 0 = no limit",
                                min=0, max=2**62),
    "max_bag_duration_s": Param(3600.0, "split the bag's .mcap file after this long, s; 0 = no limit",
                                min=0.0, max=1e9),
    "retention_max_total_bytes": Param(20000000000, "delete the oldest complete bags above this total, bytes; "
                                       "0 = no limit", min=0, max=2**62),
    "retention_max_age_s": Param(604800.0, "delete complete bags older than this, s; 0 = no limit",
                                 min=0.0, max=1e10),
    "retention_delete_unfinalised": Param(False, "let retention delete this node's bags that were not finalised "
                                          "(a crash cut them); default: kept for jident salvage"),
    "record_signals": Param(True, "also record drive/signals, drive/backlash_width, drive/true_inertia, "
                            "drive/case (replayable)"),
    "window_queue_depth": Param(50, "keep-last depth of the drive/window subscription", min=1, max=MAX_DEPTH),
    "signals_queue_depth": Param(1000, "keep-last depth of the recorder's drive/signals subscription",
                                 min=1, max=MAX_DEPTH),
    # the publishing policy (jident_ros.identify.verdict.VerdictPolicy; docs/interfaces.md "/diagnostics")
    "plausible_min_ratio": Param(0.5, "J1 below this x the nominal is refused, not published", min=0.0,
                                 max=1.0, min_exclusive=True, max_exclusive=True, read_only=False),
    "plausible_max_ratio": Param(1.5, "J1 above this x the nominal is refused, not published", min=1.0, min_exclusive=True, max=100.0,
                                 read_only=False),
    "image_min_margin": Param(1.401117, "the image method's class alone, and its disagreement as a WARN, only at "
                              "a fused margin >= this; 0 = never (from `python -m jident_ros.research.evaluation.verdicts "
                              "threshold`)", min=0.0, max=1e12, read_only=False),
    "library_width_tolerance": Param(0.05, "the image method is valid only with a library width within this "
                                     "fraction of the window's K2", min=0.0, min_exclusive=True, max=1.0, read_only=False),
    "max_torque_factor": Param(100.0, "|m_el| above this x the base torque M_b is absurd: window refused",
                               min=1.0, max=1e6, read_only=False),
    "max_speed_factor": Param(10.0, "|omega1|, |omega2| above this x the synchronous speed is absurd: window "
                              "refused", min=1.0, max=1e6, read_only=False),
    # the gap fits' drive model (jident_ros.identify.gap_free.GapModel via VerdictPolicy; issue 20)
    "torque_accuracy": Param(0.0, "the drive's torque estimate m_el: bound of its scale error, fraction (0.02 = 2 %; "
                             "0 = exact, the simulator); J1 x this/sqrt(3) goes into the gap interval and the class "
                             "verdict", min=0.0, max=0.5, max_exclusive=True, read_only=False, unit="1 (fraction)"),
    "coulomb_friction_max_nm": Param(0.0, "the motor's Coulomb (bearing) friction lies in [0, this], N m: fitted in "
                                     "the gap inside the band when the torque varies enough, else a bounded term "
                                     "of the gap interval", min=0.0, max=1e6, read_only=False, unit="N m"),
    "viscous_friction_band_nms_per_rad": Param(0.0, "viscous friction = motor.bearing_friction_nms_per_rad +- this, "
                                               "N m s/rad (a bounded term of the gap interval)", min=0.0, max=1e6,
                                               read_only=False, unit="N m s/rad"),
    "torque_offset_rel_base": Param(0.01, "an unknown constant torque in the gap (the torque estimate's offset, "
                                    "friction the keys above leave out) within +- this x the base torque M_b: a "
                                    "bounded term of the gap interval", min=0.0, max=1.0, max_exclusive=True,
                                    read_only=False, unit="1 (fraction of M_b)"),
    "torque_lag_max_s": Param(0.0, "the drive's torque estimate m_el lags (or leads) the shaft's torque by at "
                              "most this, s: a bounded term of the gap interval", min=0.0, max=1.0, read_only=False,
                              unit="s"),
    "torque_delay_s": Param(0.0, "the drive's torque estimate m_el is known to lag the shaft's torque by this, s "
                            "(reported N drive cycles late: N x the cycle): m_el is advanced by it before the gap "
                            "fits; torque_lag_max_s bounds what remains", min=0.0, max=1.0, read_only=False, unit="s"),
    "torque_filter_s": Param(0.0, "the drive smooths its torque estimate m_el with a first-order low-pass of this time "
                             "constant, s (a smoothed 'actual torque'): undone before the gap fits (m_el + this x "
                             "dm_el/dt)", min=0.0, max=1.0, read_only=False, unit="s"),
    "encoder_accuracy_rad": Param(0.0, "the motor encoder's angle error is at most this, rad, once and twice per "
                                  "revolution (its data sheet's accuracy; a resolver +-10 arc min = 2.9e-3): a bounded "
                                  "term of the gap interval (0 = an exact disc)", min=0.0, max=0.1, read_only=False,
                                  unit="rad"),
    "coupling_release_max_s": Param(4e-3, "the coupling lets go of the motor within this time after its torque starts "
                                    "to fall, s (about a quarter period of the load on the coupling, "
                                    "(pi/2) sqrt(J_load/k); 0 = a rigid contact, lost at once): the steady-entry fit "
                                    "searches the unloading times up to it", min=0.0, max=1.0, read_only=False, unit="s"),
    "assume_typical_drive": Param(True, "a drive that declares none of torque_accuracy, coulomb_friction_max_nm, "
                                  "viscous_friction_band_nms_per_rad, torque_lag_max_s, motor.bearing_friction_nms_per_rad "
                                  "is taken, on windows of raw encoder angles (a real drive's recording: flank or "
                                  "dynamics detector), for a typical drive: torque accuracy 3 %, offset band 2 % of M_b, "
                                  "lag 1 ms, bearing friction in [0, 3 % of M_b] (jident_ros.identify.verdict.TYPICAL_DRIVE, "
                                  "TYPICAL_FRICTION_REL_BASE); false: as declared (0 = exact)",
                                  read_only=False),
    "publish_ambiguous": Param(True, "publish the gap J1 (with its interval on inertia_estimate/detail) when its 95 % "
                               "interval, within +-10 %, holds two or more classes: no class named, status "
                               "'ambiguous'; false: nothing published for such a window", read_only=False),
    **TREND_PARAMS,
}

#: The publishing policy's parameters that `jident diagnose` takes as flags (--torque-accuracy, ...; fields of
#: jident_ros.identify.verdict.VerdictPolicy: a test keeps them so).  The input bounds (library_width_tolerance,
#: max_torque_factor, max_speed_factor) stay the node's only.
POLICY_CLI_FLAGS = ("image_min_margin", "plausible_min_ratio", "plausible_max_ratio", "torque_accuracy",
                    "coulomb_friction_max_nm", "viscous_friction_band_nms_per_rad", "torque_offset_rel_base",
                    "torque_lag_max_s", "torque_delay_s", "torque_filter_s", "encoder_accuracy_rad",
                    "coupling_release_max_s",
                    "assume_typical_drive",
                    "publish_ambiguous")

#: The replay node.  Everything is fixed at start: read-only.
REPLAY_PARAMS = {
    "bag": Param("", "bag directory or .mcap file (or the first command-line argument)"),
    "rate": Param(1.0, "playback speed factor; 0 = as fast as the windowing node reads", min=0.0, max=1000.0),
    "fast_sleep_s": Param(0.001, "timer period when rate = 0 (at most 4 messages per tick), s", min=0.0, max=1.0),
    "max_lead_s": Param(2.0, "at most this many drive seconds ahead of drive/progress and, once heard, "
                        "drive/diagnosed_progress, at any rate (a downstream that falls behind pauses the replay, "
                        "WARN with the count); 0 = off",
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
TREND = defaults(TREND_PARAMS)


_TYPE_NAMES = {bool: "bool", int: "integer", float: "double", str: "string"}


def _type_name(default) -> str:
    if isinstance(default, list):
        return ("string" if default and isinstance(default[0], str) else "double") + "[]"
    return _TYPE_NAMES[type(default)]


def markdown_table(schema: dict) -> str:
    """The declared parameters of a node as a Markdown table (docs/interfaces.md holds these, a test
    keeps them equal): name, type, default, range, whether a change at run time takes effect, description."""
    rows = ["| parameter | type | default | unit | range | at run time | description |",
            "|---|---|---|---|---|---|---|"]
    for name, p in schema.items():
        default = f"`{p.default!r}`" if p.default != "" else '`""`'
        rows.append(f"| `{name}` | {_type_name(p.default)} | {default} | {unit_of(name, p) or '—'} | "
                    f"{p.range_text() or '—'} | {'read-only' if p.read_only else 'settable'} | {p.description} |")
    return "\n".join(rows)
