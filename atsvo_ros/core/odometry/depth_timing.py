"""Where the camera was when the depth was exposed: the motion that moves a D455 depth image to the colour's time.

The D455 exposes depth up to +-16.7 ms off the colour and cannot synchronise the two (librealsense issue
#11609); a bound's 2 m/s moves the scene 3 cm in that time. The gyro gives the rotation between the two
exposures. The translation needs the camera's velocity, which neither the last two poses give (their
centimetre of noise over 33 ms is 0.3 m/s) nor the accelerometer alone (it measures no velocity).

Here the IMU's velocity at the newest trusted pose is fitted to the trusted poses of a short window
(``tracker.imu_velocity_window_s``, :mod:`~atsvo_ros.core.odometry.imu_state`), the preintegrated specific force
linking them: the pose noise averages over the window while the IMU carries a stance's 4 g between the poses.
Gravity enters as ``g tau^2 / 2`` over the window: 10 deg of error in its direction moves the
depth by 2-4 mm (tests), so a prior (the base upright at the first frame) serves until the online estimate
of :class:`~atsvo_ros.core.odometry.inertial.InertialPredictor` exists.
Measured on simulated bounds (tuning seeds 0-4, 2.5 s): the camera's shift over the offset 1-2 mm off
(median) against 17 mm true; from the last two poses and the accelerometer it was 8-9 mm off.
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.imu import ImuBatch, preintegrate
from atsvo_ros.core.odometry.imu_state import ImuState, VelocityWindow
from atsvo_ros.errors import ImuError


class DepthTiming:
    """The colour camera's motion between two nearby stamps from the IMU state fitted to the last trusted poses.

    Args:
        window: the trusted poses and the IMU state fitted to them (shared with the centre's prediction; the
            odometry feeds it).
        max_age_ns: no motion for a stamp this far past the newest trusted pose (mid-flip, frames not trusted:
            extrapolating the IMU over longer spans lets the velocity's error grow).
    """

    def __init__(self, window: VelocityWindow, max_age_ns: int = 70_000_000) -> None:
        self.window = window
        self.T_c_imu = window.T_c_imu
        self.t_imu_c = se3_inv(self.T_c_imu)[:3, 3]
        self.max_age_ns = int(max_age_ns)

    @property
    def oldest_ns(self) -> int | None:
        """The stamp of the oldest pose in the window (None when empty)."""
        return self.window.oldest_ns

    def camera_motion(self, imu: ImuBatch, g_w: np.ndarray, t_a_ns: int, t_b_ns: int) -> np.ndarray | None:
        """``T_a_b``: the colour camera at ``t_b_ns`` in the colour camera at ``t_a_ns`` (4x4), or None.

        None when the fit is not possible, or when ``t_a_ns`` lies more than ``max_age_ns`` past the newest pose.
        """
        newest = self.window.newest_ns
        if newest is None or int(t_a_ns) - newest > self.max_age_ns:
            return None
        state = self.window.fit(imu, g_w)
        if state is None:
            return None
        try:
            (R_w_a, c_a), (R_w_b, c_b) = (self._camera_at(imu, state, g_w, int(t)) for t in (t_a_ns, t_b_ns))
        except ImuError:
            return None
        T = np.eye(4)
        T[:3, :3] = R_w_a.T @ R_w_b
        T[:3, 3] = R_w_a.T @ (c_b - c_a)
        return T

    def _camera_at(self, imu: ImuBatch, state: ImuState, g_w: np.ndarray, t_ns: int
                   ) -> tuple[np.ndarray, np.ndarray]:
        """The colour camera's orientation ``R_w_c`` and centre at ``t_ns``, the IMU state moved there."""
        if t_ns >= state.stamp_ns:
            pre = preintegrate(imu, state.stamp_ns, t_ns)
            dt = pre.dt_s
            R_w_i = state.R_w_i @ pre.R_i0_i1
            p = state.p_w + state.v_w * dt + 0.5 * g_w * dt * dt + state.R_w_i @ pre.dp_m
        else:  # backwards: the velocity at t_ns from the state's, then the position
            pre = preintegrate(imu, t_ns, state.stamp_ns)
            dt = pre.dt_s
            R_w_i = state.R_w_i @ pre.R_i0_i1.T
            v = state.v_w - g_w * dt - R_w_i @ pre.dv_m_s
            p = state.p_w - v * dt - 0.5 * g_w * dt * dt - R_w_i @ pre.dp_m
        return R_w_i @ self.T_c_imu[:3, :3].T, p + R_w_i @ self.t_imu_c


__all__ = ["DepthTiming"]
