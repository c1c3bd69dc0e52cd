"""DSO-style RGB pixel selection: count, spread, masks, borders, adaptive thresholds."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import RgbSelectionConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.mapping.keyframes import region_counts
from atsvo_ros.core.mapping.rgb_selection import block_thresholds, gradient_magnitude, select_rgb_pixels
from atsvo_ros.errors import ImageError
from test.core.render_helpers import BoxRoom

CAM = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return BoxRoom(seed=5).render(CAM, np.eye(4), supersample=1)[0]


@pytest.mark.parametrize("target", [150, 400, 1000])
def test_reaches_target_count_and_spreads(image, target):
    cfg = RgbSelectionConfig(target_points=target)
    uv = select_rgb_pixels(image, cfg)
    assert 0.8 * target <= len(uv) <= target * 1.12
    assert len(np.unique(uv, axis=0)) == len(uv)
    assert np.all(region_counts(uv, CAM.width, CAM.height) >= target / 30)


def test_points_have_high_gradient_for_their_block(image):
    cfg = RgbSelectionConfig(target_points=300)
    uv = select_rgb_pixels(image, cfg)
    grad = gradient_magnitude(image)
    thr = block_thresholds(grad, cfg.block_size_px, cfg.min_gradient)
    strong = grad[uv[:, 1], uv[:, 0]] > thr[uv[:, 1], uv[:, 0]]
    assert strong.mean() > 0.8  # the rest come from the half-threshold pass in empty cells
    assert np.all(grad[uv[:, 1], uv[:, 0]] > 0.5 * thr[uv[:, 1], uv[:, 0]])
    # Strongest first.
    g = grad[uv[:, 1], uv[:, 0]]
    assert np.all(np.diff(g) <= 1e-6)


def test_respects_mask_and_border(image):
    cfg = RgbSelectionConfig(target_points=300, border_px=10)
    mask = np.ones(image.shape, dtype=bool)
    mask[:, :160] = False
    uv = select_rgb_pixels(image, cfg, mask=mask)
    assert len(uv) > 100
    assert np.all(uv[:, 0] >= 160)
    assert np.all((uv[:, 0] >= 10) & (uv[:, 0] < 310) & (uv[:, 1] >= 10) & (uv[:, 1] < 230))


def test_flat_image_gives_nothing_and_bad_input_raises():
    cfg = RgbSelectionConfig()
    assert len(select_rgb_pixels(np.full((60, 80), 100, np.uint8), cfg)) == 0
    with pytest.raises(ImageError):
        select_rgb_pixels(np.zeros((60, 80, 3), np.uint8), cfg)
    with pytest.raises(ImageError):
        select_rgb_pixels(np.zeros((60, 80), np.uint8), cfg, mask=np.ones((10, 10), bool))


def test_adaptive_threshold_follows_local_contrast():
    """A low-contrast half still gets points: thresholds are per block, not global."""
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1, (120, 160)).astype(np.float32)
    img[:, :80] *= 40.0
    img[:, 80:] *= 250.0
    uv = select_rgb_pixels(img, RgbSelectionConfig(target_points=200, min_gradient=2.0))
    left = (uv[:, 0] < 80).sum()
    assert left > 0.3 * len(uv)
