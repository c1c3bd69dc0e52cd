"""sensor_msgs/Imu messages -> :class:`~atsvo_ros.core.imu.ImuBatch` (duck-typed: rclpy or rosbags classes).

Only ``header.stamp``, ``angular_velocity`` and ``linear_acceleration`` are read (the orientation
is not an IMU measurement). Samples are returned in stamp order. realsense2_camera's separate
``gyro/sample`` / ``accel/sample`` topics carry one sensor each; read the united ``imu`` topic.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.ros_out import time_to_ns


def _row(msg: Any) -> tuple[int, float, float, float, float, float, float]:
    try:
        w, a = msg.angular_velocity, msg.linear_acceleration
        return (time_to_ns(msg.header.stamp), float(w.x), float(w.y), float(w.z), float(a.x), float(a.y),
                float(a.z))
    except (AttributeError, TypeError, ValueError) as exc:
        raise DecodeError(f"not a sensor_msgs/Imu message ({type(msg).__name__}): {exc}") from None


def imu_from_msgs(msgs: Iterable[Any]) -> ImuBatch:
    """One batch from sensor_msgs/Imu messages, sorted by header stamp; DecodeError for non-finite values."""
    rows = [_row(m) for m in msgs]
    if not rows:
        return ImuBatch.empty()
    stamps = np.array([r[0] for r in rows], dtype=np.int64)
    values = np.array([r[1:] for r in rows], dtype=np.float64)
    bad = ~np.all(np.isfinite(values), axis=1)
    if np.any(bad):
        raise DecodeError(f"IMU message at stamp {int(stamps[np.argmax(bad)])} ns has a non-finite value")
    if np.any(np.diff(stamps) < 0):
        order = np.argsort(stamps, kind="stable")
        stamps, values = stamps[order], values[order]
    return ImuBatch(stamps, values[:, :3], values[:, 3:])


def imu_from_msg(msg: Any) -> ImuBatch:
    """A one-sample batch from one sensor_msgs/Imu message (what :func:`imu_from_msgs` gives for ``[msg]``).

    The node calls this for every sample (200-400 Hz on its executor thread): the checks run on the six floats
    in plain Python rather than through numpy's per-call overhead.
    """
    row = _row(msg)
    if not all(math.isfinite(v) for v in row[1:]):
        raise DecodeError(f"IMU message at stamp {row[0]} ns has a non-finite value")
    return ImuBatch(np.array(row[:1], dtype=np.int64), np.array([row[1:4]]), np.array([row[4:]]))


__all__ = ["imu_from_msg", "imu_from_msgs"]
