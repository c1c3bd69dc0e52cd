"""Event model on analytic inputs: moving edges, static scenes, thresholds, refractory period."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.events import EventModel, EventSensor

MS = 1_000_000


def _sensor(width: int, height: int = 1, seed: int = 0, **kw) -> EventSensor:
    params = {"noise_rate_hz": 0.0, "refractory_s": 0.0, "contrast_sigma": 0.0}
    params.update(kw)
    return EventSensor(EventModel(**params), width, height, np.random.default_rng(seed))


def _edge(width: int, pos: float, bright: float, dark: float) -> np.ndarray:
    """One image row: area-weighted step edge, bright left of ``pos`` (pixel x covers [x-0.5, x+0.5])."""
    x = np.arange(width)
    cover = np.clip(pos - (x - 0.5), 0.0, 1.0)
    return (dark + (bright - dark) * cover)[None, :].astype(np.float32)


def _sweep(sensor: EventSensor, positions: np.ndarray, bright: float, dark: float, dt_ns: int = MS):
    w = sensor.width
    sensor.reset(_edge(w, positions[0], bright, dark), 0)
    batches = [sensor.step(_edge(w, p, bright, dark), (i + 1) * dt_ns) for i, p in enumerate(positions[1:])]
    return batches


@pytest.mark.parametrize("forward", [True, False])
def test_moving_edge_gives_right_polarity_and_threshold_count(forward):
    """A bright region growing over dark pixels fires ON events only (OFF when it recedes),
    floor(|delta log I| / C) per pixel, with C the pixel's own (mismatched) threshold."""
    width, bright, dark = 40, 1.0, 0.05
    sensor = _sensor(width, contrast_sigma=0.03, seed=3)
    pos = np.arange(2.5, 37.51, 0.5)  # from pixel boundary to pixel boundary: pixels 3..37 swept
    batches = _sweep(sensor, pos if forward else pos[::-1], bright, dark)
    x = np.concatenate([b.x for b in batches]).astype(int)
    p = np.concatenate([b.p for b in batches])
    t = np.concatenate([b.t for b in batches])
    assert len(x) > 0
    assert np.all(p == (1 if forward else 0))
    assert np.all(np.diff(t) >= 0)
    dlog = np.log(bright + sensor.model.log_eps) - np.log(dark + sensor.model.log_eps)
    thresholds = sensor.c_pos if forward else sensor.c_neg
    counts = np.bincount(x, minlength=width)
    swept = np.arange(3, 38)
    expected = np.floor(dlog / thresholds[swept]).astype(int)
    np.testing.assert_array_equal(counts[swept], expected)
    # ... which is the nominal count within the mismatch spread.
    nominal = 0.2
    assert np.all(counts[swept] >= np.floor(dlog / (nominal + 4 * 0.03)))
    assert np.all(counts[swept] <= np.floor(dlog / (nominal - 4 * 0.03)))
    # Pixels the edge never crosses stay silent.
    assert counts[:3].sum() == 0 and counts[38:].sum() == 0


def test_edge_events_are_timed_when_the_edge_crosses_the_pixel():
    width = 30
    sensor = _sensor(width)
    pos = np.arange(2.0, 28.01, 0.25)
    batches = _sweep(sensor, pos, 1.0, 0.05)
    x = np.concatenate([b.x for b in batches]).astype(float)
    t = np.concatenate([b.t for b in batches]).astype(float)
    # Edge position at time t: linear in the render index (0.25 px per ms).
    edge_at_t = 2.0 + 0.25 * t / MS
    assert np.all(np.abs(edge_at_t - x) <= 0.5 + 0.25 + 1e-9)


def test_several_thresholds_in_one_interval_fire_several_interpolated_events():
    sensor = _sensor(1, contrast_pos=0.2, contrast_neg=0.2)
    eps = sensor.model.log_eps
    i0 = 0.1
    i1 = (i0 + eps) * np.exp(3.5 * 0.2) - eps  # log change of 3.5 thresholds
    sensor.reset(np.array([[i0]]), 0)
    b = sensor.step(np.array([[i1]]), 1 * MS)
    assert len(b) == 3 and np.all(b.p == 1)
    expected = np.round(np.arange(1, 4) / 3.5 * MS / 1000) * 1000
    np.testing.assert_allclose(b.t, expected, atol=1000)
    assert np.all(b.t % 1000 == 0)  # microsecond clock


def test_refractory_period_spaces_events_and_postpones_the_rest():
    sensor = _sensor(1, refractory_s=0.0005)
    eps = sensor.model.log_eps
    i0 = 0.1
    i1 = (i0 + eps) * np.exp(10.5 * 0.2) - eps
    sensor.reset(np.array([[i0]]), 0)
    first = sensor.step(np.array([[i1]]), 1 * MS)
    assert 1 <= len(first) <= 3
    later = [sensor.step(np.array([[i1]]), (k + 2) * MS) for k in range(10)]
    t = np.concatenate([first.t] + [b.t for b in later])
    assert len(t) == 10  # all thresholds eventually fire, none lost
    assert np.all(np.diff(t) >= 500_000)


def test_static_scene_only_produces_background_noise_at_the_configured_rate():
    rng = np.random.default_rng(5)
    img = rng.uniform(0.05, 1.0, (32, 32)).astype(np.float32)
    quiet = _sensor(32, 32)
    quiet.reset(img, 0)
    assert sum(len(quiet.step(img, (k + 1) * 10 * MS)) for k in range(100)) == 0
    rate = 0.5
    noisy = _sensor(32, 32, noise_rate_hz=rate, seed=9)
    noisy.reset(img, 0)
    batches = [noisy.step(img, (k + 1) * 10 * MS) for k in range(2000)]  # 20 s
    n = sum(len(b) for b in batches)
    expected = rate * 32 * 32 * 20.0
    assert abs(n - expected) < 5 * np.sqrt(expected)
    p = np.concatenate([b.p for b in batches])
    assert 0.45 < p.mean() < 0.55
    for k, b in enumerate(batches):
        assert np.all((b.t >= k * 10 * MS) & (b.t <= (k + 1) * 10 * MS))


def test_model_validation():
    with pytest.raises(SimulationError):
        EventModel(contrast_pos=0.0)
    with pytest.raises(SimulationError):
        EventModel(max_step_px=0.0)
    sensor = _sensor(4)
    with pytest.raises(SimulationError):
        sensor.step(np.ones((1, 4)), MS)
    sensor.reset(np.ones((1, 4)), MS)
    with pytest.raises(SimulationError):
        sensor.step(np.ones((1, 4)), MS)
