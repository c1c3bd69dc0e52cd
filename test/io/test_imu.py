"""sensor_msgs/Imu -> ImuBatch for both ROS versions' message classes, and the bag's imu role."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from atsvo_ros.errors import DecodeError
from atsvo_ros.io.bags import preset_topics, resolve_topics
from atsvo_ros.io.imu import imu_from_msg, imu_from_msgs
from atsvo_ros.io.msgtypes import typestore

IMU = "sensor_msgs/msg/Imu"


def _imu_msg(ros: int, stamp_ns: int, w, a):
    T = typestore(ros).types
    t = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    header = (T["std_msgs/msg/Header"](seq=0, stamp=t, frame_id="imu") if ros == 1
              else T["std_msgs/msg/Header"](stamp=t, frame_id="imu"))
    V3 = T["geometry_msgs/msg/Vector3"]
    return T[IMU](header=header, orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                  orientation_covariance=np.zeros(9), angular_velocity=V3(x=w[0], y=w[1], z=w[2]),
                  angular_velocity_covariance=np.zeros(9), linear_acceleration=V3(x=a[0], y=a[1], z=a[2]),
                  linear_acceleration_covariance=np.zeros(9))


@pytest.mark.parametrize("ros", [1, 2])
def test_messages_decode_in_stamp_order_after_a_serialization_round_trip(ros):
    store = typestore(ros)
    rng = np.random.default_rng(0)
    stamps = 1_700_000_000_000_000_000 + np.array([0, 5_000_123, 10_000_001, 7_500_000])  # one out of order
    w, a = rng.normal(size=(4, 3)), rng.normal(size=(4, 3)) + [0, 0, 9.81]
    msgs = []
    for s, wi, ai in zip(stamps, w, a):
        m = _imu_msg(ros, int(s), wi, ai)
        raw = store.serialize_ros1(m, IMU) if ros == 1 else store.serialize_cdr(m, IMU)
        msgs.append(store.deserialize_ros1(raw, IMU) if ros == 1 else store.deserialize_cdr(raw, IMU))
    b = imu_from_msgs(msgs)
    order = np.argsort(stamps)
    np.testing.assert_array_equal(b.stamps_ns, stamps[order])
    np.testing.assert_array_equal(b.gyro_rad_s, w[order])
    np.testing.assert_array_equal(b.accel_m_s2, a[order])
    one = imu_from_msg(msgs[1])
    assert len(one) == 1 and one.t_first_ns == stamps[1]
    for m in msgs:  # the one-message fast path gives what the batch path gives for [m], dtypes and shapes too
        fast, batch = imu_from_msg(m), imu_from_msgs([m])
        for name in ("stamps_ns", "gyro_rad_s", "accel_m_s2"):
            x, y = getattr(fast, name), getattr(batch, name)
            assert x.dtype == y.dtype and x.shape == y.shape
            np.testing.assert_array_equal(x, y)


def test_duck_typed_ros1_stamps_and_errors():
    v = SimpleNamespace
    msg = v(header=v(stamp=v(secs=3, nsecs=7)), angular_velocity=v(x=1, y=2, z=3),
            linear_acceleration=v(x=4.0, y=5.0, z=6.0))
    b = imu_from_msg(msg)
    assert b.t_first_ns == 3_000_000_007 and b.accel_m_s2.tolist() == [[4.0, 5.0, 6.0]]
    assert len(imu_from_msgs([])) == 0
    with pytest.raises(DecodeError, match="not a sensor_msgs/Imu"):
        imu_from_msg(v(header=v(stamp=v(sec=1, nanosec=0))))
    bad = v(header=v(stamp=v(sec=1, nanosec=0)), angular_velocity=v(x=float("nan"), y=0, z=0),
            linear_acceleration=v(x=0, y=0, z=0))
    with pytest.raises(DecodeError, match="non-finite"):
        imu_from_msg(bad)


def test_imu_role_from_presets_and_detection():
    assert preset_topics("mini_cheetah")["imu"] == "/camera/camera/imu"
    assert preset_topics("synthetic")["imu"] == "/camera/camera/imu"
    assert preset_topics("mvsec")["imu"] == "/davis/left/imu"
    assert resolve_topics({"/davis/left/imu": IMU}).imu == "/davis/left/imu"
    # Detection by type: a single united Imu topic, never realsense's one-sensor gyro/accel sample topics.
    assert resolve_topics({"/cam/imu": IMU, "/cam/gyro/sample": IMU, "/cam/accel/sample": IMU}, presets=()).imu \
        == "/cam/imu"
    assert resolve_topics({"/cam/gyro/sample": IMU, "/cam/accel/sample": IMU}, presets=()).imu is None
    assert resolve_topics({"/vectornav/data": IMU}, presets=()).imu == "/vectornav/data"
    assert resolve_topics({"/a/data": IMU, "/b/data": IMU}, presets=()).imu is None
    assert resolve_topics({"/a/data": IMU, "/b/data": IMU}, explicit={"imu": "/b/data"}, presets=()).imu == "/b/data"
