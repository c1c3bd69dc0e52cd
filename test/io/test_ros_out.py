from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import pose_from_tq, se3_exp
from atsvo_ros.io.msgtypes import typestore
from atsvo_ros.io.ros_out import (
    MsgClasses,
    body_twist,
    odometry_msg,
    pose_from_transform_msg,
    time_to_ns,
    transform_msg,
)


@pytest.fixture(scope="module")
def classes():
    return MsgClasses.from_typestore(typestore(2))


def test_odometry_message_serialises_and_round_trips(classes):
    store = typestore(2)
    T = se3_exp(np.array([1.0, -2.0, 0.5, 0.1, 0.2, -0.3]))
    cov = np.diag([1e-4, 2e-4, 3e-4, 1e-5, 2e-5, 3e-5])
    msg = odometry_msg(classes, 1_700_000_000_123_456_789, T, cov, twist=np.arange(6.0))
    raw = store.serialize_cdr(msg, "nav_msgs/msg/Odometry")
    back = store.deserialize_cdr(raw, "nav_msgs/msg/Odometry")
    assert time_to_ns(back.header.stamp) == 1_700_000_000_123_456_789
    assert back.header.frame_id == "odom" and back.child_frame_id == "base_link"
    assert np.allclose(pose_from_transform_msg(back.pose.pose), T, atol=1e-12)
    assert np.allclose(np.asarray(back.pose.covariance).reshape(6, 6), cov)
    assert back.twist.twist.angular.z == 5.0


def test_non_finite_covariance_is_replaced_by_a_large_one(classes):
    msg = odometry_msg(classes, 0, np.eye(4), np.full((6, 6), np.nan))
    assert np.all(np.isfinite(msg.pose.covariance)) and msg.pose.covariance[0] >= 1e6


def test_transform_message(classes):
    T = pose_from_tq(np.array([0.2, 0.0, 0.08]), np.array([0.5, -0.5, 0.5, -0.5]))
    msg = transform_msg(classes, 5, T, "base_link", "camera_color_optical_frame")
    assert msg.header.frame_id == "base_link" and msg.child_frame_id == "camera_color_optical_frame"
    assert np.allclose(pose_from_transform_msg(msg.transform), T)


def test_body_twist_of_a_known_motion():
    # 1 m/s forward along the base x axis while yawing at 0.5 rad/s, observed over 10 ms.
    dt = 0.01
    T0 = se3_exp(np.array([3.0, 1.0, 0.0, 0.0, 0.0, 0.7]))
    T1 = T0 @ se3_exp(np.array([1.0 * dt, 0.0, 0.0, 0.0, 0.0, 0.5 * dt]))
    v = body_twist(T0, T1, dt)
    assert np.allclose(v, [1.0, 0, 0, 0, 0, 0.5], atol=1e-2)
    assert np.allclose(body_twist(T0, T1, 0.0), 0.0)


def test_map_cloud_of_a_snapshot_is_in_odom_and_coloured_by_the_patch_centre():
    from atsvo_ros.core.mapping.map import MapSnapshot
    from atsvo_ros.io.ros_out import MAP_CLOUD_FIELDS, MAP_CLOUD_POINT_STEP, map_cloud_from_snapshot

    points_w = np.array([[0.0, 0.0, 1.0], [0.5, -0.2, 2.0], [-1.0, 0.3, 3.5]])
    patches = np.arange(2 * 3 * 8, dtype=np.float32).reshape(2, 3, 8)
    snap = MapSnapshot(7, points_w, patches, points_w[:, 2].copy(), np.zeros(3, np.int32), np.zeros((0, 3)), (), 3, 9)
    T_odom_world = pose_from_tq(np.array([0.2, 0.0, 0.1]), np.array([0.5, -0.5, 0.5, -0.5]))
    cloud = map_cloud_from_snapshot(snap, T_odom_world)
    assert cloud.dtype == np.dtype("<f4") and cloud.shape == (3, 4)
    expected = (T_odom_world[:3, :3] @ points_w.T).T + T_odom_world[:3, 3]
    np.testing.assert_allclose(cloud[:, :3], expected, atol=1e-6)
    np.testing.assert_array_equal(cloud[:, 3], patches[0, :, 0])
    # the byte layout the PointCloud2 fields describe: x y z intensity, float32, 16 bytes a point
    assert [f[:2] for f in MAP_CLOUD_FIELDS] == [("x", 0), ("y", 4), ("z", 8), ("intensity", 12)]
    assert cloud[0].nbytes == MAP_CLOUD_POINT_STEP
    assert map_cloud_from_snapshot(MapSnapshot.empty(2, 8), np.eye(4)).shape == (0, 4)
