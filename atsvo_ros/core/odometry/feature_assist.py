"""The odometry's use of feature matches (:mod:`~atsvo_ros.core.tracking.features`): a rescue and a check.

Kept apart from direct tracking on purpose: features are computed only for a frame whose direct pose
is in doubt (the checks rejected it, it turned more than ``tracker.feature_check_deg`` since the
previous frame, or its camera centre left the constant-velocity prediction by ``tracker.feature_check_m``),
and for the previous frame once; a slow sequence never pays for them.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import camera_centre, rotation_angle_rad, se3_inv
from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.tracking.features import FeatureMatcher, FrameFeatures


def rotation_between_deg(T_a: np.ndarray, T_b: np.ndarray) -> float:
    """Angle (deg) of the rotation between two poses ``T_c_w``."""
    return float(np.degrees(rotation_angle_rad(T_a[:3, :3] @ T_b[:3, :3].T)))


class FeatureAssist:
    """The previous trusted frame and, on demand, the feature-based pose of the current one."""

    def __init__(self, config: AtsvoConfig, cameras: list[CameraModel],
                 at_colour_time: Callable[[PreparedFrame], PreparedFrame]) -> None:
        cfg = config.tracker
        # a frame's depth moved to its colour's time (RgbdFrontEnd.at_colour_time), needed only when it is described
        self.at_colour_time = at_colour_time
        self.enabled = cfg.feature_check_deg > 0
        self.check_deg = cfg.feature_check_deg
        self.check_m = cfg.feature_check_m
        self.level = min(cfg.feature_level, len(cameras) - 1)
        self.matcher = FeatureMatcher(cameras[self.level], cfg.feature_points) if self.enabled else None
        self._prev: tuple[PreparedFrame, np.ndarray] | None = None
        self._prev_features: FrameFeatures | None = None
        self._cur: tuple[int, FrameFeatures] | None = None  # the current frame's features once computed
        #: frames whose features were computed (for the benchmark's cost accounting)
        self.n_described = 0

    def _features(self, frame: PreparedFrame) -> FrameFeatures:
        self.n_described += 1
        frame = self.at_colour_time(frame)
        if self.level == 0:
            return self.matcher.describe(frame.grey, frame.depth_m)
        return self.matcher.describe(frame.pyramid[self.level][..., 0], frame.depth_pyramid[self.level])

    def guesses(self, frame: PreparedFrame, centre_w: np.ndarray) -> list[np.ndarray]:
        """Starting points for ``frame`` from matches to the previous trusted frame: the PnP pose, and its
        rotation at the camera centre ``centre_w`` (the motion's prediction). Empty when off, without a previous
        frame or with too few matches.

        Both, because PnP on a fast turn gets the rotation right to about half a degree but the translation
        (millimetres to centimetres between frames) often wrong by as much again: tracking from the PnP pose
        alone slid 15 cm on TUM fr1_rpy every 4th frame; from the rotation alone it lost frames that the PnP
        pose held. The tracker keeps the one whose optimum fits the data better."""
        if not self.enabled or self._prev is None:
            return []
        prev_frame, T_prev_w = self._prev
        if self._prev_features is None:
            self._prev_features = self._features(prev_frame)
        if self._cur is None or self._cur[0] != frame.stamp_ns:
            self._cur = (frame.stamp_ns, self._features(frame))
        rel = self.matcher.relative_pose(self._prev_features, self._cur[1])
        if rel is None:
            return []
        T = rel.T_cur_prev @ T_prev_w
        T_rot = T.copy()
        T_rot[:3, 3] = -T[:3, :3] @ np.asarray(centre_w, np.float64)
        return [T, T_rot]

    def wants_check(self, T_c_w: np.ndarray, T_last_w: np.ndarray, T_pred_w: np.ndarray | None = None) -> bool:
        """Whether a pose is checked against the features: it turned more than ``tracker.feature_check_deg`` since
        ``T_last_w``, or its camera centre is more than ``tracker.feature_check_m`` from the prediction ``T_pred_w``."""
        if not self.enabled or self._prev is None:
            return False
        if rotation_between_deg(T_c_w, T_last_w) > self.check_deg:
            return True
        return (T_pred_w is not None and self.check_m > 0
                and float(np.linalg.norm(camera_centre(T_c_w) - camera_centre(T_pred_w))) > self.check_m)

    def end_frame(self, frame: PreparedFrame, T_c_w: np.ndarray, trusted: bool) -> None:
        """The frame is done: later frames match against it when its pose is trusted (else against the last
        trusted frame before it)."""
        if not self.enabled:
            return
        if trusted:
            feats = self._cur[1] if self._cur is not None and self._cur[0] == frame.stamp_ns else None
            self._prev, self._prev_features = (frame, np.asarray(T_c_w, np.float64).copy()), feats
        self._cur = None

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """Re-express the previous trusted frame's pose in a moved world (mapping moved the map under it)."""
        if self._prev is not None:
            self._prev = (self._prev[0], self._prev[1] @ se3_inv(T_wnew_wold))

    def forget(self) -> None:
        """A new map: poses before it are not comparable."""
        self._prev, self._prev_features, self._cur = None, None, None


__all__ = ["FeatureAssist", "rotation_between_deg"]
