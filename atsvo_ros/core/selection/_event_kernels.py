"""Private numba kernel of the event pixel selection (greedy minimum-distance thinning)."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
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
