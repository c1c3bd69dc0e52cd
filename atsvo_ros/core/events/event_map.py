"""The temporary event map N of Eq. 4: selected ATS pixels of one frame, with depth, as map points.

When fast motion starts, the pixels selected on the previous frame's ATS (Section II-B) become map
points: their depth comes from that frame's colour-aligned depth image reprojected into the event
camera through ``T_rgb_event`` (z-buffered: where several depth pixels land on one event pixel the
nearest surface wins, as it occludes the others), and each keeps its 14-pixel ATS pattern on every
pyramid level. The map is rebuilt from scratch every time, never grown.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.frontend import EventFrame
from atsvo_ros.core.geometry import se3_inv, transform_points
from atsvo_ros.core.image.photometric import ATS_PATTERN, extract_patches


@dataclass
class TemporaryEventMap:
    """The event-based temporary map N of Eq. 4 (built by the fusion issue when fast motion starts).

    Same content as the RGB map (world points, per-level patches) but with ATS intensities and its
    own pattern; it is replaced wholesale, never grown. ``build_time_s``: what building it took
    (selection, z-buffered depth, patches), wherever mapping ran it.
    """

    points_w: np.ndarray
    patches: np.ndarray
    stamp_ns: int
    T_w_c: np.ndarray
    build_time_s: float = 0.0

    @classmethod
    def empty(cls, n_levels: int, pattern_size: int) -> TemporaryEventMap:
        return cls(np.zeros((0, 3)), np.zeros((n_levels, 0, pattern_size), np.float32), 0, np.eye(4))

    def __len__(self) -> int:
        return len(self.points_w)


@njit(cache=True, nogil=True, error_model="numpy")
def _zbuffer(depth, fx, fy, cx, cy, T, efx, efy, ecx, ecy, out):  # pragma: no cover - compiled
    """Scatter every valid depth pixel into ``out`` (event camera, +inf = none yet), keeping the smallest z.

    Per pixel the ray ``T_rot @ ((u - cx) / fx, (v - cy) / fy, 1)`` is a row term plus a column term,
    so a point costs three multiply-adds and one division.
    """
    h, w = depth.shape
    eh, ew = out.shape
    col = np.empty((3, w))
    for u in range(w):
        xn = (u - cx) / fx
        col[0, u] = T[0, 0] * xn
        col[1, u] = T[1, 0] * xn
        col[2, u] = T[2, 0] * xn
    for v in range(h):
        yn = (v - cy) / fy
        r0 = T[0, 1] * yn + T[0, 2]
        r1 = T[1, 1] * yn + T[1, 2]
        r2 = T[2, 1] * yn + T[2, 2]
        for u in range(w):
            z = depth[v, u]
            if not z > 0.0:  # also NaN
                continue
            qz = (col[2, u] + r2) * z + T[2, 3]
            if qz <= 1e-3:
                continue
            inv = 1.0 / qz
            fu = efx * ((col[0, u] + r0) * z + T[0, 3]) * inv + ecx + 0.5
            fv = efy * ((col[1, u] + r1) * z + T[1, 3]) * inv + ecy + 0.5
            if fu < 0.0 or fv < 0.0 or fu >= ew or fv >= eh:
                continue
            iu = int(fu)
            iv = int(fv)
            out[iv, iu] = min(out[iv, iu], np.float32(qz))  # branch-free: neighbours often hit one pixel


def depth_in_camera(depth_m: np.ndarray, rgb_camera: CameraModel, camera: CameraModel,
                    T_cam_rgb: np.ndarray) -> np.ndarray:
    """Depth (z in ``camera``, float32, 0 = none) of a depth image on ``rgb_camera``'s pinhole grid, z-buffered.

    Pixels without depth (0, negative or NaN) are skipped.
    """
    d = np.ascontiguousarray(depth_m, dtype=np.float32)
    out = np.full((camera.height, camera.width), np.inf, np.float32)
    _zbuffer(d, rgb_camera.fx, rgb_camera.fy, rgb_camera.cx, rgb_camera.cy,
             np.ascontiguousarray(T_cam_rgb, dtype=np.float64), camera.fx, camera.fy, camera.cx, camera.cy, out)
    out[np.isinf(out)] = 0.0
    return out


def build_event_map(frame: EventFrame, depth_m: np.ndarray, rgb_camera: CameraModel, event_camera: CameraModel,
                    T_w_rgb: np.ndarray, T_rgb_event: np.ndarray,
                    T_depth_rgb: np.ndarray | None = None) -> TemporaryEventMap:
    """The temporary event map of ``frame`` (selected pixels with depth), in the world frame.

    ``depth_m`` is the colour-aligned depth of the same frame on ``rgb_camera``'s pinhole grid, ``T_w_rgb``
    the colour camera's pose of that frame; both cameras are the pinhole (rectified) models. A depth exposed
    at another time (``T_depth_rgb``: that camera relative to the colour's) goes into the event camera in the
    same one warp.
    """
    uv = np.asarray(frame.selected, dtype=np.int64).reshape(-1, 2)
    n_levels = len(frame.pyramid)
    if len(uv) == 0:
        return TemporaryEventMap.empty(n_levels, len(ATS_PATTERN))
    T_event_depth = se3_inv(T_rgb_event) if T_depth_rgb is None else se3_inv(T_depth_rgb @ T_rgb_event)
    zmap = depth_in_camera(depth_m, rgb_camera, event_camera, T_event_depth)
    z = zmap[uv[:, 1], uv[:, 0]]
    ok = z > 0
    uv, z = uv[ok], z[ok].astype(np.float64)
    p_e = event_camera.backproject(uv.astype(np.float64), z)
    p_w = transform_points(np.asarray(T_w_rgb) @ np.asarray(T_rgb_event), p_e)
    patches = extract_patches(frame.pyramid, uv, ATS_PATTERN)
    return TemporaryEventMap(p_w, patches, frame.stamp_ns, np.asarray(T_w_rgb, dtype=np.float64).copy())


__all__ = ["TemporaryEventMap", "build_event_map", "depth_in_camera"]
