"""An analytic legged-robot motion and the IMU it makes: a trot, then a 4 g push-off (shared by the IMU tests)."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.geometry import se3_inv, so3_exp
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.odometry.inertial import STANDARD_GRAVITY

MS = 1_000_000
G_W = np.array([0.0, -STANDARD_GRAVITY, 0.0])  # the tracking world's axes are the first camera's: y down


def T_w_imu(t_s: float) -> np.ndarray:
    """A trot, then a push-off: 4 g forward and up for 0.15 s from t = 1.2 s, the body pitching at 300 deg/s."""
    T = np.eye(4)
    T[:3, :3] = so3_exp(np.array([0.15 * np.sin(5.0 * t_s), 0.1 * np.sin(3.0 * t_s), 0.0])
                        + np.array([max(0.0, t_s - 1.2) * 5.2, 0.0, 0.0]))
    push = max(0.0, min(t_s, 1.35) - 1.2)
    after = max(0.0, t_s - 1.35)
    T[:3, 3] = [0.02 * np.sin(9.0 * t_s), 0.01 * np.cos(11.0 * t_s) - 20.0 * (push ** 2 / 2 + 0.15 * after),
                0.4 * t_s + 20.0 * (push ** 2 / 2 + 0.15 * after)]
    return T


def imu_batch(T_c_imu: np.ndarray, span_s: float = 1.6, rate_hz: float = 400.0) -> ImuBatch:
    """Rates and specific forces of :func:`T_w_imu` by central differences (exact enough: ~1e-5)."""
    t = np.arange(0.0, span_s, 1.0 / rate_hz)
    h = 1e-4
    gyro, accel = [], []
    for ti in t:
        Rm, R0, Rp = (T_w_imu(ti + d)[:3, :3] for d in (-h, 0.0, h))
        W = R0.T @ (Rp - Rm) / (2 * h)
        gyro.append([W[2, 1], W[0, 2], W[1, 0]])
        a_w = (T_w_imu(ti + h)[:3, 3] - 2 * T_w_imu(ti)[:3, 3] + T_w_imu(ti - h)[:3, 3]) / (h * h)
        accel.append(R0.T @ (a_w - G_W))
    return ImuBatch((t * 1e9).astype(np.int64), np.array(gyro), np.array(accel))


def T_c_w(t_s: float, T_c_imu: np.ndarray) -> np.ndarray:
    """The colour camera's pose of :func:`T_w_imu` at ``t_s``."""
    return T_c_imu @ se3_inv(T_w_imu(t_s))
