"""The frame clock: host-stamp jitter removed, dropped frames bridged, rate changes and clock jumps restart it."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.frame_clock import FrameClock

PERIOD_NS = 33_329_692  # a Kinect's measured frame period (TUM fr1_rpy)


def _exposures(n: int, t0_ns: int = 1_305_031_000_000_000_000) -> np.ndarray:
    return t0_ns + np.round(np.arange(n) * PERIOD_NS).astype(np.int64)


def _host_stamps(exposures: np.ndarray, jitter_s: float, seed: int = 0) -> np.ndarray:
    """Stamps taken on arrival: a half-normal delay after each exposure."""
    rng = np.random.default_rng(seed)
    return exposures + np.round(np.abs(rng.standard_normal(len(exposures))) * jitter_s * 1e9).astype(np.int64)


def _run(clock: FrameClock, stamps: np.ndarray) -> np.ndarray:
    return np.array([clock(int(s)) for s in stamps], np.int64)


def test_hardware_stamps_pass_through() -> None:
    t = _exposures(200)
    out = _run(FrameClock(30), t)
    assert np.max(np.abs(out - t)) <= 1


def test_off_passes_stamps_through() -> None:
    s = _host_stamps(_exposures(50), 0.002)
    assert np.array_equal(_run(FrameClock(0), s), s)


def test_host_stamp_jitter_is_removed() -> None:
    t = _exposures(600)
    s = _host_stamps(t, 0.002)
    out = _run(FrameClock(30), s)
    settled = slice(30, None)
    # the mean delay stays (a constant latency is not observable from the stamps); the jitter goes
    err_raw = (s - t)[settled] * 1e-6
    err = (out - t)[settled] * 1e-6
    assert np.std(err_raw) > 1.0  # ms: 2 ms half-normal
    assert np.std(err) < 0.35 * np.std(err_raw)
    assert abs(np.mean(err) - np.mean(err_raw)) < 0.3
    # the intervals the motion model divides by are right to a few percent, not ~10 %
    assert np.max(np.abs(np.diff(out[settled]) - PERIOD_NS)) < 0.05 * PERIOD_NS
    assert np.max(np.abs(np.diff(s[settled]) - PERIOD_NS)) > 0.1 * PERIOD_NS


def test_dropped_frames_are_bridged() -> None:
    t = _exposures(600)
    keep = np.random.default_rng(1).random(600) > 0.3
    keep[:10] = True
    s = _host_stamps(t, 0.002)[keep]
    clock = FrameClock(30)
    out = _run(clock, s)
    assert clock.restarts == 0
    err = (out - t[keep])[30:] * 1e-6
    assert np.std(err) < 0.5
    assert abs(clock.period_s - PERIOD_NS * 1e-9) < 2e-5


def test_a_new_frame_rate_restarts_the_fit() -> None:
    fast = _exposures(100)
    slow = fast[-1] + np.round((np.arange(1, 101)) * 2 * PERIOD_NS + 0.4 * PERIOD_NS).astype(np.int64)
    t = np.concatenate([fast, slow])
    clock = FrameClock(30)
    out = _run(clock, _host_stamps(t, 0.001))
    assert clock.restarts >= 1
    assert abs(clock.period_s - 2 * PERIOD_NS * 1e-9) < 1e-4
    assert np.all(np.diff(out) > 0)
    assert np.std((out - t)[150:] * 1e-6) < 0.3


def test_a_clock_jump_back_restarts_and_returns_the_stamp() -> None:
    t = _exposures(60)
    clock = FrameClock(30)
    _run(clock, t)
    back = int(t[0] - 10 * PERIOD_NS)
    assert clock(back) == back
    assert clock.restarts == 1
    assert clock.period_s is None  # the fit starts over
