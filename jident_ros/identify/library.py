"""Where the pattern library lives and how it is loaded (or built when missing)."""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable

from jident_ros.method.patterns import LibraryMismatch, PatternLibrary, library_metadata


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


__all__ = ["default_library_path", "load_pattern_library"]
