#!/usr/bin/env bash
# One idempotent setup step for a bare machine: .venv with pinned dependencies, the wheel
# CMake-path fix, the colcon build of ros_ws, and the `qgl` command. Both README commands call it.
# A second run with nothing changed only compares stamps and returns in a few seconds.
#
#   scripts/setup.sh            set up (or verify) everything
#   scripts/setup.sh --relock   rewrite scripts/constraints.txt from the current .venv
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
STAMPS="$VENV/.qg-stamps"
log() { printf '[setup] %s\n' "$*" >&2; }

if [[ "${1:-}" == "--relock" ]]; then
  { echo "# Exact versions the stack was tested with (pip freeze of a fresh setup). Regenerate with scripts/setup.sh --relock."
    "$VENV/bin/pip" freeze --exclude-editable | grep -v -E '^torch=='; echo "torch==2.13.0"; } > "$ROOT/scripts/constraints.txt"
  log "wrote scripts/constraints.txt"; exit 0
fi

hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

# One setup at a time: test runs started together would otherwise build the same venv and
# workspace at once (the second waits here, then finds the stamps current and returns).
exec 9>"$ROOT/.setup.lock"
flock 9

# 1. The virtual environment.
if [[ ! -x "$PY" ]]; then
  log "creating .venv"
  python3 -m venv "$VENV"
fi
mkdir -p "$STAMPS"

# 2. Pinned dependencies (torch==2.13.0 exactly: it is the local CPU wheel; anything else pulls CUDA).
deps_hash="$(hash_of "$ROOT/scripts/requirements.txt" "$ROOT/scripts/constraints.txt")"
if [[ "$(cat "$STAMPS/deps" 2>/dev/null)" != "$deps_hash" ]]; then
  log "installing pinned dependencies (a few minutes on a bare machine)"
  # (The local index mirrors print a warning per missing package; they are noise here.)
  "$VENV/bin/pip" install --quiet --disable-pip-version-check \
    -r "$ROOT/scripts/requirements.txt" -c "$ROOT/scripts/constraints.txt" 2>&1 \
    | { grep -v '^WARNING: Location' || true; }
  echo "$deps_hash" > "$STAMPS/deps"
fi

# 3. The wheels were built in a manylinux container: point their hard-coded Python and numpy
#    include paths at this interpreter, or rosidl's Python generator cannot compile.
if [[ "$(cat "$STAMPS/cmakefix" 2>/dev/null)" != "$deps_hash" ]]; then
  py_inc="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
  np_inc="$("$PY" -c 'import numpy; print(numpy.get_include())')"
  # (grep finds nothing once the files are patched: not an error under pipefail)
  { grep -rl --include='*.cmake' '/opt/python/cp311-cp311' "$VENV/share" 2>/dev/null || true; } | while read -r f; do
    sed -i -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#${np_inc}#g" \
           -e "s#/opt/python/cp311-cp311/include/python3.11#${py_inc}#g" "$f"
  done
  echo "$deps_hash" > "$STAMPS/cmakefix"
fi

# 4. Our packages' sources are importable from .venv (the pure-Python cores need no ROS
#    environment), with their metadata: robots and environments are plugins found through
#    entry points (egg-info beside each source tree), and `qgl` is a console script of the venv.
PY_PACKAGES=(ros_ws/src/qg_common ros_ws/src/qg_recording sim_robot_node franka_robot_node franka_sim_node robot_bridge_node qg_learning_node
             qg_experiments qg_bringup)
site="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
printf "$ROOT/%s\n" "${PY_PACKAGES[@]}" > "$site/qg_stack_sources.pth"
# A plain interpreter of the venv (no ROS environment sourced: a Gymnasium user's) finds the
# workspace's config files and message definitions where .venv/bin/qgl does (QG_ROS_INSTALL).
printf 'import os; os.environ.setdefault("QG_ROS_INSTALL", "%s/ros_ws/install")\n' "$ROOT" \
  > "$site/qg_stack_install.pth"
meta_hash="$(cd "$ROOT" && cat "${PY_PACKAGES[@]/%//setup.py}" | sha256sum | cut -c1-16)"
if [[ "$(cat "$STAMPS/egg_info" 2>/dev/null)" != "$meta_hash" ]]; then
  for pkg in "${PY_PACKAGES[@]}"; do
    ( cd "$ROOT/$pkg" && "$PY" setup.py --quiet egg_info >/dev/null 2>&1 ) \
      || { log "egg_info failed in $pkg"; exit 1; }
  done
  echo "$meta_hash" > "$STAMPS/egg_info"
fi
# `qgl` is the console script qg_bringup declares; this is the wrapper pip would write,
# plus where the workspace is (a sourced shell's ament index says it too).
cat > "$VENV/bin/qgl" <<EOF
#!$PY
import os
import sys
from importlib.metadata import entry_points
os.environ.setdefault("QG_ROS_INSTALL", "$ROOT/ros_ws/install")
(qgl,) = entry_points(group="console_scripts", name="qgl")
sys.exit(qgl.load()())
EOF
chmod +x "$VENV/bin/qgl"

# 5. colcon build of the workspace (the interface packages qg_interfaces and tf2_msgs, which no
#    wheel ships, + the ament_python packages of PY_PACKAGES).
src_hash="$(cd "$ROOT" && find ros_ws/src/qg_interfaces ros_ws/src/tf2_msgs "${PY_PACKAGES[@]}" \
  -type f \( -name '*.msg' -o -name '*.srv' -o -name 'CMakeLists.txt' -o -name 'package.xml' \
  -o -name 'setup.py' -o -name 'setup.cfg' \) -print0 | sort -z | xargs -0 cat | sha256sum | cut -c1-16)"
if [[ "$(cat "$STAMPS/colcon" 2>/dev/null)" != "$src_hash" || ! -f "$ROOT/ros_ws/install/setup.bash" ]]; then
  log "colcon build"
  mkdir -p "$ROOT/ros_ws/log"
  ( cd "$ROOT/ros_ws"
    export AMENT_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
    unset CMAKE_PREFIX_PATH
    "$VENV/bin/colcon" --log-base log build --symlink-install \
      --event-handlers console_direct- console_cohesion- summary+ \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$PY" >"$ROOT/ros_ws/log/last_build.txt" 2>&1 \
      || { tail -40 "$ROOT/ros_ws/log/last_build.txt" >&2; exit 1; } )
  echo "$src_hash" > "$STAMPS/colcon"
fi
# 6. The torque loop's compiled per-tick kernels (robot_bridge_node/core/native): Pinocchio's C++
#    templates, Eigen and pybind11 from the pinned wheels. Hidden visibility and -Bsymbolic keep its
#    template instances its own (never Pinocchio's library's, nor the other way round). No
#    -march=native: it gained < 10 % and changes Eigen's alignment against the wheel's build. A cold
#    build takes 2-5 minutes (Pinocchio's headers); it reruns only when the source or the pins change.
native_dir="$ROOT/robot_bridge_node/robot_bridge_node/core/native"
native_so="$native_dir/_torque_kernels$("$PY" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
native_hash="$(hash_of "$native_dir/torque_kernels.cpp" "$ROOT/scripts/constraints.txt")"
if [[ "$(cat "$STAMPS/native" 2>/dev/null)" != "$native_hash" || ! -f "$native_so" ]]; then
  log "compiling the torque loop's kernels (a few minutes)"
  mkdir -p "$ROOT/ros_ws/log"
  cmeel_prefix="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/cmeel.prefix"
  g++ -std=c++17 -O3 -DNDEBUG -fPIC -shared -fvisibility=hidden -fvisibility-inlines-hidden \
    -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
    -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_FUSION_INVOKE_MAX_ARITY=12 \
    -I"$cmeel_prefix/include" -I"$cmeel_prefix/include/eigen3" $("$PY" -m pybind11 --includes) \
    "$native_dir/torque_kernels.cpp" -o "$native_so.tmp" \
    -L"$cmeel_prefix/lib" -lboost_serialization -Wl,-rpath,"$cmeel_prefix/lib" -Wl,-Bsymbolic \
    >"$ROOT/ros_ws/log/native_build.txt" 2>&1 \
    || { grep -E 'error' -A3 "$ROOT/ros_ws/log/native_build.txt" | head -40 >&2; exit 1; }
  mv "$native_so.tmp" "$native_so"
  echo "$native_hash" > "$STAMPS/native"
fi
#    The tick's elementwise arithmetic (the safety filter's torque limits, the simulated arm's
#    friction and readings): pybind11 alone, seconds to build. -ffp-contract=off, no -ffast-math,
#    no -march: its results must stay NumPy's to the bit.
arith_so="$native_dir/_tick_arithmetic$("$PY" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
arith_hash="$(hash_of "$native_dir/tick_arithmetic.cpp" "$ROOT/scripts/constraints.txt")"
if [[ "$(cat "$STAMPS/tick_arithmetic" 2>/dev/null)" != "$arith_hash" || ! -f "$arith_so" ]]; then
  log "compiling the tick's elementwise arithmetic"
  mkdir -p "$ROOT/ros_ws/log"
  g++ -std=c++17 -O3 -DNDEBUG -ffp-contract=off -fPIC -shared -fvisibility=hidden \
    -fvisibility-inlines-hidden $("$PY" -m pybind11 --includes) \
    "$native_dir/tick_arithmetic.cpp" -o "$arith_so.tmp" \
    >"$ROOT/ros_ws/log/tick_arithmetic_build.txt" 2>&1 \
    || { grep -E 'error' -A3 "$ROOT/ros_ws/log/tick_arithmetic_build.txt" | head -40 >&2; exit 1; }
  mv "$arith_so.tmp" "$arith_so"
  echo "$arith_hash" > "$STAMPS/tick_arithmetic"
fi
# 6b. The shaft cell's MuJoCo contact filter and contact wrench sum (sim_robot_node/core/native):
#    plain C against the MuJoCo wheel's own headers, loaded with ctypes. The filter calls nothing
#    of MuJoCo's and links to nothing; the wrench sum calls mj_contactForce and links to the
#    wheel's library (the one `import mujoco` has loaded already). No contraction into fused
#    multiply-adds: the wrench sum writes its own. Seconds; it reruns only when the sources or
#    the pins change.
filter_dir="$ROOT/sim_robot_node/sim_robot_node/core/native"
filter_so="$filter_dir/_contact_filter.so"
wrench_so="$filter_dir/_contact_wrench.so"
filter_hash="$(hash_of "$filter_dir/contact_filter.c" "$filter_dir/contact_wrench.c" \
  "$ROOT/scripts/constraints.txt")"
if [[ "$(cat "$STAMPS/contact_filter" 2>/dev/null)" != "$filter_hash" || ! -f "$filter_so" \
      || ! -f "$wrench_so" ]]; then
  log "compiling the shaft cell's contact filter and contact wrench sum"
  mujoco_dir="$("$PY" -c 'import mujoco, os; print(os.path.dirname(mujoco.__file__))')"
  mujoco_lib="$(cd "$mujoco_dir" && ls libmujoco.so.* | head -1)"
  c_compiler=(gcc)                   # a machine with g++ alone: its driver compiles C too
  command -v gcc >/dev/null || c_compiler=(g++ -x c)
  c_flags=(-std=c11 -O2 -ffp-contract=off -fPIC -shared -Wall -Wextra -Werror
           -I"$mujoco_dir/include")
  "${c_compiler[@]}" "${c_flags[@]}" "$filter_dir/contact_filter.c" -o "$filter_so.tmp" -lm
  "${c_compiler[@]}" "${c_flags[@]}" "$filter_dir/contact_wrench.c" -o "$wrench_so.tmp" \
    -L"$mujoco_dir" -l:"$mujoco_lib" -Wl,-rpath,"$mujoco_dir" -lm
  mv "$filter_so.tmp" "$filter_so"
  mv "$wrench_so.tmp" "$wrench_so"
  echo "$filter_hash" > "$STAMPS/contact_filter"
fi
# 7. The bytecode of the stack's own modules and of the generated interfaces, compiled here once
#    (a second when nothing changed): where PYTHONDONTWRITEBYTECODE is set, as on our development
#    machine, no process caches it, and every node process compiled them again as it started
#    (0.15 s of CPU for the robot process's imports, 0.25 s for the learner's, measured).
( cd "$ROOT" && "$PY" -m compileall -q ros_ws/install "${PY_PACKAGES[@]}" >/dev/null ) \
  || log "compileall reported errors (the modules still run from source)"
log "ready: .venv, ros_ws/install, qgl, native kernels, contact filter and wrench sum, bytecode"
