#!/usr/bin/env bash
# The experiment suite in one command: setup (idempotent), then every experiment of a profile
# through the fast in-process runner, then docs/results.md with its figures.
#
#   scripts/experiments.sh                  the thesis profile (about an hour on 2 cores)
#   scripts/experiments.sh --profile small  a reduced set (about an hour)
#   scripts/experiments.sh --profile tiny   every code path in a minute (also a CI test)
# Further arguments go to `python -m qg_experiments` (e.g. --only random,grid,
# --report-only). Saved runs are reused, so an interrupted suite resumes where it stopped
# (a peg run from its progress of the last 2 minutes); --status says how far a sweep is.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
export QG_ROS_INSTALL="$ROOT/ros_ws/install"    # the workspace the Python side runs from
eval "$(.venv/bin/python -m qg_bringup.ros_env)"   # config files via the ament index
args=("$@")
[[ " ${args[*]-} " == *" --profile "* ]] || args=(--profile thesis "${args[@]}")
exec .venv/bin/python -m qg_experiments "${args[@]}"
