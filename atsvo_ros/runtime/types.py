"""The runtime's interface types: what goes into the core per frame, what comes out, and who gets it.

They live apart from :class:`~atsvo_ros.runtime.runtime.OdometryRuntime` because every part of the
runtime (:mod:`.ingest`, :mod:`.release`, :mod:`.problems`) and its users (the nodes' frame queue, the
bag recorder sink, the tests) need them without needing the runtime itself.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.frame import OdometryResult, RgbdFrame
from atsvo_ros.core.imu import ImuBatch

Logger = Callable[[str, str], None]  # (level: "info" | "warn" | "error", text)


class OdometryCore(Protocol):
    """What the runtime needs from the core (:class:`atsvo_ros.core.odometry.odometry.Odometry`, or a test double)."""

    def process_frame(self, frame: RgbdFrame) -> OdometryResult: ...

    def add_events(self, batch: EventBatch) -> None: ...

    def add_imu(self, batch: ImuBatch) -> None: ...


@dataclass(frozen=True)
class FrameInput:
    """One frame ready for the core: the colour/depth pair and the events and IMU samples since the previous one.

    ``ready_s`` is ``time.monotonic()`` when the frame became complete (queue age and latency).
    """

    frame: RgbdFrame
    events: EventBatch
    imu: ImuBatch
    ready_s: float

    @property
    def stamp_ns(self) -> int:
        return int(self.frame.stamp_ns)

    def after(self, dropped: FrameInput) -> FrameInput:
        """This frame, also carrying the events and IMU samples of an earlier frame that is dropped.

        The time surface and the gyro need every event and sample in order; only images may be skipped.

        Args:
            dropped: The earlier frame whose image is dropped.

        Returns:
            This frame with ``dropped``'s events and IMU samples prepended.
        """
        events = EventBatch.concatenate([dropped.events, self.events]) if len(dropped.events) else self.events
        imu = ImuBatch.concatenate([dropped.imu, self.imu]) if len(dropped.imu) else self.imu
        return FrameInput(self.frame, events, imu, self.ready_s)


@dataclass(frozen=True)
class RuntimeOutput:
    """One processed frame: the core's result, the base twist since the previous output, the events it got."""

    result: OdometryResult
    twist: np.ndarray | None
    n_events: int


#: An output sink (e.g. the bag recorder of ``atsvo-replay --record``): ``sink(output, core)`` after each frame.
Sink = Callable[[RuntimeOutput, OdometryCore], None]

__all__ = ["FrameInput", "Logger", "OdometryCore", "RuntimeOutput", "Sink"]
