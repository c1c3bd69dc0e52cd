"""DSO-style pixel selection on the colour (grey) image.

The image is cut into ``d x d`` blocks; each block gets an adaptive gradient threshold (its median
gradient plus ``min_gradient``, smoothed over neighbouring blocks, like DSO), so that textured and
flat parts of the image both contribute. Candidates above the threshold are then thinned to the
strongest pixel per cell of an adaptive cell size that makes the count reach ``target_points``,
and cells left empty get a second chance at half the threshold (never below ``min_gradient``) on a
coarser grid, which spreads the points over the whole image without picking pure sensor noise.
"""
from __future__ import annotations

import cv2
import numpy as np

from atsvo_ros.config import RgbSelectionConfig
from atsvo_ros.core.mapping import _rgb_selection_kernels as kern
from atsvo_ros.errors import ImageError


def gradient_magnitude(grey: np.ndarray) -> np.ndarray:
    """Central-difference gradient norm (intensity units per pixel; 0 across the border), float32."""
    return kern._gradient_magnitude(np.ascontiguousarray(grey, dtype=np.float32))


def block_thresholds(grad: np.ndarray, block_px: int, min_gradient: float) -> np.ndarray:
    """Per-pixel threshold: median gradient of each ``block_px`` block + ``min_gradient``, smoothed 3x3."""
    h, w = grad.shape
    thr = kern._block_thresholds(np.ascontiguousarray(grad, dtype=np.float32), int(block_px), float(min_gradient))
    thr = cv2.blur(thr, (3, 3), borderType=cv2.BORDER_REPLICATE)
    full = np.repeat(np.repeat(thr, block_px, axis=0), block_px, axis=1)
    return full[:h, :w]


def _candidates(score: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels of positive score, row-major: (x, y, score)."""
    ys, xs = np.nonzero(score > 0)
    return np.ascontiguousarray(xs), np.ascontiguousarray(ys), np.ascontiguousarray(score[ys, xs], dtype=np.float32)


def _best_per_cell(cand: tuple[np.ndarray, np.ndarray, np.ndarray], shape: tuple[int, int],
                   cell: int) -> tuple[np.ndarray, np.ndarray]:
    """Position (x, y) of the highest candidate in each ``cell x cell`` cell (cells in row-major order)."""
    xs, ys, vs = cand
    return kern._best_per_cell(xs, ys, vs, int(shape[0]), int(shape[1]), max(1, int(cell)))


def select_rgb_pixels(grey: np.ndarray, config: RgbSelectionConfig, mask: np.ndarray | None = None,
                      target_points: int | None = None) -> np.ndarray:
    """Select well-spread high-gradient pixels.

    Args:
        grey: HxW image (uint8 or float, 0-255 intensities).
        config: block size, target count, gradient floor and border.
        mask: optional HxW bool, True where a pixel may be selected (e.g. valid depth).
        target_points: overrides ``config.target_points``.

    Returns:
        ``(N, 2)`` int32 pixel positions ``(x, y)``, strongest gradient first.
    """
    img = np.asarray(grey, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 3:
        raise ImageError(f"pixel selection needs a 2-D grey image, got shape {img.shape}")
    h, w = img.shape
    target = int(target_points if target_points is not None else config.target_points)
    grad = gradient_magnitude(img)
    thr = block_thresholds(grad, config.block_size_px, config.min_gradient)
    allowed = np.zeros((h, w), dtype=bool)
    b = config.border_px
    allowed[b:h - b, b:w - b] = True
    if mask is not None:
        if mask.shape != (h, w):
            raise ImageError(f"selection mask shape {mask.shape} differs from image shape {(h, w)}")
        allowed &= mask
    n_allowed = int(allowed.sum())
    if n_allowed == 0 or target <= 0:
        return np.zeros((0, 2), dtype=np.int32)
    cand = _candidates(np.where(allowed & (grad > thr), grad, -1.0).astype(np.float32))
    cell = float(np.sqrt(n_allowed / target))
    best: tuple[np.ndarray, np.ndarray] | None = None
    for _ in range(6):
        c = max(1, int(round(cell)))
        xs, ys = _best_per_cell(cand, (h, w), c)
        n = len(xs)
        if best is None or abs(n - target) < abs(len(best[0]) - target):
            best = (xs, ys)
        if n == 0 or abs(n - target) <= 0.1 * target or (c == 1 and n < target):
            break
        cell = max(1.0, cell * float(np.sqrt(n / target)))
    xs, ys = best
    # Second pass: empty cells of the size that would spread ``target`` points evenly accept
    # weaker gradients, so flat regions still get points; only the strongest fill the shortfall.
    c = max(2, int(np.sqrt(n_allowed / target)))
    if len(xs) < target:
        taken = np.zeros((-(-h // c), -(-w // c)), dtype=bool)
        taken[ys // c, xs // c] = True
        occupied = np.repeat(np.repeat(taken, c, 0), c, 1)[:h, :w]
        weak_thr = np.maximum(0.5 * thr, config.min_gradient)  # never below the absolute floor (noise)
        weak = _candidates(np.where(allowed & (grad > weak_thr) & ~occupied, grad, -1.0).astype(np.float32))
        x2, y2 = _best_per_cell(weak, (h, w), c)
        keep = np.argsort(-grad[y2, x2], kind="stable")[: target - len(xs)]
        xs, ys = np.concatenate([xs, x2[keep]]), np.concatenate([ys, y2[keep]])
    order = np.argsort(-grad[ys, xs], kind="stable")
    return np.column_stack([xs[order], ys[order]]).astype(np.int32)


__all__ = ["block_thresholds", "gradient_magnitude", "select_rgb_pixels"]
