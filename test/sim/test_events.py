"""Event model: ideal change detection on analytic inputs (moving edges, thresholds), the pixel reset
(change during it is lost), the DVXplorer's scanned readout (scan lattice, column phase, no one-scan
repeats), background noise, and the readout statistics against a real DVXplorer recording."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.events import EventModel, EventSensor

MS = 1_000_000
EPS = EventModel().log_eps


def _sensor(width: int, height: int = 1, seed: int = 0, **kw) -> EventSensor:
    """An ideal sensor by default: asynchronous readout, no refractory period, no noise, no mismatch."""
    params = {"noise_rate_hz": 0.0, "refractory_s": 0.0, "scan_period_s": 0.0, "contrast_sigma": 0.0}
    params.update(kw)
    return EventSensor(EventModel(**params), width, height, np.random.default_rng(seed))


def _dvx(width: int, height: int = 1, seed: int = 0, **kw) -> EventSensor:
    """The default (DVXplorer Lite) model, without threshold mismatch and noise unless asked."""
    params = {"noise_rate_hz": 0.0, "contrast_sigma": 0.0}
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


def _level(log_change: float, i0: float = 0.1) -> np.ndarray:
    """A 1x1 irradiance image whose log intensity is ``log_change`` above that of ``i0``."""
    return np.array([[(i0 + EPS) * np.exp(log_change) - EPS]])


def _ramp(sensor: EventSensor, slope_per_ms: float, duration_ms: float, render_us: int = 100) -> np.ndarray:
    """Event stamps of a one-pixel sensor under a log-intensity ramp, rendered every ``render_us``."""
    sensor.reset(_level(0.0), 0)
    n = int(duration_ms * 1000 / render_us)
    out = [sensor.step(_level(slope_per_ms * (k + 1) * render_us / 1000), (k + 1) * render_us * 1000)
           for k in range(n)]
    return np.concatenate([b.t for b in out])


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
    sensor.reset(_level(0.0), 0)
    b = sensor.step(_level(3.5 * 0.2), 1 * MS)  # log change of 3.5 thresholds
    assert len(b) == 3 and np.all(b.p == 1)
    expected = np.round(np.arange(1, 4) / 3.5 * MS / 1000) * 1000
    np.testing.assert_allclose(b.t, expected, atol=1000)
    assert np.all(b.t % 1000 == 0)  # microsecond clock


def test_change_during_the_refractory_period_is_lost_not_postponed():
    """Asynchronous readout, 0.5 ms reset: a ramp of 10.5 thresholds within 1 ms fires at its first
    crossing (95 us), the reference is re-taken at the end of the reset (6.25 C at 595 us), the next
    event comes one threshold later (7.25 C at 690 us), and the rest of the change is gone."""
    sensor = _sensor(1, refractory_s=0.0005)
    sensor.reset(_level(0.0), 0)
    first = sensor.step(_level(10.5 * 0.2), 1 * MS)
    later = [sensor.step(_level(10.5 * 0.2), (k + 2) * MS) for k in range(10)]
    assert sum(len(b) for b in later) == 0
    np.testing.assert_array_equal(first.t, [96_000, 691_000])  # crossing times on the 1 us clock (ceil)
    assert np.all(first.p == 1)
    # A step (the whole change within 1 us) gives one event, not |dlog I| / C = 10.
    sensor = _sensor(1, refractory_s=0.0005)
    sensor.reset(_level(0.0), 0)
    steps = [sensor.step(_level(10.5 * 0.2), 1000)] + [sensor.step(_level(10.5 * 0.2), (k + 1) * MS) for k in range(5)]
    assert sum(len(b) for b in steps) == 1


@pytest.mark.parametrize("threshold_time_us", [50.0, 150.0, 400.0, 1000.0])
def test_a_ramp_fires_on_the_first_scan_after_reset_plus_one_threshold(threshold_time_us):
    """Scanned readout: read at scan k, reset for R, the reference re-taken then, the next crossing one
    threshold time T later, read at the next scan: every interval is ceil((R + T) / P) scans."""
    sensor = _dvx(1)
    m = sensor.model
    period_ns, refr_ns = m.scan_period_s * 1e9, m.refractory_s * 1e9
    t = _ramp(sensor, 0.2 / (threshold_time_us * 1e-3), duration_ms=min(20.0, 0.06 * threshold_time_us))
    assert len(t) >= 5
    scans = np.diff(t) / period_ns
    expected = np.ceil((refr_ns + threshold_time_us * 1000) / period_ns)
    np.testing.assert_allclose(scans, expected, atol=1000 / period_ns)  # within the 1 us clock
    assert expected >= 2  # never on consecutive scans


def _columns_textured_motion(width: int, height: int, duration_ms: float, seed: int, **kw) -> EventBatch:
    """Events of a random texture translating (with a speed change) under a sensor of the default model."""
    rng = np.random.default_rng(seed)
    tex = rng.uniform(0.05, 1.0, (height, 4 * width)).astype(np.float32)
    tex = (tex + np.roll(tex, 1, axis=1) + np.roll(tex, 1, axis=0)) / 3  # some spatial correlation
    xs = np.arange(width)
    sensor = _dvx(width, height, seed=seed, **kw)

    def image(shift: float) -> np.ndarray:
        i0 = int(np.floor(shift))
        f = np.float32(shift - i0)
        return (1 - f) * tex[:, i0 + xs] + f * tex[:, i0 + xs + 1]

    sensor.reset(image(0.0), 0)
    out, shift, dt_ns = [], 0.0, 50_000
    for k in range(int(duration_ms * 1e6 / dt_ns)):
        speed_px_s = 2000.0 if (k // 40) % 2 == 0 else 300.0
        shift += speed_px_s * dt_ns * 1e-9
        out.append(sensor.step(image(shift), (k + 1) * dt_ns))
    return EventBatch.concatenate(out)


def _readout_stats(b: EventBatch, period_ns: float) -> dict:
    """Per-pixel intervals in scans, the share on the scan lattice, and the column sweep of the stamp
    phase within a scan (fraction of a period from the first to the last column; negative: the last
    column is read first), estimated as on the real recordings."""
    key = b.y.astype(np.int64) * b.width + b.x
    order = np.lexsort((b.t, key))
    same = key[order][1:] == key[order][:-1]
    dt = np.diff(b.t[order])[same].astype(np.float64)
    scans = np.round(dt / period_ns)
    on_lattice = float(np.mean(np.abs(dt - scans * period_ns) <= 1000))
    hist = np.array([np.count_nonzero(scans == n) for n in range(1, 7)])
    z = np.exp(2j * np.pi * (b.t - b.t[0]).astype(np.float64) / period_ns)
    cols = np.flatnonzero(np.bincount(b.x, minlength=b.width) >= 20)
    phase = np.unwrap([np.angle(z[b.x == c].mean()) for c in cols]) / (2 * np.pi)
    sweep = np.polyfit(cols, phase, 1)[0] * b.width
    return {"on_lattice": on_lattice, "hist": hist, "sweep": float(sweep)}


def test_scanned_readout_puts_stamps_on_the_column_lattice_and_never_on_consecutive_scans():
    b = _columns_textured_motion(64, 24, 60.0, seed=1, noise_rate_hz=20.0)
    m = EventModel()
    period_ns = m.scan_period_s * 1e9
    assert len(b) > 2000 and b.is_sorted() and np.all(b.t % 1000 == 0)
    # Every stamp (signal and noise alike) = scan start + its column's offset, rounded up to the 1 us clock.
    offset = m.column_offsets_ns(64)[b.x]
    lag = b.t - (offset + np.floor((b.t - offset) / period_ns) * period_ns)
    assert np.all((lag >= 0) & (lag < 1000))
    # Within a scan the columns are read from the last to the first, the sweep taking scan_sweep_s.
    np.testing.assert_allclose(np.diff(m.column_offsets_ns(64)), -m.scan_sweep_s * 1e9 / 64)
    st = _readout_stats(b, period_ns)
    assert st["on_lattice"] == 1.0
    assert st["hist"][0] == 0 and st["hist"][1] > 0  # a pixel can fire every second scan, never every scan
    assert st["sweep"] == pytest.approx(-m.scan_sweep_s / m.scan_period_s, abs=0.01)
    # Many events of one column share a stamp (each column is read at one instant).
    _, per_stamp = np.unique(b.t, return_counts=True)
    assert per_stamp.mean() > 1.2


def test_scanned_step_fires_once_at_the_next_scan_of_its_column():
    """A big fast step (10.5 thresholds in 1 us) gives one event per pixel, stamped at the first scan
    after the step at its column's offset; the change is not queued for later scans."""
    sensor = _dvx(8)
    m = sensor.model
    period_ns = m.scan_period_s * 1e9
    row0, row1 = np.full((1, 8), 0.1, np.float32), _level(10.5 * 0.2).repeat(8, axis=1).astype(np.float32)
    sensor.reset(row0, 0)
    t_step = 1_000_000
    batches = [sensor.step(row0, t_step - 1000), sensor.step(row1, t_step)]
    batches += [sensor.step(row1, t_step + (k + 1) * 100_000) for k in range(30)]
    b = EventBatch.concatenate([x for x in batches if len(x)])
    assert len(b) == 8 and np.all(b.p == 1) and sorted(b.x.tolist()) == list(range(8))
    offset = m.column_offsets_ns(8)[b.x]
    first_scan = offset + np.ceil((t_step - 1000 - offset) / period_ns) * period_ns
    np.testing.assert_array_equal(b.t, np.ceil(first_scan / 1000) * 1000)


def test_static_scene_only_produces_background_noise_at_the_configured_rate():
    rng = np.random.default_rng(5)
    img = rng.uniform(0.05, 1.0, (32, 32)).astype(np.float32)
    quiet = _dvx(32, 32)
    quiet.reset(img, 0)
    assert sum(len(quiet.step(img, (k + 1) * 10 * MS)) for k in range(100)) == 0
    rate = 0.5
    noisy = _dvx(32, 32, noise_rate_hz=rate, seed=9)
    noisy.reset(img, 0)
    batches = [noisy.step(img, (k + 1) * 10 * MS) for k in range(2000)]  # 20 s
    n = sum(len(b) for b in batches)
    expected = rate * 32 * 32 * 20.0  # requests lost while a pixel is busy: ~rate x 0.4 ms, negligible
    assert abs(n - expected) < 5 * np.sqrt(expected)
    p = np.concatenate([b.p for b in batches])
    assert 0.45 < p.mean() < 0.55
    for k, b in enumerate(batches):
        assert np.all((b.t > k * 10 * MS) & (b.t <= (k + 1) * 10 * MS))


def test_model_validation():
    with pytest.raises(SimulationError):
        EventModel(contrast_pos=0.0)
    with pytest.raises(SimulationError):
        EventModel(max_step_px=0.0)
    with pytest.raises(SimulationError):
        EventModel(scan_period_s=100e-6, scan_sweep_s=150e-6)
    with pytest.raises(SimulationError):
        EventModel(scan_period_s=-1e-6)
    assert np.all(EventModel(scan_period_s=0.0).column_offsets_ns(5) == 0)
    sensor = _sensor(4)
    with pytest.raises(SimulationError):
        sensor.step(np.ones((1, 4)), MS)
    sensor.reset(np.ones((1, 4)), MS)
    with pytest.raises(SimulationError):
        sensor.step(np.ones((1, 4)), MS)


def test_readout_statistics_match_the_real_dvxplorer_recording(realdata):
    """The real DVXplorer (tonic sample.aedat4, 320x240) and the model agree on what the readout
    imposes: the scan period, every per-pixel interval on the scan lattice, the column sweep of the
    stamp phase, and (almost) no repeats on consecutive scans; two-scan repeats occur in both."""
    from atsvo_ros.io.aedat import iter_aedat4

    real = EventBatch.concatenate(list(iter_aedat4(realdata / "tonic_samples" / "sample.aedat4")))
    m = EventModel()
    period_ns = m.scan_period_s * 1e9
    # Period: the concentration of exp(2 pi i dt / P) over short per-pixel intervals peaks at the model's P.
    key = real.y.astype(np.int64) * real.width + real.x
    order = np.lexsort((real.t, key))
    dt = np.diff(real.t[order])[key[order][1:] == key[order][:-1]].astype(np.float64)
    dt = dt[dt < 5 * MS]
    periods = np.arange(195_000.0, 200_000.0, 10.0)
    conc = [abs(np.exp(2j * np.pi * dt / p).mean()) for p in periods]
    assert periods[int(np.argmax(conc))] == pytest.approx(period_ns, abs=20.0) and max(conc) > 0.99
    sim = _columns_textured_motion(320, 24, 40.0, seed=2)
    got, want = _readout_stats(sim, period_ns), _readout_stats(real.select(slice(0, 40_000)), 197_283.3)
    assert want["on_lattice"] > 0.999 and got["on_lattice"] == 1.0
    assert got["sweep"] == pytest.approx(want["sweep"], abs=0.01)
    for st in (got, want):
        share = st["hist"] / st["hist"].sum()
        assert share[0] < 0.03 and share[1] > 0.01  # one-scan repeats (almost) never, two-scan ones do occur
