#!/usr/bin/env bash
# Demo: set up the venv, then run the end-to-end demo (jident demo): the simulator, windowing and
# diagnostic nodes as three processes over DDS on five grid cases; prints true and identified J1 per
# case and leaves the MCAP recording (out/demo/recording), summary.png/.md/.json and node logs in out/demo/.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

OUT=out/demo
# The demo itself (extra arguments go to `jident demo`, e.g. --case 1.102,0.009,0.05 --real-time-factor 1)
DEMO_CMD=(.venv/bin/jident demo --out "$OUT" "$@")

bash scripts/setup.sh

# Same ROS environment as scripts/test.sh (the demo starts ROS nodes).
export AMENT_PREFIX_PATH="$REPO/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(($$ % 100 + 1))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export PYTHONUNBUFFERED=1

mkdir -p "$OUT"
echo "[demo] ${DEMO_CMD[*]}"
"${DEMO_CMD[@]}"

echo "[demo] outputs in $REPO/$OUT:"
ls -l "$OUT" | tail -n +2 | sed 's/^/  /'
