"""Nine-region health rule (Section II-C)."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import MappingConfig
from atsvo_ros.core.mapping.keyframes import assess_health, region_counts


def _grid_points(per_region: np.ndarray, w: int = 300, h: int = 240) -> np.ndarray:
    pts = []
    rng = np.random.default_rng(0)
    for r in range(3):
        for c in range(3):
            n = int(per_region[r, c])
            pts.append(np.column_stack([rng.uniform(c * w / 3, (c + 1) * w / 3 - 1e-6, n),
                                        rng.uniform(r * h / 3, (r + 1) * h / 3 - 1e-6, n)]))
    return np.concatenate(pts)


def test_region_counts_bins_pixels_and_ignores_outside():
    counts = np.arange(9).reshape(3, 3) * 5
    uv = _grid_points(counts)
    uv = np.concatenate([uv, [[-1.0, 5.0], [300.0, 10.0], [10.0, 240.0]]])
    assert np.array_equal(region_counts(uv, 300, 240), counts)


def test_healthy_map_needs_no_keyframe():
    cfg = MappingConfig(region_min_points=20, min_healthy_regions=7, min_tracked_fraction=0.6)
    uv = _grid_points(np.full((3, 3), 30))
    h = assess_health(uv, 300, 240, n_reference=300, config=cfg)
    assert h.healthy_regions == 9 and h.n_tracked == 270 and not h.needs_keyframe


def test_keyframe_when_regions_go_unhealthy():
    cfg = MappingConfig(region_min_points=20, min_healthy_regions=7, min_tracked_fraction=0.1)
    counts = np.full((3, 3), 30)
    counts[:, 2] = 5  # the right third leaves the view
    h = assess_health(_grid_points(counts), 300, 240, n_reference=270, config=cfg)
    assert h.healthy_regions == 6 and h.needs_keyframe


def test_keyframe_when_tracked_fraction_drops():
    cfg = MappingConfig(region_min_points=5, min_healthy_regions=7, min_tracked_fraction=0.6)
    uv = _grid_points(np.full((3, 3), 10))
    assert not assess_health(uv, 300, 240, n_reference=140, config=cfg).needs_keyframe
    assert assess_health(uv, 300, 240, n_reference=200, config=cfg).needs_keyframe


def test_scene_that_never_fills_all_regions_does_not_trigger_every_frame():
    cfg = MappingConfig(region_min_points=20, min_healthy_regions=7, min_tracked_fraction=0.5)
    counts = np.full((3, 3), 30)
    counts[0, :] = 0  # blank ceiling: only 6 regions can ever be healthy
    uv = _grid_points(counts)
    assert not assess_health(uv, 300, 240, 180, cfg, reference_healthy=6).needs_keyframe
    counts[1, 0] = 0
    assert assess_health(_grid_points(counts), 300, 240, 180, cfg, reference_healthy=6).needs_keyframe
