"""The map: keyframes, photometric map points with per-level patches, geometric points, snapshots.

A photometric map point is a selected pixel of a keyframe back-projected with the aligned depth; it
stores the intensities of the residual pattern around it on every pyramid level of its host keyframe
(Section II-C), divided into a common brightness scale with the keyframe's affine parameters so
points of different keyframes are comparable. A geometric point is a pixel of smooth valid depth
(for the point-to-plane term). Tracking never sees the mutable store: it reads a
:class:`MapSnapshot`, an immutable copy that mapping replaces after each keyframe (DSO's coarse
tracking reference), so tracking and mapping can run in one thread or in two.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.config import RigConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_inv, transform_points
from atsvo_ros.errors import TrackingError


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: its pose (``T_w_c``, colour camera) and the brightness parameters of its patches."""

    kf_id: int
    stamp_ns: int
    T_w_c: np.ndarray
    affine: tuple[float, float]


def valid_depth_mask(depth_m: np.ndarray, rig: RigConfig, edge_ratio: float | None = None,
                     window_px: int = 3) -> np.ndarray:
    """True where depth is finite, inside the rig's range and (optionally) not on a depth edge.

    A depth edge is a pixel whose ``window_px`` square neighbourhood spans more than
    ``edge_ratio`` of its depth: there the colour and depth images disagree most and the
    back-projected point is unreliable. Pixels next to invalid depth (hole borders, usually
    occlusion shadows) count as edges.
    """

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

    if window_px <= 1:
        return np.where(valid, depth_m, 0.0).astype(np.float32)
    k = (int(window_px), int(window_px))
    num = cv2.blur(np.where(valid, depth_m, 0.0).astype(np.float32), k, borderType=cv2.BORDER_CONSTANT)
    den = cv2.blur(valid.astype(np.float32), k, borderType=cv2.BORDER_CONSTANT)
    return np.where(den > 0, num / np.maximum(den, 1e-6), 0.0).astype(np.float32)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class MapSnapshot:
    """What tracking reads: an immutable copy of the local map, replaced (never edited) by mapping.

    ``snapshot_id`` increases with every replacement, so observations made against one snapshot
    (per-point outlier runs) are matched to it. ``n_reference`` / ``healthy_reference`` are the
    tracked points and healthy regions right after the last keyframe: the nine-region rule of
    :mod:`atsvo_ros.core.mapping.keyframes` compares the current frame with them.
    """

    snapshot_id: int
    points_w: np.ndarray  # (N, 3) photometric points
    patches: np.ndarray  # (L, N, P) float32
    host_depth: np.ndarray  # (N,) depth in the host keyframe
    host: np.ndarray  # (N,) host keyframe id
    geo_points_w: np.ndarray  # (M, 3) geometric points
    keyframes: tuple[Keyframe, ...]
    n_reference: int
    healthy_reference: int

    def __post_init__(self) -> None:
        for name in ("points_w", "patches", "host_depth", "host", "geo_points_w"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    @classmethod
    def empty(cls, n_levels: int, pattern_size: int, snapshot_id: int = 0) -> MapSnapshot:
        return cls(snapshot_id, np.zeros((0, 3)), np.zeros((n_levels, 0, pattern_size), np.float32), np.zeros(0),
                   np.zeros(0, np.int32), np.zeros((0, 3)), (), 1, 9)

    def __len__(self) -> int:
        return len(self.points_w)

    @property
    def last_keyframe(self) -> Keyframe | None:
        return self.keyframes[-1] if self.keyframes else None


@dataclass(frozen=True)
class _Retired:
    """A keyframe out of the local map, kept with its points so that a camera back over its ground can use it."""

    keyframe: Keyframe
    points_w: np.ndarray
    patches: np.ndarray
    host_depth: np.ndarray
    geo_points_w: np.ndarray


class PointMap:
    """The mutable store behind the snapshots (struct of arrays), owned by the mapper."""

    def __init__(self, n_levels: int, pattern_size: int) -> None:
        self.n_levels = int(n_levels)
        self.pattern_size = int(pattern_size)
        self.keyframes: dict[int, Keyframe] = {}
        self._next_kf = 0
        self.points_w = np.zeros((0, 3))
        self.patches = np.zeros((self.n_levels, 0, self.pattern_size), dtype=np.float32)
        self.host = np.zeros(0, dtype=np.int32)
        self.host_depth = np.zeros(0)
        self.geo_points_w = np.zeros((0, 3))
        self.geo_host = np.zeros(0, dtype=np.int32)
        #: keyframes culled from the local map with their points, newest last (see :meth:`cull`, :meth:`restore`)
        self.retired: dict[int, _Retired] = {}

    def __len__(self) -> int:
        return len(self.points_w)

    def add_keyframe(self, stamp_ns: int, T_w_c: np.ndarray, affine: tuple[float, float],
                     points_c: np.ndarray, patches: np.ndarray, geo_points_c: np.ndarray | None = None) -> Keyframe:
        """Insert a keyframe, its photometric points (camera frame, patches ``(L, N, P)``) and geometric points."""
        points_c = np.asarray(points_c, dtype=np.float64).reshape(-1, 3)
        geo = np.zeros((0, 3)) if geo_points_c is None else np.asarray(geo_points_c, dtype=np.float64).reshape(-1, 3)
        patches = np.asarray(patches, dtype=np.float32)
        if patches.shape != (self.n_levels, len(points_c), self.pattern_size):
            raise TrackingError(f"patches shape {patches.shape} does not match "
                                f"({self.n_levels}, {len(points_c)}, {self.pattern_size})")
        for name, p in (("map points", points_c), ("geometric points", geo)):
            if not np.all(np.isfinite(p)) or (len(p) and p[:, 2].min() <= 0):
                raise TrackingError(f"{name} need finite positions in front of the camera")
        kf = Keyframe(self._next_kf, int(stamp_ns), np.asarray(T_w_c, dtype=np.float64).copy(),
                      (float(affine[0]), float(affine[1])))
        self._next_kf += 1
        self.keyframes[kf.kf_id] = kf
        self.points_w = np.concatenate([self.points_w, transform_points(kf.T_w_c, points_c)])
        self.patches = np.ascontiguousarray(np.concatenate([self.patches, patches], axis=1))
        self.host = np.concatenate([self.host, np.full(len(points_c), kf.kf_id, dtype=np.int32)])
        self.host_depth = np.concatenate([self.host_depth, points_c[:, 2]])
        self.geo_points_w = np.concatenate([self.geo_points_w, transform_points(kf.T_w_c, geo)])
        self.geo_host = np.concatenate([self.geo_host, np.full(len(geo), kf.kf_id, dtype=np.int32)])
        return kf

    def move_keyframe(self, kf_id: int, T_w_c: np.ndarray) -> None:
        """Put keyframe ``kf_id`` at ``T_w_c``; the points it hosts move with it (they keep their host-frame
        coordinates)."""
        kf = self.keyframes[kf_id]
        T_new = np.asarray(T_w_c, dtype=np.float64).copy()
        D = T_new @ se3_inv(kf.T_w_c)
        for points, host in ((self.points_w, self.host), (self.geo_points_w, self.geo_host)):
            mine = host == kf_id
            points[mine] = transform_points(D, points[mine])
        self.keyframes[kf_id] = dataclasses.replace(kf, T_w_c=T_new)

    def remove_points(self, remove: np.ndarray) -> int:
        """Drop photometric points where ``remove`` is True; returns how many were dropped."""
        keep = ~np.asarray(remove, dtype=bool)
        n = int((~keep).sum())
        if n:
            self.points_w = self.points_w[keep]
            self.patches = np.ascontiguousarray(self.patches[:, keep])
            self.host = self.host[keep]
            self.host_depth = self.host_depth[keep]
        return n

    def cull(self, max_keyframes: int, max_points: int, order: list[int] | None = None, memory: int = 0) -> int:
        """Bound the map: keyframes beyond the window (with their points), then excess points.

        ``order`` ranks the keyframe ids from first to drop to last (default: oldest first); the excess
        points go in the same order, their host's oldest first. With ``memory`` > 0 the dropped keyframes are
        retired with their points (the newest ``memory`` kept) instead of deleted.
        """
        order = sorted(self.keyframes) if order is None else [k for k in order if k in self.keyframes]
        removed = 0
        while len(self.keyframes) > max_keyframes and order:
            drop = order.pop(0)
            mine, mine_geo = self.host == drop, self.geo_host == drop
            if memory > 0:
                self.retired[drop] = _Retired(self.keyframes[drop], self.points_w[mine], self.patches[:, mine],
                                              self.host_depth[mine], self.geo_points_w[mine_geo])
            removed += self.remove_points(mine)
            self.geo_points_w, self.geo_host = self.geo_points_w[~mine_geo], self.geo_host[~mine_geo]
            del self.keyframes[drop]
        for k in sorted(self.retired)[:max(0, len(self.retired) - memory)]:
            del self.retired[k]
        excess = len(self) - max_points
        if excess > 0:  # within a host, points are in insertion order
            rank = np.full(max(self.keyframes, default=0) + 1, len(order), dtype=np.int64)
            rank[np.asarray(order, dtype=np.int64)] = np.arange(len(order))
            mask = np.zeros(len(self), dtype=bool)
            mask[np.argsort(rank[self.host], kind="stable")[:excess]] = True
            removed += self.remove_points(mask)
        return removed

    def restore(self, kf_id: int) -> None:
        """Bring retired keyframe ``kf_id`` and its points back into the local map."""
        r = self.retired.pop(kf_id)
        self.keyframes[kf_id] = r.keyframe
        self.points_w = np.concatenate([self.points_w, r.points_w])
        self.patches = np.ascontiguousarray(np.concatenate([self.patches, r.patches], axis=1))
        self.host = np.concatenate([self.host, np.full(len(r.points_w), kf_id, dtype=np.int32)])
        self.host_depth = np.concatenate([self.host_depth, r.host_depth])
        self.geo_points_w = np.concatenate([self.geo_points_w, r.geo_points_w])
        self.geo_host = np.concatenate([self.geo_host, np.full(len(r.geo_points_w), kf_id, dtype=np.int32)])

    def visible_shares(self, T_c_w: np.ndarray, camera: CameraModel, max_scale_change: float) -> dict[int, float]:
        """Per keyframe, in the map or retired: the share of its points a camera at ``T_c_w`` sees in front of it,
        inside its image and at a distance within ``max_scale_change`` times the host's (a patch seen much nearer
        or further no longer matches). Photometric points; a keyframe hosting none is judged by its depth points."""
        c_new = -T_c_w[:3, :3].T @ T_c_w[:3, 3]
        groups = [(k, self.points_w[self.host == k], self.geo_points_w[self.geo_host == k], self.keyframes[k])
                  for k in self.keyframes]
        groups += [(k, r.points_w, r.geo_points_w, r.keyframe) for k, r in self.retired.items()]
        shares = {}
        for k, points, geo, kf in groups:
            p = points if len(points) else geo
            if not len(p):
                shares[k] = 0.0
                continue
            uv, front = camera.project(transform_points(T_c_w, p))
            ratio = np.linalg.norm(p - c_new, axis=1) / np.maximum(np.linalg.norm(p - kf.T_w_c[:3, 3], axis=1), 1e-9)
            seen = front & camera.in_image(uv) & (ratio < max_scale_change) & (ratio > 1.0 / max_scale_change)
            shares[k] = float(seen.mean())
        return shares

    def snapshot(self, snapshot_id: int, n_reference: int, healthy_reference: int) -> MapSnapshot:
        """An immutable copy for tracking."""
        kfs = tuple(self.keyframes[k] for k in sorted(self.keyframes))
        return MapSnapshot(snapshot_id, self.points_w.copy(), self.patches.copy(), self.host_depth.copy(),
                           self.host.copy(), self.geo_points_w.copy(), kfs, int(n_reference), int(healthy_reference))


__all__ = ["Keyframe", "MapSnapshot", "PointMap", "smoothed_depth",
           "valid_depth_mask"]
