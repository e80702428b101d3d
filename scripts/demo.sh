#!/usr/bin/env bash
# Demo: set up the venv, then simulate one nominal drive run and plot it.
# Outputs go to out/demo/.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

OUT=out/demo
# The demo itself: change this one line when it grows into the ROS end-to-end demo.
DEMO_CMD=(.venv/bin/jident simulate --j1 1.16 --backlash 0.005 --eta 0.025 --out "$OUT/nominal.npz" --plot "$OUT/nominal.png")

bash scripts/setup.sh

# Same ROS environment as scripts/test.sh, for when the demo starts ROS nodes.
export AMENT_PREFIX_PATH="$REPO/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(($$ % 100 + 1))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export PYTHONUNBUFFERED=1

mkdir -p "$OUT"
echo "[demo] ${DEMO_CMD[*]}"
"${DEMO_CMD[@]}"

echo "[demo] outputs in $REPO/$OUT:"
ls -l "$OUT" | tail -n +2 | sed 's/^/  /'
