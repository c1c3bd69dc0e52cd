"""Frame clock: when a fixed-rate camera really took its frames, recovered from jittered stamps.

A camera's frames come off a crystal at a fixed period, but a driver without hardware timestamps
stamps each image when it reaches the host (OpenNI's Kinect in the TUM RGB-D benchmark: intervals of
27-40 ms around 33.33 ms, 1.8 ms rms off a straight line). Those 2-4 ms matter at the rotation rates
of a legged robot: 90 deg/s x 2 ms is 0.2 deg, and the velocity ``pose step / stamp interval`` that
the motion model and the rolling-shutter correction use is off by up to 10 %. A straight line
fitted to the last second of stamps against frame numbers recovers the frame clock to a fraction of
a millisecond; frames dropped in transport are bridged (the frame number advances by the rounded
number of periods), and a stamp off the line by more than ``max_residual`` periods (a changed frame
rate, a clock jump, a long gap) starts the fit over. Hardware-stamped cameras (the D455 with global
time) lie on the line already: the clock passes their stamps through to within a few nanoseconds.
"""
from __future__ import annotations

from collections import deque

import numpy as np


class FrameClock:
    """Regularised frame times from image stamps (see the module docstring).

    Args:
        window: frames in the fit (0 = off: stamps are passed through).
        min_frames: frames needed before the fit is used (until then stamps pass through).
        max_residual: a stamp further than this many periods from the line restarts the fit.
        max_gap_periods: a gap longer than this many periods restarts the fit.
    """

    def __init__(self, window: int = 30, min_frames: int = 8, max_residual: float = 0.3,
                 max_gap_periods: float = 10.0) -> None:
        self.window = int(window)
        self.min_frames = max(3, int(min_frames))
        self.max_residual = float(max_residual)
        self.max_gap_periods = float(max_gap_periods)
        self._k: deque[int] = deque(maxlen=max(self.window, 1))
        self._s: deque[int] = deque(maxlen=max(self.window, 1))
        self._line: tuple[float, float] | None = None  # (intercept s, slope s/frame) relative to _s[0], _k[0]
        #: Times the fit started over (rate change, clock jump, long gap).
        self.restarts = 0

    @property
    def period_s(self) -> float | None:
        """The fitted frame period, once the fit is in use."""
        return None if self._line is None else self._line[1]

    def reset(self) -> None:
        """Forget the frames seen so far."""
        self._k.clear()
        self._s.clear()
        self._line = None

    def __call__(self, stamp_ns: int) -> int:
        """The frame time of an image stamped ``stamp_ns`` (the stamp itself until the fit is in use)."""
        stamp_ns = int(stamp_ns)
        if self.window <= 0:
            return stamp_ns
        if not self._s:
            self._start(stamp_ns)
            return stamp_ns
        gap_s = (stamp_ns - self._s[-1]) * 1e-9
        period_s = self._period_guess_s()
        if gap_s <= 0.0 or gap_s > self.max_gap_periods * period_s:
            self._restart(stamp_ns)
            return stamp_ns
        k = self._k[-1] + max(1, int(round(gap_s / period_s)))
        if self._line is not None and abs(self._residual_s(k, stamp_ns)) > self.max_residual * period_s:
            self._restart(stamp_ns)
            return stamp_ns
        self._k.append(k)
        self._s.append(stamp_ns)
        if len(self._s) < self.min_frames:
            return stamp_ns
        self._fit()
        return self._s[0] + int(round(self._at_s(k) * 1e9))

    # ------------------------------------------------------------------ internals
    def _start(self, stamp_ns: int) -> None:
        self.reset()
        self._k.append(0)
        self._s.append(stamp_ns)

    def _restart(self, stamp_ns: int) -> None:
        self.restarts += 1
        self._start(stamp_ns)

    def _period_guess_s(self) -> float:
        """The fitted period, or before the fit the median interval per frame step seen so far."""
        if self._line is not None:
            return self._line[1]
        if len(self._s) < 2:
            return np.inf  # one stamp: any positive gap is the first period
        s = np.diff(np.asarray(self._s, dtype=np.int64)) * 1e-9
        k = np.diff(np.asarray(self._k, dtype=np.int64))
        return float(np.median(s / k))

    def _at_s(self, k: int) -> float:
        a, b = self._line
        return a + b * (k - self._k[0])

    def _residual_s(self, k: int, stamp_ns: int) -> float:
        return (stamp_ns - self._s[0]) * 1e-9 - self._at_s(k)

    def _fit(self) -> None:
        k = np.asarray(self._k, dtype=np.float64) - self._k[0]
        s = (np.asarray(self._s, dtype=np.int64) - self._s[0]) * 1e-9
        km, sm = k.mean(), s.mean()
        slope = float(np.sum((k - km) * (s - sm)) / np.sum((k - km) ** 2))
        self._line = (float(sm - slope * km), slope)


__all__ = ["FrameClock"]
