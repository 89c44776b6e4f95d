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
# --fast first: the fast tier, what a change is checked with while it is made (no ROS processes,
# no Ray, nothing that takes more than a few seconds of a core; pytest.ini's markers). It runs in
# this one process: its ~730 tests take ~50 s of CPU, and every xdist worker would import the
# whole stack again (two workers: 63 s against 59 s in one process, 2026-11-29).
tier=()
workers="${QG_TEST_WORKERS:-3}"
if [[ "${1:-}" == "--fast" ]]; then
  shift
  tier=(-m "not ros and not slow")
  workers="${QG_TEST_WORKERS:-0}"
fi
exec .venv/bin/python -m pytest -n "$workers" --dist loadfile --no-loadscope-reorder \
    ${tier[@]+"${tier[@]}"} "$@"
