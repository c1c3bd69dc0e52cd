"""Image pyramids (with gradients) for coarse-to-fine alignment."""
from __future__ import annotations

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.image import _pyramid_kernels as kern


def build_pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """Float32 pyramid, level 0 = input, each level half the size (2x2 box average, like DSO).

    The box average keeps the pixel-centre convention used by :meth:`CameraModel.scaled`.
    """
    img = np.ascontiguousarray(image, dtype=np.float32)
    pyr = [img]
    for _ in range(1, levels):
        h, w = pyr[-1].shape[:2]
        if h < 2 or w < 2:
            break
        h2, w2 = h // 2, w // 2
        pyr.append(cv2.resize(pyr[-1][: 2 * h2, : 2 * w2], (w2, h2), interpolation=cv2.INTER_AREA))
    return pyr


def pyramid_cameras(camera: CameraModel, levels: int) -> list[CameraModel]:
    """Pinhole models matching :func:`build_pyramid` levels (camera must be undistorted)."""
    cams = [camera]
    for _ in range(1, levels):
        cams.append(cams[-1].scaled(0.5))
    return cams


def image_gradients(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference gradients (gx, gy) in intensity units per pixel, float32."""
    img = np.asarray(image, dtype=np.float32)
    gx = np.zeros_like(img)
    gy = np.zeros_like(img)
    gx[:, 1:-1] = 0.5 * (img[:, 2:] - img[:, :-2])
    gy[1:-1, :] = 0.5 * (img[2:, :] - img[:-2, :])
    return gx, gy


def image_pyramid_with_gradients(pyramid: list[np.ndarray]) -> list[np.ndarray]:
    """Stack each level with its central-difference gradients: (H, W, 3) float32 ``[I, Ix, Iy]``.

    One array per level keeps the three values a residual reads next to each other in memory.
    """
    return [kern._gradient_stack(np.ascontiguousarray(img, dtype=np.float32)) for img in pyramid]


def depth_pyramid(depth_m: np.ndarray, levels: int, edge_ratio: float = 0.05, min_m: float = 0.0,
                  max_m: float = np.inf) -> list[np.ndarray]:
    """float32 depth per pyramid level (0 = invalid: NaN, inf or outside ``[min_m, max_m]``).

    Coarse pixels never average across a depth edge.
    """
    d0 = kern._valid_depth(np.ascontiguousarray(depth_m, dtype=np.float32), float(min_m), float(max_m))
    out = [d0]
    for _ in range(1, levels):
        if min(out[-1].shape) < 4:
            break
        out.append(kern._depth_pyramid_level(out[-1], float(edge_ratio)))
    return out


__all__ = ["build_pyramid", "depth_pyramid", "image_gradients", "image_pyramid_with_gradients", "pyramid_cameras"]
