"""Where the pattern library lives and how it is loaded (or built when missing)."""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable

from jident_ros.method.patterns import LibraryMismatch, PatternLibrary, library_metadata
from jident_ros.sim import Case, steady_state

#: How a library error starts when the image method is off by configuration (no library for this drive), not
#: broken: the diagnosis then says it once per run, not in every window's message (docs/your_drive.md).
IMAGE_METHOD_OFF = "image method off"


def model_problem(system) -> str:
    """'' when our simulator can run this drive's loaded steady state (and so build a pattern library), else one
    line: why not, and what to set."""
    cases = [Case(system.motor.nominal_inertia_kgm2, system.grid.backlash_widths_m[0], e)
             for e in system.grid.consistency_indices_pa_sn]
    try:
        steady_state(system, cases, 0.0)
    except ValueError as exc:
        b = system.motor.base
        r = system.load.wheel_radius_m
        return (f"the simulator's motor-load model cannot run this drive ({exc}): its load is the paper's "
                f"(load.process_force_n {system.load.process_force_n:g} N at load.wheel_radius_m {r:g} m = "
                f"{r * system.load.process_force_n:.4g} N m) on a motor of base torque M_b = {b.torque_nm:.4g} N m "
                f"(from motor.nominal_inertia_kgm2 and mechanical_time_constant_s); identification from recordings "
                f"does not need the simulator (the gap estimate works); to simulate, scale load.process_force_n to "
                f"about 0.7 M_b / r = {0.7 * b.torque_nm / r:.4g} N")
    return ""


def no_library_text(system) -> str:
    """The one-line reason of a drive without a matching library that the simulator cannot build."""
    return (f"{IMAGE_METHOD_OFF}: no pattern library for this drive (nominal J1 "
            f"{system.motor.nominal_inertia_kgm2:g} kg m^2) and the simulator cannot build one; J1 comes from the gap. "
            f"Build one from calibration recordings with known J1: jident build-patterns --from-recordings REC... "
            f"--label REC=J1 (docs/your_drive.md)")


def default_library_path(system, method) -> Path:
    """~/.cache/jident_ros/patterns-<hash>.npz (or $JIDENT_CACHE_DIR)."""
    meta = library_metadata(system, method)
    base = Path(os.environ.get("JIDENT_CACHE_DIR") or Path.home() / ".cache" / "jident_ros")
    return base / f"patterns-{meta['system_hash'][:8]}-{meta['method_hash'][:8]}.npz"


def load_pattern_library(path, system, method, build_if_missing: bool = True,
                         log: Callable[[str], Any] = lambda text: None,
                         warn: Callable[[str], Any] = lambda text: None):
    """Load the pattern library at ``path`` (or build and save it there when it is missing).

    Returns ``(library, None)`` or ``(None, error)`` with a one-line reason naming the file: missing (and
    not to be built), unreadable (empty, truncated zip, bad CRC), inconsistent (shapes, NaN/Inf, class
    count), built for another configuration (LibraryMismatch), or the build failed.  ``log`` gets the
    progress lines, ``warn`` a failed save (the built library is still used).
    """
    path = Path(path)
    try:
        lib = PatternLibrary.load(path, system, method)
        log(f"pattern library {path}")
        return lib, None
    except FileNotFoundError as exc:
        if not build_if_missing:
            return None, f"pattern library missing: {exc}"
    except LibraryMismatch as exc:
        return None, f"pattern library unusable: {exc}"
    except Exception as exc:  # whatever else a damaged file raises: never a traceback, always the reason
        return None, f"pattern library unusable: {path}: {type(exc).__name__}: {exc}"
    if model_problem(system):
        return None, no_library_text(system)
    n_classes = len(system.grid.inertia_classes_kgm2)
    log(f"pattern library {path} not found: building it ({n_classes} J1 classes x "
        f"{len(system.grid.backlash_widths_m)} widths, a few seconds)")
    t0 = time.perf_counter()

    def progress(k, n):
        step = "noise seed" if method.variant == "sensor_matched" else "signal"   # what PatternLibrary.build counts
        log(f"building pattern library: {step} {k}/{n} done ({time.perf_counter() - t0:.1f} s)")

    try:
        lib = PatternLibrary.build(system, method, progress=progress)
    except Exception as exc:
        return None, f"pattern library could not be built: {type(exc).__name__}: {exc}"
    try:
        lib.save(path)
        log(f"pattern library built in {time.perf_counter() - t0:.1f} s, saved to {path}")
    except OSError as exc:
        warn(f"pattern library built but not saved to {path}: {exc}")
    return lib, None


__all__ = ["IMAGE_METHOD_OFF", "default_library_path", "load_pattern_library", "model_problem", "no_library_text"]
