"""OdometryResult -> nav_msgs/Odometry and TF messages, for rclpy and rosbags classes alike.

Message classes are passed in (duck typing: both rclpy and rosbags message classes accept keyword
arguments with the same field names), so this module runs and is tested without ROS.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from atsvo_ros.core.geometry import pose_from_tq, quat_from_rotmat, se3_inv, so3_log, transform_points


@dataclass(frozen=True)
class MsgClasses:
    """The message classes needed to publish odometry (from rclpy modules or a rosbags typestore)."""

    Time: Any
    Header: Any
    Odometry: Any
    PoseWithCovariance: Any
    Pose: Any
    Point: Any
    Quaternion: Any
    TwistWithCovariance: Any
    Twist: Any
    Vector3: Any
    TransformStamped: Any
    Transform: Any

    @classmethod
    def from_typestore(cls, store: Any) -> MsgClasses:
        """Classes from a rosbags typestore (tests, bag writing)."""
        t = store.types
        return cls(t["builtin_interfaces/msg/Time"], t["std_msgs/msg/Header"], t["nav_msgs/msg/Odometry"],
                   t["geometry_msgs/msg/PoseWithCovariance"], t["geometry_msgs/msg/Pose"],
                   t["geometry_msgs/msg/Point"], t["geometry_msgs/msg/Quaternion"],
                   t["geometry_msgs/msg/TwistWithCovariance"], t["geometry_msgs/msg/Twist"],
                   t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/TransformStamped"],
                   t["geometry_msgs/msg/Transform"])


def stamp_to_time(classes: MsgClasses, stamp_ns: int) -> Any:
    """builtin_interfaces/Time from int64 ns."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return classes.Time(sec=int(sec), nanosec=int(nanosec))


def time_to_ns(stamp: Any) -> int:
    """int64 ns from a ROS 2 Time (sec/nanosec) or ROS 1 time (secs/nsecs)."""
    if hasattr(stamp, "nanosec"):
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return int(getattr(stamp, "secs", getattr(stamp, "sec", 0))) * 1_000_000_000 + int(getattr(stamp, "nsecs", 0))


def body_twist(T_odom_base_prev: np.ndarray, T_odom_base: np.ndarray, dt_s: float) -> np.ndarray:
    """Linear and angular velocity (6,) of the base, in the base frame, from two poses ``dt_s`` apart."""
    if dt_s <= 0:
        return np.zeros(6)
    T_rel = se3_inv(T_odom_base_prev) @ T_odom_base
    # Velocities expressed in the current base frame (REP 105: twist in child_frame_id).
    R_cur_prev = T_rel[:3, :3].T
    v = R_cur_prev @ T_rel[:3, 3] / dt_s
    w = R_cur_prev @ so3_log(T_rel[:3, :3]) / dt_s
    return np.concatenate([v, w])


def odometry_msg(classes: MsgClasses, stamp_ns: int, T_odom_base: np.ndarray, pose_covariance: np.ndarray,
                 twist: np.ndarray | None = None, odom_frame: str = "odom",
                 base_frame: str = "base_link") -> Any:
    """nav_msgs/Odometry of ``T_odom_base`` with a 6x6 covariance (x y z rot_x rot_y rot_z)."""
    q = quat_from_rotmat(T_odom_base[:3, :3])
    t = T_odom_base[:3, 3]
    pose = classes.Pose(position=classes.Point(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                        orientation=classes.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))
    tw = np.zeros(6) if twist is None else np.asarray(twist, dtype=np.float64)
    twist_cov = np.diag(np.full(6, 1e-2 if twist is not None else 1e6)).ravel()
    return classes.Odometry(
        header=classes.Header(stamp=stamp_to_time(classes, stamp_ns), frame_id=odom_frame),
        child_frame_id=base_frame,
        pose=classes.PoseWithCovariance(pose=pose, covariance=_cov36(pose_covariance)),
        twist=classes.TwistWithCovariance(
            twist=classes.Twist(linear=classes.Vector3(x=float(tw[0]), y=float(tw[1]), z=float(tw[2])),
                                angular=classes.Vector3(x=float(tw[3]), y=float(tw[4]), z=float(tw[5]))),
            covariance=twist_cov))


def transform_msg(classes: MsgClasses, stamp_ns: int, T_parent_child: np.ndarray, parent: str, child: str) -> Any:
    """geometry_msgs/TransformStamped of ``T_parent_child`` (TF convention: child pose in parent)."""
    q = quat_from_rotmat(T_parent_child[:3, :3])
    t = T_parent_child[:3, 3]
    return classes.TransformStamped(
        header=classes.Header(stamp=stamp_to_time(classes, stamp_ns), frame_id=parent),
        child_frame_id=child,
        transform=classes.Transform(
            translation=classes.Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
            rotation=classes.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))


def pose_from_transform_msg(msg: Any) -> np.ndarray:
    """4x4 pose from a geometry_msgs/Transform or Pose (fields translation/rotation or position/orientation)."""

    t = getattr(msg, "translation", None) or msg.position
    q = getattr(msg, "rotation", None) or msg.orientation
    return pose_from_tq(np.array([t.x, t.y, t.z]), np.array([q.x, q.y, q.z, q.w]))


#: frame_id of the debug images (/atsvo/debug/*): the event camera after rectification onto its pinhole model.
DEBUG_IMAGE_FRAME = "atsvo_event_camera_rectified"

#: Fields of the published map (sensor_msgs/PointCloud2): name, byte offset, datatype (7 = FLOAT32), count.
MAP_CLOUD_FIELDS = (("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1))
MAP_CLOUD_POINT_STEP = 16


def map_cloud_data(points_w: np.ndarray, intensity: np.ndarray, T_odom_world: np.ndarray) -> np.ndarray:
    """The map as PointCloud2 data: (N, 4) little-endian float32 rows x y z intensity, positions in odom.

    ``intensity`` is each point's brightness-normalised intensity in its host keyframe (0-255 scale), so
    RViz / Foxglove can colour the cloud like the scene.
    """

    p = np.asarray(points_w, dtype=np.float64).reshape(-1, 3)
    out = np.empty((len(p), 4), dtype="<f4")
    out[:, :3] = transform_points(np.asarray(T_odom_world, dtype=np.float64), p) if len(p) else p
    out[:, 3] = np.asarray(intensity, dtype=np.float64).reshape(-1)
    return out


def map_cloud_from_snapshot(snapshot: Any, T_odom_world: np.ndarray) -> np.ndarray:
    """:func:`map_cloud_data` of a map snapshot: its photometric points, coloured by their patch centre.

    The intensity is the first pyramid level's first pattern sample of each point's patch (zero for a
    snapshot without patches).
    """
    intensity = snapshot.patches[0, :, 0] if snapshot.patches.size else snapshot.host_depth * 0.0
    return map_cloud_data(snapshot.points_w, intensity, T_odom_world)


def _cov36(cov: np.ndarray) -> np.ndarray:
    c = np.asarray(cov, dtype=np.float64).reshape(6, 6)
    if not np.all(np.isfinite(c)):
        c = np.diag(np.full(6, 1e6))
    return 0.5 * (c + c.T).ravel()
