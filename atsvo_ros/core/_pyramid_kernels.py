"""numba kernels of the image pyramid; private, see :mod:`atsvo_ros.core.pyramid`."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
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
