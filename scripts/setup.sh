#!/usr/bin/env bash
# Create or refresh the project's virtual environment at <repo>/.venv:
#   pip install -e '.[test,mcap]' -r requirements-ros.txt -r requirements-dev.txt
# Idempotent: skipped when nothing that feeds the install has changed (stamp file).
#
# Environment knobs:
#   JIDENT_PYTHON=/path/to/python   interpreter to build the venv from (3.10-3.13)
#   JIDENT_ROS_WHEELS=auto|yes|no   install the ros-* wheels of requirements-ros.txt;
#                                   auto (default) = no when a ROS 2 distribution is
#                                   sourced (ROS_DISTRO set), yes otherwise
#   JIDENT_SETUP_FORCE=1            reinstall even if the stamp matches
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"
VENV="$REPO/.venv"
STAMP="$VENV/.jident-setup-stamp"
PIP_LOG="$VENV/setup-pip.log"

log() { echo "[setup] $*"; }
die() { echo "[setup] ERROR: $*" >&2; exit 1; }

# --- pick an interpreter ----------------------------------------------------
py_supported() {
  "$1" -c 'import sys; sys.exit(0 if (3, 10) <= sys.version_info[:2] <= (3, 13) else 1)' >/dev/null 2>&1
}

find_python() {
  if [[ -n "${JIDENT_PYTHON:-}" ]]; then
    py_supported "$JIDENT_PYTHON" || die "JIDENT_PYTHON=$JIDENT_PYTHON is not a working Python 3.10-3.13"
    echo "$JIDENT_PYTHON"
    return 0
  fi
  local c
  for c in python3 python3.13 python3.12 python3.11 python3.10; do
    if command -v "$c" >/dev/null 2>&1 && py_supported "$c"; then
      command -v "$c"
      return 0
    fi
  done
  return 1
}

apt_install() {
  command -v apt-get >/dev/null 2>&1 || return 1
  local sudo=()
  if [[ "$(id -u)" != 0 ]]; then
    command -v sudo >/dev/null 2>&1 || return 1
    sudo=(sudo -n)
  fi
  log "installing Debian package(s) $* (apt-get)"
  local out
  out="$(mktemp)"
  if "${sudo[@]}" apt-get update -qq >"$out" 2>&1 &&
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq "$@" >>"$out" 2>&1; then
    rm -f "$out"
    return 0
  fi
  tail -n 20 "$out" >&2
  rm -f "$out"
  return 1
}

create_venv() {
  local py="$1" err
  err="$(mktemp)"
  log "creating $VENV with $py ($("$py" -c 'import sys; print(sys.version.split()[0])'))"
  if "$py" -m venv "$VENV" 2>"$err"; then
    rm -f "$err"
    return 0
  fi
  rm -rf "$VENV"   # a half-made venv (python but no pip) would fool the next run
  if grep -qiE 'ensurepip|venv' "$err"; then
    # Debian/Ubuntu system Python ships venv/ensurepip separately.
    local ver
    ver="$("$py" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
    if apt_install "python${ver}-venv" || apt_install python3-venv; then
      rm -f "$err"
      "$py" -m venv "$VENV" || { rm -rf "$VENV"; die "python -m venv still fails after installing python${ver}-venv"; }
      return 0
    fi
    cat "$err" >&2
    rm -f "$err"
    die "'$py -m venv' failed and python3-venv could not be installed (run: apt-get install python${ver}-venv)"
  fi
  cat "$err" >&2
  rm -f "$err"
  die "'$py -m venv $VENV' failed"
}

if [[ -e "$VENV" && ! -x "$VENV/bin/python" ]]; then
  die "$VENV exists but has no bin/python; remove it and rerun scripts/setup.sh"
fi
if [[ ! -x "$VENV/bin/python" ]]; then
  PY="$(find_python)" || die "need Python 3.10-3.13 (python3 is $(python3 --version 2>&1 || echo missing)); install one or set JIDENT_PYTHON"
  create_venv "$PY"
fi
VPY="$VENV/bin/python"
py_supported "$VPY" || die "$VENV uses $("$VPY" --version 2>&1), need 3.10-3.13; remove .venv and rerun"
if ! "$VPY" -m pip --version >/dev/null 2>&1; then
  log "bootstrapping pip in $VENV"
  "$VPY" -m ensurepip --upgrade >/dev/null || die "$VENV has no pip; remove .venv and rerun"
fi

# --- what to install --------------------------------------------------------
ros_wheels="${JIDENT_ROS_WHEELS:-auto}"
if [[ "$ros_wheels" == auto ]]; then
  if [[ -n "${ROS_DISTRO:-}" ]]; then ros_wheels=no; else ros_wheels=yes; fi
fi
req_args=(-r requirements-dev.txt)
stamp_files=(scripts/setup.sh setup.py requirements-dev.txt)
if [[ "$ros_wheels" == yes ]]; then
  req_args+=(-r requirements-ros.txt)
  stamp_files+=(requirements-ros.txt)
else
  log "ROS_DISTRO=${ROS_DISTRO:-} is sourced: using its rclpy, not installing requirements-ros.txt"
fi

want_stamp="$(
  {
    "$VPY" -c 'import sys; print(sys.version)'
    echo "ros_wheels=$ros_wheels repo=$REPO"
    sha256sum "${stamp_files[@]}"
  } | sha256sum | cut -d' ' -f1
)"

installed_ok() {
  [[ -f "$STAMP" && "$(cat "$STAMP")" == "$want_stamp" ]] || return 1
  [[ -x "$VENV/bin/jident" && -x "$VENV/bin/colcon" ]] || return 1
  # the editable install must point at this checkout (not a copied venv's origin)
  local where
  where="$("$VPY" -c 'import jident_ros, os; print(os.path.dirname(os.path.abspath(jident_ros.__file__)))' 2>/dev/null)" || return 1
  [[ "$where" == "$REPO/jident_ros" ]]
}

# --- register the editable install in the venv's ament index ------------------
# So that the venv answers like a colcon install space: get_package_prefix('jident_ros')
# is the venv and <prefix>/lib/jident_ros/<exe> are the node executables, which is where
# `ros2 run` (and our demo and tests) look.  Symlinks into the checkout: always current.
EXECUTABLES=(jident simulator windowing diagnostic replay)
register_ament() {
  local idx="$VENV/share/ament_index/resource_index/packages" share="$VENV/share/jident_ros" lib="$VENV/lib/jident_ros" e
  mkdir -p "$idx" "$share" "$lib"
  : >"$idx/jident_ros"
  ln -sfn "$REPO/package.xml" "$share/package.xml"
  ln -sfn "$REPO/config" "$share/config"
  ln -sfn "$REPO/launch" "$share/launch"
  for e in "${EXECUTABLES[@]}"; do
    [[ -x "$VENV/bin/$e" ]] || die "$VENV/bin/$e is missing (setup.py console_scripts)"
    ln -sfn "$VENV/bin/$e" "$lib/$e"
  done
}
registered_ok() {
  local e
  [[ -f "$VENV/share/ament_index/resource_index/packages/jident_ros" ]] || return 1
  for e in "${EXECUTABLES[@]}"; do [[ -x "$VENV/lib/jident_ros/$e" ]] || return 1; done
}

if [[ "${JIDENT_SETUP_FORCE:-0}" != 1 ]] && installed_ok; then
  registered_ok || register_ament
  log "$VENV is up to date (stamp matches); nothing to do"
  exit 0
fi

log "pip install -e '.[test,mcap]' ${req_args[*]}  (log: ${PIP_LOG#"$REPO"/})"
start=$SECONDS
rm -f "$STAMP"
# --use-pep517: without pyproject.toml, pip<23.1 (Debian's) or any pip once `wheel` is
# installed falls back to `setup.py develop`, which obeys setup.cfg's ROS script_dir and
# hides the console script in .venv/lib/jident_ros instead of .venv/bin.
if ! "$VPY" -m pip install --progress-bar off --use-pep517 -e ".[test,mcap]" "${req_args[@]}" >"$PIP_LOG" 2>&1; then
  echo "[setup] pip install failed; last lines of $PIP_LOG:" >&2
  grep -v "^WARNING: Location '" "$PIP_LOG" | tail -n 40 >&2
  exit 1
fi
[[ -x "$VENV/bin/jident" ]] || die "pip succeeded but $VENV/bin/jident is missing"
[[ -x "$VENV/bin/colcon" ]] || die "pip succeeded but $VENV/bin/colcon is missing"
register_ament
echo "$want_stamp" >"$STAMP"
log "done in $((SECONDS - start)) s: $VENV ready ($("$VPY" --version 2>&1))"
