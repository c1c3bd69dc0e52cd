"""Moving a depth image to another moment by the camera's rotation in between (no cracks, no holes added).

A D455's depth is exposed up to half a frame away from the colour it is registered to; in a 500 deg/s
flip that is several degrees. Over such an interval the rotation dominates the image motion (8 deg is
~130 px at 640 px; 1.5 cm of translation at 1 m is ~8 px), and a pure rotation moves pixels by a
homography that does not depend on depth: each target pixel is looked up in the source (nearest, so no
depth is mixed across an edge) and its z re-expressed in the rotated frame.
"""
from __future__ import annotations

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel


def rotate_depth(depth_m: np.ndarray, camera: CameraModel, R_to_from: np.ndarray) -> np.ndarray:
    """``depth_m`` (float32 metres on ``camera``'s pinhole grid, 0 = none) seen after the camera rotated.

    ``R_to_from`` maps points of the depth's camera frame into the target camera frame.
    """
    K = camera.K
    R = np.asarray(R_to_from, dtype=np.float64)
    H = K @ R @ np.linalg.inv(K)  # source pixel -> target pixel
    d = np.ascontiguousarray(depth_m, dtype=np.float32)
    src = cv2.warpPerspective(d, H, (camera.width, camera.height), flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    # z in the target frame: the source pixel's ray (z = 1) scaled by its depth, rotated
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    Hinv = np.linalg.inv(H)
    w = Hinv[2, 0] * u + Hinv[2, 1] * v + Hinv[2, 2]
    xs = (Hinv[0, 0] * u + Hinv[0, 1] * v + Hinv[0, 2]) / w
    ys = (Hinv[1, 0] * u + Hinv[1, 1] * v + Hinv[1, 2]) / w
    rx, ry = (xs - camera.cx) / camera.fx, (ys - camera.cy) / camera.fy
    scale = R[2, 0] * rx + R[2, 1] * ry + R[2, 2]
    out = np.where(np.isfinite(src) & (src > 0), src * scale, 0.0)
    return out.astype(np.float32)


__all__ = ["rotate_depth"]
