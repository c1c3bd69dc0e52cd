"""Launch the atsvo_ros odometry on the robot.

    ros2 launch atsvo_ros atsvo.launch.py [config:=/path/params.yaml] [mode:=fused|rgbd] [use_sim_time:=false]
        [split:=false] [rgb_topic:=...] [depth_topic:=...] [events_topic:=...] [imu_topic:=...]
        [odometry_topic:=...] [fastdds_profile:=...] [realtime_priority:=0]

Default: ``atsvo_node`` (tracking and mapping in one process, snapshots shared in memory, the lowest
latency); ``split:=true`` starts ``tracking_node`` and ``mapping_node`` instead. The parameter file
(default: the package's config/mini_cheetah.yaml) is the same YAML the offline tools read, so a
configuration checked with ``atsvo-info --config FILE`` runs unchanged on the robot; topic arguments
left empty keep the file's topics. Our processes get the Fast DDS profile config/fastdds_shm.xml;
the camera driver must be started with it too (``FASTRTPS_DEFAULT_PROFILES_FILE``), see the README.
``realtime_priority:=10`` runs the odometry's threads under SCHED_RR before the robot's best-effort work
(``node.realtime_priority``; needs CAP_SYS_NICE or an rtprio limit; docs/nodes.md).
"""
from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

#: launch argument -> parameter it sets when not empty
TOPIC_ARGUMENTS = {"rgb_topic": "topics.rgb", "depth_topic": "topics.depth", "events_topic": "topics.events",
                   "imu_topic": "topics.imu", "odometry_topic": "topics.odometry"}


def _nodes(context, *args, **kwargs) -> list[Node]:
    config = LaunchConfiguration("config").perform(context)
    params: dict[str, object] = {"mode": LaunchConfiguration("mode").perform(context),
                                 "use_sim_time": LaunchConfiguration("use_sim_time").perform(context) == "true"}
    for arg, key in TOPIC_ARGUMENTS.items():
        value = LaunchConfiguration(arg).perform(context)
        if value:
            params[key] = value
    priority = int(LaunchConfiguration("realtime_priority").perform(context) or 0)
    if priority:
        params["node.realtime_priority"] = priority
    env = {"FASTRTPS_DEFAULT_PROFILES_FILE": LaunchConfiguration("fastdds_profile").perform(context)}
    common = {"package": "atsvo_ros", "output": "screen", "parameters": [config, params], "additional_env": env}
    if LaunchConfiguration("split").perform(context) == "true":
        return [Node(executable="tracking_node", name="atsvo_tracking", **common),
                Node(executable="mapping_node", name="atsvo_mapping", **common)]
    # no `name`: it would rename both nodes of the process (atsvo_tracking and atsvo_mapping)
    return [Node(executable="atsvo_node", **common)]


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("atsvo_ros")
    return LaunchDescription([
        DeclareLaunchArgument("config", default_value=os.path.join(share, "config", "mini_cheetah.yaml"),
                              description="ROS-parameter YAML (same format as the package's config/*.yaml)"),
        DeclareLaunchArgument("mode", default_value="fused", description="fused (RGB-D + events) or rgbd"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="true when playing a bag"),
        DeclareLaunchArgument("split", default_value="false",
                              description="true: tracking_node + mapping_node in two processes"),
        DeclareLaunchArgument("fastdds_profile", default_value=os.path.join(share, "config", "fastdds_shm.xml"),
                              description="Fast DDS profile of our processes (64 MiB shared memory for images)"),
        DeclareLaunchArgument("realtime_priority", default_value="0",
                              description="SCHED_RR priority of the odometry's threads, 1-99 (0: the config file's)"),
        *(DeclareLaunchArgument(arg, default_value="", description=f"{key} (empty: the config file's)")
          for arg, key in TOPIC_ARGUMENTS.items()),
        OpaqueFunction(function=_nodes),
    ])
