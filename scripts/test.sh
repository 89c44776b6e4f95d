#!/usr/bin/env bash
# Runs the whole test suite on a bare machine: setup (idempotent), then pytest in the stack's
# ROS environment (what `source ros_ws/install/setup.bash` gives, plus loopback-only discovery).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
export QG_ROS_INSTALL="$ROOT/ros_ws/install"    # the workspace the Python side runs from
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_LOG_DIR="${ROS_LOG_DIR:-$ROOT/runs/ros_log}"
eval "$(.venv/bin/python -m qg_learning_node.cli.ros_env)"
# Three workers (pytest-xdist), each taking whole files, so a file's shared stack is started once.
# Three on two cores: a ROS test spends much of its time waiting for its processes, and a third
# worker keeps both cores busy (the suite took 259-272 s with two, 209-222 s with three, on the
# same 2-core machine). QG_TEST_WORKERS=0 runs in this one process (for -s output or a debugger).
exec .venv/bin/python -m pytest -n "${QG_TEST_WORKERS:-3}" --dist loadfile "$@"
