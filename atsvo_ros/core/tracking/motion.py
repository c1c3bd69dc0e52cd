"""Motion model: predictions of the next camera pose from the last estimates (and the gyro when present).

The history holds the colour camera poses ``T_c_w`` of the last trusted frames. The constant-motion
prediction extrapolates the last inter-frame motion to the new stamp (scaled by the time ratio, so
a dropped frame is bridged); the zero-motion prediction repeats the last pose. With a gyro, the
rotation between the last frame and the new one comes from integrating the IMU's angular velocity
(no bias is estimated: a turn-on bias of ~1 deg/s adds ~0.03 deg per frame), which is accurate to
a small fraction of a degree over one frame even at the rates of a backflip.
The translation comes from constant motion here; the odometry replaces the centre with the
accelerometer's when it has one (:mod:`atsvo_ros.core.odometry.inertial`).

:meth:`MotionModel.relative_motion` gives the paper's relative-motion factor of ``T_{i-2}, T_{i-1}``
as angular and linear velocity (rad/s, m/s), independent of the frame rate.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from atsvo_ros.core.geometry import camera_centre, se3_exp, se3_inv, se3_log, so3_log


class MotionModel:
    """Pose history and predictions (see the module docstring)."""

    #: Extrapolate at most this many inter-frame intervals (a long gap makes constant motion meaningless).
    MAX_RATIO = 3.0

    def __init__(self) -> None:
        self._history: deque[tuple[int, np.ndarray]] = deque(maxlen=2)
        self._trusted: deque[bool] = deque(maxlen=2)
        self._twist: tuple[np.ndarray, int] | None = None  # the last motion's twist (computed once per push)
        #: the last prediction (stamp, scale, T_c_w): a frame asks for the same one five times (0.05 ms each)
        self._predicted: tuple[int, float, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the motion (after a clock jump or a re-initialisation the velocity is unknown)."""
        last = self._history[-1] if self._history else None
        self._history.clear()
        self._trusted.clear()
        self._twist = None
        self._predicted = None
        if last is not None:
            self._history.append(last)
            self._trusted.append(False)

    def push(self, stamp_ns: int, T_c_w: np.ndarray, trusted: bool = True) -> None:
        """Record the pose of a frame: trusted (an alignment the checks passed) or not (degraded, predicted);
        the published trajectory continues from either."""
        self._history.append((int(stamp_ns), np.asarray(T_c_w, dtype=np.float64).copy()))
        self._trusted.append(bool(trusted))
        self._twist = None
        self._predicted = None

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """Re-express the pose history in a moved world (mapping moved the map under it); the motion is unchanged."""
        T_wold_wnew = se3_inv(T_wnew_wold)
        self._history = deque(((s, T @ T_wold_wnew) for s, T in self._history), maxlen=2)
        self._predicted = None

    def centre_prior(self, stamp_ns: int, max_acceleration_m_s2: float,
                     noise_m: float) -> tuple[np.ndarray, float] | None:
        """The constant-velocity camera centre at ``stamp_ns`` and how far from it the camera can be: the
        acceleration bound times :meth:`prediction_spread`, plus ``noise_m`` for the estimates' own noise (None
        when there is no spread).
        """
        spread = self.prediction_spread(stamp_ns)
        if spread is None:
            return None
        return camera_centre(self.predict(stamp_ns)), max_acceleration_m_s2 * spread + noise_m

    def prediction_spread(self, stamp_ns: int) -> float | None:
        """``dt (dt + dt0) / 2`` (s^2): times an acceleration, how far the constant-velocity prediction can be off.

        Poses at ``-dt0, 0`` give the velocity at ``-dt0 / 2``; an acceleration ``a`` moves the pose at ``dt`` by up
        to ``a dt (dt + dt0) / 2`` from the prediction. None unless the last two poses are trusted (a wrong pose
        would make a wrong prediction) and the frame follows within :attr:`MAX_RATIO` intervals.
        """
        if len(self._history) < 2 or not all(self._trusted):
            return None
        (s0, _), (s1, _) = self._history
        dt0_s, dt_s = (s1 - s0) * 1e-9, (int(stamp_ns) - s1) * 1e-9
        if dt0_s <= 0.0 or dt_s <= 0.0 or dt_s > self.MAX_RATIO * dt0_s:
            return None
        return 0.5 * dt_s * (dt_s + dt0_s)

    @property
    def history(self) -> tuple[tuple[int, np.ndarray], ...]:
        """The last (at most two) ``(stamp_ns, T_c_w)``, oldest first."""
        return tuple(self._history)

    @property
    def velocity_trusted(self) -> bool:
        """The last motion comes from two trusted poses (else predictions from it are guesses)."""
        return len(self._history) == 2 and all(self._trusted)

    @property
    def last(self) -> tuple[int, np.ndarray] | None:
        return self._history[-1] if self._history else None

    def _velocity(self) -> tuple[np.ndarray, int] | None:
        """Twist of the last inter-frame motion (``T1 T0^-1``) and its duration in ns."""
        if len(self._history) < 2:
            return None
        if self._twist is None:  # predictions ask for it several times per frame
            (s0, T0), (s1, T1) = self._history
            self._twist = (se3_log(T1 @ se3_inv(T0)), max(1, s1 - s0))
        return self._twist

    def twist_per_s(self) -> np.ndarray:
        """Velocity of the last inter-frame motion as a twist per second (``T(t + dt) = exp(dt xi) T(t)``).

        Zeros without a motion history.
        """
        vel = self._velocity()
        if vel is None:
            return np.zeros(6)
        xi, dt = vel
        return xi / (dt * 1e-9)

    def predict(self, stamp_ns: int) -> np.ndarray:
        """Constant-motion prediction of ``T_c_w`` (the last pose without motion history, identity before any)."""
        return self.predict_scaled(stamp_ns, 1.0)

    def predict_scaled(self, stamp_ns: int, scale: float) -> np.ndarray:
        """The constant-motion prediction with the last motion scaled by ``scale`` (an accelerating or braking turn)."""
        if not self._history:
            return np.eye(4)
        s1, T1 = self._history[-1]
        vel = self._velocity()
        if vel is None:
            return T1.copy()
        cached = self._predicted
        if cached is not None and cached[0] == stamp_ns and cached[1] == scale:
            return cached[2].copy()
        xi, dt = vel
        ratio = float(np.clip((stamp_ns - s1) / dt, 0.0, self.MAX_RATIO))
        T = se3_exp(scale * ratio * xi) @ T1
        self._predicted = (stamp_ns, scale, T)
        return T.copy()

    def predict_with_rotation(self, stamp_ns: int, R_c1_c0: np.ndarray) -> np.ndarray:
        """Prediction with the rotation from the last frame ``c0`` to the new one ``c1`` given (e.g. by the gyro).

        The camera centre moves as in :meth:`predict`; the orientation is ``R_c1_c0 R_c0_w``.
        """
        T_pred = self.predict(stamp_ns)
        if not self._history:
            return T_pred
        T1 = self._history[-1][1]
        centre = camera_centre(T_pred)
        out = np.eye(4)
        out[:3, :3] = R_c1_c0 @ T1[:3, :3]
        out[:3, 3] = -out[:3, :3] @ centre
        return out

    def relative_motion(self) -> tuple[float, float] | None:
        """Angular (rad/s) and linear (m/s) speed of the camera between the last two frames, or None."""
        vel = self._velocity()
        if vel is None:
            return None
        (s0, T0), (s1, T1) = self._history
        dt_s = (s1 - s0) * 1e-9
        if dt_s <= 0:
            return None
        ang = float(np.linalg.norm(so3_log(T1[:3, :3] @ T0[:3, :3].T)))  # rotation c0 -> c1
        centre0, centre1 = camera_centre(T0), camera_centre(T1)
        return ang / dt_s, float(np.linalg.norm(centre1 - centre0)) / dt_s


__all__ = ["MotionModel"]
