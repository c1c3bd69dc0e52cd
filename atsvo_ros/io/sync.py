"""FrameAssembler: pair colour and depth images by stamp and cut the event stream at frame stamps.

ROS-free and incremental, so the replay tool and the ROS tracking node share it: feed images and
event batches in arrival order (any interleaving), collect ``(RgbdFrame, EventBatch)`` pairs as
they become complete. A colour image is paired with the nearest depth image within
``rig.sync_tolerance_s`` once no nearer depth can still arrive; unpaired images are dropped and
counted. With events enabled, a pair is released once the event stream has advanced to its stamp,
together with every event in ``(previous frame stamp, frame stamp]``; if the event stream stalls for
more than ``max_event_wait_s`` beyond a waiting frame, the frame is released with what has arrived
(counted), so a silent event camera never blocks tracking.

Stalled means behind in stamp time *and*, given an arrival ``clock`` (the live node), silent for
``max_event_wait_s`` of that clock. Stamp time alone misjudges a live node that was starved of CPU:
its subscriptions' backlogs drain one message per topic per executor cycle, so 30 Hz images catch up
in stamp time long before a 1 kHz event stream does, though no event is missing. Without a clock (a
bag replay, fed in log-time order) stamp time is the arrival time.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from atsvo_ros.config import RigConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.io.images import colour_from_msg, depth_from_msg, stamp_ns


@dataclass
class SyncStats:
    """What the assembler had to drop or release early, and what never reached it."""

    frames: int = 0
    dropped_rgb: int = 0
    dropped_depth: int = 0
    released_without_events: int = 0
    late_events: int = 0
    clock_jumps: int = 0
    dropped_events: int = 0
    #: images missing from the streams, from gaps in their stamps (lost in transport, or never sent)
    missing_rgb: int = 0
    missing_depth: int = 0


def _percentile_25(values: Iterable[int]) -> int:
    """``int(np.percentile(values, 25))``, exactly (numpy's linear rule), in plain Python: called for every IMU
    sample and image, numpy's overhead on 32 values was a tenth of the node's executor thread (py-spy)."""
    v = sorted(values)
    index = 0.25 * (len(v) - 1)
    lo = int(index)
    t = index - lo
    a, b = float(v[lo]), float(v[min(lo + 1, len(v) - 1)])
    return int(b - (b - a) * (1.0 - t)) if t >= 0.5 else int(a + (b - a) * t)


class StampGaps:
    """Counts the images missing from a periodic stream from gaps between the stamps that arrive.

    Best-effort transport loses images without telling the subscriber; a camera's stamps are periodic,
    so a gap of k periods means k - 1 images missing. The period is a low percentile of the recent
    intervals (robust to losses of up to about three in four); an image that arrives late into a gap
    takes one back; a stamp far behind (a clock jump, a bag loop) starts over.
    """

    WINDOW = 32  # recent intervals kept for the period
    GAP = 1.5  # an interval this many periods long (or more) holds missing images

    def __init__(self, clock_jump_ns: int = 1_000_000_000) -> None:
        self.missing = 0
        self._clock_jump_ns = int(clock_jump_ns)
        self._newest: int | None = None
        self._intervals: deque[int] = deque(maxlen=self.WINDOW)

    @property
    def period_ns(self) -> int | None:
        """The stream's period as measured (None before three intervals)."""
        if len(self._intervals) < 3:
            return None
        return _percentile_25(self._intervals)

    def add(self, stamp_ns: int) -> None:
        """One image's stamp, in arrival order."""
        t = int(stamp_ns)
        if self._newest is None or t < self._newest - self._clock_jump_ns:
            self._newest = t
            self._intervals.clear()
            return
        if t <= self._newest:
            if t < self._newest and self.missing > 0:
                self.missing -= 1  # late into a gap counted as missing (a duplicate stamp is not)
            return
        dt = t - self._newest
        period = self.period_ns
        if period is not None and period > 0 and dt >= self.GAP * period:
            self.missing += int(round(dt / period)) - 1
        else:
            self._intervals.append(dt)
        self._newest = t


class FrameAssembler:
    """Incremental RGB/depth pairing and event cutting (see the module docstring)."""

    #: Data this far behind the newest stamp of its own stream (images, or events) is a clock jump (a bag
    #: loop, a simulator restart): the assembler starts over instead of calling everything that follows
    #: late. Two streams this far apart are on different clocks, not jumping (the runtime says so).
    CLOCK_JUMP_NS = 1_000_000_000

    def __init__(self, rig: RigConfig, with_events: bool = True, max_event_wait_s: float = 0.25,
                 max_pending: int = 30, max_buffered_events: int = 5_000_000,
                 clock: Callable[[], int] | None = None) -> None:
        """See the module docstring; ``clock`` gives arrival times in ns (e.g. ``time.monotonic_ns``)."""
        self.rig = rig
        self.clock = clock
        self.with_events = with_events
        self.tol_ns = int(round(rig.sync_tolerance_s * 1e9))
        self.max_wait_ns = int(round(max_event_wait_s * 1e9))
        self.max_pending = max_pending
        #: events waiting for a frame beyond this are dropped, oldest first (no frames for a while, a flood):
        #: the core keeps only the newest anyway, and the buffer must not grow with the outage
        self.max_buffered_events = int(max_buffered_events)
        self._n_events = 0
        self.stats = SyncStats()
        self._rgb: deque[tuple[int, np.ndarray]] = deque()
        self._depth: deque[tuple[int, np.ndarray]] = deque()
        self._pairs: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self._events: list[EventBatch] = []
        self._event_mark_ns: int | None = None  # the event stream is complete up to here
        self._events_heard_ns: int | None = None  # arrival time (``clock``) of the last event message
        self._last_cut_ns: int | None = None
        self._newest_ns = -(2**63)
        # per stream: a clock jump is a stream's own stamps going back, not two streams on different clocks
        self._newest_img_ns = self._newest_ev_ns = -(2**63)
        self._gaps_rgb, self._gaps_depth = StampGaps(self.CLOCK_JUMP_NS), StampGaps(self.CLOCK_JUMP_NS)

    # ------------------------------------------------------------------ input
    def add_rgb(self, stamp_ns: int, rgb: np.ndarray) -> None:
        """A colour (H, W, 3 RGB uint8) or grey image at its header stamp."""
        self._gaps_rgb.add(stamp_ns)
        self.stats.missing_rgb = self._gaps_rgb.missing
        self._insert(self._rgb, int(stamp_ns), rgb)
        self._match()

    def add_depth(self, stamp_ns: int, depth_m: np.ndarray) -> None:
        """A depth image in float32 metres (0 = invalid) aligned to the colour image."""
        self._gaps_depth.add(stamp_ns)
        self.stats.missing_depth = self._gaps_depth.missing
        self._insert(self._depth, int(stamp_ns), depth_m)
        self._match()

    def add_rgb_msg(self, msg: Any) -> None:
        """sensor_msgs/Image or CompressedImage (rclpy or rosbags)."""

        self.add_rgb(stamp_ns(msg), colour_from_msg(msg))

    def add_depth_msg(self, msg: Any) -> None:
        """Depth image message: 16UC1 scaled by ``rig.depth_scale_m``, 32FC1 metres, range-checked."""

        self.add_depth(stamp_ns(msg), depth_from_msg(msg, self.rig.depth_scale_m, self.rig.depth_min_m,
                                                     self.rig.depth_max_m))

    def add_events(self, batch: EventBatch, complete_to_ns: int | None = None) -> None:
        """Events in time order; ``complete_to_ns`` (e.g. the message stamp) says the stream reached it."""
        if self.clock is not None:
            self._events_heard_ns = self.clock()
        if len(batch) and batch.t_first_ns < self._newest_ev_ns - self.CLOCK_JUMP_NS:
            self._restart_clock()
        if len(batch):
            self._newest_ev_ns = max(self._newest_ev_ns, batch.t_last_ns)
        if len(batch):
            if self._last_cut_ns is not None and batch.t_first_ns <= self._last_cut_ns:
                late = batch.t <= self._last_cut_ns
                self.stats.late_events += int(np.count_nonzero(late))
                batch = batch.select(~late)
            if len(batch):
                self._events.append(batch)
                self._n_events += len(batch)
                self._bound_events()
        mark = max(batch.t_last_ns if len(batch) else -(2**63), complete_to_ns if complete_to_ns is not None
                   else -(2**63))
        if mark > -(2**63):
            self._event_mark_ns = mark if self._event_mark_ns is None else max(self._event_mark_ns, mark)
            self._newest_ns = max(self._newest_ns, mark)

    # ------------------------------------------------------------------ output
    def pop_ready(self) -> list[tuple[Any, EventBatch]]:
        """Complete frames (oldest first) with the events since the previous frame."""
        out = []
        while self._pairs:
            t = self._pairs[0][0]
            if self.with_events:
                mark = self._event_mark_ns
                complete = mark is not None and mark >= t
                stalled = (self._newest_ns - t > self.max_wait_ns and self.silent(self._events_heard_ns)) or \
                    len(self._pairs) > self.max_pending
                if not (complete or stalled):
                    break
                if not complete:
                    self.stats.released_without_events += 1
            out.append(self._release())
        return out

    def flush(self) -> list[tuple[Any, EventBatch]]:
        """End of stream: release every paired frame with the events that arrived."""
        self._match(final=True)
        out = []
        while self._pairs:
            if self.with_events and (self._event_mark_ns is None or self._event_mark_ns < self._pairs[0][0]):
                self.stats.released_without_events += 1
            out.append(self._release())
        self.stats.dropped_rgb += len(self._rgb)
        self.stats.dropped_depth += len(self._depth)
        self._rgb.clear()
        self._depth.clear()
        return out

    def silent(self, heard_ns: int | None) -> bool:
        """Whether a stream last heard at ``heard_ns`` (``clock`` time) counts as silent: always without a clock."""
        return self.clock is None or heard_ns is None or self.clock() - heard_ns > self.max_wait_ns

    @property
    def n_pairs(self) -> int:
        """Paired frames waiting for the event stream to pass them."""
        return len(self._pairs)

    @property
    def newest_ns(self) -> int | None:
        """The newest stamp seen on any stream (images, event marks); None before the first."""
        return None if self._newest_ns == -(2**63) else self._newest_ns

    @property
    def pending(self) -> int:
        """Images and pairs held back (bounded)."""
        return len(self._rgb) + len(self._depth) + len(self._pairs)

    # ------------------------------------------------------------------ internals
    def _restart_clock(self) -> None:
        """The stamps jumped back: drop what is pending (it belongs to the old timeline) and start over."""
        self.stats.clock_jumps += 1
        self.stats.dropped_rgb += len(self._rgb) + len(self._pairs)
        self.stats.dropped_depth += len(self._depth) + len(self._pairs)
        self._rgb.clear()
        self._depth.clear()
        self._pairs.clear()
        self._events = []
        self._n_events = 0
        self._event_mark_ns = None
        self._last_cut_ns = None
        self._newest_ns = self._newest_img_ns = self._newest_ev_ns = -(2**63)

    def _insert(self, q: deque, t: int, img: np.ndarray) -> None:
        if t < self._newest_img_ns - self.CLOCK_JUMP_NS:
            self._restart_clock()
        self._newest_ns = max(self._newest_ns, t)
        self._newest_img_ns = max(self._newest_img_ns, t)
        if q and q[-1][0] > t:  # out of order: keep the queue sorted
            items = sorted([*q, (t, img)], key=lambda x: x[0])
            q.clear()
            q.extend(items)
        else:
            q.append((t, img))

    def _match(self, final: bool = False) -> None:
        while self._rgb and self._depth:
            t_r, rgb = self._rgb[0]
            # depth images too old for this (and hence every later) colour image
            while self._depth and self._depth[0][0] < t_r - self.tol_ns:
                self._depth.popleft()
                self.stats.dropped_depth += 1
            if not self._depth:
                break
            t_d0 = self._depth[0][0]
            if t_d0 > t_r + self.tol_ns:
                self._rgb.popleft()  # no depth near this colour image will come any more
                self.stats.dropped_rgb += 1
                continue
            stamps = np.fromiter((d[0] for d in self._depth), np.int64, len(self._depth))
            k = int(np.argmin(np.abs(stamps - t_r)))
            nearer_may_come = stamps[-1] < t_r and not final
            if nearer_may_come and len(self._rgb) <= self.max_pending:
                break
            for _ in range(k):
                self._depth.popleft()
                self.stats.dropped_depth += 1
            _, depth = self._depth.popleft()
            self._rgb.popleft()
            self._pairs.append((t_r, rgb, depth))
        while len(self._rgb) > self.max_pending:
            self._rgb.popleft()
            self.stats.dropped_rgb += 1
        while len(self._depth) > self.max_pending:
            self._depth.popleft()
            self.stats.dropped_depth += 1

    def _bound_events(self) -> None:
        """Drop the oldest buffered events beyond ``max_buffered_events``."""
        excess = self._n_events - self.max_buffered_events
        while excess > 0 and self._events:
            head = self._events[0]
            if len(head) <= excess:
                self._events.pop(0)
                cut = len(head)
            else:
                self._events[0] = head.select(slice(excess, None))
                cut = excess
            self._n_events -= cut
            self.stats.dropped_events += cut
            excess -= cut

    def _release(self) -> tuple[Any, EventBatch]:
        t, rgb, depth = self._pairs.popleft()
        events = EventBatch.empty()
        if self._events:
            allev = EventBatch.concatenate(self._events) if len(self._events) > 1 else self._events[0]
            k = int(np.searchsorted(allev.t, t, side="right"))
            events = allev.select(slice(0, k))
            rest = allev.select(slice(k, None))
            self._events = [rest] if len(rest) else []
            self._n_events = len(rest)
        self._last_cut_ns = t
        self.stats.frames += 1
        return RgbdFrame(stamp_ns=t, rgb=rgb, depth_m=depth), events


__all__ = ["FrameAssembler", "StampGaps", "SyncStats"]
