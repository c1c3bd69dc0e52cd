"""The IMU's velocity fitted to the trusted poses of a short window, shared by the depth's timing and the centre's
prediction.

Two poses 33 ms apart give a velocity with their centimetre of noise over 33 ms (0.3 m/s). Here each trusted pose
of the last ``tracker.imu_velocity_window_s`` is linked to the newest by the preintegrated specific force and
gravity, and least squares gives the IMU's position and velocity at the newest: the poses' noise averages while
the IMU carries a stance's 4 g between them (Forster et al., "On-Manifold Preintegration", T-RO 2017, for the
preintegrated terms; the fit is the linear step of visual-inertial initialisation with known gravity and scale).

An accelerometer clips at its range: the D4xx firmware sets the BMI055 to +-4 g (librealsense PR #2777), which a
Mini-Cheetah's push-off and landing exceed for a few samples. Over a clipped interval the preintegrated terms miss
the excess, so a prediction across it is no better than the robot's acceleration bound (:func:`clipped`).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.imu import ImuBatch, preintegrate
from atsvo_ros.errors import ImuError

#: share of the range at which a sample counts as clipped (12-bit over +-4 g: one step is 0.05 % of the range)
CLIP_SHARE = 0.995


@dataclass(frozen=True)
class ImuState:
    """The IMU's position (m), velocity (m/s) and orientation in the tracking world at one stamp."""

    stamp_ns: int
    p_w: np.ndarray
    v_w: np.ndarray
    R_w_i: np.ndarray


def fit_imu_state(poses: tuple[tuple[int, np.ndarray], ...], imu: ImuBatch, g_w: np.ndarray) -> ImuState | None:
    """The IMU's state at the newest of ``poses`` (``(stamp_ns, T_w_imu)``, oldest first), least squares over them.

    Each pose k gives ``p_n - v_n tau_k = p_k - g tau_k^2 / 2 - R_k dv_kn tau_k + R_k dp_kn`` (``tau_k`` from pose
    k to the newest, ``dv``, ``dp`` preintegrated from k to the newest). None when the IMU does not cover the span.
    """
    s_n = poses[-1][0]
    rows, rhs = [], []
    for s_k, T_w_i in poses:
        try:
            pre = preintegrate(imu, s_k, s_n)
        except ImuError:
            return None
        tau, R_k = pre.dt_s, T_w_i[:3, :3]
        rows.append((1.0, -tau))
        rhs.append(T_w_i[:3, 3] - 0.5 * g_w * tau * tau - tau * (R_k @ pre.dv_m_s) + R_k @ pre.dp_m)
    sol = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)[0]
    return ImuState(s_n, sol[0], sol[1], poses[-1][1][:3, :3].copy())


def clipped(imu: ImuBatch, t0_ns: int, t1_ns: int, accel_range_m_s2: float) -> bool:
    """Whether an accelerometer sample from ``t0_ns`` to ``t1_ns`` (inclusive) reached the range on any axis.

    Args:
        imu: the samples.
        t0_ns: start of the interval.
        t1_ns: end of the interval.
        accel_range_m_s2: the accelerometer's range (0: unknown, never clipped).

    Returns:
        True when the interval holds a clipped sample.
    """
    if accel_range_m_s2 <= 0.0:
        return False
    i0 = int(np.searchsorted(imu.stamps_ns, int(t0_ns), side="left"))
    i1 = int(np.searchsorted(imu.stamps_ns, int(t1_ns), side="right"))
    return bool(np.any(np.abs(imu.accel_m_s2[i0:i1]) >= CLIP_SHARE * accel_range_m_s2))


class VelocityWindow:
    """The trusted poses of the last ``window_ns`` and the IMU state fitted to them (see the module docstring).

    Args:
        T_rgb_imu: the IMU frame in the colour optical frame (4x4).
        window_ns: trusted poses older than this before the newest are dropped.
        min_poses: poses a fit needs (two give the velocity, a third averages its noise).
    """

    def __init__(self, T_rgb_imu: np.ndarray, window_ns: int, min_poses: int = 3) -> None:
        self.T_c_imu = np.asarray(T_rgb_imu, dtype=np.float64).reshape(4, 4)
        self.window_ns = int(window_ns)
        self.min_poses = max(2, int(min_poses))
        self._poses: deque[tuple[int, np.ndarray]] = deque()  # (stamp, T_w_imu) of the trusted frames
        self._cache: tuple[tuple, ImuState | None] | None = None  # a frame fits once for all its users

    def reset(self) -> None:
        """Forget the poses (a new map or a clock jump)."""
        self._poses.clear()
        self._cache = None

    @property
    def oldest_ns(self) -> int | None:
        """The stamp of the oldest pose in the window (None when empty)."""
        return self._poses[0][0] if self._poses else None

    @property
    def newest_ns(self) -> int | None:
        """The stamp of the newest pose in the window (None when empty)."""
        return self._poses[-1][0] if self._poses else None

    def observe(self, stamp_ns: int, T_c_w: np.ndarray) -> None:
        """Add a trusted frame's pose; poses older than the window before it are dropped."""
        stamp_ns = int(stamp_ns)
        if self._poses and stamp_ns <= self._poses[-1][0]:
            self.reset()  # time went back: the window no longer describes one motion
        self._poses.append((stamp_ns, se3_inv(T_c_w) @ self.T_c_imu))
        while self._poses[0][0] < stamp_ns - self.window_ns:
            self._poses.popleft()

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """Re-express the window's poses in a moved world (mapping moved the map under them)."""
        self._poses = deque((s, T_wnew_wold @ T) for s, T in self._poses)
        self._cache = None

    def fit(self, imu: ImuBatch, g_w: np.ndarray) -> ImuState | None:
        """The IMU's state at the newest pose; None with too few poses or when the IMU does not cover them."""
        if len(self._poses) < self.min_poses:
            return None
        key = (self._poses[-1][0], len(self._poses), len(imu), imu.t_last_ns, np.asarray(g_w, np.float64).tobytes())
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, fit_imu_state(tuple(self._poses), imu, g_w))
        return self._cache[1]


__all__ = ["CLIP_SHARE", "ImuState", "VelocityWindow", "clipped", "fit_imu_state"]
