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


@pytest.mark.parametrize("shape", [(240, 320), (237, 317), (31, 45)])
def test_the_kernels_give_their_numpy_definitions_bit_for_bit(shape):
    """Gradient norm, block medians (edge-replicated partial blocks) and the best pixel per cell, against the plain
    numpy expressions they replaced (float32 throughout: a keyframe's points must not move with the speed-up)."""
    from atsvo_ros.core.mapping import rgb_selection as rs

    rng = np.random.default_rng(shape[1])
    img = (rng.random(shape) * 255).astype(np.float32)
    img[:, : shape[1] // 3] = np.round(img[:, : shape[1] // 3] / 64) * 64  # ties and flat parts
    gx, gy = np.zeros_like(img), np.zeros_like(img)
    gx[:, 1:-1] = 0.5 * (img[:, 2:] - img[:, :-2])
    gy[1:-1, :] = 0.5 * (img[2:, :] - img[:-2, :])
    grad = np.sqrt(gx * gx + gy * gy)
    assert np.array_equal(gradient_magnitude(img), grad)
    for block in (16, 7):
        hb, wb = -(-shape[0] // block), -(-shape[1] // block)
        padded = np.pad(grad, ((0, hb * block - shape[0]), (0, wb * block - shape[1])), mode="edge")
        blocks = padded.reshape(hb, block, wb, block).transpose(0, 2, 1, 3).reshape(hb, wb, -1)
        assert np.array_equal(rs.kern._block_thresholds(grad, block, 7.0), (np.median(blocks, axis=2) + 7.0))
    score = np.where(grad > 20, grad, -1.0).astype(np.float32)
    for cell in (1, 3, 8):
        hc, wc = -(-shape[0] // cell), -(-shape[1] // cell)
        padded = np.full((hc * cell, wc * cell), -1.0, np.float32)
        padded[: shape[0], : shape[1]] = score
        cells = padded.reshape(hc, cell, wc, cell).transpose(0, 2, 1, 3).reshape(hc, wc, cell * cell)
        idx = np.argmax(cells, axis=2)
        cy, cx = np.nonzero(np.take_along_axis(cells, idx[..., None], axis=2)[..., 0] > 0)
        k = idx[cy, cx]
        xs, ys = rs._best_per_cell(rs._candidates(score), shape, cell)
        assert np.array_equal(xs, cx * cell + k % cell) and np.array_equal(ys, cy * cell + k // cell)
