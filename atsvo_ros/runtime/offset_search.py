"""The event clock's offset estimated at start-up, when ``event_camera.time_offset_search_s`` asks for it.

Two drivers on one host stamp their messages with different latencies, and a camera on its own clock
keeps a small offset after the coarse move of :mod:`.clock_check`: events then reach the wrong frame
by tens of milliseconds, which :class:`~.clock_check.ClockCheck` (over a second) cannot see. Here the
events placed so far are counted in 1 ms bins and each colour image's log-brightness change is
measured; every :data:`EVERY` frames, from :data:`MIN_FRAMES` on, the offset within
``+-time_offset_search_s`` that lines the two up is computed
(:func:`~atsvo_ros.core.events.time_offset.estimate_offset`). Two successive estimates that agree
within :data:`AGREE_S`, each with a clear peak, are taken: the event times move by it from then on
(:meth:`.clock_check.EventClock.adjust`), said once. Until then events are placed with the configured
offset. With no usable motion after :data:`MAX_FRAMES` frames the search ends and says so.

A gait repeats: with a search wider than half the gait's period, the neighbouring period's peak
competes with the true one, the estimates disagree and none is taken (the simulator's bound repeats
every ~0.38 s).
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.time_offset import OffsetEstimate, estimate_offset, image_change
from atsvo_ros.runtime.problems import ProblemLog

#: Event count bin.
BIN_NS = 1_000_000
#: Frames before the first estimate, and frames between estimates.
MIN_FRAMES = 45
EVERY = 15
#: The search ends (said once) when no estimate was taken after this many frames.
MAX_FRAMES = 900
#: Two successive estimates this close are taken (their mean).
AGREE_S = 0.003
#: A peak this strong, this far above the next local maximum, counts.
MIN_CORRELATION = 0.5
MIN_MARGIN = 0.02


class EventOffsetSearch:
    """Collects event counts and image change until the event clock's offset is known (module docstring)."""

    def __init__(self, search_s: float, problems: ProblemLog) -> None:
        self.search_s = float(search_s)
        self._problems = problems
        self.active = self.search_s > 0
        self.estimates: list[OffsetEstimate] = []  #: every estimate computed, for reports and tests
        self.offset_s: float | None = None  #: the offset taken (added to the configured one)
        self._t0_ns: int | None = None
        self._counts = np.zeros(0, np.int64)
        self._stamps: list[int] = []
        self._changes: list[float] = []
        self._span = 0  # bins of _counts in use
        self._previous: np.ndarray | None = None
        self._previous_stamp_ns = 0

    def add_events(self, batch: EventBatch) -> None:
        """Events as placed (configured offset applied)."""
        if not self.active or not len(batch):
            return
        if self._t0_ns is None:
            self._t0_ns = batch.t_first_ns - batch.t_first_ns % BIN_NS
        bins = (batch.t - self._t0_ns) // BIN_NS
        bins = bins[bins >= 0]
        if len(bins):
            lo = int(bins.min())
            hist = np.bincount(bins - lo)
            end = lo + len(hist)
            if end > len(self._counts):  # grow geometrically: one copy per doubling, not per message
                grown = np.zeros(max(end, 2 * len(self._counts)), np.int64)
                grown[:len(self._counts)] = self._counts
                self._counts = grown
            self._span = max(self._span, end)
            self._counts[lo:end] += hist

    def add_image(self, stamp_ns: int, image: np.ndarray) -> int | None:
        """A colour image; returns the offset to add to event times (ns) once it is known, else None."""
        if not self.active:
            return None
        stamp = int(stamp_ns)
        previous = self._previous
        if previous is not None and stamp <= self._previous_stamp_ns:
            return None  # out of order or repeated: the runtime skips it too
        if previous is not None and previous.shape == image.shape:
            if not self._stamps:
                self._stamps.append(self._previous_stamp_ns)
            self._stamps.append(stamp)
            self._changes.append(image_change(previous, image))
        elif previous is not None:  # the image size changed: the intervals start over
            self._stamps.clear()
            self._changes.clear()
        self._previous, self._previous_stamp_ns = image, stamp
        n = len(self._changes)
        if n < MIN_FRAMES or n % EVERY:
            return None
        if n >= MAX_FRAMES:
            self.active = False
            self._problems.report("event_offset_not_estimated", f"the event clock offset could not be estimated "
                                  f"over {n} frames (no clear correlation peak within +-{self.search_s:g} s: too "
                                  "little motion, or a search wider than half the gait's period): event_camera."
                                  "time_offset_s is used as configured", level="warn")
            return None
        return self._estimate()

    def _estimate(self) -> int | None:
        edges = np.asarray(self._stamps, np.int64)
        change = np.asarray(self._changes)
        # the intervals whose events, shifted by any searched offset, fall inside the counted span
        if self._t0_ns is None:
            return None
        counts = self._counts[:self._span]
        span_end = self._t0_ns + BIN_NS * len(counts)
        margin_ns = int(self.search_s * 1e9) + BIN_NS
        keep = (edges >= self._t0_ns + margin_ns) & (edges <= span_end - margin_ns)
        first, last = np.flatnonzero(keep)[[0, -1]] if keep.any() else (0, 0)
        if last - first < MIN_FRAMES // 2:
            return None
        est = estimate_offset(self._t0_ns, BIN_NS, counts, edges[first:last + 1], change[first:last],
                              self.search_s, differenced=True)
        if est is None or not est.confident(MIN_CORRELATION, MIN_MARGIN):
            return None
        self.estimates.append(est)
        if len(self.estimates) < 2 or abs(self.estimates[-1].offset_s - self.estimates[-2].offset_s) > AGREE_S:
            return None
        self.active = False
        self.offset_s = 0.5 * (self.estimates[-1].offset_s + self.estimates[-2].offset_s)
        self._counts, self._span = np.zeros(0, np.int64), 0
        self._problems.report("event_offset_estimated", f"event clock offset estimated: {self.offset_s:+.4f} s "
                              f"(correlation of event counts and image change {est.correlation:.2f}, next peak "
                              f"{est.runner_up:.2f}, over {est.intervals} frames); event times moved by it from "
                              "now on", level="info")
        return int(round(self.offset_s * 1e9))


__all__ = ["EventOffsetSearch"]
