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
eval "$(.venv/bin/python -m qg_bringup.ros_env)"
# Three workers (pytest-xdist) on the two cores, each taking whole files, so a file's shared
# stack is started once. Many tests wait on their ROS processes (a step, a discovery, a reply)
# and two workers left the cores 17 % idle: 180-208 s against 166-172 s with three, the cores
# then 95 % busy; 152-155 s once the stack itself used less CPU (2026-11-27). The tests that
# time themselves by the wall clock take the machine to themselves (`machine_to_itself`),
# however many workers run. QG_TEST_WORKERS=0 runs in this one process (for -s output or a
# debugger). Files go out in the order tests/conftest.py sorts them, not by their number of
# tests.
exec .venv/bin/python -m pytest -n "${QG_TEST_WORKERS:-3}" --dist loadfile --no-loadscope-reorder \
    "$@"
