"""ROS 2 tracking node: synchronized RGB + aligned depth + events in, nav_msgs/Odometry and TF out.

All logic lives in :class:`atsvo_ros.pipeline.TrackingPipeline` (ROS-free, tested with rosbags
messages); this node only declares parameters, wires subscriptions and publishes what the
pipeline hands back. Errors in a callback are logged and counted; the node keeps running.
"""
from __future__ import annotations

import importlib
from typing import Any

import message_filters
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    Transform,
    TransformStamped,
    Twist,
    TwistWithCovariance,
    Vector3,
)
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from tf2_ros import TransformBroadcaster

from atsvo_ros.config import AtsvoConfig, config_from_dict, flatten
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.ros_out import MsgClasses, odometry_msg, transform_msg
from atsvo_ros.runtime import OdometryRuntime

_CLASSES = MsgClasses(Time, Header, Odometry, PoseWithCovariance, Pose, Point, Quaternion, TwistWithCovariance,
                      Twist, Vector3, TransformStamped, Transform)


def _msg_class(msgtype: str) -> Any:
    """``pkg/msg/Name`` -> the rclpy message class (e.g. event_camera_msgs/msg/EventPacket)."""
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


class TrackingNode(Node):
    """Runs the odometry pipeline on live topics."""

    def __init__(self) -> None:
        super().__init__("atsvo_tracking")
        dyn = ParameterDescriptor(dynamic_typing=True)
        defaults = flatten(AtsvoConfig())
        for key, value in defaults.items():
            self.declare_parameter(key, value, dyn)
        self.declare_parameter("event_msg_type", "event_camera_msgs/msg/EventPacket")
        self.declare_parameter("publish_tf", True)
        params = {k: self.get_parameter(k).value for k in defaults}
        self.config = config_from_dict(params)
        self.event_msgtype = str(self.get_parameter("event_msg_type").value)
        self.publish_tf = bool(self.get_parameter("publish_tf").value)
        topics = self.config.topics

        self.pipeline = OdometryRuntime(self.config, logger=self._log)
        self.odom_pub = self.create_publisher(Odometry, topics.odometry, 10)
        self.tf_broadcaster = TransformBroadcaster(self) if self.publish_tf else None

        qos = qos_profile_sensor_data
        self.create_subscription(CameraInfo, topics.rgb_info, self.pipeline.on_rgb_camera_info, qos)
        self.create_subscription(CameraInfo, topics.event_info, self.pipeline.on_event_camera_info, qos)
        if self.config.mode == "fused":
            # raw=True: the callback gets the CDR bytes, decoded with numpy (no object per event).
            self.create_subscription(_msg_class(self.event_msgtype), topics.events, self._on_events, qos, raw=True)
        rgb_sub = message_filters.Subscriber(self, Image, topics.rgb, qos_profile=qos)
        depth_sub = message_filters.Subscriber(self, Image, topics.depth, qos_profile=qos)
        self.sync = message_filters.ApproximateTimeSynchronizer(
            [rgb_sub, depth_sub], queue_size=10, slop=self.config.rig.sync_tolerance_s)
        self.sync.registerCallback(self._on_rgbd)
        self.create_timer(10.0, self._report)
        self.get_logger().info(f"atsvo tracking: mode={self.config.mode}, rgb={topics.rgb}, depth={topics.depth}, "
                               f"events={topics.events} ({self.event_msgtype}), odometry={topics.odometry}")

    def _log(self, level: str, text: str) -> None:
        getattr(self.get_logger(), level)(text)

    def _on_events(self, msg: bytes) -> None:
        self.pipeline.add_event_msg(msg, self.event_msgtype, self.config.topics.events)

    def _on_rgbd(self, rgb: Image, depth: Image) -> None:
        self.pipeline.add_rgb_msg(rgb, self.config.topics.rgb)
        self.pipeline.add_depth_msg(depth, self.config.topics.depth)
        for out in self.pipeline.poll():
            self._publish(out)

    def _publish(self, out) -> None:
        topics = self.config.topics
        self.odom_pub.publish(odometry_msg(_CLASSES, out.result.stamp_ns, out.result.T_odom_base,
                                           out.result.covariance, out.twist, topics.odom_frame, topics.base_frame))
        if self.tf_broadcaster is not None:
            self.tf_broadcaster.sendTransform(transform_msg(_CLASSES, out.result.stamp_ns, out.result.T_odom_base,
                                                            topics.odom_frame, topics.base_frame))

    def _report(self) -> None:
        self.get_logger().info("atsvo stats: " + ", ".join(f"{k}={v}" for k, v in self.pipeline.counters.items()))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run atsvo_ros tracking_node``."""
    rclpy.init(args=args)
    try:
        node = TrackingNode()
    except AtsvoError as exc:
        rclpy.logging.get_logger("atsvo_tracking").fatal(f"bad configuration: {exc}")
        rclpy.try_shutdown()
        raise SystemExit(1) from None
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
