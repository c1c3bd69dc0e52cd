"""A second opinion on a fast frame: ORB matches to the previous frame and PnP-RANSAC on its depth.

Direct alignment converges from within a few degrees of the answer; at 3-20 deg between frames (a
bound's push-off, fr1_rpy with dropped frames) it can settle in a wrong optimum that still looks
healthy. Features matched by descriptor do not need a starting point: ORB keypoints of the previous
frame, lifted to 3D with its depth, matched to this frame's and fitted by PnP-RANSAC give the motion
between the two frames to about half a degree (measured on TUM fr1_rpy every 5th frame, 4-20 deg
between frames: median 0.55 deg, 90 % under 1.6 deg). The odometry uses it only where direct
tracking is in doubt: as a starting point when the checks reject the direct pose, and as a check on
frames that turned more than ``tracker.feature_check_deg``.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel


@dataclass(frozen=True)
class FrameFeatures:
    """ORB keypoints of one frame: pixel positions, descriptors, and camera-frame points where depth is valid."""

    uv: np.ndarray  # (N, 2) float32 pixels on the pinhole grid
    descriptors: np.ndarray  # (N, 32) uint8
    points_c: np.ndarray  # (N, 3) float64, NaN where the depth is invalid

    def __len__(self) -> int:
        return len(self.uv)


@dataclass(frozen=True)
class RelativePose:
    """``T_cur_prev`` (points of the previous camera into this one) supported by ``n_inliers`` matches."""

    T_cur_prev: np.ndarray
    n_inliers: int
    n_matches: int


class FeatureMatcher:
    """ORB detection, brute-force Hamming matching with cross-check, and PnP-RANSAC (OpenCV).

    Args:
        camera: the pinhole camera the images are rectified to.
        n_features: ORB keypoints per frame.
        reprojection_px: RANSAC inlier threshold.
        min_inliers: fewer inliers than this and no pose is returned.
    """

    def __init__(self, camera: CameraModel, n_features: int = 1000, reprojection_px: float = 3.0,
                 min_inliers: int = 30) -> None:
        self.K = np.asarray(camera.K, np.float64)
        self.reprojection_px = float(reprojection_px)
        self.min_inliers = int(min_inliers)
        self._orb = cv2.ORB_create(nfeatures=int(n_features), fastThreshold=10)
        self._matcher = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)

    def describe(self, grey: np.ndarray, depth_m: np.ndarray) -> FrameFeatures:
        """ORB features of a grey image (float [0, 255] or uint8) with the depth of the same grid."""
        img = grey if grey.dtype == np.uint8 else np.clip(np.round(grey), 0, 255).astype(np.uint8)
        kps, des = self._orb.detectAndCompute(img, None)
        if des is None or not kps:
            return FrameFeatures(np.zeros((0, 2), np.float32), np.zeros((0, 32), np.uint8), np.zeros((0, 3)))
        uv = np.array([k.pt for k in kps], np.float32)
        h, w = depth_m.shape
        col = np.clip(np.round(uv[:, 0]).astype(np.int64), 0, w - 1)
        row = np.clip(np.round(uv[:, 1]).astype(np.int64), 0, h - 1)
        z = depth_m[row, col].astype(np.float64)
        z = np.where(np.isfinite(z) & (z > 0), z, np.nan)
        K = self.K
        pts = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * z, (uv[:, 1] - K[1, 2]) / K[1, 1] * z, z], axis=1)
        return FrameFeatures(uv, des, pts)

    def relative_pose(self, prev: FrameFeatures, cur: FrameFeatures) -> RelativePose | None:
        """The motion from ``prev`` to ``cur`` (3D points of ``prev``, pixels of ``cur``), or None when it is not
        supported by ``min_inliers`` RANSAC inliers."""
        if len(prev) < self.min_inliers or len(cur) < self.min_inliers:
            return None
        matches = self._matcher.match(prev.descriptors, cur.descriptors)
        if len(matches) < self.min_inliers:
            return None
        qi = np.array([m.queryIdx for m in matches])
        ti = np.array([m.trainIdx for m in matches])
        X = prev.points_c[qi]
        has_depth = np.isfinite(X[:, 2])
        if has_depth.sum() < self.min_inliers:
            return None
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            X[has_depth], cur.uv[ti[has_depth]].astype(np.float64), self.K, None, iterationsCount=100,
            reprojectionError=self.reprojection_px, confidence=0.99, flags=cv2.SOLVEPNP_EPNP)
        n_inl = 0 if inliers is None else len(inliers)
        if not ok or n_inl < self.min_inliers or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
            return None
        # EPnP on RANSAC's minimal sets is coarse (1.1 deg off on a rendered 12 deg turn); Levenberg-Marquardt on
        # all inliers' reprojection errors takes it to a tenth of that
        idx = inliers.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(X[has_depth][idx], cur.uv[ti[has_depth]][idx].astype(np.float64), self.K,
                                          None, rvec, tvec)
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rvec)[0]
        T[:3, 3] = np.asarray(tvec, np.float64).ravel()
        return RelativePose(T, n_inl, int(has_depth.sum()))


__all__ = ["FeatureMatcher", "FrameFeatures", "RelativePose"]
