"""``jident info`` for any drive: what the configuration tells the identification, and whether the simulator and
the image method's pattern library can serve this drive (docs/your_drive.md).  Never imports rclpy."""
from __future__ import annotations

from jident_ros.identify.library import model_problem
from jident_ros.parameters import DIAGNOSTIC as DIAGNOSTIC_DEFAULTS
from jident_ros.parameters import WINDOWING as WINDOWING_DEFAULTS


def identification_lines(system, diagnostic: dict | None = None, windowing: dict | None = None) -> list:
    """The keys the gap estimator and the detectors read, with their values and units; ``diagnostic`` and
    ``windowing``: what a drive file declares for those nodes (cli/drive_file.py), over the nodes' defaults."""
    m, s, g, r = system.motor, system.sampling, system.grid, system.load.wheel_radius_m
    dg = dict(DIAGNOSTIC_DEFAULTS, **(diagnostic or {}))
    wd = dict(WINDOWING_DEFAULTS, **(windowing or {}))
    lo, hi = dg["plausible_min_ratio"], dg["plausible_max_ratio"]
    j = m.nominal_inertia_kgm2
    widths = ", ".join(f"{w:g}" for w in g.backlash_widths_m)
    return [
        "Identification (docs/your_drive.md):",
        f"  motor.nominal_inertia_kgm2 = {j:g} kg m^2 (plausible band {lo * j:.4g}..{hi * j:.4g} kg m^2: "
        f"plausible_min/max_ratio {lo:g}/{hi:g})",
        f"  grid.inertia_classes_kgm2 = [{', '.join(f'{c:g}' for c in g.inertia_classes_kgm2)}] kg m^2",
        f"  load.wheel_radius_m = {r:g} m (K2 is reported at this radius: half zone K2/r; library widths "
        f"[{widths}] m = [{', '.join(f'{w / r * 1e3:.4g}' for w in g.backlash_widths_m)}] mrad)",
        f"  motor.bearing_friction_nms_per_rad = {m.bearing_friction_nms_per_rad:g} N m s/rad",
        f"  sampling.sample_period_s = {s.sample_period_s:g} s ({1.0 / s.sample_period_s:g} Hz); window "
        f"{s.samples_before_entry} + {s.samples_from_entry} samples = "
        f"{(s.samples_before_entry + s.samples_from_entry) * s.sample_period_s:g} s",
        f"  windowing: detector {wd['detector']}, gear_ratio {wd['gear_ratio']:g} "
        f"(motor turns per load-encoder turn), joints motor_joint '{wd['motor_joint']}' / "
        f"load_joint '{wd['load_joint']}' (node parameters; jident diagnose --gear-ratio, "
        f"--motor-joint, --load-joint)",
        f"  the drive's torque estimate and friction: torque_accuracy {dg['torque_accuracy']:g}, torque_offset_rel_base "
        f"{dg['torque_offset_rel_base']:g} (± {dg['torque_offset_rel_base'] * m.base.torque_nm:.3g} N m), "
        f"coulomb_friction_max_nm {dg['coulomb_friction_max_nm']:g}, viscous_friction_band_nms_per_rad "
        f"{dg['viscous_friction_band_nms_per_rad']:g}, torque_lag_max_s {dg['torque_lag_max_s']:g}, torque_delay_s "
        f"{dg['torque_delay_s']:g}, torque_filter_s {dg['torque_filter_s']:g}; the motor "
        f"encoder's accuracy: encoder_accuracy_rad {dg['encoder_accuracy_rad']:g}; the coupling lets go within "
        f"coupling_release_max_s {dg['coupling_release_max_s']:g} (diagnostic node parameters; jident "
        f"diagnose --torque-accuracy, ...)",
    ]


def library_line(system, method, path, exists: bool, problem: str) -> str:
    """Whether the image method has a pattern library for this drive, and how to get one."""
    if exists:
        return f"Pattern library: {path} (the image method is on)"
    if problem:
        return ("Pattern library: none for this drive, and the simulator cannot build one: the image method is off "
                "(windows are identified from the gap). Build one from calibration recordings of this drive with "
                "known J1: jident build-patterns --from-recordings REC... --label REC=J1 (docs/recording.md, "
                "docs/your_drive.md)")
    return (f"Pattern library: not built yet ({path}); the first jident diagnose / diagnostic node builds it from "
            f"the simulator ({len(system.grid.inertia_classes_kgm2)} classes x {len(system.grid.backlash_widths_m)} "
            f"widths), or jident build-patterns --from-recordings REC... --label REC=J1 from your recordings")


__all__ = ["identification_lines", "library_line", "model_problem"]
