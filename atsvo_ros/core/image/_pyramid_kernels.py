"""numba kernels of the image pyramid; private, see :mod:`atsvo_ros.core.image.pyramid`."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _gradient_stack(img):  # pragma: no cover - compiled
    """(H, W, 3) float32 ``[I, dI/dx, dI/dy]`` with central differences (0 on the border)."""
    h, w = img.shape
    out = np.empty((h, w, 3), dtype=np.float32)
    for y in range(h):
        ym = y - 1 if y > 0 else y
        yp = y + 1 if y < h - 1 else y
        inner_y = 0 < y < h - 1
        for x in range(w):
            out[y, x, 0] = img[y, x]
            if 0 < x < w - 1:
                out[y, x, 1] = 0.5 * (img[y, x + 1] - img[y, x - 1])
            else:
                out[y, x, 1] = 0.0
            out[y, x, 2] = 0.5 * (img[yp, x] - img[ym, x]) if inner_y else 0.0
    return out


@njit(cache=True, nogil=True)
def _depth_pyramid_level(depth, max_ratio):  # pragma: no cover - compiled
    """Half-resolution depth: the mean of the valid pixels of each 2x2 block when they agree within
    ``max_ratio`` of their minimum, else 0 (invalid): a coarse pixel never averages across an edge."""
    h = depth.shape[0] // 2
    w = depth.shape[1] // 2
    out = np.zeros((h, w), np.float32)
    for y in range(h):
        for x in range(w):
            s = 0.0
            c = 0
            lo = np.inf
            hi = 0.0
            for dy in range(2):
                for dx in range(2):
                    z = depth[2 * y + dy, 2 * x + dx]
                    if z > 0.0:
                        s += z
                        c += 1
                        lo = min(lo, z)
                        hi = max(hi, z)
            if c >= 2 and hi - lo <= max_ratio * lo:
                out[y, x] = s / c
    return out


@njit(cache=True, nogil=True)
def _valid_depth(depth, min_m, max_m):  # pragma: no cover - compiled
    """A copy with 0 wherever the depth is not a finite value within ``[min_m, max_m]``."""
    h, w = depth.shape
    out = np.empty((h, w), np.float32)
    for y in range(h):
        for x in range(w):
            z = depth[y, x]
            out[y, x] = z if (z >= min_m and z <= max_m) else 0.0  # NaN fails both comparisons
    return out
