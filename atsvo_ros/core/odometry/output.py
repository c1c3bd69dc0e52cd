"""The odometry's output: a frame's pose and covariance moved from the colour camera into odom/base."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.frame import OdometryResult, TrackingStatus
from atsvo_ros.core.geometry import se3_adjoint, se3_inv
from atsvo_ros.core.tracking.checks import OK
from atsvo_ros.core.tracking.tracking import TrackingOutcome


class ResultBuilder:
    """Builds the published :class:`OdometryResult` of a frame.

    The ``odom`` frame is the base frame at the first frame and the internal world frame the colour optical
    frame of the first frame, so ``T_odom_world = T_base_rgb``.

    Args:
        config: the odometry's configuration (``tracker.degraded_covariance_scale``).
        T_base_rgb: the colour optical frame in the base frame.
        T_rgb_base: its inverse.
    """

    def __init__(self, config: AtsvoConfig, T_base_rgb: np.ndarray, T_rgb_base: np.ndarray) -> None:
        self.config = config
        self.T_base_rgb = T_base_rgb
        self.T_rgb_base = T_rgb_base

    def __call__(self, stamp: int, T_c_w: np.ndarray, out: TrackingOutcome | None, status: TrackingStatus, *,
                 t_track: float, kf: bool, fused: bool, n_points: int, dropped: int, event_map_time_s: float,
                 reason: str | None) -> OdometryResult:
        """The result of a frame at the published ``stamp`` and pose ``T_c_w``.

        Args:
            stamp: the published stamp (ns).
            T_c_w: the colour camera's published pose in the internal world frame.
            out: the tracking outcome the pose comes from (None when no measurement made it: its covariance is
                then large).
            status: the frame's status.
            t_track: tracking time (s).
            kf: whether a keyframe was inserted.
            fused: whether the event term took part.
            n_points: points of the map tracked against.
            dropped: events dropped since the previous result.
            event_map_time_s: build time of the temporary event map used (0 without one).
            reason: why the frame was not ``ok`` (None when it was).
        """
        T_w_c = se3_inv(T_c_w)
        T_odom_cam = self.T_base_rgb @ T_w_c
        T_odom_base = T_odom_cam @ self.T_rgb_base
        res = out.result if out is not None else None
        if res is None:
            cov = np.eye(6) * 1e3  # no measurement: a large, honest uncertainty
        else:
            A = se3_adjoint(self.T_base_rgb)
            cov = A @ res.covariance @ A.T
            if status is TrackingStatus.DEGRADED and out.verdict.level != OK:  # doubted, not merely one-eyed
                cov = cov * self.config.tracker.degraded_covariance_scale
        inliers = {k: v.n_inliers for k, v in res.blocks.items()} if res is not None else {}
        return OdometryResult(stamp, T_odom_base, T_odom_cam, cov, status, "fused" if fused else "rgbd",
                              float(t_track), int(n_points),
                              int(inliers.get("rgb", 0)), bool(kf), reason, inliers, int(dropped),
                              float(event_map_time_s))


__all__ = ["ResultBuilder"]
