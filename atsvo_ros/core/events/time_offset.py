"""The event camera's clock offset from motion: event counts correlated with the colour images' change.

An event camera and a D455 on different clocks (or host-stamped by different drivers) put the same
motion at different times. Both sensors see the same brightness change: the events counted between
two colour frames grow with how much the log image changed between them. So the offset ``d`` that
makes the event counts over the frame intervals shifted by ``-d`` best match the image change is the
event clock's offset (added to event times, like ``event_camera.time_offset_s``). This is the
signal-correlation idea of camera-IMU time calibration (Kelly & Sukhatme, "A General Framework for
Temporal Calibration of Multiple Proprioceptive and Exteroceptive Sensors", ISER 2010), with the
image change in place of the gyro: it needs no IMU and no map.

Motion makes the signal: a robot standing still gives none, and a gait repeats itself, so an
estimate is only taken when the peak is strong and stands clear of the next-best peak.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Grid stride for the image change (a 640x480 image gives 160x120 samples: ~0.2 ms).
CHANGE_STRIDE = 4


@dataclass(frozen=True)
class OffsetEstimate:
    """The correlation peak over the searched offsets.

    Attributes:
        offset_s: add this to the event times (what ``event_camera.time_offset_s`` holds).
        correlation: Pearson correlation of event counts and image change at the peak.
        runner_up: the best correlation at another local maximum at least ``separation_s`` away (the
            peak's own when it lies at the search's edge: no margin).
        intervals: frame intervals used.
    """

    offset_s: float
    correlation: float
    runner_up: float
    intervals: int

    def confident(self, min_correlation: float, min_margin: float) -> bool:
        """Strong peak, clear of the next one (a gait's period gives secondary peaks)."""
        return self.correlation >= min_correlation and self.correlation - self.runner_up >= min_margin


def image_change(previous: np.ndarray, current: np.ndarray) -> float:
    """Mean absolute change of log brightness between two images (grey or RGB uint8, same size).

    Events fire per contrast step of log brightness, so this is the colour camera's view of the
    quantity the event count measures.
    """
    a = _log_grey(previous)
    b = _log_grey(current)
    if a.shape != b.shape:
        raise ValueError(f"images of different sizes: {previous.shape} and {current.shape}")
    return float(np.mean(np.abs(b - a)))


def _log_grey(image: np.ndarray) -> np.ndarray:
    sub = np.asarray(image)[::CHANGE_STRIDE, ::CHANGE_STRIDE]
    grey = sub.mean(axis=2) if sub.ndim == 3 else sub
    return np.log1p(grey.astype(np.float32))


def estimate_offset(bin_t0_ns: int, bin_ns: int, counts: np.ndarray, edges_ns: np.ndarray, change: np.ndarray,
                    search_s: float, step_s: float = 0.001, separation_s: float = 0.03,
                    differenced: bool = False) -> OffsetEstimate | None:
    """The event clock offset that best lines the event counts up with the image change.

    Args:
        bin_t0_ns: start time of ``counts[0]``'s bin.
        bin_ns: bin width of ``counts``.
        counts: events per bin (time order).
        edges_ns: colour frame stamps (K + 1, increasing): interval k is ``(edges[k], edges[k + 1]]``.
        change: image change over each interval (K,), from :func:`image_change`.
        search_s: offsets searched, ``-search_s`` to ``+search_s``.
        step_s: search step; the peak is refined to a fraction of it by a parabola.
        separation_s: how far another peak must be to count as the runner-up.

    Returns:
        The estimate, or None when the intervals shifted by every offset do not fit inside the
        counted span, or either signal is flat (no motion).
    """
    edges = np.asarray(edges_ns, dtype=np.int64)
    change = np.asarray(change, dtype=np.float64)
    if len(edges) != len(change) + 1 or len(change) < 3:
        return None
    lags_ns = np.round(np.arange(-search_s, search_s + step_s / 2, step_s) * 1e9).astype(np.int64)
    # the counts' clock is d behind the frames' when the offset is d: interval k holds events at edges - d
    lo_ns, hi_ns = edges[0] - lags_ns[-1], edges[-1] - lags_ns[0]
    if lo_ns < bin_t0_ns or hi_ns > bin_t0_ns + bin_ns * len(counts):
        return None
    cumulative = np.concatenate(([0.0], np.cumsum(counts, dtype=np.float64)))
    at = (edges[None, :] - lags_ns[:, None] - bin_t0_ns) / bin_ns  # fractional bin positions, (L, K + 1)
    n_events = np.diff(np.interp(at, np.arange(len(cumulative)), cumulative), axis=1)  # (L, K)
    if differenced:
        change, n_events = np.diff(change), np.diff(n_events, axis=1)
    ref = change - change.mean()
    dev = n_events - n_events.mean(axis=1, keepdims=True)
    denom = np.linalg.norm(dev, axis=1) * np.linalg.norm(ref)
    if not np.all(denom > 0):
        return None
    corr = dev @ ref / denom
    i = int(np.argmax(corr))
    offset = float(lags_ns[i]) * 1e-9
    if 0 < i < len(corr) - 1:  # parabola through the peak and its neighbours
        c0, c1, c2 = corr[i - 1], corr[i], corr[i + 1]
        curvature = c0 - 2 * c1 + c2
        if curvature < 0:
            offset += 0.5 * (c0 - c2) / curvature * step_s
    # local maxima, and the search's ends (a peak beyond them would be at least as high)
    peaks = np.concatenate(([0], np.flatnonzero((corr[1:-1] >= corr[:-2]) & (corr[1:-1] >= corr[2:])) + 1,
                            [len(corr) - 1]))
    far = peaks[np.abs(lags_ns[peaks] - lags_ns[i]) > separation_s * 1e9]
    runner_up = float(corr[far].max()) if len(far) else -1.0
    if i in (0, len(corr) - 1):
        runner_up = float(corr[i])  # at the search's edge: the slope of a peak beyond it, not a peak
    return OffsetEstimate(offset, float(corr[i]), runner_up, len(change))


__all__ = ["CHANGE_STRIDE", "OffsetEstimate", "estimate_offset", "image_change"]
