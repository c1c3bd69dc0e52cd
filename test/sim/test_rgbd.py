"""Colour and depth sensor models: motion blur, noise, auto gain, depth noise / holes / range."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.rgbd import ColorSensor, DepthModel, RgbModel, depth_to_mm


def _sensor(shape=(40, 60), seed=0, **kw) -> ColorSensor:
    h, w = shape
    rays = np.zeros((h * w, 3))
    rays[:, 2] = 1.0
    model = RgbModel(vignetting=0.0, **kw)
    return ColorSensor(model, 0.008, rays, shape, np.random.default_rng(seed))


def _edge_rgb(shape, pos: float) -> np.ndarray:
    h, w = shape
    x = np.arange(w)
    cover = np.clip(pos - (x - 0.5), 0.0, 1.0)
    img = 0.1 + 1.2 * cover
    return np.repeat(np.broadcast_to(img, (h, w))[..., None], 3, axis=2).astype(np.float32)


def _transition_width(row: np.ndarray) -> int:
    lo, hi = row.min(), row.max()
    return int(np.count_nonzero((row > lo + 0.1 * (hi - lo)) & (row < lo + 0.9 * (hi - lo))))


def test_motion_blur_spreads_an_edge_over_the_motion():
    shape = (20, 80)
    sharp = _sensor(shape, read_noise=0.0, full_well=1e12)
    blurred = _sensor(shape, read_noise=0.0, full_well=1e12)
    img_sharp = sharp.expose([_edge_rgb(shape, 40.0)], 0)
    subs = [_edge_rgb(shape, p) for p in np.linspace(30.0, 50.0, 21)]  # 20 px of motion, 1 px apart
    img_blur = blurred.expose(subs, 0)
    w_sharp = _transition_width(img_sharp[10, :, 1].astype(float))
    w_blur = _transition_width(img_blur[10, :, 1].astype(float))
    assert w_sharp <= 2
    assert 12 <= w_blur <= 20  # 10-90 % of a 20 px linear ramp (gamma bends it a little)


def test_noise_grows_with_signal_and_output_is_rgb8():
    sensor = _sensor((100, 100))
    dark = np.full((100, 100, 3), 0.2, np.float32)
    bright = np.full((100, 100, 3), 1.6, np.float32)
    sensor.gain = 1.0
    a = sensor.expose([dark], 0)
    sensor.gain = 1.0
    b = sensor.expose([bright], 0)
    assert a.dtype == np.uint8 and a.shape == (100, 100, 3)
    m = sensor.model
    # Noise in linear units: sqrt(x / full_well + read^2); compare linearised std to the model.
    for img, irr in ((a, 0.2), (b, 1.6)):
        lin = (img.astype(float) / 255.0) ** (1.0 / m.gamma)
        x = irr * 0.008 * m.sensitivity
        expected = np.sqrt(x / m.full_well + m.read_noise**2)
        assert 0.7 * expected < lin.std() < 1.6 * expected + 0.002
    assert b.mean() > a.mean()


def test_auto_gain_brings_dark_views_to_the_target():
    sensor = _sensor((30, 30), read_noise=0.0)
    dim = np.full((30, 30, 3), 0.1, np.float32)
    means = []
    for k in range(60):  # 2 s at 30 Hz, time constant 0.3 s
        img = sensor.expose([dim], k * 33_333_333)
        means.append(((img.astype(float) / 255.0) ** (1 / sensor.model.gamma)).mean())
    assert means[0] < 0.5 * sensor.model.ae_target
    assert abs(means[-1] - sensor.model.ae_target) < 0.1 * sensor.model.ae_target
    assert sensor.model.gain_limits[0] <= sensor.gain <= sensor.model.gain_limits[1]


def test_depth_noise_grows_with_range_squared():
    model = DepthModel(dropout_fraction=0.0)
    rng = np.random.default_rng(0)
    for z in (1.0, 3.0, 5.0):
        mm = depth_to_mm(np.full((200, 200), z, np.float32), model, rng)
        assert mm.dtype == np.uint16 and np.all(mm > 0)
        err = mm.astype(float) / 1000.0 - z
        sigma = model.sigma_at_1m_m * z * z
        assert abs(err.mean()) < 0.1 * sigma + 0.0005
        assert 0.85 * sigma < err.std() < 1.15 * sigma + 0.0003


def test_depth_validity_range_holes_and_dropouts():
    model = DepthModel()
    rng = np.random.default_rng(1)
    assert np.all(depth_to_mm(np.full((50, 50), 0.2, np.float32), model, rng) == 0)
    assert np.all(depth_to_mm(np.full((50, 50), 7.0, np.float32), model, rng) == 0)
    step = np.full((60, 60), 1.0, np.float32)
    step[:, 30:] = 3.0
    mm = depth_to_mm(step, DepthModel(dropout_fraction=0.0), rng)
    assert np.all(mm[:, 29:31] == 0)  # the discontinuity is a hole
    assert np.all(mm[:, :28] > 0) and np.all(mm[:, 32:] > 0)
    flat = depth_to_mm(np.full((300, 300), 2.0, np.float32), DepthModel(dropout_fraction=0.01), rng)
    frac = np.mean(flat == 0)
    assert 0.003 < frac < 0.03


def test_rgb_model_validation():
    with pytest.raises(SimulationError):
        ColorSensor(RgbModel(), 0.0, np.zeros((4, 3)), (2, 2), np.random.default_rng(0))
    with pytest.raises(SimulationError):
        RgbModel(max_subframes=0)
