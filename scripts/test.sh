#!/usr/bin/env bash
# Run the test suite in the project venv: bash scripts/test.sh [pytest args...]
# Without arguments pytest uses pytest.ini's default selection (-m "not slow").
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

bash scripts/setup.sh

# ament_index_python finds the ros-* wheels' (and our own) resource index under the venv prefix.
export AMENT_PREFIX_PATH="$REPO/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# A DDS domain of its own per run, so concurrent runs on one machine do not see each other.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(($$ % 100 + 1))}"
# Keep DDS discovery on this host.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export PYTHONUNBUFFERED=1
# setup.sh installed rclpy (or a ROS distribution is sourced): ros-marked tests must run, not skip.
export JIDENT_REQUIRE_ROS="${JIDENT_REQUIRE_ROS:-1}"

# Lint first (ruff.toml: pyflakes, pycodestyle, import order, pep257 as ament_flake8/ament_pep257): a lint
# error fails the run like a test.  JIDENT_LINT=0 skips it (e.g. while editing).
if [[ "${JIDENT_LINT:-1}" != 0 ]]; then
  echo "[test] .venv/bin/ruff check ."
  .venv/bin/ruff check . || { echo "[test] FAILED: lint (ruff check .)" >&2; exit 1; }
fi

echo "[test] AMENT_PREFIX_PATH=$AMENT_PREFIX_PATH ROS_DOMAIN_ID=$ROS_DOMAIN_ID"
echo "[test] .venv/bin/python -m pytest $*"
rc=0
.venv/bin/python -m pytest "$@" || rc=$?
if [[ $rc -eq 5 ]]; then
  echo "[test] FAILED: pytest collected no tests (exit 5)" >&2
fi
exit "$rc"
