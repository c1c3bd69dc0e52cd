"""The event clock offset from event counts against image change (core/events/time_offset.py)."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.events.time_offset import estimate_offset, image_change

FRAME_NS = 33_333_333
BIN_NS = 1_000_000


def _stream(offset_s: float, change_of_t, n_frames: int = 90, seed: int = 0):
    """Frame stamps, the image change per interval and 1 ms event counts stamped ``-offset_s`` off.

    The event rate follows ``change_of_t`` (a function of true time, s) like a sensor's events follow
    the brightness change; the frames integrate the same rate over their intervals.
    """
    rng = np.random.default_rng(seed)
    t0_ns = 1_000_000_000
    edges = t0_ns + np.arange(n_frames + 1, dtype=np.int64) * FRAME_NS
    fine_t = np.arange(0, (n_frames + 30) * FRAME_NS, BIN_NS, dtype=np.int64) + t0_ns - 15 * FRAME_NS
    rate = change_of_t((fine_t - t0_ns) * 1e-9)  # events per ms at true time fine_t
    counts = rng.poisson(rate)
    change = np.array([rate[(fine_t > a) & (fine_t <= b)].sum() for a, b in zip(edges[:-1], edges[1:])])
    change = 1e-3 * (change + rng.normal(0, 0.1 * change.std(), len(change)))  # other units, 10 % noise
    # the event clock reads true time - offset: its bins start offset earlier
    return int(fine_t[0] - round(offset_s * 1e9)), counts, edges, change


def _gait(t):
    """Bursts of motion at irregular times, as steps and landings give."""
    rng = np.random.default_rng(7)
    centres = np.cumsum(rng.uniform(0.15, 0.5, 40)) - 1.0
    return 20 + 200 * np.exp(-0.5 * ((t[:, None] - centres[None]) / 0.03) ** 2).sum(axis=1)


@pytest.mark.parametrize("offset_s", [-0.07, 0.0, 0.043])
def test_the_offset_is_recovered_to_a_millisecond_or_two(offset_s):
    t0, counts, edges, change = _stream(offset_s, _gait)
    est = estimate_offset(t0, BIN_NS, counts, edges[15:80], change[15:79], 0.1, differenced=True)
    assert est is not None and est.confident(0.5, 0.02), est
    assert est.offset_s == pytest.approx(offset_s, abs=0.002)


def test_without_motion_there_is_no_estimate():
    t0, counts, edges, change = _stream(0.02, lambda t: np.full_like(t, 30.0))
    change[:] = 1.0  # a still camera: the image does not change
    assert estimate_offset(t0, BIN_NS, counts, edges[15:80], change[15:79], 0.1) is None


def test_a_periodic_motion_searched_beyond_half_its_period_is_not_trusted():
    period_s = 0.2
    t0, counts, edges, change = _stream(0.03, lambda t: 50 + 40 * np.sin(2 * np.pi * t / period_s))
    est = estimate_offset(t0, BIN_NS, counts, edges[15:80], change[15:79], 0.3, differenced=True)
    assert est is not None and not est.confident(0.5, 0.02), est  # the peak one period away is as high


def test_intervals_outside_the_counted_span_give_no_estimate():
    t0, counts, edges, change = _stream(0.0, _gait)
    # counting began 0.5 s before the first frame: offsets up to 0.6 s would need events from before it
    assert estimate_offset(t0, BIN_NS, counts, edges, change, 0.6) is None
    assert estimate_offset(t0, BIN_NS, counts, edges, change, 0.4) is not None


def test_image_change_is_the_mean_log_brightness_change():
    rng = np.random.default_rng(1)
    a = rng.integers(0, 200, (48, 64, 3), dtype=np.uint8)
    assert image_change(a, a) == 0.0
    brighter = (a.astype(np.int32) * 2).clip(0, 255).astype(np.uint8)
    assert image_change(a, brighter) > image_change(a, a + 1) > 0.0
    assert image_change(a[..., 0], a[..., 0]) == 0.0  # grey images too
    with pytest.raises(ValueError, match="different sizes"):
        image_change(a, a[:40])


def test_a_peak_at_the_edge_of_the_search_is_not_trusted():
    t0, counts, edges, change = _stream(0.08, _gait)
    est = estimate_offset(t0, BIN_NS, counts, edges[15:80], change[15:79], 0.05, differenced=True)
    assert est is not None and est.offset_s == pytest.approx(0.05, abs=1e-3)
    assert est.runner_up == est.correlation and not est.confident(0.0, 0.01)  # no margin
