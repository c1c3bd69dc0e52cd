"""The odometry's IMU buffer: rotations between frame stamps from the samples buffered so far."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.geometry import so3_log
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.odometry.gyro import GyroBuffer

MS = 1_000_000


def _batch(t0_ms: int, n: int, rate_rad_s: float) -> ImuBatch:
    stamps = (t0_ms + 5 * np.arange(n)) * MS  # 200 Hz
    gyro = np.tile([0.0, 0.0, rate_rad_s], (n, 1))
    return ImuBatch(stamps, gyro, np.zeros((n, 3)))


def _angle_z(R: np.ndarray) -> float:
    return float(so3_log(R)[2])


def test_rotation_uses_the_samples_added_after_an_earlier_query():
    """Queries between adds see every batch added so far (the joined buffer is rebuilt after an add)."""
    buf = GyroBuffer(np.eye(3))
    buf.add(_batch(0, 20, 1.0))  # 0-95 ms at 1 rad/s
    assert abs(_angle_z(buf.rotation(0, 90 * MS)) - 0.09) < 1e-9
    assert buf.rotation(0, 300 * MS) is None  # not covered yet (beyond the 30 ms hold)
    buf.add(_batch(100, 40, 2.0))  # 100-295 ms at 2 rad/s
    assert abs(_angle_z(buf.rotation(100 * MS, 290 * MS)) - 0.38) < 1e-9
    # across both batches: 1 rad/s up to the sample at 95 ms, then 2 rad/s (the rate steps between samples)
    both = _angle_z(buf.rotation(0, 290 * MS))
    assert 0.09 + 0.38 < both < 0.10 + 0.38 + 0.01
    assert abs(buf.angular_rate(100 * MS, 290 * MS) - 2.0) < 1e-9


def test_old_batches_leave_the_buffer():
    buf = GyroBuffer(np.eye(3))
    buf.add(_batch(0, 20, 1.0))
    buf.add(_batch(GyroBuffer.BUFFER_NS // MS + 200, 20, 1.0))
    assert buf.rotation(0, 90 * MS) is None


def test_an_add_keeps_only_the_rotations_its_samples_cannot_change():
    """Rotations are cached across adds (the next frame asks for the last frame's interval again), but one that held
    the newest rate past the newest sample is computed again from the samples that came since."""
    buf = GyroBuffer(np.eye(3))
    buf.add(_batch(0, 20, 1.0))  # 0-95 ms at 1 rad/s
    buf.rotation(0, 90 * MS)
    assert abs(_angle_z(buf.rotation(80 * MS, 110 * MS)) - 0.03) < 1e-9  # 1 rad/s held past 95 ms
    buf.add(_batch(100, 20, 2.0))
    fresh = GyroBuffer(np.eye(3))
    fresh.add(_batch(0, 20, 1.0))
    fresh.add(_batch(100, 20, 2.0))
    assert np.array_equal(buf.rotation(0, 90 * MS), fresh.rotation(0, 90 * MS))
    assert np.array_equal(buf.rotation(80 * MS, 110 * MS), fresh.rotation(80 * MS, 110 * MS))
    assert _angle_z(buf.rotation(80 * MS, 110 * MS)) > 0.04  # 2 rad/s from 100 ms on
