"""The temporary event map N of Eq. 4: selected ATS pixels of one frame, with depth, as map points.

When fast motion starts, the pixels selected on the previous frame's ATS (Section II-B) become map
points: their depth comes from that frame's colour-aligned depth image reprojected into the event
camera through ``T_rgb_event`` (z-buffered: where several depth pixels land on one event pixel the
nearest surface wins, as it occludes the others), and each keeps its 14-pixel ATS pattern on every
pyramid level. The map is rebuilt from scratch every time, never grown.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.event_frontend import EventFrame
from atsvo_ros.core.geometry import transform_points
from atsvo_ros.core.map import TemporaryEventMap, extract_patches
from atsvo_ros.core.photometric import ATS_PATTERN


@njit(cache=True)
def _zbuffer(depth, fx, fy, cx, cy, T, efx, efy, ecx, ecy, out):  # pragma: no cover - compiled
    """Scatter every valid depth pixel into ``out`` (event camera), keeping the smallest z per pixel."""
    h, w = depth.shape
    eh, ew = out.shape
    for v in range(h):
        for u in range(w):
            z = depth[v, u]
            if not z > 0.0:
                continue
            x = (u - cx) / fx * z
            y = (v - cy) / fy * z
            qx = T[0, 0] * x + T[0, 1] * y + T[0, 2] * z + T[0, 3]
            qy = T[1, 0] * x + T[1, 1] * y + T[1, 2] * z + T[1, 3]
            qz = T[2, 0] * x + T[2, 1] * y + T[2, 2] * z + T[2, 3]
            if qz <= 1e-3:
                continue
            iu = int(efx * qx / qz + ecx + 0.5)
            iv = int(efy * qy / qz + ecy + 0.5)
            if iu < 0 or iv < 0 or iu >= ew or iv >= eh:
                continue
            cur = out[iv, iu]
            if cur == 0.0 or qz < cur:
                out[iv, iu] = qz


def depth_in_camera(depth_m: np.ndarray, rgb_camera: CameraModel, camera: CameraModel,
                    T_cam_rgb: np.ndarray) -> np.ndarray:
    """Depth (z in ``camera``, float32, 0 = none) of a depth image on ``rgb_camera``'s pinhole grid, z-buffered."""
    d = np.where(np.isfinite(depth_m), depth_m, 0.0).astype(np.float32)
    out = np.zeros((camera.height, camera.width), np.float32)
    _zbuffer(d, rgb_camera.fx, rgb_camera.fy, rgb_camera.cx, rgb_camera.cy,
             np.ascontiguousarray(T_cam_rgb, dtype=np.float64), camera.fx, camera.fy, camera.cx, camera.cy, out)
    return out


def build_event_map(frame: EventFrame, depth_m: np.ndarray, rgb_camera: CameraModel, event_camera: CameraModel,
                    T_w_rgb: np.ndarray, T_rgb_event: np.ndarray) -> TemporaryEventMap:
    """The temporary event map of ``frame`` (selected pixels with depth), in the world frame.

    ``depth_m`` is the colour-aligned depth of the same frame on ``rgb_camera``'s pinhole grid, ``T_w_rgb``
    the colour camera's pose of that frame; both cameras are the pinhole (rectified) models.
    """
    uv = np.asarray(frame.selected, dtype=np.int64).reshape(-1, 2)
    n_levels = len(frame.pyramid)
    if len(uv) == 0:
        return TemporaryEventMap.empty(n_levels, len(ATS_PATTERN))
    zmap = depth_in_camera(depth_m, rgb_camera, event_camera, np.linalg.inv(T_rgb_event))
    z = zmap[uv[:, 1], uv[:, 0]]
    ok = z > 0
    uv, z = uv[ok], z[ok].astype(np.float64)
    p_e = event_camera.backproject(uv.astype(np.float64), z)
    p_w = transform_points(np.asarray(T_w_rgb) @ np.asarray(T_rgb_event), p_e)
    patches = extract_patches(frame.pyramid, uv, ATS_PATTERN)
    return TemporaryEventMap(p_w, patches, frame.stamp_ns, np.asarray(T_w_rgb, dtype=np.float64).copy())


__all__ = ["build_event_map", "depth_in_camera"]
