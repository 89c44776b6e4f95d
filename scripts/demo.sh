#!/usr/bin/env bash
# The main job on a bare machine: setup (idempotent), then `qgl demo` — the ROS stack trains
# QG-DDPG on the simulated Panda insertion, tests on the 8 poses, records MCAP, plots.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
export QG_ROS_INSTALL="$ROOT/ros_ws/install"    # the workspace the Python side runs from
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}"
exec .venv/bin/qgl demo "$@"
