"""The geometric residual block: map points against the current depth image (point-to-plane).

Photometric alignment converges only within a few pixels of the answer and fails under heavy
motion blur; real cameras turning 2-5 deg per frame (the rates of a trotting or bounding robot, or
a hand-held Kinect in TUM fr1_rpy) leave it outside that basin. The depth image is smooth over
most of the scene and unaffected by blur, so projective point-to-plane ICP on it (KinectFusion,
Open3D's point-to-plane RGB-D odometry) has a much wider basin; as a second block of Eq. 4 it
pulls the estimate into the photometric basin and constrains what texture does not.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.core.tracking.residuals import NO_MOTION, BlockSystem
from atsvo_ros.core.tracking.residuals import _geometric_kernels as kern
from atsvo_ros.errors import TrackingError


@dataclass
class GeometricBlock:
    """Point-to-plane residuals of world points against one camera's depth pyramid.

    Attributes:
        name: label for per-block results (``"depth"``).
        points_w: (N, 3) float64 world points (sampled on smooth depth at keyframes).
        depth: float32 depth per pyramid level of the current frame (0 = invalid).
        cameras: pinhole model per level, matching ``depth``.
        T_cam_rgb: 4x4 extrinsic from the RGB camera frame to the depth camera's frame.
        weight: block weight in Eq. 4 (residuals are already divided by the depth noise).
        sigma_at_1m_m, sigma_min_m: depth noise model ``max(sigma_min, sigma_at_1m z^2)``.
        huber, outlier: Huber threshold and outlier threshold in noise units.
        edge_ratio: relative depth jump that makes a pixel a depth edge (no normal there).
        coarse_points: on level ``l > 0`` use ``max(coarse_points, N / 4^l)`` points (strided).
        rolling_shutter: row timing of the depth image (None = global shutter).
    """

    name: str
    points_w: np.ndarray
    depth: list[np.ndarray]
    cameras: list[CameraModel]
    T_cam_rgb: np.ndarray = field(default_factory=lambda: np.eye(4))
    weight: float = 1.0
    sigma_at_1m_m: float = 0.003
    sigma_min_m: float = 0.002
    huber: float = 2.0
    outlier: float = 10.0
    edge_ratio: float = 0.05
    coarse_points: int = 0
    rolling_shutter: RollingShutter | None = None
    estimate_affine: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        self.points_w = np.ascontiguousarray(self.points_w, dtype=np.float64).reshape(-1, 3)
        self.T_cam_rgb = np.ascontiguousarray(self.T_cam_rgb, dtype=np.float64)
        if len(self.depth) > len(self.cameras):
            raise TrackingError(f"block {self.name}: {len(self.depth)} depth levels but {len(self.cameras)} cameras")
        self.depth = [np.ascontiguousarray(d, dtype=np.float32) for d in self.depth]
        self.state = np.zeros(len(self.points_w), dtype=np.int8)
        self._subsets: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def n_levels(self) -> int:
        return len(self.depth)

    @property
    def residuals_per_point(self) -> int:
        return 1

    def __len__(self) -> int:
        return len(self.points_w)

    def _level_points(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        n = len(self.points_w)
        keep = n if level == 0 or self.coarse_points <= 0 else max(self.coarse_points, n >> (2 * level))
        if keep >= n:
            return self.points_w, self.state
        if level not in self._subsets:
            idx = np.floor(np.arange(keep) * (n / keep)).astype(np.int64)
            self._subsets[level] = (np.ascontiguousarray(self.points_w[idx]), np.zeros(keep, np.int8))
        return self._subsets[level]

    def linearise(self, level: int, T_rgb_w: np.ndarray, affine: tuple[float, float],
                  relax: float = 1.0) -> BlockSystem:
        """Normal equations in the RGB pose at ``level`` (``affine`` is unused: depth has no brightness)."""
        del affine
        cam = self.cameras[level]
        pts, state = self._level_points(level)
        H = np.zeros((6, 6))
        g = np.zeros(6)
        T_rgb_w = np.ascontiguousarray(T_rgb_w, dtype=np.float64)
        vel, t0, line = (NO_MOTION, 0.0, 0.0) if self.rolling_shutter is None else \
            self.rolling_shutter.params(level, T_rgb_w)
        e, n_in, n_vis, sse = kern._linearise_geometric(
            pts, self.depth[level], cam.fx, cam.fy, cam.cx, cam.cy, T_rgb_w, self.T_cam_rgb, float(self.sigma_at_1m_m),
            float(self.sigma_min_m), float(self.huber), float(self.outlier * relax), float(self.edge_ratio), vel,
            float(t0), float(line), H, g, state)
        return BlockSystem(H * self.weight, g * self.weight, float(e) * self.weight, int(n_in), int(n_vis),
                           int(n_in), float(sse))


__all__ = ["GeometricBlock"]
