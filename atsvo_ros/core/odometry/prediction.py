"""The odometry's predictions: what the motion model and the gyro say about a frame before it is tracked."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.geometry import camera_centre, rotation_angle_rad
from atsvo_ros.core.odometry.gyro import GyroBuffer
from atsvo_ros.core.odometry.inertial import CameraMotion, InertialPredictor
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.core.tracking.checks import Priors
from atsvo_ros.core.tracking.motion import MotionModel
from atsvo_ros.core.tracking.residuals.prior import MotionPrior


class Predictor:
    """Starting points, priors, row timing and the relative-motion factor of a frame, from the poses so far.

    Args:
        config: the odometry's configuration (``tracker``, ``fusion``, ``rgb_camera.readout_time_s``).
        motion: the odometry's motion model (read, never changed here).
        gyro: the odometry's IMU buffer.
        image_height: rows of the colour image (its rolling shutter's rows).
        inertial: the accelerometer's prediction of the camera's centre and velocity, or None.
    """

    def __init__(self, config: AtsvoConfig, motion: MotionModel, gyro: GyroBuffer, image_height: int,
                 inertial: InertialPredictor | None = None) -> None:
        self.config = config
        self.motion = motion
        self.gyro = gyro
        self.image_height = image_height
        self.inertial = inertial

    def imu_motion(self, stamp: int) -> CameraMotion | None:
        """The camera's centre and velocity at ``stamp`` from the accelerometer, after two trusted frames."""
        if self.inertial is None or not self.gyro or not self.motion.velocity_trusted:
            return None
        return self.inertial.predict(self.gyro.samples(), self.motion.history, stamp)

    def gyro_pose(self, stamp: int, centre: np.ndarray | None = None) -> np.ndarray | None:
        """``T_c_w`` with the rotation since the last frame from the gyro, or None when the IMU does not cover it.

        The camera centre is ``centre`` when given (the accelerometer's), else constant velocity's.
        """
        last = self.motion.last
        if last is None:
            return None
        R_c0_c1 = self.gyro.camera_rotation(last[0], stamp)
        if R_c0_c1 is None:
            return None
        T = self.motion.predict_with_rotation(stamp, R_c0_c1.T)
        if centre is not None:
            T[:3, 3] = -T[:3, :3] @ centre
        return T

    def guesses(self, stamp: int, predicted: np.ndarray, gyro: np.ndarray | None, fast: bool,
                event_rate_ratio: float | None) -> list[np.ndarray]:
        """Starting points: the gyro's prediction (with an IMU), constant motion, zero motion, and while the
        camera turns fast (or the events say it speeds up: ``event_rate_ratio``) the constant motion scaled."""
        guesses = [predicted] if gyro is None else [gyro, predicted]
        if self.motion.last is None or np.allclose(self.motion.last[1], predicted):
            return guesses
        guesses.append(self.motion.last[1])  # zero motion
        if gyro is not None:
            return guesses
        scales = list(self.config.tracker.velocity_scales) if fast else []
        if event_rate_ratio is not None and event_rate_ratio > 1.5:
            # Events per frame grow with the image motion: a surge of events says the turn sped up.
            scales += [0.75 * event_rate_ratio, event_rate_ratio, 1.25 * event_rate_ratio]
        return guesses + [self.motion.predict_scaled(stamp, k) for k in scales]

    def priors(self, stamp: int, gyro: np.ndarray | None, imu: CameraMotion | None = None) -> Priors:
        """What the motion says this frame's pose should be: the gyro's prediction and, after two trusted frames,
        the camera centre (``imu``'s, the accelerometer's, else constant velocity's) with the reach of
        ``tracker.max_acceleration_m_s2``."""
        cfg = self.config.tracker
        centre = None if imu is None else imu.centre_w
        check = self.motion.centre_prior(stamp, cfg.max_acceleration_m_s2, cfg.motion_noise_m)
        prior = None
        a_m, a_rad = cfg.motion_prior_acceleration_m_s2, cfg.motion_prior_angular_acceleration_rad_s2
        spread = self.motion.prediction_spread(stamp) if a_m > 0 and a_rad > 0 else None
        if spread is not None:  # the last two poses are trusted
            # The rotation is constant velocity's, or the gyro's with tracker.gyro_prior_sigma_deg; the centre is
            # the accelerometer's when it has one. Node and replay give the core the same IMU samples (each
            # frame's cut ends at its exposure), so both track against the same prior.
            T_prior = self.motion.predict(stamp)
            sigma_rad = a_rad * spread
            if gyro is not None and cfg.gyro_prior_sigma_deg > 0:
                c_w = camera_centre(T_prior)
                T_prior[:3, :3] = gyro[:3, :3]
                T_prior[:3, 3] = -gyro[:3, :3] @ c_w
                sigma_rad = self._gyro_sigma_rad(stamp, gyro)
            sigma_m = a_m * spread
            if imu is not None:
                T_prior[:3, 3] = -T_prior[:3, :3] @ imu.centre_w
                if imu.measured and cfg.imu_prior_sigma_m > 0:
                    # the accelerometer measured every sample since the fit's first pose: as good as those poses
                    sigma_m = min(sigma_m, cfg.imu_prior_sigma_m)
            prior = MotionPrior(T_prior, sigma_m, sigma_rad, cfg.motion_prior_huber)
        if check is None:
            return Priors(gyro, motion=prior)
        return Priors(gyro, check[0] if centre is None else centre, check[1], motion=prior)

    def _gyro_sigma_rad(self, stamp: int, gyro: np.ndarray) -> float:
        """How far the gyro's rotation since the last frame may be off: a floor (bias, noise), a share of the turn
        (scale, axes) and the change of rate over the IMU's time error (a shifted window misses that much)."""
        cfg = self.config.tracker
        last_stamp, last_T = self.motion.last
        turn_rad = float(rotation_angle_rad(gyro[:3, :3] @ last_T[:3, :3].T))
        change = self.gyro.rate_change(last_stamp, stamp) or 0.0
        return float(np.linalg.norm([np.radians(cfg.gyro_prior_sigma_deg), cfg.gyro_prior_relative_error * turn_rad,
                                     change * cfg.gyro_prior_time_error_s]))

    def rolling_shutter(self, stamp: int) -> RollingShutter | None:
        """Row timing of the colour (and depth) image when the camera has a rolling shutter."""
        cam = self.config.rgb_camera
        last = self.motion.last
        if cam.readout_time_s == 0.0 or last is None or stamp <= last[0]:
            return None
        return RollingShutter.centred(cam.readout_time_s, self.image_height, last[1], (stamp - last[0]) * 1e-9)

    def motion_rates(self) -> tuple[float, float] | None:
        """The paper's relative-motion factor: camera angular rate (rad/s) and speed (m/s) over the last two frames.

        The angular rate comes from the gyro when it covers the interval (measured, not estimated), else
        from the two poses; None before two frames.
        """
        measured = self._measured_rates()
        return None if measured is None else measured[:2]

    def _measured_rates(self) -> tuple[float, float, bool] | None:
        """:meth:`motion_rates` and whether the gyro gave the angular rate."""
        rel = self.motion.relative_motion()
        if rel is None:
            return None
        ang, speed = rel
        hist = self.motion.history
        if len(hist) == 2:
            rate = self.gyro.angular_rate(hist[0][0], hist[1][0])
            if rate is not None:
                return rate, speed, True
        return ang, speed, False

    def is_fast(self) -> bool:
        """The relative-motion factor of the last two frames is above a threshold (angular rate or speed); the
        rate's threshold is ``fusion.rate_threshold_gyro_deg_s`` when the gyro measured it."""
        rates = self._measured_rates()
        if rates is None:
            return False
        fu = self.config.fusion
        limit = fu.rate_threshold_gyro_deg_s if rates[2] else fu.rate_threshold_deg_s
        return bool(np.degrees(rates[0]) > limit or rates[1] > fu.speed_threshold_m_s)


__all__ = ["Predictor"]
