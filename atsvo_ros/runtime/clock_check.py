"""Event and IMU streams on the colour images' clock: placed there, and checked on the first frames.

:class:`EventClock` places event times: ``event_camera.time_offset_s`` is added, and a stream whose event
times are far (over :data:`SENSOR_CLOCK_S`) from their messages' header stamps carries the camera's own
clock (evt3, which has no time base; a driver that leaves time_base at 0): it is moved onto the header
clock by the first message's difference (drivers stamp a packet at its first event), said once.

On a robot the event camera and the D455 run on different clocks; a bag recorded with a driver whose
time base is off puts a stream seconds away from the frames. The assembler then gives no frame an
event (or the IMU to no frame), and before this check the run said "mode fused" over it. At each of
the first :data:`FRAMES` colour images, the newest event time and IMU stamp that had arrived are
compared with the image's stamp; when the median difference is over :data:`APART_S`, the stream is
on another clock, and one line at error level says by how much and which offset puts it right
(``event_camera.time_offset_s``, ``rig.imu_time_offset_s``). Streams that arrive late but are
stamped right stay within a second and are not flagged (their late events are counted elsewhere).
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.runtime.problems import ProblemLog

#: Event times this far from their message's header stamp are on the camera's own clock, not the header's.
SENSOR_CLOCK_S = 1.0
#: Colour images over which the streams are compared.
FRAMES = 10
#: A stream whose median stamp difference to the images is over this is on another clock.
APART_S = 1.0

_FIX = {"events": "event_camera.time_offset_s", "imu": "rig.imu_time_offset_s"}
_WHAT = {"events": "no frame gets events (the run is RGB-D)", "imu": "the IMU is not used"}
_NAME = {"events": "the events", "imu": "the IMU samples"}


class EventClock:
    """Puts event times on the colour images' clock (see the module docstring)."""

    def __init__(self, time_offset_s: float, problems: ProblemLog) -> None:
        self._offset_ns = int(round(time_offset_s * 1e9))
        self._problems = problems
        self._to_header_ns: int | None = None  # camera clock -> header clock; 0 when on the header's already
        self._newest_ns: int | None = None  # newest event time placed
        self._floor_ns: int | None = None  # after an adjustment back in time: events up to here were placed

    @property
    def offset_s(self) -> float:
        """The offset added to event times (configured, plus an estimate once taken)."""
        return self._offset_ns * 1e-9

    def adjust(self, delta_ns: int) -> None:
        """Move the events placed from now on by ``delta_ns`` more (an estimated offset).

        After a move back in time, events at or before the newest already placed are dropped, so the
        stream stays in time order (one message's worth, once).
        """
        self._offset_ns += int(delta_ns)
        if delta_ns < 0:
            self._floor_ns = self._newest_ns

    def place(self, batch: EventBatch, header_ns: int | None) -> tuple[EventBatch, int | None]:
        """The batch and its message's header stamp, on the colour images' clock."""
        if self._to_header_ns is None and len(batch) and header_ns is not None:
            self._to_header_ns = self._clock_of(batch, header_ns)
        shift = (self._to_header_ns or 0) + self._offset_ns
        if shift and len(batch):
            batch = batch.shifted(shift)
        if self._floor_ns is not None and len(batch):
            if batch.t_first_ns <= self._floor_ns:
                batch = batch.select(batch.t > self._floor_ns)
            if len(batch):
                self._floor_ns = None
        if len(batch):
            self._newest_ns = batch.t_last_ns
        if header_ns is not None:
            header_ns += self._offset_ns
        return batch, header_ns

    def _clock_of(self, batch: EventBatch, header_ns: int) -> int:
        apart = header_ns - batch.t_first_ns
        if abs(apart) <= SENSOR_CLOCK_S * 1e9:
            return 0
        self._problems.report(
            "events_on_camera_clock", f"the event times are on the camera's own clock (first event at "
            f"{batch.t_first_ns * 1e-9:.3f} s, its message stamped {header_ns * 1e-9:.3f} s): moved onto the "
            "messages' header clock by that difference", level="warn")
        return apart


class ClockCheck:
    """Compares the event and IMU streams' stamps with the colour images' over the first frames."""

    def __init__(self, problems: ProblemLog) -> None:
        self._problems = problems
        self._newest: dict[str, int] = {}
        self._apart: dict[str, list[int]] = {"events": [], "imu": []}
        self.offsets_s: dict[str, float] = {}  #: streams found on another clock: the offset that would fix them

    def stream(self, name: str, newest_ns: int) -> None:
        """The newest stamp of a stream (``events`` or ``imu``) that arrived."""
        self._newest[name] = max(self._newest.get(name, newest_ns), int(newest_ns))

    def image(self, stamp_ns: int) -> None:
        """A colour image arrived: compare each stream's newest stamp with it (first :data:`FRAMES` only)."""
        for name, apart in self._apart.items():
            if name not in self._newest or len(apart) >= FRAMES:
                continue
            apart.append(self._newest[name] - int(stamp_ns))
            if len(apart) == FRAMES:
                self._judge(name, float(np.median(apart)) * 1e-9)

    def _judge(self, name: str, apart_s: float) -> None:
        if abs(apart_s) <= APART_S:
            return
        self.offsets_s[name] = -apart_s
        where = "ahead of" if apart_s > 0 else "behind"
        self._problems.report(
            f"clock_{name}", f"{_NAME[name]} are stamped {abs(apart_s):.2f} s {where} the colour images (median "
            f"over the first {FRAMES} frames): another clock? Set {_FIX[name]}: {-apart_s:.2f} (or fix the "
            f"driver's time base); until then {_WHAT[name]}", level="error")


__all__ = ["APART_S", "FRAMES", "SENSOR_CLOCK_S", "ClockCheck", "EventClock"]
