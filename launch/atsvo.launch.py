"""Launch the atsvo_ros odometry on the robot.

    ros2 launch atsvo_ros atsvo.launch.py [config:=/path/params.yaml] [mode:=fused|rgbd] [use_sim_time:=false]

The parameter file (default: the package's config/mini_cheetah.yaml) is the same YAML the offline
tools read, so a configuration checked with `atsvo-info --config FILE` runs unchanged on the robot.
"""
from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    default_config = os.path.join(get_package_share_directory("atsvo_ros"), "config", "mini_cheetah.yaml")
    config = LaunchConfiguration("config")
    use_sim_time = LaunchConfiguration("use_sim_time")
    mode = LaunchConfiguration("mode")
    return LaunchDescription([
        DeclareLaunchArgument("config", default_value=default_config,
                              description="ROS-parameter YAML (same format as the package's config/*.yaml)"),
        DeclareLaunchArgument("mode", default_value="fused", description="fused (RGB-D + events) or rgbd"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="true when playing a bag"),
        Node(
            package="atsvo_ros",
            executable="tracking_node",
            name="atsvo_tracking",
            output="screen",
            parameters=[config, {"use_sim_time": use_sim_time, "mode": mode}],
        ),
    ])
