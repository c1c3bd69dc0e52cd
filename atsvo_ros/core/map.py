"""Map of the RGB-D odometry: keyframes, map points with per-level patches, the temporary event map.

A map point is a selected pixel of a keyframe back-projected with the aligned depth; it stores the
intensities of the residual pattern around it on every pyramid level of its host keyframe (Section
II-C), divided into a common brightness scale with the keyframe's affine parameters so points of
different keyframes are comparable. The local map is the points of the last ``max_keyframes``
keyframes; :meth:`PointMap.cull` keeps memory bounded on long runs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import MappingConfig, RigConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import transform_points
from atsvo_ros.core.photometric import level_position, sample_patches
from atsvo_ros.errors import TrackingError


@dataclass
class Keyframe:
    """A keyframe: its pose, brightness parameters and how many points it hosts."""

    kf_id: int
    stamp_ns: int
    T_w_c: np.ndarray
    affine: tuple[float, float]
    n_points: int = 0


def valid_depth_mask(depth_m: np.ndarray, rig: RigConfig, edge_ratio: float | None = None,
                     window_px: int = 3) -> np.ndarray:
    """True where depth is finite, inside the rig's range and (optionally) not on a depth edge.

    A depth edge is a pixel whose ``window_px`` square neighbourhood spans more than
    ``edge_ratio`` of its depth: there the colour and depth images disagree most and the
    back-projected point is unreliable. Pixels next to invalid depth (hole borders, usually
    occlusion shadows) count as edges.
    """
    import cv2

    d = np.asarray(depth_m, dtype=np.float32)
    ok = np.isfinite(d) & (d >= rig.depth_min_m) & (d <= rig.depth_max_m)
    if edge_ratio is not None:
        filled = np.where(ok, d, 0.0).astype(np.float32)
        kernel = np.ones((window_px, window_px), np.uint8)
        dmax = cv2.dilate(filled, kernel)
        dmin = cv2.erode(filled, kernel)  # an invalid neighbour (0) marks a hole border: rejected too
        ok &= (dmax - dmin) <= edge_ratio * np.where(ok, d, 0.0)
    return ok


def smoothed_depth(depth_m: np.ndarray, valid: np.ndarray, window_px: int) -> np.ndarray:
    """Mean of the valid depths in a ``window_px`` square around each pixel (float32, 0 where none).

    Away from depth edges (see :func:`valid_depth_mask`) surfaces are locally planar, so the mean
    keeps the depth of the centre pixel while dividing stereo noise (which grows with z^2 on a
    D455) by about ``window_px``.
    """
    import cv2

    if window_px <= 1:
        return np.where(valid, depth_m, 0.0).astype(np.float32)
    k = (int(window_px), int(window_px))
    num = cv2.blur(np.where(valid, depth_m, 0.0).astype(np.float32), k, borderType=cv2.BORDER_CONSTANT)
    den = cv2.blur(valid.astype(np.float32), k, borderType=cv2.BORDER_CONSTANT)
    return np.where(den > 0, num / np.maximum(den, 1e-6), 0.0).astype(np.float32)


def extract_patches(pyramid: list[np.ndarray], uv0: np.ndarray, pattern: np.ndarray,
                    affine: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Pattern intensities of level-0 pixels on every level, ``(L, N, P)`` float32.

    Positions are clamped into each level so a point near the border still gets a patch (the
    tracker never reads it there). Intensities are mapped to the reference brightness scale
    ``z = (I - b) / e^a`` with the host frame's ``affine = (a, b)``.
    """
    uv0 = np.asarray(uv0, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(pyramid), len(uv0), len(pattern)), dtype=np.float32)
    a, b = affine
    for lvl, img in enumerate(pyramid):
        img = img[..., 0] if img.ndim == 3 else img
        h, w = img.shape
        pos = level_position(uv0, lvl)[:, None, :] + np.asarray(pattern, dtype=np.float64)[None]
        pos[..., 0] = np.clip(pos[..., 0], 0, w - 1)
        pos[..., 1] = np.clip(pos[..., 1], 0, h - 1)
        vals, _ = sample_patches(img, pos.reshape(-1, 2), np.zeros((1, 2)))
        out[lvl] = ((vals.reshape(len(uv0), len(pattern)) - b) / np.exp(a)).astype(np.float32)
    return out


class PointMap:
    """Struct-of-arrays store of map points and the keyframes hosting them."""

    def __init__(self, n_levels: int, pattern_size: int) -> None:
        self.n_levels = int(n_levels)
        self.pattern_size = int(pattern_size)
        self.keyframes: dict[int, Keyframe] = {}
        self._next_kf = 0
        self.points_w = np.zeros((0, 3))
        self.patches = np.zeros((self.n_levels, 0, self.pattern_size), dtype=np.float32)
        self.host = np.zeros(0, dtype=np.int32)
        self.outlier_run = np.zeros(0, dtype=np.int32)
        self.host_depth = np.zeros(0)

    def __len__(self) -> int:
        return len(self.points_w)

    @property
    def last_keyframe(self) -> Keyframe | None:
        return self.keyframes[max(self.keyframes)] if self.keyframes else None

    def add_keyframe(self, stamp_ns: int, T_w_c: np.ndarray, affine: tuple[float, float],
                     points_c: np.ndarray, patches: np.ndarray) -> Keyframe:
        """Insert a keyframe and its new points (camera frame ``points_c``, patches ``(L, N, P)``)."""
        points_c = np.asarray(points_c, dtype=np.float64).reshape(-1, 3)
        patches = np.asarray(patches, dtype=np.float32)
        if patches.shape != (self.n_levels, len(points_c), self.pattern_size):
            raise TrackingError(f"patches shape {patches.shape} does not match "
                                f"({self.n_levels}, {len(points_c)}, {self.pattern_size})")
        if not np.all(np.isfinite(points_c)) or (len(points_c) and points_c[:, 2].min() <= 0):
            raise TrackingError("map points need finite positions in front of the camera")
        kf = Keyframe(self._next_kf, int(stamp_ns), np.asarray(T_w_c, dtype=np.float64).copy(),
                      (float(affine[0]), float(affine[1])), len(points_c))
        self._next_kf += 1
        self.keyframes[kf.kf_id] = kf
        self.points_w = np.concatenate([self.points_w, transform_points(kf.T_w_c, points_c)])
        self.patches = np.ascontiguousarray(np.concatenate([self.patches, patches], axis=1))
        self.host = np.concatenate([self.host, np.full(len(points_c), kf.kf_id, dtype=np.int32)])
        self.outlier_run = np.concatenate([self.outlier_run, np.zeros(len(points_c), dtype=np.int32)])
        self.host_depth = np.concatenate([self.host_depth, points_c[:, 2]])
        return kf

    def remove_points(self, remove: np.ndarray) -> int:
        """Drop points where ``remove`` is True; returns how many were dropped."""
        keep = ~np.asarray(remove, dtype=bool)
        n = int((~keep).sum())
        if n:
            self.points_w = self.points_w[keep]
            self.patches = np.ascontiguousarray(self.patches[:, keep])
            self.host = self.host[keep]
            self.outlier_run = self.outlier_run[keep]
            self.host_depth = self.host_depth[keep]
            for kf in self.keyframes.values():
                kf.n_points = int((self.host == kf.kf_id).sum())
        return n

    def update_observations(self, states: np.ndarray) -> None:
        """Count consecutive outlier frames per point (tracker states: 1 inlier, 2 outlier)."""
        states = np.asarray(states)
        if len(states) != len(self):
            raise TrackingError(f"{len(states)} point states for a map of {len(self)} points")
        self.outlier_run = np.where(states == 2, self.outlier_run + 1,
                                    np.where(states == 1, 0, self.outlier_run)).astype(np.int32)

    def cull(self, config: MappingConfig) -> int:
        """Bound the map: drop repeated outliers, keyframes beyond the window and the oldest excess points."""
        removed = self.remove_points(self.outlier_run >= config.max_outlier_frames)
        while len(self.keyframes) > config.max_keyframes:
            oldest = min(self.keyframes)
            removed += self.remove_points(self.host == oldest)
            del self.keyframes[oldest]
        excess = len(self) - config.max_points
        if excess > 0:  # hosts are in insertion order, so the first points are the oldest
            mask = np.zeros(len(self), dtype=bool)
            mask[np.argsort(self.host, kind="stable")[:excess]] = True
            removed += self.remove_points(mask)
        for kid in [k for k, kf in self.keyframes.items() if kf.n_points == 0 and k != max(self.keyframes)]:
            del self.keyframes[kid]
        return removed

    def project(self, T_c_w: np.ndarray, camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) of all points in a pinhole camera and a mask of points in front and inside."""
        p_c = transform_points(T_c_w, self.points_w)
        uv, front = camera.project(p_c)
        return uv, front & camera.in_image(uv)


@dataclass
class TemporaryEventMap:
    """The event-based temporary map N of Eq. 4 (built by the fusion issue when fast motion starts).

    Same content as the RGB map (world points, per-level patches) but with ATS intensities and its
    own pattern; it is replaced wholesale, never grown.
    """

    points_w: np.ndarray
    patches: np.ndarray
    stamp_ns: int
    T_w_c: np.ndarray

    @classmethod
    def empty(cls, n_levels: int, pattern_size: int) -> TemporaryEventMap:
        return cls(np.zeros((0, 3)), np.zeros((n_levels, 0, pattern_size), np.float32), 0, np.eye(4))

    def __len__(self) -> int:
        return len(self.points_w)


__all__ = ["Keyframe", "PointMap", "TemporaryEventMap", "extract_patches", "smoothed_depth", "valid_depth_mask"]
