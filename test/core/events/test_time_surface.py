"""Time surfaces: Eq. 1-2 against a direct per-pixel reference, behaviour under fast/slow motion."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from atsvo_ros.config import AtsConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.time_surface import (
    AdaptiveTimeSurface,
    ConstantTimeSurface,
    SpeedInvariantTimeSurface,
    make_time_surface,
    ring_pattern,
)
from atsvo_ros.errors import ConfigError
from atsvo_ros.sim.events import EventModel, EventSensor

# the FAST-9 Bresenham circle of radius 3, written out independently of ring_pattern()
FAST16 = [(0, -3), (1, -3), (2, -2), (3, -1), (3, 0), (3, 1), (2, 2), (1, 3),
          (0, 3), (-1, 3), (-2, 2), (-3, 1), (-3, 0), (-3, -1), (-2, -2), (-1, -3)]
RAW = dict(blur_ksize=1, median_ksize=1)  # compare Eq. 1-2 before the smoothing
MODES = ["fire_age", "mean_age", "eq2_printed"]
# fire_age renders from float32 ages (tau_map is exact): relative ~1e-7 of an age, ~1e-5 of the value
RENDER_RTOL = {"fire_age": 1e-4, "mean_age": 1e-5, "eq2_printed": 1e-5}


def _random_events(n, w, h, span_ns, seed):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, span_ns, n))
    return EventBatch(rng.integers(0, w, n), rng.integers(0, h, n), t, rng.integers(0, 2, n), w, h)


def _reference_ats(b: EventBatch, w: int, h: int, t_q: int, cfg: AtsConfig,
                   ring: list[tuple[int, int]] = FAST16) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1-2 computed pixel by pixel in plain Python, straight from the paper's description (and, for
    ``fire_age``, from the module docstring: the mean age of the ring at the moment the pixel fired)."""
    last: dict[tuple[int, int], int] = {}
    for x, y, t in zip(b.x.tolist(), b.y.tolist(), b.t.tolist()):
        last[(x, y)] = t  # events are time-ordered: the later one wins
    img = np.zeros((h, w))
    tau = np.full((h, w), np.nan)
    for (x, y), tl in last.items():
        neighbours = [last[(x + dx, y + dy)] for dx, dy in ring if (x + dx, y + dy) in last]
        latest = sorted(neighbours, reverse=True)[: cfg.n_latest]  # inactive pixels never enter the ranking
        if cfg.tau_mode == "fire_age":
            clip_ns = round(cfg.tau_u_s * 1e9)
            before = [min(tl - v, clip_ns) for v in neighbours if v <= tl]  # fired at or before the pixel
            tau_x = (min(max(cfg.fire_age_gain * sum(before) / len(before) * 1e-9, cfg.tau_l_s), cfg.tau_u_s)
                     if before else cfg.tau_u_s)
        elif latest:
            age = sum(max(t_q - v, 0) for v in latest) / len(latest) * 1e-9
            if cfg.tau_mode == "mean_age":
                tau_x = min(max(age, cfg.tau_l_s), cfg.tau_u_s)
            else:
                tau_x = max(cfg.tau_u_s - age, cfg.tau_l_s)
        else:
            tau_x = cfg.tau_u_s
        tau[y, x] = tau_x
        img[y, x] = 255.0 * math.exp(-max(t_q - tl, 0) * 1e-9 / tau_x)
    return img, tau


def test_ring_pattern_is_the_fast_circle():
    dx, dy = ring_pattern(3)
    assert sorted(zip(dx.tolist(), dy.tolist())) == sorted(FAST16)
    dx1, dy1 = ring_pattern(1)
    assert len(set(zip(dx1.tolist(), dy1.tolist()))) == len(dx1) == 8  # duplicates removed at small radii


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("n_latest", [1, 4, 16])
def test_ats_matches_per_pixel_reference_on_random_events(mode, n_latest):
    w, h = 23, 17
    cfg = AtsConfig(tau_u_s=0.03, tau_l_s=0.002, n_latest=n_latest, tau_mode=mode, **RAW)
    b = _random_events(1500, w, h, 60_000_000, seed=n_latest)
    ats = AdaptiveTimeSurface(w, h, cfg)
    for part in np.array_split(np.arange(len(b)), 7):  # incremental updates must equal one pass
        ats.update(b.select(part))
    for t_q in (int(b.t[-1]), int(b.t[-1]) + 7_000_000, int(b.t[len(b) // 2])):
        ref_img, ref_tau = _reference_ats(b, w, h, t_q, cfg) if t_q >= b.t[-1] else (None, None)
        if ref_img is None:
            continue
        np.testing.assert_allclose(ats.tau_map(t_q), ref_tau, rtol=1e-5, equal_nan=True)
        # render skips pixels so old that even tau_u leaves < 0.5 grey levels
        np.testing.assert_allclose(ats.render_raw(t_q), ref_img, atol=0.5, rtol=RENDER_RTOL[mode])
    assert ats.n_events == len(b) and ats.n_skipped == 0


@pytest.mark.parametrize("mode", MODES)
def test_ats_eq1_is_exact_to_float32_over_the_whole_decay(mode):
    """The render evaluates exp with its own (vectorisable) polynomial: against math.exp it must stay at float32
    precision wherever Eq. 1 is evaluated -- ages from 0 to past the cutoff, age / tau from 0 to far beyond the
    float32 range (tau_l small) -- and give exactly 0 beyond the cutoff; dense and sparse rows both. fire_age
    runs in float32 from the ages on (tau from differences of float32 ages), so its exponent x = age / tau
    carries a relative error below 1e-6, which exp turns into a relative error below (1 + x) * 1e-6."""
    w, h = 64, 40
    cfg = AtsConfig(tau_u_s=0.03, tau_l_s=0.0004, n_latest=4, tau_mode=mode, **RAW)
    rng = np.random.default_rng(11)
    n = 6000
    x, y = rng.integers(0, w, n), rng.integers(0, h - 8, n)
    y[: n // 2] = np.minimum(y[: n // 2], h // 2)  # upper half dense, lower rows sparse
    t = rng.integers(0, 300_000_000, n)  # spans beyond the cutoff (0.03 s * ln 510 = 0.187 s)
    # three pixels of the bottom rows with age / tau >> 87: one whose ring fires just before the query
    # (tau = tau_l in mean_age mode), one whose ring fired long before it (tau = tau_l in eq2_printed mode),
    # one whose ring fired just before the pixel itself (tau = tau_l in fire_age mode)
    for cx, t_centre, t_ring in ((10, 150_000_000, 299_900_000), (40, 200_000_000, 100_000_000),
                                 (25, 150_000_000, 149_990_000)):
        x = np.concatenate([x, [cx], [cx + dx for dx, _ in FAST16]])
        y = np.concatenate([y, [h - 4], [h - 4 + dy for _, dy in FAST16]])
        t = np.concatenate([t, [t_centre], np.full(16, t_ring)])
    order = np.argsort(t, kind="stable")
    b = EventBatch(x[order], y[order], t[order], np.zeros(len(t)), w, h)
    ats = AdaptiveTimeSurface(w, h, cfg)
    ats.update(b)
    t_q = 300_000_000
    ref_img, ref_tau = _reference_ats(b, w, h, t_q, cfg)
    img = ats.render_raw(t_q)
    age_s = np.where(ats.active_mask(), (t_q - ats.t_last) * 1e-9, np.inf)
    inside = age_s <= cfg.tau_u_s * math.log(2 * 255.0)
    assert inside.sum() > 500 and (~inside & ats.active_mask()).sum() > 100
    assert (age_s / np.nan_to_num(ref_tau, nan=1.0))[inside].max() > 100.0  # exp underflows float32 there
    if mode == "fire_age":
        x = (age_s / np.nan_to_num(ref_tau, nan=1.0))[inside]
        err = np.abs(img[inside] - ref_img[inside])
        assert np.all(err <= ref_img[inside] * 1e-6 * (1.0 + x) + 1e-30)
    else:
        np.testing.assert_allclose(img[inside], ref_img[inside], rtol=1e-6, atol=1e-30)
    assert np.all(img[~inside] == 0.0)
    np.testing.assert_allclose(ats.tau_map(t_q), ref_tau, rtol=1e-6, equal_nan=True)


def test_ats_with_duplicate_timestamps_matches_reference():
    w, h = 12, 10
    rng = np.random.default_rng(7)
    n = 800
    t = np.sort(rng.integers(0, 40, n)) * 1_000_000  # only 40 distinct stamps: many ties
    b = EventBatch(rng.integers(0, w, n), rng.integers(0, h, n), t, np.zeros(n), w, h)
    for mode in MODES:
        cfg = AtsConfig(n_latest=3, tau_mode=mode, **RAW)
        ats = AdaptiveTimeSurface(w, h, cfg)
        ats.update(b)
        _, ref_tau = _reference_ats(b, w, h, int(t[-1]), cfg)
        np.testing.assert_allclose(ats.tau_map(), ref_tau, rtol=1e-5, equal_nan=True)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("n_latest,radius", [(1, 3), (4, 3), (16, 3), (5, 1)])
def test_ats_incremental_state_matches_reference_on_long_stream(mode, n_latest, radius):
    """The O(1)-per-neighbour recency lists against the reference: a long stream in which a few pixels fire
    again and again (members re-fire, leave and re-enter the n latest), many events share a timestamp, most
    pixels lie within the ring radius of the border, fed in uneven batches; queried after the last event and
    before it (ages clamped at 0). Radius 1 (an 8-pixel ring) takes the kernel's generic path (for fire_age,
    which keeps the times alone, the int64 render instead of the float32 one of the 16-point ring)."""
    w, h = 11, 9
    rng = np.random.default_rng(100 + n_latest)
    n = 20_000
    hot = rng.integers(0, w * h, 12)  # half of the events hit these 12 pixels
    pix = np.where(rng.random(n) < 0.5, rng.choice(hot, n), rng.integers(0, w * h, n))
    t = 1_700_000_000_000_000_000 + np.sort(rng.integers(0, 400, n)) * 100_000  # ~50 events per timestamp
    b = EventBatch(pix % w, pix // w, t, rng.integers(0, 2, n), w, h)
    cfg = AtsConfig(tau_u_s=0.02, tau_l_s=0.001, n_latest=n_latest, tau_mode=mode, pattern_radius_px=radius, **RAW)
    ring = FAST16 if radius == 3 else list(zip(*(d.tolist() for d in ring_pattern(radius))))
    ats = AdaptiveTimeSurface(w, h, cfg)
    cuts = np.sort(rng.choice(np.arange(1, n), 12, replace=False))
    for part in np.split(np.arange(n), cuts):
        ats.update(b.select(part))
    for t_q in (int(t[-1]), int(t[-1]) + 3_000_000, int(t[-1]) - 2_000_000):
        ref_img, ref_tau = _reference_ats(b, w, h, t_q, cfg, ring)
        np.testing.assert_allclose(ats.tau_map(t_q), ref_tau, rtol=1e-6, equal_nan=True)
        np.testing.assert_allclose(ats.render_raw(t_q), ref_img, atol=0.5, rtol=RENDER_RTOL[mode])
    assert ats.n_skipped == 0 and ats.active_mask().sum() == len(np.unique(pix))


def _sweeping_edge(speed_px_s: float, w: int = 120, h: int = 40, x0: int = 5, x1: int = 100) -> EventBatch:
    """A vertical edge crossing columns x0..x1 at ``speed_px_s``; every pixel of a column fires when it passes."""
    xs, ys, ts = [], [], []
    for col in range(x0, x1):
        t = int((col - x0) / speed_px_s * 1e9)
        xs.append(np.full(h, col))
        ys.append(np.arange(h))
        ts.append(np.full(h, t))
    return EventBatch(np.concatenate(xs), np.concatenate(ys), np.concatenate(ts), np.ones(h * (x1 - x0)), w, h)


def _moving_texture(speed_px_s: float, mean_spacing_px: float, duration_s: float = 0.08, w: int = 80, h: int = 24,
                    seed: int = 0) -> EventBatch:
    """Vertical edges at random spacing translating right at ``speed_px_s``: a column fires whenever an edge
    crosses it, so the local event rate grows with speed and with texture density."""
    rng = np.random.default_rng(seed)
    reach = speed_px_s * duration_s + w
    edges = -np.cumsum(rng.exponential(mean_spacing_px, int(reach / mean_spacing_px * 2) + 10)) + w
    xs, ts = [], []
    for col in range(w):
        t = (col - edges) / speed_px_s  # when each edge reaches this column
        t = t[(t >= 0) & (t < duration_s)]
        xs.append(np.full(len(t), col))
        ts.append(t)
    x = np.concatenate(xs)
    t = (np.concatenate(ts) * 1e9).astype(np.int64)
    x = np.repeat(x, h)
    y = np.tile(np.arange(h), len(t))
    t = np.repeat(t, h)
    order = np.argsort(t, kind="stable")
    return EventBatch(x[order], y[order], t[order], np.ones(len(t)), w, h)


def _steady_state(b: EventBatch, mode: str = "fire_age") -> tuple[float, float]:
    """(median tau over fired pixels, median brightness of pixels that fired 4-6 ms before the query)."""
    cfg = AtsConfig(tau_u_s=0.05, tau_l_s=0.0005, n_latest=4, tau_mode=mode, **RAW)
    ats = AdaptiveTimeSurface(b.width, b.height, cfg)
    ats.update(b)
    t_q = int(b.t[-1])
    tau = ats.tau_map(t_q)[:, 5:-5]
    img = ats.render_raw(t_q)[:, 5:-5]
    age = (t_q - ats.t_last[:, 5:-5]) * 1e-9
    band = (age > 0.004) & (age < 0.006)
    assert band.any()
    return float(np.nanmedian(tau)), float(np.median(img[band]))


# The paper's intent (faster decay under fast motion and dense texture) holds for the default and the old
# reading of Eq. 2; as printed it is the opposite (test_eq2_as_printed_behaves_the_opposite_way).
INTENT_MODES = ["fire_age", "mean_age"]


@pytest.mark.parametrize("mode", INTENT_MODES)
def test_ats_decays_faster_under_fast_motion_than_slow(mode):
    tau_fast, val_fast = _steady_state(_moving_texture(2000.0, 6.0), mode)
    tau_slow, val_slow = _steady_state(_moving_texture(200.0, 6.0), mode)
    assert tau_fast < tau_slow
    # a pixel that fired 5 ms ago has faded more under fast motion
    assert val_fast < val_slow


@pytest.mark.parametrize("mode", INTENT_MODES)
def test_ats_decays_faster_in_dense_texture_than_sparse(mode):
    tau_dense, val_dense = _steady_state(_moving_texture(500.0, 3.0), mode)
    tau_sparse, val_sparse = _steady_state(_moving_texture(500.0, 20.0), mode)
    assert tau_dense < tau_sparse
    assert val_dense < val_sparse


@pytest.mark.parametrize("mode", INTENT_MODES)
def test_ats_decays_faster_under_dense_random_events_than_sparse(mode):
    w, h = 64, 48
    cfg = AtsConfig(tau_u_s=0.05, tau_l_s=0.001, tau_mode=mode, **RAW)
    dense = _random_events(40_000, w, h, 50_000_000, seed=1)   # ~13 events per pixel in 50 ms
    sparse = _random_events(800, w, h, 50_000_000, seed=2)     # ~0.26 events per pixel
    taus = []
    for b in (dense, sparse):
        ats = AdaptiveTimeSurface(w, h, cfg)
        ats.update(b)
        taus.append(np.nanmedian(ats.tau_map(50_000_000)))
    assert taus[0] < taus[1]


def test_eq2_as_printed_behaves_the_opposite_way():
    """Documents why Eq. 2 as printed is not the default (see the module docstring)."""
    tau_fast, _ = _steady_state(_moving_texture(2000.0, 6.0), "eq2_printed")
    tau_slow, _ = _steady_state(_moving_texture(200.0, 6.0), "eq2_printed")
    assert tau_fast > tau_slow


def _stripe_events(edges_px: list[float], speed_px_s: float, duration_s: float, w: int = 160,
                   h: int = 24) -> EventBatch:
    """Events of the simulator's DVS model (ideal: no threshold mismatch, refractory period or noise, so that
    the test is about the surface, not the sensor) watching bright bands between ``edges_px[0::2]`` and
    ``edges_px[1::2]`` (1-px ramps) translate to the right at ``speed_px_s``, rendered every 0.2 px."""
    model = EventModel(contrast_sigma=0.0, noise_rate_hz=0.0, refractory_s=0.0)
    sensor = EventSensor(model, w, h, np.random.default_rng(0))
    lo, hi = np.array(edges_px[0::2]), np.array(edges_px[1::2])

    def render(t_s: float) -> np.ndarray:
        u = np.arange(w)[:, None] + 0.5 - speed_px_s * t_s  # pattern coordinate of each column
        level = (np.clip(u - lo + 0.5, 0, 1) * np.clip(hi - u + 0.5, 0, 1)).sum(axis=1)
        return np.repeat((0.2 + 0.6 * level)[None, :].astype(np.float32), h, axis=0)

    times = np.linspace(0.0, duration_s, int(speed_px_s * duration_s / 0.2) + 2)
    sensor.reset(render(0.0), 0)
    parts = [sensor.step(render(t), int(round(t * 1e9))) for t in times[1:]]
    return EventBatch.concatenate([p for p in parts if len(p)])


def _trail_rises(b: EventBatch, mode: str, t_ns: int, skip_px: int = 2) -> tuple[float, int]:
    """Largest rise (grey levels) of the rendered profile (blur and median blur included, mean over rows)
    when walking back along a trail, and how many trails were checked. A trail is a run of columns whose
    (median) last event gets older and older away from the edge that passed last; ``skip_px`` columns at
    each end (where the blur mixes in the neighbouring edge) and the fully decayed tail (< 1) are left out."""
    ats = AdaptiveTimeSurface(b.width, b.height, AtsConfig(tau_mode=mode))
    ats.update(b.select(b.t <= t_ns))
    profile = ats.render(t_ns)[3:-3].mean(axis=0)
    t_col = np.median(ats.t_last[3:-3], axis=0)  # NEVER (never fired) sorts as oldest
    worst, trails, x = 0.0, 0, b.width - 1
    while x > 0:
        newest = x
        while x > 0 and t_col[x - 1] < t_col[x]:
            x -= 1
        seg = profile[x + skip_px:newest - skip_px + 1]
        seg = seg[int(np.argmax(seg > 1.0)):] if len(seg) else seg
        if len(seg) > 3:
            worst = max(worst, float(np.max(seg[:-1] - seg[1:])))  # rise when walking from the edge backwards
            trails += 1
        x -= 1
    return worst, trails


DENSE_EDGES = list(np.cumsum(np.random.default_rng(1).uniform(3.0, 9.0, 300)) - 1500.0)  # bands 3-9 px apart


@pytest.mark.parametrize("speed", [150.0, 1000.0, 3000.0])
@pytest.mark.parametrize("scene", ["isolated", "dense"])
def test_default_ats_decays_monotonically_behind_a_moving_edge(scene, speed):
    """Behind an edge the default surface falls steadily: no sign change of the gradient along any trail, for
    an isolated edge (sparse scene) and between the edges of a dense texture, slow and fast (tau_u and tau_l
    bound the decay at 150 and 3000 px/s). Events come from the simulator's DVS model."""
    t_ns = int(min(0.2, 130.0 / speed) * 1e9)  # the leading edge at ~130 px
    edges = [-1000.0, 0.0] if scene == "isolated" else DENSE_EDGES
    b = _stripe_events(edges, speed, t_ns * 1e-9 + 0.01)
    worst, trails = _trail_rises(b, "fire_age", t_ns)
    assert trails >= (1 if scene == "isolated" else 4)
    assert worst <= 1e-3, worst  # float rounding only


@pytest.mark.parametrize("speed", [150.0, 1000.0])
def test_mean_age_leaves_a_notch_behind_an_isolated_edge(speed):
    """Documents why mean_age is no longer the default: a few pixels behind an isolated edge the ring's
    neighbours fired just before the query, tau collapses to tau_l and the profile dips, then climbs back into
    a band at ~255/e where tau grows with the age (the issue's "dark notch and ghost band")."""
    t_ns = int(min(0.2, 130.0 / speed) * 1e9)
    b = _stripe_events([-1000.0, 0.0], speed, t_ns * 1e-9 + 0.01)
    worst, _ = _trail_rises(b, "mean_age", t_ns)
    assert worst > 5.0


@pytest.mark.parametrize("mode", MODES)
def test_every_tau_mode_is_available_behind_the_common_interface(mode):
    b = _random_events(2000, 30, 20, 20_000_000, seed=3)
    surf = make_time_surface("ats", 30, 20, AtsConfig(tau_mode=mode))
    surf.update(b)
    img, tau = surf.render(), surf.tau_map()
    assert img.shape == tau.shape == (20, 30) and float(img.max()) > 0.0
    assert np.all(np.isnan(tau) == ~surf.active_mask())
    assert surf.window_ns() == 30_000_000 and surf.n_events == len(b) and surf.t_latest_ns == int(b.t[-1])
    bad = AtsConfig()
    object.__setattr__(bad, "tau_mode", "fancy")  # the config loader rejects it; the surface must as well
    with pytest.raises(ConfigError):
        AdaptiveTimeSurface(30, 20, bad)


def test_constant_time_surface_is_eq1_with_one_tau():
    w, h = 20, 15
    cfg = AtsConfig(constant_tau_s=0.01, **RAW)
    b = _random_events(500, w, h, 30_000_000, seed=4)
    ts = ConstantTimeSurface(w, h, cfg)
    ts.update(b)
    t_q = int(b.t[-1]) + 1_000_000
    last = np.full((h, w), -1, np.int64)
    for x, y, t in zip(b.x, b.y, b.t):
        last[y, x] = t
    ref = np.where(last >= 0, 255.0 * np.exp(-(t_q - last) * 1e-9 / 0.01), 0.0)
    np.testing.assert_allclose(ts.render_raw(t_q), ref, rtol=1e-5, atol=1e-3)
    assert np.all(np.isnan(ts.tau_map()[last < 0])) and np.all(ts.tau_map()[last >= 0] == np.float32(0.01))


def _reference_sits(b: EventBatch, w: int, h: int, r: int) -> np.ndarray:
    s = np.zeros((h, w), np.int64)
    full = (2 * r + 1) ** 2
    for x, y in zip(b.x.tolist(), b.y.tolist()):
        sp = s[y, x]
        for yy in range(max(0, y - r), min(h, y + r + 1)):
            for xx in range(max(0, x - r), min(w, x + r + 1)):
                if s[yy, xx] >= sp and s[yy, xx] > 0:
                    s[yy, xx] -= 1
        s[y, x] = full
    return s * 255.0 / full


def test_speed_invariant_surface_matches_reference_and_ignores_speed():
    w, h = 25, 20
    cfg = AtsConfig(sits_radius_px=2, **RAW)
    b = _random_events(2000, w, h, 10_000_000, seed=5)
    s = SpeedInvariantTimeSurface(w, h, cfg)
    for part in np.array_split(np.arange(len(b)), 3):
        s.update(b.select(part))
    np.testing.assert_allclose(s.render_raw(), _reference_sits(b, w, h, 2), rtol=1e-6)
    # the same edge at 10x the speed leaves the same surface
    imgs = []
    for speed in (300.0, 3000.0):
        e = _sweeping_edge(speed)
        sits = SpeedInvariantTimeSurface(e.width, e.height, cfg)
        sits.update(e)
        imgs.append(sits.render_raw())
    np.testing.assert_array_equal(imgs[0], imgs[1])


@pytest.mark.parametrize("kind", ["ats", "constant", "sits"])
def test_common_interface_and_smoothing(kind):
    b = _random_events(3000, 40, 30, 20_000_000, seed=9)
    surf = make_time_surface(kind, 40, 30, AtsConfig(blur_ksize=3, median_ksize=3))
    surf.update(b)
    img = surf.render()
    assert img.shape == (30, 40) and img.dtype == np.float32
    assert 0.0 <= float(img.min()) and float(img.max()) <= 255.0
    raw = surf.render_raw()
    assert float(np.abs(np.diff(img, axis=1)).mean()) < float(np.abs(np.diff(raw, axis=1)).mean())
    np.testing.assert_array_equal(img, cv2.medianBlur(cv2.blur(raw, (3, 3)), 3))  # box blur, then median blur
    assert not np.shares_memory(img, surf.render())  # every render is a new image
    surf.reset()
    assert float(surf.render(int(b.t[-1])).max()) == 0.0


def test_out_of_range_and_backwards_events_are_skipped_and_counted():
    ats = AdaptiveTimeSurface(10, 10, AtsConfig(**RAW))
    ats.update(EventBatch([1, 50, 2], [1, 2, 60], [10, 20, 30], [1, 1, 1]))
    ats.update(EventBatch([1], [1], [5], [0]))  # older than that pixel's last event
    assert ats.n_skipped == 3 and ats.t_last[1, 1] == 10
    with pytest.raises(ConfigError):
        make_time_surface("fancy", 10, 10)
    with pytest.raises(ConfigError):
        AdaptiveTimeSurface(0, 10)
