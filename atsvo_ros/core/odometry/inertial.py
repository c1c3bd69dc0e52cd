"""The accelerometer's prediction of the camera centre: what carries the translation through a push-off.

Constant velocity misses a Mini-Cheetah's push-off (up to 4 g for ~0.1 s) by 13-61 cm over the frames the
camera is blurred; the specific force integrated from the last trusted velocity predicted the same frames to
2.4-2.6 cm (simulated backflips, seed 21). Per frame: the IMU's velocity at the last frame, fitted to the
trusted poses of a short window (:mod:`~atsvo_ros.core.odometry.imu_state`) or else from the last two poses and
what the IMU measured between them, then its position at the new stamp, the IMU's rotation from the gyro.

Gravity in the tracking world (whose axes are the first camera's, not level) is estimated while tracking from
three trusted poses about :data:`GRAVITY_SPAN_NS` apart, velocities eliminated: the linear step of
visual-inertial initialisation (Mur-Artal and Tardos, IEEE RA-L 2017; Qin et al., VINS-Mono, T-RO 2018). Depth
gives metric scale, so nothing else is unknown. Estimates are averaged and scaled to standard gravity. The
accelerometer's bias is not estimated: the BMI055's +-70 mg turn-on offset moves a one-frame prediction by
under 0.5 mm. It does move each gravity estimate's magnitude by as much, so the gate that drops wrong estimates
leaves room for it (:data:`GRAVITY_TOLERANCE_M_S2`).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.imu import ImuBatch, preintegrate
from atsvo_ros.core.odometry.imu_state import ImuState, VelocityWindow, clipped
from atsvo_ros.errors import ImuError

#: m/s^2: the magnitude the gravity estimate is scaled to (local gravity differs by < 0.3 %)
STANDARD_GRAVITY = 9.80665
#: spacing of the three poses of one gravity estimate: a 5 mm pose error over 0.4 s is 0.1 m/s^2 in gravity
GRAVITY_SPAN_NS = 400_000_000
#: estimates averaged (a running mean over the last ones: the tracking world's axes drift slowly)
GRAVITY_ESTIMATES = 30
#: an estimate whose magnitude is further than this from standard gravity is dropped (a wrong pose among the three).
#: Not tighter: the accelerometer's turn-on offset enters the estimate along gravity. The BMI055 reads up to 70 mg
#: off per axis (typical, over life) and 2 % off in scale (Bosch BMI055 datasheet, BST-BMI055-DS000): 3 x 70 mg + 2 %
#: = 0.23 g. The old 1.5 m/s^2 (0.15 g) dropped every estimate of a unit 180 mg off (simulated backflip seed 11:
#: 8.05 m/s^2), so the IMU never predicted its flight: 19.4 cm ATE against 8.9 with the estimates kept.
GRAVITY_TOLERANCE_M_S2 = 0.23 * STANDARD_GRAVITY


@dataclass(frozen=True)
class CameraMotion:
    """The colour camera's centre (m) and velocity (m/s) in the tracking world at one stamp.

    ``measured`` is True when the centre comes from the fitted velocity and the accelerometer measured the whole
    span from the fit's oldest pose to the stamp without clipping: then it is as good as the trusted poses.
    """

    centre_w: np.ndarray
    velocity_w: np.ndarray
    measured: bool = False


class InertialPredictor:
    """Camera centres predicted from the IMU, and the gravity estimate they need (see the module docstring).

    Args:
        T_rgb_imu: the IMU frame in the colour optical frame (4x4).
        window: the IMU state fitted to the last trusted poses, or None (the last two poses' velocity only).
        accel_range_m_s2: the accelerometer's range (0: unknown): a span with a clipped sample is not measured.
    """

    def __init__(self, T_rgb_imu: np.ndarray, window: VelocityWindow | None = None,
                 accel_range_m_s2: float = 0.0) -> None:
        self.T_c_imu = np.asarray(T_rgb_imu, dtype=np.float64).reshape(4, 4)
        self.t_imu_c = se3_inv(self.T_c_imu)[:3, 3]
        self.window = window
        self.accel_range_m_s2 = float(accel_range_m_s2)
        self._trusted: deque[tuple[int, np.ndarray]] = deque()  # (stamp, T_w_imu) of trusted frames, ~2 spans
        self._estimates: deque[np.ndarray] = deque(maxlen=GRAVITY_ESTIMATES)
        self._last_estimate_ns: int | None = None

    @property
    def gravity_w(self) -> np.ndarray | None:
        """Gravity in the tracking world (m/s^2), or None before the first estimate."""
        if not self._estimates:
            return None
        g = np.mean(self._estimates, axis=0)
        return g * (STANDARD_GRAVITY / max(float(np.linalg.norm(g)), 1e-9))

    def reset(self) -> None:
        """Forget the poses (a clock jump); the gravity estimate stays (the world's axes do not change)."""
        self._trusted.clear()
        self._last_estimate_ns = None

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """Re-express the trusted poses and the gravity estimates in a moved world (mapping moved the map)."""
        self._trusted = deque((s, T_wnew_wold @ T) for s, T in self._trusted)
        self._estimates = deque((T_wnew_wold[:3, :3] @ g for g in self._estimates), maxlen=GRAVITY_ESTIMATES)

    def observe(self, imu: ImuBatch, stamp_ns: int, T_c_w: np.ndarray, trusted: bool) -> None:
        """Record a frame's pose; with three trusted ones spread over two spans, estimate gravity once more."""
        if not trusted:
            return
        stamp_ns = int(stamp_ns)
        self._trusted.append((stamp_ns, se3_inv(T_c_w) @ self.T_c_imu))
        while self._trusted and self._trusted[0][0] < stamp_ns - 2 * GRAVITY_SPAN_NS - GRAVITY_SPAN_NS // 2:
            self._trusted.popleft()
        if self._last_estimate_ns is not None and stamp_ns - self._last_estimate_ns < GRAVITY_SPAN_NS // 4:
            return
        first = self._trusted[0]
        if stamp_ns - first[0] < 2 * GRAVITY_SPAN_NS:
            return
        mid_ns = (first[0] + stamp_ns) // 2
        middle = min(self._trusted, key=lambda item: abs(item[0] - mid_ns))
        g = _gravity_from_three(imu, first, middle, self._trusted[-1])
        if g is not None and abs(float(np.linalg.norm(g)) - STANDARD_GRAVITY) < GRAVITY_TOLERANCE_M_S2:
            self._estimates.append(g)
            self._last_estimate_ns = stamp_ns

    def predict(self, imu: ImuBatch, history: tuple[tuple[int, np.ndarray], ...],
                stamp_ns: int) -> CameraMotion | None:
        """The colour camera's centre and velocity in the world at ``stamp_ns``, or None.

        Args:
            imu: the buffered IMU samples.
            history: the last two trusted ``(stamp_ns, T_c_w)``, oldest first.
            stamp_ns: the new frame's stamp.

        The velocity is the window's fit when the last frame is its newest pose, else the last two poses'.
        None before a gravity estimate, without two poses or when the IMU does not cover the interval.
        """
        g_w = self.gravity_w
        if g_w is None or len(history) != 2:
            return None
        fitted = self._from_window(imu, g_w, history[-1][0], int(stamp_ns))
        if fitted is not None:
            return fitted
        (s0, T0_c_w), (s1, T1_c_w) = history
        if not s0 < s1 < int(stamp_ns):
            return None
        try:
            pre01 = preintegrate(imu, s0, s1)
            pre12 = preintegrate(imu, s1, int(stamp_ns))
        except ImuError:
            return None
        T_w_i0 = se3_inv(T0_c_w) @ self.T_c_imu
        T_w_i1 = se3_inv(T1_c_w) @ self.T_c_imu
        dt01, dt12 = pre01.dt_s, pre12.dt_s
        # velocity at s1: from the two positions (velocity at s0 eliminated) plus the IMU's change in between
        v0 = (T_w_i1[:3, 3] - T_w_i0[:3, 3] - 0.5 * g_w * dt01 * dt01 - T_w_i0[:3, :3] @ pre01.dp_m) / dt01
        v1 = v0 + g_w * dt01 + T_w_i0[:3, :3] @ pre01.dv_m_s
        R_w_i1 = T_w_i1[:3, :3]
        p2 = T_w_i1[:3, 3] + v1 * dt12 + 0.5 * g_w * dt12 * dt12 + R_w_i1 @ pre12.dp_m
        v2 = v1 + g_w * dt12 + R_w_i1 @ pre12.dv_m_s
        return self._camera(imu, int(stamp_ns), p2, v2, R_w_i1 @ pre12.R_i0_i1, measured=False)

    def dead_reckon(self, imu: ImuBatch, window: VelocityWindow, stamp_ns: int,
                    max_gap_ns: int) -> tuple[np.ndarray, CameraMotion] | None:
        """The colour camera's pose ``T_c_w`` and motion at ``stamp_ns`` from the IMU alone, integrated from the state
        fitted to ``window`` at its newest trusted pose when that is at most ``max_gap_ns`` old (None otherwise,
        before a gravity estimate or when the IMU does not cover the span).

        What carries the pose through frames that neither the image nor the depth held (a flip's flight): constant
        motion would go on from the last, possibly wrong, pose at its velocity.
        """
        g_w = self.gravity_w
        newest = window.newest_ns
        if g_w is None or newest is None or not 0 < int(stamp_ns) - newest <= int(max_gap_ns):
            return None
        propagated = _propagate(imu, window.fit(imu, g_w), g_w, int(stamp_ns))
        if propagated is None:
            return None
        p, v, R_w_i = propagated
        T_w_i = np.eye(4)
        T_w_i[:3, :3], T_w_i[:3, 3] = R_w_i, p
        measured = not clipped(imu, window.oldest_ns, int(stamp_ns), self.accel_range_m_s2)
        return se3_inv(T_w_i @ se3_inv(self.T_c_imu)), self._camera(imu, int(stamp_ns), p, v, R_w_i, measured)

    def _from_window(self, imu: ImuBatch, g_w: np.ndarray, last_ns: int, stamp_ns: int) -> CameraMotion | None:
        """The prediction from the window's fitted state, when the last frame is the window's newest pose."""
        if self.window is None or self.window.newest_ns != last_ns or not last_ns < stamp_ns:
            return None
        propagated = _propagate(imu, self.window.fit(imu, g_w), g_w, stamp_ns)
        if propagated is None:
            return None
        measured = not clipped(imu, self.window.oldest_ns, stamp_ns, self.accel_range_m_s2)
        return self._camera(imu, stamp_ns, *propagated, measured)

    def _camera(self, imu: ImuBatch, stamp_ns: int, p_w: np.ndarray, v_w: np.ndarray, R_w_i: np.ndarray,
                measured: bool) -> CameraMotion:
        """The colour camera's centre and velocity from the IMU's: it sits a lever arm off the IMU, so it moves
        with the body's turn as well (``w x r``)."""
        w_i = _last_rate(imu, stamp_ns)
        return CameraMotion(p_w + R_w_i @ self.t_imu_c, v_w + R_w_i @ np.cross(w_i, self.t_imu_c), measured)


def _propagate(imu: ImuBatch, state: ImuState | None, g_w: np.ndarray,
               stamp_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The IMU's position, velocity and orientation at ``stamp_ns`` integrated from ``state`` (None without a state
    or when the IMU does not cover the span)."""
    if state is None:
        return None
    try:
        pre = preintegrate(imu, state.stamp_ns, stamp_ns)
    except ImuError:
        return None
    dt = pre.dt_s
    p = state.p_w + state.v_w * dt + 0.5 * g_w * dt * dt + state.R_w_i @ pre.dp_m
    v = state.v_w + g_w * dt + state.R_w_i @ pre.dv_m_s
    return p, v, state.R_w_i @ pre.R_i0_i1


def _last_rate(imu: ImuBatch, stamp_ns: int) -> np.ndarray:
    """The gyro's rate at ``stamp_ns`` (the nearest sample not after it, else the first)."""
    k = int(np.searchsorted(imu.stamps_ns, stamp_ns, side="right")) - 1
    return imu.gyro_rad_s[max(k, 0)]


def _gravity_from_three(imu: ImuBatch, a: tuple[int, np.ndarray], b: tuple[int, np.ndarray],
                        c: tuple[int, np.ndarray]) -> np.ndarray | None:
    """Gravity in the world from the IMU poses ``(stamp_ns, T_w_imu)`` of three frames (velocities eliminated).

    With ``A = (p_c - p_b - R_b dp_bc) / dt_bc`` and ``B = (p_b - p_a - R_a dp_ab) / dt_ab``:
    ``g (dt_ab + dt_bc) / 2 = A - B - R_a dv_ab``. None when the IMU does not cover the span.
    """
    (sa, Ta), (sb, Tb), (sc, Tc) = a, b, c
    if not sa < sb < sc:
        return None
    try:
        ab, bc = preintegrate(imu, sa, sb), preintegrate(imu, sb, sc)
    except ImuError:
        return None
    A = (Tc[:3, 3] - Tb[:3, 3] - Tb[:3, :3] @ bc.dp_m) / bc.dt_s
    B = (Tb[:3, 3] - Ta[:3, 3] - Ta[:3, :3] @ ab.dp_m) / ab.dt_s
    return 2.0 * (A - B - Ta[:3, :3] @ ab.dv_m_s) / (ab.dt_s + bc.dt_s)


__all__ = ["CameraMotion", "InertialPredictor", "STANDARD_GRAVITY"]
