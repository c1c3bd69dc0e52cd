"""Event pixel selection (Section II-B, Eq. 3): mask, window, threshold and spacing rules."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import AtsConfig, EventSelectionConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.selection import (
    ats_mask,
    select_event_pixels,
    select_event_pixels_detailed,
)
from atsvo_ros.core.events.time_surface import AdaptiveTimeSurface
from atsvo_ros.errors import ImageError

W, H = 80, 60
T = 1_000_000_000
WINDOW = 40_000_000


def _events_at(xs, ys, t_ns) -> EventBatch:
    n = len(xs)
    return EventBatch(np.asarray(xs), np.asarray(ys), np.full(n, t_ns), np.ones(n), W, H)


def _smooth_random_ats(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.uniform(0, 255, (H, W)).astype(np.float32)
    import cv2

    return cv2.GaussianBlur(img, (0, 0), 2.0) * 2.0 - 100.0


def _all_pixel_events(t_ns: int) -> EventBatch:
    yy, xx = np.mgrid[0:H, 0:W]
    return _events_at(xx.ravel(), yy.ravel(), t_ns)


@pytest.mark.parametrize("d", [0, 1, 3, 6])
def test_minimum_distance_in_x_and_y(d):
    ats = np.clip(_smooth_random_ats(d), 0, 255).astype(np.float32)
    cfg = EventSelectionConfig(h=0.0, alpha=1.0, min_distance_px=d, max_points=100000, border_px=0)
    sel = select_event_pixels_detailed(ats, _all_pixel_events(T), T, WINDOW, cfg)
    pts = sel.selected
    assert len(pts) > 10
    dx = np.abs(pts[:, None, 0] - pts[None, :, 0])
    dy = np.abs(pts[:, None, 1] - pts[None, :, 1])
    close = (dx <= d) & (dy <= d)
    np.fill_diagonal(close, False)
    assert not close.any()
    # greedy by score: every candidate that passed but was not kept has a better kept pixel within d
    kept = {tuple(p) for p in pts.tolist()}
    cand, score = sel.candidates, sel.score
    best_of = {tuple(p): s for p, s in zip(cand.tolist(), score.tolist())}
    for (x, y), ok, s in zip(cand.tolist(), sel.passed.tolist(), score.tolist()):
        if ok and (x, y) not in kept:
            blockers = [q for q in pts.tolist() if abs(q[0] - x) <= d and abs(q[1] - y) <= d]
            assert blockers and max(best_of[tuple(q)] for q in blockers) >= s
    # best first
    assert np.all(np.diff([best_of[tuple(p)] for p in pts.tolist()]) <= 1e-4)


@pytest.mark.parametrize("alpha,h", [(1.0, 90.0), (0.0, 120.0), (5.0, 150.0)])
def test_threshold_rule_of_eq3(alpha, h):
    ats = np.clip(_smooth_random_ats(1), 0, 255).astype(np.float32)
    cfg = EventSelectionConfig(h=h, alpha=alpha, min_distance_px=0, max_points=100000, border_px=0,
                               mask_median_ksize=1)
    sel = select_event_pixels_detailed(ats, _all_pixel_events(T), T, WINDOW, cfg)
    gy, gx = np.gradient(ats.astype(np.float64))
    score = ats + alpha * np.hypot(gx, gy)
    expected = ats_mask(ats, 1) & (score > h)
    got = np.zeros_like(expected)
    got[sel.selected[:, 1], sel.selected[:, 0]] = True
    # with d = 0 the spacing rule only removes duplicates, so the selection is exactly Eq. 3 on the mask
    near = np.abs(score - h) < 1e-3  # float32 vs float64 ties at the threshold
    np.testing.assert_array_equal(got[~near], expected[~near])
    assert got.any()


def test_mask_drops_isolated_bright_noise_and_black_areas():
    ats = np.zeros((H, W), np.float32)
    ats[20:40, 20:40] = 200.0      # a bright region
    ats[5, 60] = 255.0             # one isolated bright pixel: removed by the median blur
    ev = _events_at([30, 60, 70], [30, 5, 50], T)  # region, noise pixel, black area
    cfg = EventSelectionConfig(h=0.0, alpha=0.0, min_distance_px=0, border_px=0, mask_median_ksize=5)
    sel = select_event_pixels_detailed(ats, ev, T, WINDOW, cfg)
    assert sel.mask[30, 30] and not sel.mask[5, 60] and not sel.mask[50, 70]
    assert sel.selected.tolist() == [[30, 30]]


def test_only_events_of_the_last_window_fraction_are_candidates():
    ats = np.full((H, W), 150.0, np.float32)
    ats[:, : W // 2] = 0.0  # make the median of the blurred image below 150
    cfg = EventSelectionConfig(h=100.0, alpha=0.0, window_fraction=0.25, min_distance_px=0, border_px=0)
    old = _events_at([50], [10], T - WINDOW // 2)            # half a window ago: too old
    edge = _events_at([52], [10], T - WINDOW // 4 + 1)       # just inside the last quarter
    future = _events_at([54], [10], T + 1)                   # after the ATS time
    out_of_range = _events_at([500], [10], T)                # outside the image
    b = EventBatch.concatenate([old, edge, future, out_of_range])
    assert select_event_pixels(ats, b, T, WINDOW, cfg).tolist() == [[52, 10]]


def test_max_points_and_border():
    ats = np.full((H, W), 200.0, np.float32)
    ats[:, :10] = 0.0
    cfg = EventSelectionConfig(h=100.0, alpha=0.0, min_distance_px=2, max_points=7, border_px=5)
    pts = select_event_pixels(ats, _all_pixel_events(T), T, WINDOW, cfg)
    assert len(pts) == 7
    assert pts[:, 0].min() >= 5 and pts[:, 1].min() >= 5 and pts[:, 0].max() < W - 5 and pts[:, 1].max() < H - 5
    with pytest.raises(ImageError):
        select_event_pixels(np.zeros((3, 4, 2)), _all_pixel_events(T), T, WINDOW)
    empty = select_event_pixels(ats, EventBatch.empty(W, H), T, WINDOW, cfg)
    assert empty.shape == (0, 2)


def test_selection_on_an_ats_of_moving_edges_lands_on_recent_edges():
    # three vertical bars moving right at 1000 px/s for 60 ms
    xs, ys, ts = [], [], []
    for k in range(60):
        t = k * 1_000_000
        for bar in (5, 30, 55):
            xs.append(np.full(H, bar + k // 3))
            ys.append(np.arange(H))
            ts.append(np.full(H, t))
    b = EventBatch(np.concatenate(xs), np.concatenate(ys), np.concatenate(ts), np.ones(60 * 3 * H), W, H)
    ats = AdaptiveTimeSurface(W, H, AtsConfig())
    ats.update(b)
    t_q = int(b.t[-1])
    cfg = EventSelectionConfig()
    pts = select_event_pixels(ats.render(t_q), b, t_q, ats.window_ns(), cfg)
    assert len(pts) > 5
    recent_cols = set(np.unique(b.x[b.t > t_q - cfg.window_fraction * ats.window_ns()]).tolist())
    assert set(pts[:, 0].tolist()) <= recent_cols


def test_the_thinning_kernel_sees_one_array_layout_whatever_fired():
    """One fired pixel or many, the kernel gets C-contiguous arrays: a second layout would compile mid-run (on a
    cold numba cache a 1-3 s stall with the GIL held) where the nodes' warm-up compiled only the first."""
    from atsvo_ros.core.events._selection_kernels import _thin

    ats = _smooth_random_ats(1)
    for n in (0, 1, 2, 300):
        fired = np.zeros((H, W), bool)
        fired.flat[np.random.default_rng(n).choice(H * W, n, replace=False)] = True
        select_event_pixels(ats, fired, T, WINDOW)
    layouts = {arg.layout for sig in _thin.signatures for arg in sig[:2]}
    assert layouts == {"C"}, _thin.signatures
