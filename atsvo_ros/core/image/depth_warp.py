"""Moving a depth image to another moment by the camera's motion in between (no cracks, no holes added).

A D455's depth is exposed up to half a frame away from the colour it is registered to; in a 500 deg/s
flip that is several degrees. Over such an interval the rotation dominates the image motion (8 deg is
~130 px at 640 px; 1.5 cm of translation at 1 m is ~8 px), and a pure rotation moves pixels by a
homography that does not depend on depth: each target pixel is looked up in the source (nearest, so no
depth is mixed across an edge) and its z re-expressed in the rotated frame. The translation matters for
the values rather than the pixels: a bound's 2 m/s over 16 ms moves every depth by up to 3 cm, which
the depth term would read as the camera's own offset. :func:`warp_depth` adds it with one more lookup
(a numba kernel, 1.8 ms a 640x480 frame with the translation).
"""
from __future__ import annotations

import threading

import numba
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.image._depth_warp_kernels import _warp_depth

# The kernel runs on one thread (see its module); numba's workqueue threading layer must not be entered from
# two threads at once: the lock.
_KERNEL_LOCK = threading.Lock()


def rotate_depth(depth_m: np.ndarray, camera: CameraModel, R_to_from: np.ndarray) -> np.ndarray:
    """``depth_m`` (float32 metres on ``camera``'s pinhole grid, 0 = none) seen after the camera rotated.

    ``R_to_from`` maps points of the depth's camera frame into the target camera frame.
    """
    return warp_depth(depth_m, camera, R_to_from, np.zeros(3))


def warp_depth(depth_m: np.ndarray, camera: CameraModel, R_to_from: np.ndarray,
               t_to_from_m: np.ndarray) -> np.ndarray:
    """``depth_m`` seen after the camera moved: a point ``X`` of the depth's frame is ``R X + t`` in the target.

    Each target pixel looks up the source pixel its ray came from under the rotation (nearest: no depth
    is mixed across an edge); with a translation, its point (that depth plus ``t_z``) is moved back by
    ``t`` and looked up once more. No cracks; pixels whose ray leaves the source image are 0.
    """
    R = np.ascontiguousarray(R_to_from, dtype=np.float64).reshape(3, 3)
    t = np.ascontiguousarray(t_to_from_m, dtype=np.float64).reshape(3)
    d = np.ascontiguousarray(depth_m, dtype=np.float32)
    with _KERNEL_LOCK:
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            return _warp_depth(d, float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy), R, t)
        finally:
            numba.set_num_threads(threads)


__all__ = ["rotate_depth", "warp_depth"]
