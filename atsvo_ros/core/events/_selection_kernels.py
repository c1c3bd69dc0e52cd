"""Private numba kernel of the event pixel selection (greedy minimum-distance thinning)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _thin(xs: np.ndarray, ys: np.ndarray, order: np.ndarray, d: int, width: int, height: int,
          max_points: int) -> np.ndarray:
    """Visit candidates in ``order``; keep one unless a kept pixel lies within d in x and in y.

    Returns the indices of the kept candidates (in visiting order).
    """
    taken = np.zeros((height, width), np.bool_)
    keep = np.empty(min(order.shape[0], max_points), np.int64)
    k = 0
    for oi in range(order.shape[0]):
        if k >= max_points:
            break
        i = order[oi]
        x = np.int64(xs[i])
        y = np.int64(ys[i])
        free = True
        for yy in range(max(y - d, 0), min(y + d + 1, height)):
            for xx in range(max(x - d, 0), min(x + d + 1, width)):
                if taken[yy, xx]:
                    free = False
                    break
            if not free:
                break
        if free:
            taken[y, x] = True
            keep[k] = i
            k += 1
    return keep[:k]


@njit(cache=True, nogil=True)
def _event_pixels(x, y, t, t_from, t_to, lut_x, lut_y, raw_w, raw_h, out):  # pragma: no cover - compiled
    """Mark in ``out`` (bool, target grid) the pixels of events with ``t_from < t <= t_to``.

    ``lut_x``/``lut_y`` (flat over the raw sensor, -1 = off the target grid) map raw pixels to target
    pixels, so undistortion and the duplicate removal of a ``np.unique`` happen in one O(events) pass.
    Returns the number of events marked.
    """
    n = 0
    for i in range(t.shape[0]):
        ti = t[i]
        if ti <= t_from or ti > t_to:
            continue
        xi = np.int64(x[i])
        yi = np.int64(y[i])
        if xi >= raw_w or yi >= raw_h:
            continue
        k = yi * raw_w + xi
        u = lut_x[k]
        if u < 0:
            continue
        out[lut_y[k], u] = True
        n += 1
    return n
