"""Locate files shipped with jident_ros (default configuration) in every install mode.

The single source of truth for configuration is the top-level ``config/`` folder
of the repository.  Depending on how the package was installed, a copy of it
lives in a different place; :func:`default_config_path` looks, in this order:

1. ``$JIDENT_CONFIG_DIR`` (explicit override, when set and non-empty);
2. the source checkout, ``<repo>/config`` (running from source or after
   ``pip install -e``); only used when ``<repo>/package.xml`` is beside it, so a
   stray ``site-packages/config`` folder of some other distribution is never
   mistaken for ours;
3. ``<share>/config`` where ``<share>`` is
   ``ament_index_python.get_package_share_directory('jident_ros')`` (``colcon
   build`` + ``source install/setup.bash``, or a ROS distribution package);
4. ``<sys.prefix>/share/jident_ros/config`` (``pip install .``, non-editable:
   setup.py's ``data_files`` land there), then the same under the user base
   (``pip install --user .``).

The first folder that holds the requested file wins.
"""

from __future__ import annotations

import os
import signal
import site
import subprocess
import sys
from pathlib import Path

PACKAGE_NAME = "jident_ros"
CONFIG_ENV_VAR = "JIDENT_CONFIG_DIR"

__all__ = ["CONFIG_ENV_VAR", "PACKAGE_NAME", "config_search_dirs", "default_config_path", "find_executable",
           "node_command"]


def _checkout_config_dir() -> Path | None:
    root = Path(__file__).resolve().parents[1]
    if (root / "package.xml").is_file():
        return root / "config"
    return None


def _ament_config_dir() -> tuple[str, Path | None]:
    """Return (description, folder or None) for the ament index lookup."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except Exception:  # not installed, or broken: the lookup simply does not apply
        return "ament index (ament_index_python not importable)", None
    try:
        share = get_package_share_directory(PACKAGE_NAME)
    except (PackageNotFoundError, LookupError, ValueError, OSError) as exc:
        # LookupError/ValueError: AMENT_PREFIX_PATH unset or empty
        reason = type(exc).__name__
        prefixes = os.environ.get("AMENT_PREFIX_PATH", "")
        return f"ament index ({PACKAGE_NAME} not indexed: {reason}; AMENT_PREFIX_PATH={prefixes!r})", None
    return "ament index share directory", Path(share) / "config"


def config_search_dirs() -> list[tuple[str, Path | None]]:
    """Every place searched, in order, as (description, folder or None if the
    mode does not apply)."""
    dirs: list[tuple[str, Path | None]] = []
    env = os.environ.get(CONFIG_ENV_VAR, "").strip()
    dirs.append((f"${CONFIG_ENV_VAR}" + ("" if env else " (unset)"), Path(env).expanduser() if env else None))
    checkout = _checkout_config_dir()
    dirs.append(("source checkout" + ("" if checkout else " (no package.xml next to the package)"), checkout))
    dirs.append(_ament_config_dir())
    dirs.append(("sys.prefix share", Path(sys.prefix) / "share" / PACKAGE_NAME / "config"))
    try:
        user_base = site.getuserbase()
    except Exception:
        user_base = None
    if user_base:
        dirs.append(("user base share", Path(user_base) / "share" / PACKAGE_NAME / "config"))
    return dirs


def default_config_path(name: str = "system.yaml") -> Path:
    """Return the path of the default configuration file ``name`` (e.g. ``"system.yaml"``).

    Raises FileNotFoundError naming every place that was looked at.
    """
    if not name or Path(name).is_absolute():
        raise ValueError(f"expected a file name relative to the config folder, got {name!r}")
    looked: list[str] = []
    for what, folder in config_search_dirs():
        if folder is None:
            looked.append(f"  - {what}: not applicable")
            continue
        candidate = folder / name
        if candidate.is_file():
            return candidate
        looked.append(f"  - {what}: {candidate}")
    raise FileNotFoundError(
        f"default config {name!r} of {PACKAGE_NAME} not found; looked in:\n"
        + "\n".join(looked)
        + f"\nSet {CONFIG_ENV_VAR} to a folder holding {name!r}, or reinstall the package."
    )


def find_executable(name: str) -> Path | None:
    """``<prefix>/lib/jident_ros/<name>`` where ``<prefix>`` is the ament index prefix of jident_ros:
    the file ``ros2 run jident_ros <name>`` runs (colcon install space, a ROS distribution, or the
    venv that scripts/setup.sh registers in its own index).  None when the package is not indexed
    (AMENT_PREFIX_PATH unset) or the executable is not there."""
    try:
        from ament_index_python.packages import get_package_prefix
        prefix = get_package_prefix(PACKAGE_NAME)
    except Exception:
        return None
    exe = Path(prefix) / "lib" / PACKAGE_NAME / name
    return exe if exe.is_file() and os.access(exe, os.X_OK) else None


def node_command(name: str, *, require_index: bool = False) -> list[str]:
    """Command line that starts node executable ``name`` (simulator, windowing, diagnostic, replay):
    the ``ros2 run`` executable when the package is indexed, else ``python -m jident_ros.nodes.entry <name>``
    with this interpreter (a checkout without install).  ``require_index``: FileNotFoundError instead
    of the fallback."""
    exe = find_executable(name)
    if exe is not None:
        return [str(exe)]
    if require_index:
        prefixes = os.environ.get("AMENT_PREFIX_PATH", "")
        raise FileNotFoundError(f"executable {name!r} of {PACKAGE_NAME} not found the way `ros2 run` looks "
                                f"(<ament prefix>/lib/{PACKAGE_NAME}/{name}; AMENT_PREFIX_PATH={prefixes!r}); "
                                f"run `bash scripts/setup.sh` or `colcon build` and source install/setup.bash")
    return [sys.executable, "-m", f"{PACKAGE_NAME}.nodes.entry", name]   # signal handlers before the imports


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGINT, timeout_s: float = 20.0) -> int:
    """Stop a node process started from :func:`node_command`: ``sig`` (SIGINT: the node's shutdown path,
    which finalises a recording), then SIGKILL if it has not ended after ``timeout_s``; its exit status."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode
