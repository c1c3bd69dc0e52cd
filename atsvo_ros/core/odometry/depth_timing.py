"""Where the camera was when the depth was exposed: the motion that moves a D455 depth image to the colour's time.

The D455 exposes depth up to +-16.7 ms off the colour and cannot synchronise the two (librealsense issue
#11609); a bound's 2 m/s moves the scene 3 cm in that time. The gyro gives the rotation between the two
exposures. The translation needs the camera's velocity, which neither the last two poses give (their
centimetre of noise over 33 ms is 0.3 m/s) nor the accelerometer alone (it measures no velocity).

Here the IMU's velocity at the newest trusted pose is fitted to the trusted poses of a short window
(``tracker.depth_velocity_window_s``), the preintegrated specific force linking them, each older pose's
velocity eliminated: the pose noise averages over the window while the IMU carries a stance's 4 g between
the poses. Gravity enters as ``g tau^2 / 2`` over the window: 10 deg of error in its direction moves the
depth by 2-4 mm (tests), so a prior (the base upright at the first frame) serves until the online estimate
of :class:`~atsvo_ros.core.odometry.inertial.InertialPredictor` exists.
Measured on simulated bounds (tuning seeds 0-4, 2.5 s): the camera's shift over the offset 1-2 mm off
(median) against 17 mm true; from the last two poses and the accelerometer it was 8-9 mm off.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.imu import ImuBatch, preintegrate
from atsvo_ros.errors import ImuError


@dataclass(frozen=True)
class ImuState:
    """The IMU's position (m), velocity (m/s) and orientation in the tracking world at one stamp."""

    stamp_ns: int
    p_w: np.ndarray
    v_w: np.ndarray
    R_w_i: np.ndarray


class DepthTiming:
    """The colour camera's motion between two nearby stamps from the last trusted poses and the IMU.

    Args:
        T_rgb_imu: the IMU frame in the colour optical frame (4x4).
        window_ns: trusted poses older than this before the newest are dropped from the fit.
        min_poses: poses the fit needs (two give the velocity, a third averages its noise).
        max_age_ns: no motion for a stamp this far past the newest trusted pose (mid-flip, frames not trusted:
            extrapolating the IMU over longer spans lets the velocity's error grow).
    """

    def __init__(self, T_rgb_imu: np.ndarray, window_ns: int, min_poses: int = 3,
                 max_age_ns: int = 70_000_000) -> None:
        self.T_c_imu = np.asarray(T_rgb_imu, dtype=np.float64).reshape(4, 4)
        self.t_imu_c = se3_inv(self.T_c_imu)[:3, 3]
        self.window_ns = int(window_ns)
        self.min_poses = max(2, int(min_poses))
        self.max_age_ns = int(max_age_ns)
        self._poses: deque[tuple[int, np.ndarray]] = deque()  # (stamp, T_w_imu) of the trusted frames in the window

    def reset(self) -> None:
        """Forget the poses (a new map or a clock jump)."""
        self._poses.clear()

    @property
    def oldest_ns(self) -> int | None:
        """The stamp of the oldest pose in the window (None when empty)."""
        return self._poses[0][0] if self._poses else None

    def observe(self, stamp_ns: int, T_c_w: np.ndarray) -> None:
        """Add a trusted frame's pose; poses older than the window before it are dropped."""
        stamp_ns = int(stamp_ns)
        if self._poses and stamp_ns <= self._poses[-1][0]:
            self.reset()  # time went back: the window no longer describes one motion
        self._poses.append((stamp_ns, se3_inv(T_c_w) @ self.T_c_imu))
        while self._poses[0][0] < stamp_ns - self.window_ns:
            self._poses.popleft()

    def fit(self, imu: ImuBatch, g_w: np.ndarray) -> ImuState | None:
        """The IMU's state at the newest pose, least squares over the window; None with too few poses or no IMU.

        Each pose k gives ``p_n - v_n tau_k = p_k - g tau_k^2 / 2 - R_k dv_kn tau_k + R_k dp_kn``
        (``tau_k`` from pose k to the newest, ``dv``, ``dp`` preintegrated from k to the newest).
        """
        if len(self._poses) < self.min_poses:
            return None
        s_n = self._poses[-1][0]
        rows, rhs = [], []
        for s_k, T_w_i in self._poses:
            try:
                pre = preintegrate(imu, s_k, s_n)
            except ImuError:
                return None
            tau, R_k = pre.dt_s, T_w_i[:3, :3]
            rows.append((1.0, -tau))
            rhs.append(T_w_i[:3, 3] - 0.5 * g_w * tau * tau - tau * (R_k @ pre.dv_m_s) + R_k @ pre.dp_m)
        sol = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)[0]
        return ImuState(s_n, sol[0], sol[1], self._poses[-1][1][:3, :3].copy())

    def camera_motion(self, imu: ImuBatch, g_w: np.ndarray, t_a_ns: int, t_b_ns: int) -> np.ndarray | None:
        """``T_a_b``: the colour camera at ``t_b_ns`` in the colour camera at ``t_a_ns`` (4x4), or None.

        None when the fit is not possible, or when ``t_a_ns`` lies more than ``max_age_ns`` past the newest pose.
        """
        if not self._poses or int(t_a_ns) - self._poses[-1][0] > self.max_age_ns:
            return None
        state = self.fit(imu, g_w)
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


__all__ = ["DepthTiming", "ImuState"]
