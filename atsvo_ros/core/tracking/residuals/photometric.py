"""The photometric residual block of Eq. 4: stored patches against the current image pyramid.

Each map point carries the intensities of a pattern around it on every pyramid level of its host
keyframe (``z_p`` of Eq. 4); the residual is the current image at the projected pattern minus those
values under a brightness model ``I' = e^a z + b`` (DSO). The RGB term (9-pixel pattern, colour
camera) and the ATS term of the fusion (14-pixel pattern, event camera, ``T_event_rgb``) are two
instances with their own camera, pattern, weight and robust parameters.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.core.tracking.residuals import NO_MOTION, BlockSystem
from atsvo_ros.core.tracking.residuals import _photometric_kernels as kern
from atsvo_ros.errors import TrackingError


@dataclass
class PhotometricBlock:
    """One photometric term of Eq. 4: map points observed in one camera's image pyramid.

    Attributes:
        name: label (``"rgb"``, ``"ats"``) used for per-block results.
        points_w: (N, 3) float64 map points in the world frame.
        patches: (L, N, P) float32 stored intensities per pyramid level (``z_p`` of Eq. 4).
        pattern: (P, 2) float32 pixel offsets of the residual pattern.
        pyramid: per level an (H, W, 3) float32 array ``[I, dI/dx, dI/dy]`` of the current image.
        cameras: pinhole model per level, matching ``pyramid``.
        T_cam_rgb: 4x4 extrinsic from the RGB camera frame to this block's camera frame.
        weight: omega of Eq. 4.
        sigma: residual noise scale (intensity): energies and normal equations are divided by
            ``sigma^2`` so blocks in other units (depth, another image) combine in one system.
        huber: Huber threshold on a pixel residual (intensity).
        outlier: RMS patch residual (intensity) above which a point is an outlier.
        gradient_weight: ``c`` of the pixel weight ``c^2 / (c^2 + |grad I|^2)`` (DSO), 0 = off.
        estimate_affine: whether the block has its own gain/offset parameters.
        border_px: projections closer than this to the image edge are not used (default: pattern
            radius + 1, the least that keeps bilinear reads inside the image).
        coarse_points: on level ``l > 0`` use an evenly strided subset of ``max(coarse_points, N / 4^l)``
            points (0 = all): coarse levels only need to bring the estimate into the basin of the
            next level, and their pixels are 4x fewer per level anyway.
        zero_mean: compare patches after removing their means (only the gain of the brightness
            model remains): robust to vignetting and uneven lighting.
        ref_depth: (N,) depth of each point in its host keyframe, for ``max_scale_change``.
        max_scale_change: skip points now nearer/farther than this factor times their host depth
            (their stored patch shows another scale); 0 = use every point.
        rolling_shutter: row timing of the current image (None = global shutter).
    """

    name: str
    points_w: np.ndarray
    patches: np.ndarray
    pattern: np.ndarray
    pyramid: list[np.ndarray]
    cameras: list[CameraModel]
    T_cam_rgb: np.ndarray = field(default_factory=lambda: np.eye(4))
    weight: float = 1.0
    sigma: float = 1.0
    huber: float = 9.0
    outlier: float = 20.0
    gradient_weight: float = 0.0
    estimate_affine: bool = True
    border_px: float | None = None
    coarse_points: int = 0
    zero_mean: bool = False
    ref_depth: np.ndarray | None = None
    max_scale_change: float = 0.0
    rolling_shutter: RollingShutter | None = None

    def __post_init__(self) -> None:
        self.points_w = np.ascontiguousarray(self.points_w, dtype=np.float64).reshape(-1, 3)
        self.patches = np.asarray(self.patches, dtype=np.float32)
        self.pattern = np.ascontiguousarray(self.pattern, dtype=np.float64)
        self.T_cam_rgb = np.ascontiguousarray(self.T_cam_rgb, dtype=np.float64)
        n = len(self.points_w)
        if self.patches.ndim != 3 or self.patches.shape[1] != n or self.patches.shape[2] != len(self.pattern):
            raise TrackingError(f"block {self.name}: patches shape {self.patches.shape} does not match "
                                f"{n} points x {len(self.pattern)} pattern pixels")
        if len(self.pyramid) != len(self.cameras):
            raise TrackingError(f"block {self.name}: {len(self.pyramid)} pyramid levels but "
                                f"{len(self.cameras)} cameras")
        self.ref_depth = (np.zeros(n) if self.ref_depth is None
                          else np.ascontiguousarray(self.ref_depth, dtype=np.float64).reshape(-1))
        if len(self.ref_depth) != n:
            raise TrackingError(f"block {self.name}: {len(self.ref_depth)} reference depths for {n} points")
        if self.border_px is None:  # the pattern plus the bilinear neighbour must stay inside
            self.border_px = float(np.abs(self.pattern).max(initial=0.0)) + 1.0
        self.state = np.zeros(n, dtype=np.int8)
        #: per point, ZNCC of stored and current patch after the last ``linearise`` at level 0 (NaN = not visible)
        self.zncc = np.full(n, np.nan)
        self._subsets: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self.points_w)

    @property
    def n_levels(self) -> int:
        return min(len(self.pyramid), self.patches.shape[0])

    def _level_data(self, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Points, patches, reference depths and state array used on ``level`` (strided subset on coarse levels)."""
        n = len(self.points_w)
        keep = n if level == 0 or self.coarse_points <= 0 else max(self.coarse_points, n >> (2 * level))
        if keep >= n:
            patches = self.patches[level]
            if not patches.flags.c_contiguous:
                patches = np.ascontiguousarray(patches)
            return self.points_w, patches, self.ref_depth, self.state
        if level not in self._subsets:
            idx = np.floor(np.arange(keep) * (n / keep)).astype(np.int64)
            self._subsets[level] = (np.ascontiguousarray(self.points_w[idx]),
                                    np.ascontiguousarray(self.patches[level][idx]),
                                    np.ascontiguousarray(self.ref_depth[idx]), np.zeros(keep, np.int8))
        return self._subsets[level]

    def linearise(self, level: int, T_rgb_w: np.ndarray, affine: tuple[float, float],
                  relax: float = 1.0) -> BlockSystem:
        """Normal equations (8x8 over pose, log-gain, offset) at ``level``; ``relax`` scales the outlier threshold."""
        cam = self.cameras[level]
        H = np.zeros((8, 8))
        g = np.zeros(8)
        points, patches, zref, state = self._level_data(level)
        zncc = self.zncc if state is self.state else np.empty(len(state))
        T_rgb_w = np.ascontiguousarray(T_rgb_w, dtype=np.float64)
        vel, t0, line = (NO_MOTION, 0.0, 0.0) if self.rolling_shutter is None else \
            self.rolling_shutter.params(level, T_rgb_w)
        e, n_in, n_vis, sse = kern._linearise(
            points, patches, self.pyramid[level], self.pattern, cam.fx, cam.fy, cam.cx, cam.cy,
            T_rgb_w, self.T_cam_rgb, float(np.exp(affine[0])), float(affine[1]), float(self.huber),
            float(self.outlier * relax), float(self.border_px), float(self.gradient_weight) ** 2, bool(self.zero_mean),
            zref, float(self.max_scale_change), vel, float(t0), float(line), H, g, state, zncc, level == 0)
        s = self.weight / (self.sigma * self.sigma)
        return BlockSystem(H * s, g * s, float(e) * s, int(n_in), int(n_vis), int(n_in) * len(self.pattern),
                           float(sse) / (self.sigma * self.sigma))


__all__ = ["PhotometricBlock"]
