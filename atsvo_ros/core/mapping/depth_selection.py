"""Selection of geometric points: pixels of smooth valid depth spread evenly over the image.

The point-to-plane term needs points on surfaces, not on texture: a regular grid over the pixels
whose depth is valid and not on an edge, with the cell size that gives about ``target`` points.
"""
from __future__ import annotations

import numpy as np


def select_depth_pixels(valid: np.ndarray, target: int, border_px: int = 2) -> np.ndarray:
    """``(N, 2)`` int32 pixel positions ``(x, y)`` on a regular grid over ``valid`` (about ``target`` of them)."""
    h, w = valid.shape
    n_valid = int(np.count_nonzero(valid))
    if n_valid == 0 or target <= 0:
        return np.zeros((0, 2), np.int32)
    cell = max(1, int(round(np.sqrt(n_valid / target))))
    ys, xs = np.mgrid[border_px + cell // 2:h - border_px:cell, border_px + cell // 2:w - border_px:cell]
    xs, ys = xs.ravel(), ys.ravel()
    keep = valid[ys, xs]
    return np.column_stack([xs[keep], ys[keep]]).astype(np.int32)


__all__ = ["select_depth_pixels"]
