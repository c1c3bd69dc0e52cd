# Source (do not run) with the project's venv active, from .ci/run or a developer shell:
#
#     source .ci/ros_env.sh && python -m pytest test/nodes
#
# 1. installs the `ros` extra (rclpy + messages + Fast DDS as wheels from the package index),
# 2. builds event_camera_msgs, dvs_msgs and tf2_msgs (.ci/build_ros_msgs.sh, cached under .atsvo_cache/),
# 3. exports what the DDS tests need: the message prefix (PYTHONPATH, LD_LIBRARY_PATH, AMENT_PREFIX_PATH),
#    the RMW, our Fast DDS profile, and discovery kept on loopback with a private domain id.
# Returns non-zero (and says why) when any step fails; the caller's shell options are left as they were.
# rclpy itself needs no sourcing: the wheels' ros_wheels_bootstrapper (.pth) re-executes python with
# LD_LIBRARY_PATH set at start-up.

if ! (return 0 2>/dev/null); then
  echo "ros_env.sh: source this file (source .ci/ros_env.sh), do not run it" >&2
  exit 1
fi

_atsvo_ros_env() {
  local root lines
  root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  if [ -z "${VIRTUAL_ENV:-}" ]; then
    echo "ros_env.sh: activate the project's venv first" >&2
    return 1
  fi
  echo "[ros_env] pip install -e '.[ros]'" >&2
  python -m pip install -q -e "$root[ros]" 2>&1 | { grep -v "^WARNING: Location" >&2 || true; }
  if [ "${PIPESTATUS[0]}" -ne 0 ]; then
    echo "ros_env.sh: installing the ros extra failed" >&2
    return 1
  fi
  lines="$(bash "$root/.ci/build_ros_msgs.sh")" || return 1
  eval "$lines"
  export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
  # Fast DDS 2.14 (Jazzy) reads FASTRTPS_DEFAULT_PROFILES_FILE; the profile enlarges shared memory for images.
  export FASTRTPS_DEFAULT_PROFILES_FILE="$root/config/fastdds_shm.xml"
  # Default discovery multicasts out of every interface; LOCALHOST keeps DDS on this machine.
  export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
  # ROS_DOMAIN_ID is left as the user set it (unset: ROS's default, 0), so every shell that sources this
  # script sees the others' nodes; the test suite takes a private domain of its own (test/nodes/conftest.py).
  if ! python -c "import rclpy, sensor_msgs.msg, event_camera_msgs.msg, dvs_msgs.msg, tf2_msgs.msg" >&2; then
    echo "ros_env.sh: the ROS packages are installed but do not import (see above)" >&2
    return 1
  fi
  echo "[ros_env] ready: rclpy + event_camera_msgs, dvs_msgs, tf2_msgs; domain ${ROS_DOMAIN_ID:-0} on loopback" >&2
}

_atsvo_ros_env || { unset -f _atsvo_ros_env; return 1; }
unset -f _atsvo_ros_env
