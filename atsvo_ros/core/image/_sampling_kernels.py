"""numba kernel of bilinear image sampling; private, see :func:`atsvo_ros.core.image.photometric.bilinear`."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _bilinear(img, uv, out, valid):  # pragma: no cover - compiled
    """Sample ``img`` (H, W float32) at ``uv`` (N, 2 float64 x, y) into ``out``/``valid``; 0 where invalid.

    The 2x2 support is clamped into the image so a position on the last row or column reads the
    pixel itself (weights 0 on the clamped side), like the numpy formulation it replaces.
    """
    h, w = img.shape
    xmax = w - 2 if w > 1 else 0
    ymax = h - 2 if h > 1 else 0
    one = np.float32(1.0)
    for i in range(uv.shape[0]):
        x = uv[i, 0]
        y = uv[i, 1]
        if not (x >= 0.0 and y >= 0.0 and x <= w - 1 and y <= h - 1):  # also false for NaN
            out[i] = 0.0
            valid[i] = False
            continue
        x0 = min(int(np.floor(x)), xmax)
        y0 = min(int(np.floor(y)), ymax)
        fx = np.float32(x - x0)
        fy = np.float32(y - y0)
        x1 = min(x0 + 1, w - 1)
        y1 = min(y0 + 1, h - 1)
        top = img[y0, x0] * (one - fx) + img[y0, x1] * fx
        bot = img[y1, x0] * (one - fx) + img[y1, x1] * fx
        out[i] = top * (one - fy) + bot * fy
        valid[i] = True
