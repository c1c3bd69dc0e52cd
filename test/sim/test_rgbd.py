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


def test_rolling_shutter_rows_average_their_own_exposure_window():
    from atsvo_ros.sim.rgbd import row_weights

    t = np.linspace(-0.02, 0.02, 21)  # sub-frames every 2 ms over a 40 ms span
    w = row_weights(t, 101, exposure_s=0.008, readout_time_s=0.03)
    assert w.shape == (21, 101) and np.allclose(w.sum(axis=0), 1.0)
    centre = (t[:, None] * w).sum(axis=0)  # the mean time each row saw
    assert np.allclose(centre, 0.03 * (np.arange(101) / 100 - 0.5), atol=2e-4)  # top early, bottom late
    assert np.allclose(row_weights(t, 5, 0.008, 0.0), row_weights(t, 5, 0.008, 0.0)[:, :1])  # global: equal
    # exposure shorter than the sub-frame spacing: each row takes the nearest sub-frame
    w1 = row_weights(np.array([-0.01, 0.0, 0.01]), 3, exposure_s=1e-6, readout_time_s=0.02)
    assert np.array_equal(w1, np.eye(3))


def test_simulated_rolling_shutter_skews_a_turning_view():
    """Turning about the vertical axis, the rows of a rolling-shutter frame see the scene at their own time."""
    import dataclasses

    from atsvo_ros.sim.sequence import SequenceSpec, make_simulation

    base = SequenceSpec(scenario="flying", duration_s=0.2, seed=1, width=96, height=72, imu=False)
    rs = dataclasses.replace(base, rgb_model=dataclasses.replace(base.rgb_model, readout_time_s=0.03))
    g = [f.rgb.astype(float) for f in make_simulation(base).frames()]
    r = [f.rgb.astype(float) for f in make_simulation(rs).frames()]
    # the middle rows are exposed at the stamp in both; the top and bottom rows are not
    mid = slice(33, 39)
    edge = np.r_[0:6, 66:72]
    d_mid = np.mean([np.abs(a[mid] - b[mid]).mean() for a, b in zip(g[2:], r[2:])])
    d_edge = np.mean([np.abs(a[edge] - b[edge]).mean() for a, b in zip(g[2:], r[2:])])
    assert d_edge > 2 * d_mid, (d_edge, d_mid)
