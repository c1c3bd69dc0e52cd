"""Frame release: the IMU gate on paired frames, the IMU cut per frame, and frames held for the camera_info.

A frame paired by the :class:`~atsvo_ros.io.sync.FrameAssembler` waits here until the IMU has passed
its exposure time (stamp plus ``rgb_camera.time_offset_s``), unless the IMU is ``node.imu_max_wait_s``
behind in stamp time and, given an arrival ``clock`` (the node), has been silent that long, never
spoke, or too many frames wait. A released frame takes the buffered IMU samples up to its exposure
time; samples that arrive for an already released frame are late (dropped and counted), unless the
clock jumped back (a bag loop): then the IMU stream starts over. So the core sees, for every frame,
exactly the samples up to its exposure time whatever order they arrived in.

Released frames wait (bounded, oldest dropped with its events and IMU samples handed on) while the
colour camera_info is missing: the first frame defines the odom origin. This is apart from the runtime
because it is the one place that decides *when* a frame may go to the core.
"""
from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.io.sync import FrameAssembler
from atsvo_ros.runtime.problems import ProblemLog
from atsvo_ros.runtime.types import FrameInput


class FrameRelease:
    """Holds paired frames until their IMU samples are in (and the colour camera is known), then hands them out."""

    def __init__(self, config: AtsvoConfig, assembler: FrameAssembler, problems: ProblemLog, *,
                 clock: Callable[[], int] | None, clock_jump_s: float, imu_keep_ns: int,
                 max_held_frames: int, expect_imu: bool = False, imu_wait_s: float | None = None) -> None:
        """Create the gate.

        Args:
            config: The configuration (``rgb_camera.time_offset_s``, ``node.imu_max_wait_s``).
            assembler: The frame assembler the pairs come from (its newest stamp and its bound).
            problems: Where problems and the IMU counts go.
            clock: Arrival time in ns (the node); None (replay) judges IMU stalls by stamps only.
            clock_jump_s: An IMU batch this far behind the last cut starts the stream over.
            imu_keep_ns: IMU samples kept waiting for a frame.
            max_held_frames: Frames held while the colour camera_info is missing.
            expect_imu: An IMU stream is coming: the first frames wait ``node.imu_max_wait_s`` of stamps for its
                first sample (without, a frame goes as soon as it is paired until the IMU speaks).
            imu_wait_s: How long the IMU may lag (stamps) and be silent (``clock``) before it counts as stalled;
                None: ``node.imu_max_wait_s``.
        """
        self.assembler = assembler
        self._problems = problems
        self._clock = clock
        self._clock_jump_s = clock_jump_s
        self._imu_keep_ns = imu_keep_ns
        self._max_held_frames = max_held_frames
        self._imu: list[ImuBatch] = []  # samples after the last frame's cut
        self._imu_cut_ns: int | None = None
        self._imu_mark_ns: int | None = None  # newest IMU stamp received
        self._imu_heard_ns: int | None = None  # arrival time (``clock``) of the last IMU samples
        self._await_imu: deque[tuple[RgbdFrame, EventBatch]] = deque()  # paired frames waiting for the IMU
        # a frame waits for (and takes) the IMU up to its exposure time, or up to its depth's when that is later
        # (the depth is turned to the colour's time by the gyro in between)
        self._offset_ns = int(round((config.rgb_camera.time_offset_s + max(0.0, config.rig.depth_time_offset_s))
                                    * 1e9))
        wait_s = config.node.imu_max_wait_s if imu_wait_s is None else imu_wait_s
        self._imu_wait_ns = int(round(wait_s * 1e9))  # then the IMU counts as silent
        self._held: deque[FrameInput] = deque()  # frames waiting for the colour camera_info
        # no IMU expected, or it never spoke within imu_max_wait_s of stamps after the first frame: frames go
        self._imu_absent = not expect_imu

    def add_imu(self, batch: ImuBatch) -> None:
        """IMU samples (time order), buffered for the frames to come; late ones are dropped and counted.

        Args:
            batch: The samples.
        """
        if len(batch) == 0:
            return
        if self._clock is not None:
            self._imu_heard_ns = self._clock()  # alive, even when its samples turn out late
        self._problems.counters["imu_samples"] += len(batch)
        cut = self._imu_cut_ns
        if cut is not None and batch.t_first_ns <= cut:
            if batch.t_last_ns < cut - int(self._clock_jump_s * 1e9):
                self._imu.clear()  # clock jump (bag loop): the samples belong to the new timeline
                self._imu_cut_ns = self._imu_mark_ns = None
            else:
                late = batch.stamps_ns <= cut
                n_late = int(np.count_nonzero(late))
                self._problems.report("imu_late", f"{n_late} IMU sample(s) arrived after the frame at {cut} ns "
                                      "they belong to had been released: dropped", count=n_late)
                batch = batch.select(~late)
                if len(batch) == 0:
                    return
        self._imu.append(batch)
        newest = batch.t_last_ns
        self._imu_mark_ns = newest if self._imu_mark_ns is None else max(self._imu_mark_ns, newest)
        while len(self._imu) > 1 and self._imu[0].t_last_ns < newest - self._imu_keep_ns:
            self._imu.pop(0)

    def release(self, pairs: list[tuple[RgbdFrame, EventBatch]], *, final: bool,
                hold: bool) -> list[FrameInput]:
        """Take new pairs; hand out the frames (oldest first) that may go to the core now.

        Args:
            pairs: Frames just paired by the assembler (oldest first), with their events.
            final: End of stream: release every frame, whether the IMU passed it or not.
            hold: The colour camera is unknown: keep the frames (bounded) instead of handing them out.

        Returns:
            The released frames, each with its IMU samples (and those held earlier first).
        """
        self._await_imu.extend(pairs)
        return self._release(self._imu_ready(final), hold)

    @property
    def n_waiting(self) -> int:
        """Paired frames not handed out yet: waiting for IMU samples or the camera_info."""
        return len(self._await_imu) + len(self._held)

    def _imu_ready(self, final: bool) -> list[tuple[RgbdFrame, EventBatch]]:
        """Paired frames whose IMU samples are all in: the IMU passed the frame, is silent, or never spoke."""
        out = []
        mark = self._imu_mark_ns
        newest = self.assembler.newest_ns
        silent = self._clock is None or self._imu_heard_ns is None or \
            self._clock() - self._imu_heard_ns > self._imu_wait_ns
        if mark is None and not self._imu_absent and self._await_imu and newest is not None:
            # The first frames wait for the IMU's first sample as later frames wait for the next: streams that
            # start together deliver the first frame before it, its IMU cut came out empty and the samples up
            # to it were then dropped as late, so the map's first depth missed the gyro's turn over its offset
            self._imu_absent = newest - int(self._await_imu[0][0].stamp_ns) > self._imu_wait_ns
        stalled = (mark is None and self._imu_absent) or \
            (mark is not None and newest is not None and newest - mark > self._imu_wait_ns and silent) or \
            len(self._await_imu) > self.assembler.max_pending
        while self._await_imu:
            behind = mark is None or mark < int(self._await_imu[0][0].stamp_ns) + self._offset_ns
            if behind and not (final or stalled):
                break
            if behind and mark is not None and not final:
                self._problems.counters["frames_without_imu"] += 1  # released before the IMU passed it
            out.append(self._await_imu.popleft())
        return out

    def _cut_imu(self, stamp_ns: int) -> ImuBatch:
        """The buffered IMU samples up to a frame's exposure time (its stamp plus the colour time offset)."""
        cut = int(stamp_ns) + self._offset_ns
        self._imu_cut_ns = cut if self._imu_cut_ns is None else max(self._imu_cut_ns, cut)
        if not self._imu:
            return ImuBatch.empty()
        buf = ImuBatch.concatenate(self._imu) if len(self._imu) > 1 else self._imu[0]
        k = int(np.searchsorted(buf.stamps_ns, cut, side="right"))
        rest = buf.select(slice(k, None))
        self._imu = [rest] if len(rest) else []
        return buf.select(slice(0, k))

    def _release(self, pairs: list[tuple[RgbdFrame, EventBatch]], hold: bool) -> list[FrameInput]:
        now = time.monotonic()
        inputs = [FrameInput(frame, events, self._cut_imu(frame.stamp_ns), now) for frame, events in pairs]
        if hold:
            for inp in inputs:
                self._problems.report("frames_waiting_camera_info", "waiting for the colour camera_info: frames held")
                self._held.append(inp)
                if len(self._held) > self._max_held_frames:
                    oldest = self._held.popleft()
                    self._held[0] = self._held[0].after(oldest)
                    self._problems.counters["frames_dropped_waiting_camera_info"] += 1
            return []
        if self._held:
            inputs = [*self._held, *inputs]
            self._held.clear()
        return inputs


__all__ = ["FrameRelease"]
