"""The motion prior's rotation: the gyro's with an IMU (tracker.gyro_prior_sigma_deg), constant rate when that is 0."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.geometry import camera_centre, rotation_angle_rad, so3_exp
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.odometry.gyro import GyroBuffer
from atsvo_ros.core.odometry.inertial import CameraMotion
from atsvo_ros.core.odometry.prediction import Predictor
from atsvo_ros.core.tracking.motion import MotionModel

MS = 1_000_000


def _predictor(**overrides: float) -> Predictor:
    """Two trusted poses turning 2 deg a frame about y; a gyro measuring 300 deg/s about x since (a push-off)."""
    cfg = load_config("synthetic", overrides={f"tracker.{k}": v for k, v in overrides.items()})
    motion = MotionModel()
    for k in range(2):
        T = np.eye(4)
        T[:3, :3] = so3_exp(np.array([0.0, np.radians(2.0) * k, 0.0]))
        T[:3, 3] = [0.01 * k, 0.0, 0.0]
        motion.push(k * 33 * MS, T, trusted=True)
    gyro = GyroBuffer(np.eye(3))
    stamps = np.arange(0, 120 * MS, 2_500_000, dtype=np.int64)
    rate = np.tile([np.radians(300.0), 0.0, 0.0], (len(stamps), 1))
    gyro.add(ImuBatch(stamps, rate, np.zeros_like(rate)))
    return Predictor(cfg, motion, gyro, image_height=480)


@pytest.mark.parametrize("sigma_deg", [0.0, 0.1])
def test_the_prior_turns_with_the_gyro_only_when_asked(sigma_deg: float) -> None:
    pred = _predictor(gyro_prior_sigma_deg=sigma_deg)
    stamp = 66 * MS
    gyro_T = pred.gyro_pose(stamp)
    prior = pred.priors(stamp, gyro_T).motion
    cv_T = pred.motion.predict(stamp)
    off_cv = np.degrees(rotation_angle_rad(prior.T_pred_rgb_w[:3, :3] @ cv_T[:3, :3].T))
    off_gyro = np.degrees(rotation_angle_rad(prior.T_pred_rgb_w[:3, :3] @ gyro_T[:3, :3].T))
    # the centre stays constant velocity's either way
    assert np.allclose(camera_centre(prior.T_pred_rgb_w), camera_centre(cv_T), atol=1e-12)
    if sigma_deg == 0.0:
        assert off_cv < 1e-9 and off_gyro > 9.0  # 2 deg about y against 9.9 deg about x
        assert prior.sigma_rad == pytest.approx(32.0 * 0.033 * 0.066 / 2)  # 32 rad/s^2 over the frame: 2 deg
    else:
        assert off_gyro < 1e-9 and off_cv > 9.0
        turn = np.radians(300.0) * 0.033  # 300 deg/s over 33 ms
        expected = np.hypot(np.radians(0.1), 0.015 * turn)  # a constant rate: the time error costs nothing
        assert prior.sigma_rad == pytest.approx(expected, rel=0.01)  # 0.18 deg: tighter than the constant rate's 2 deg


def test_the_gyros_rate_change_is_measured_over_a_frame() -> None:
    """A take-off's ramp, 0 to 600 deg/s over 0.1 s: the rate changes by 200 deg/s over a 33 ms frame."""
    gyro = GyroBuffer(np.eye(3))
    stamps = np.arange(0, 150 * MS, 2_500_000, dtype=np.int64)
    rate = np.zeros((len(stamps), 3))
    rate[:, 1] = np.radians(6000.0) * np.minimum(stamps * 1e-9, 0.1)
    gyro.add(ImuBatch(stamps, rate, np.zeros_like(rate)))
    assert np.degrees(gyro.rate_change(20 * MS, 53 * MS)) == pytest.approx(198.0, rel=0.02)
    assert np.degrees(gyro.rate_change(105 * MS, 138 * MS)) < 0.5  # a constant rate after the ramp
    assert gyro.rate_change(130 * MS, 200 * MS) is None  # past the samples


@pytest.mark.parametrize("measured", [False, True])
def test_the_prior_holds_a_measured_accelerometer_centre_tight_only_when_asked(measured: bool) -> None:
    """``tracker.imu_prior_sigma_m`` (opt-in): the centre's sigma is it where the accelerometer measured the span,
    constant velocity's reach (20 m/s^2 x 33 ms x 66 ms / 2: 2.2 cm) otherwise and with it off."""
    centre = np.array([0.05, -0.01, 0.02])
    motion = CameraMotion(centre, np.zeros(3), measured)
    reach = 20.0 * 0.033 * 0.066 / 2
    for sigma in (0.0, 0.003):
        pred = _predictor(imu_prior_sigma_m=sigma)
        prior = pred.priors(66 * MS, None, motion).motion
        assert np.allclose(camera_centre(prior.T_pred_rgb_w), centre, atol=1e-12)  # the accelerometer's centre
        expected = 0.003 if measured and sigma > 0 else reach
        assert prior.sigma_m == pytest.approx(expected)
