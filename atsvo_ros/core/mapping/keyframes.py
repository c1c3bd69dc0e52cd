"""The nine-region health rule of Section II-C that decides keyframe insertion.

The image is divided into 3x3 regions; a region is healthy when at least ``region_min_points``
map points are tracked (inliers) inside it. A keyframe is inserted when fewer than
``min_healthy_regions`` regions are healthy or when the tracked points fall below
``min_tracked_fraction`` of the reference count (the points tracked right after the last keyframe).
The region count of a scene that cannot fill every region is capped by what the last keyframe had.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import MappingConfig


@dataclass(frozen=True)
class MapHealth:
    """Tracked points per region and the keyframe decision derived from them."""

    counts: np.ndarray
    healthy_regions: int
    n_tracked: int
    tracked_fraction: float
    needs_keyframe: bool


def region_counts(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Number of pixel positions (N, 2) in each of the 3x3 image regions, ``(3, 3)`` int (row, col)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
    uv = uv[inside]
    col = np.minimum((uv[:, 0] * 3 / width).astype(np.int64), 2)
    row = np.minimum((uv[:, 1] * 3 / height).astype(np.int64), 2)
    return np.bincount(row * 3 + col, minlength=9).reshape(3, 3)


def assess_health(uv_tracked: np.ndarray, width: int, height: int, n_reference: int,
                  config: MappingConfig, reference_healthy: int = 9) -> MapHealth:
    """Apply the nine-region rule to the tracked points' pixel positions.

    Args:
        uv_tracked: (N, 2) pixel positions of the inlier map points in the current frame.
        width, height: image size in pixels.
        n_reference: tracked points right after the last keyframe (denominator of the fraction).
        config: region threshold, healthy-region minimum and tracked-fraction minimum.
        reference_healthy: healthy regions right after the last keyframe. A scene that never fills
            all regions (a blank wall in one corner) would otherwise ask for a keyframe every frame;
            the rule fires when health drops below ``min(min_healthy_regions, reference_healthy)``.
    """
    counts = region_counts(uv_tracked, width, height)
    healthy = int((counts >= config.region_min_points).sum())
    n = int(counts.sum())
    frac = n / n_reference if n_reference > 0 else 0.0
    need = healthy < min(config.min_healthy_regions, reference_healthy) or frac < config.min_tracked_fraction
    return MapHealth(counts, healthy, n, float(frac), bool(need))


__all__ = ["MapHealth", "assess_health", "region_counts"]
