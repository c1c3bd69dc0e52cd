"""numba kernel of the depth warp; private, see :mod:`atsvo_ros.core.image.depth_warp`.

Explicit signature: compiled (or loaded from numba's cache) at import, never per frame.
"""
from __future__ import annotations

import os

import numba
import numpy as np
from numba import njit, prange

# Compiled as a parallel loop, the kernel takes 1.9 ms a 640x480 frame with a translation on one thread (the
# wrapper's) against 7.9 as a plain loop: same arithmetic, better code. One thread keeps the tracking thread's
# cost where it was, with no second core spinning beside the robot's other work. Of numba's threading layers,
# GNU OpenMP aborts a process that forks after using it (a worker pool, the benchmarks' jobs): fork-safe ones
# first unless the user chose. Set before the decorators (compiling or loading a parallel kernel starts the
# layer), in numba's configuration and in the environment (numba re-reads its configuration from there).
if numba.config.THREADING_LAYER == "default" and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    os.environ["NUMBA_THREADING_LAYER_PRIORITY"] = "tbb workqueue omp"
    numba.config.THREADING_LAYER_PRIORITY = ["tbb", "workqueue", "omp"]


@njit("float64(float32[:, ::1], float64, float64, float64, float64, float64[:, ::1], float64, float64, float64)",
      cache=True, nogil=True)
def _rotated_z(depth, fx, fy, cx, cy, R, x, y, z):  # pragma: no cover - compiled
    """z in the target frame of the source pixel nearest the ray ``(x, y, z)`` (source frame), rotated by ``R``;
    0 when the ray leaves the image or the pixel has no depth."""
    h, w = depth.shape
    if z <= 1e-9:
        return 0.0
    inv_z = 1.0 / z
    xn, yn = x * inv_z, y * inv_z
    iu, iv = int(np.floor(fx * xn + cx + 0.5)), int(np.floor(fy * yn + cy + 0.5))
    if iu < 0 or iu >= w or iv < 0 or iv >= h:
        return 0.0
    d = depth[iv, iu]
    if not d > 0.0:
        return 0.0
    return d * (R[2, 0] * xn + R[2, 1] * yn + R[2, 2])


@njit("float32[:, ::1](float32[:, ::1], float64, float64, float64, float64, float64[:, ::1], float64[::1])",
      cache=True, nogil=True, parallel=True)
def _warp_depth(depth, fx, fy, cx, cy, R, t):  # pragma: no cover - compiled
    """Each target pixel's depth after the camera moved by ``X -> R X + t`` (nearest source pixel, 0 = none).

    The rotation maps rays whatever their depth (a homography); with a translation, the target point
    (rotated depth plus ``t_z``) is moved back by ``t`` and looked up once more.
    """
    h, w = depth.shape
    out = np.zeros((h, w), np.float32)
    moved = t[0] != 0.0 or t[1] != 0.0 or t[2] != 0.0
    for v in prange(h):
        ry = (v - cy) / fy
        for u in range(w):
            rx = (u - cx) / fx
            # the source ray of this target pixel under the rotation alone: R^T [rx, ry, 1]
            z = _rotated_z(depth, fx, fy, cx, cy, R, R[0, 0] * rx + R[1, 0] * ry + R[2, 0],
                           R[0, 1] * rx + R[1, 1] * ry + R[2, 1], R[0, 2] * rx + R[1, 2] * ry + R[2, 2])
            if moved and z > 0.0:
                zt = z + t[2]
                px, py, pz = zt * rx - t[0], zt * ry - t[1], zt - t[2]  # X_s = R^T (X_t - t)
                z = _rotated_z(depth, fx, fy, cx, cy, R, R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz,
                               R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz, R[0, 2] * px + R[1, 2] * py + R[2, 2] * pz)
                z = z + t[2] if z > 0.0 else 0.0
            if z > 0.0:
                out[v, u] = z
    return out
