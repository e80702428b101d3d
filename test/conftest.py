"""Shared pytest fixtures for jident_ros.

* ``repo_root``: the checkout's top folder.
* ``ros_env``: (session) environment for ROS processes of this test run:
  AMENT_PREFIX_PATH includes ``sys.prefix`` (where the ros-* wheels register
  themselves in the ament index), ROS_DOMAIN_ID is unique to this run (kept
  from the environment when scripts/test.sh already chose one) and DDS
  discovery stays on localhost.  The same values are applied to ``os.environ``
  for the session, so in-process ``rclpy.init()`` and subprocesses agree.  JIDENT_DATA_DIR points to a
  session temporary directory: the diagnostic node records by default, and never into the home directory
  from a test.
* Tests marked ``ros`` are skipped with a reason when rclpy cannot be imported,
  unless JIDENT_REQUIRE_ROS=1 (set by scripts/test.sh), in which case they fail:
  the venv that scripts/setup.sh builds always has rclpy.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from jident_ros.config import load_method_config, load_system_config
from jident_ros.method.patterns import PatternLibrary
from jident_ros.sim import paper_grid_cases, simulate_grid

REPO_ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="module")
def system():
    """The model's configuration, the package's config/system.yaml."""
    return load_system_config()


@pytest.fixture(scope="module")
def pattern_cases(system):
    """The 42 pattern runs: every J1 class x every backlash width at the pattern eta_k (class-major,
    width-minor)."""
    return paper_grid_cases(system, [system.grid.pattern_consistency_pa_sn])


@pytest.fixture(scope="module")
def windows(request, system, pattern_cases):
    """One simulation: the 42 pattern runs (``pattern_cases``), then the test module's ``EXTRA_CASES``
    (off-pattern runs, none when the module has no such list)."""
    return simulate_grid(system, pattern_cases + list(getattr(request.module, "EXTRA_CASES", ())))


@pytest.fixture(scope="module")
def library(windows, pattern_cases, system, method):
    """The pattern library of the simulated pattern runs (the first ``len(pattern_cases)`` windows)
    under the test module's ``method`` fixture."""
    return PatternLibrary.from_windows(windows, list(range(len(pattern_cases))), system, method)


@pytest.fixture(scope="session")
def default_library_file(tmp_path_factory):
    """The pattern library of the default configuration (config/system.yaml + config/method.yaml), built once
    per test run and saved (test_offline, test_verdicts and test_nodes each built the same one: issue 23)."""
    path = tmp_path_factory.mktemp("default_patterns") / "patterns.npz"
    PatternLibrary.build(load_system_config(), load_method_config()).save(path)
    return path


def _unique_domain_id() -> str:
    preset = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if preset:
        return preset
    return str(os.getpid() % 100 + 1)


@pytest.fixture(scope="session")
def ros_env(tmp_path_factory):
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    if sys.prefix not in prefixes:
        prefixes.insert(0, sys.prefix)
    values = {
        "AMENT_PREFIX_PATH": os.pathsep.join(prefixes),
        "ROS_DOMAIN_ID": _unique_domain_id(),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "LOCALHOST",
        "PYTHONUNBUFFERED": "1",
        "JIDENT_DATA_DIR": str(tmp_path_factory.mktemp("jident_data")),
    }
    with pytest.MonkeyPatch.context() as mp:
        for key, value in values.items():
            mp.setenv(key, value)
        yield dict(os.environ)


_RCLPY_ERROR: list[str | None] = []


def _rclpy_import_error() -> str | None:
    if not _RCLPY_ERROR:
        try:
            import rclpy  # noqa: F401
        except Exception as exc:  # ImportError, or a broken native library
            _RCLPY_ERROR.append(f"{type(exc).__name__}: {exc}")
        else:
            _RCLPY_ERROR.append(None)
    return _RCLPY_ERROR[0]


def pytest_runtest_setup(item):
    if item.get_closest_marker("ros") is None:
        return
    error = _rclpy_import_error()
    if error is None:
        return
    if os.environ.get("JIDENT_REQUIRE_ROS") == "1":
        pytest.fail(
            f"rclpy is not importable ({error}) but JIDENT_REQUIRE_ROS=1; "
            "run `bash scripts/setup.sh` (installs the ros-* wheels of requirements-ros.txt) "
            "or source a ROS 2 distribution",
            pytrace=False,
        )
    pytest.skip(f"needs rclpy, which is not importable here ({error}); run `bash scripts/setup.sh`")
