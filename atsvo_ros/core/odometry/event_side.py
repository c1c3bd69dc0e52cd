"""The odometry's event side: the event front end, the events counted per frame and the previous frame's surface."""
from __future__ import annotations

import time
from collections import deque

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.event_map import TemporaryEventMap
from atsvo_ros.core.events.frontend import EventFrame, EventFrontEnd
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.mapping.mapper import EventMapRequest
from atsvo_ros.core.mapping.ports import MappingPort


class EventSide:
    """What the odometry keeps of the event camera between frames (all of it inert without an event front end).

    The events since the last frame are counted (a surge of them says the turn sped up) and timed (their
    time-surface updates count towards the next frame's tracking time); the previous frame's surface, depth
    and pose are kept for the temporary event map of the next frame, which mapping builds.

    Args:
        config: the odometry's configuration (``fusion.min_points``).
        frontend: the event camera's front end, or None without an event camera (or outside fused mode).
        mapping: the port that builds the temporary event maps.
    """

    def __init__(self, config: AtsvoConfig, frontend: EventFrontEnd | None, mapping: MappingPort) -> None:
        self.config = config
        self.frontend = frontend
        self.mapping = mapping
        self._time_s = 0.0  # ATS updates since the last frame (counted in its tracking time)
        # the previous frame's event surface, colour frame (for its depth) and pose: its temporary event map's source
        self._prev_event: tuple[EventFrame, PreparedFrame, np.ndarray] | None = None
        self._prev_request: EventMapRequest | None = None  # its event map, asked for ahead of the next frame
        self._since_frame = 0
        self._dropped_reported = 0  # the event front end's drop count at the last result
        self._per_frame: deque[int] = deque(maxlen=2)

    @property
    def has_previous(self) -> bool:
        """Whether a previous frame's surface is kept (a temporary event map can be built)."""
        return self._prev_event is not None

    def add(self, batch: EventBatch) -> None:
        """Fold a time-ordered event batch into the time surface (ignored without an event front end)."""
        if self.frontend is None or len(batch) == 0:
            return
        t0 = time.perf_counter()
        self.frontend.add_events(batch)
        self._since_frame += len(batch)
        self._time_s += time.perf_counter() - t0

    def start_frame(self) -> tuple[float, int]:
        """Seconds spent on events and events added since the last frame; the time count starts over."""
        time_s, self._time_s = self._time_s, 0.0
        return time_s, self._since_frame

    def render(self, stamp_ns: int, n_events: int) -> EventFrame | None:
        """The surface at ``stamp_ns``, or None when the event camera was silent (dropout, cap on): a stale
        surface would pull towards zero motion."""
        live = self.frontend is not None and n_events >= self.config.fusion.min_points
        return self.frontend.render(stamp_ns) if live else None

    def end_frame(self, n_events: int) -> None:
        """Close the frame's event count (``n_events`` from :meth:`start_frame`)."""
        self._per_frame.append(n_events)
        self._since_frame = 0

    def rate_ratio(self) -> float | None:
        """Events since the last frame over events in the frame interval before (None without both)."""
        if len(self._per_frame) < 2 or self._per_frame[-2] < 1000:
            return None
        return float(np.clip(self._since_frame / self._per_frame[-1], 0.2, 8.0)) \
            if self._per_frame[-1] > 0 else None

    def take_dropped(self) -> int:
        """Events the front end dropped since the last call (0 without a front end)."""
        if self.frontend is None:
            return 0
        dropped = self.frontend.dropped_events - self._dropped_reported
        self._dropped_reported = self.frontend.dropped_events
        return dropped

    def event_map(self) -> TemporaryEventMap | None:
        """The temporary event map built (by mapping) from the previous frame's surface, depth and pose, or None."""
        if self._prev_event is None:
            return None
        request, self._prev_request = self._prev_request or self._event_request(), None
        return self.mapping.event_map(request)

    def _event_request(self) -> EventMapRequest:
        """The event-map request of the previous frame (mapping selects its pixels among those that fired)."""
        ev_frame, frame, T_c_w = self._prev_event
        return EventMapRequest(ev_frame, frame.depth_m, T_c_w, self.frontend.recent_pixels(ev_frame.stamp_ns),
                               frame.T_depth_rgb)

    def remember(self, ev_frame: EventFrame, frame: PreparedFrame, T_c_w: np.ndarray, fast: bool) -> None:
        """Keep this frame's surface (and its colour frame's depth) for the next frame's event map, and have it
        built now if that frame will fuse (``fast``: the relative-motion factor of the poses so far, what the next
        frame tests): the build then runs while tracking waits for the next frame, not after it arrives."""
        self._prev_event = (ev_frame, frame, T_c_w)
        self._prev_request = None
        if fast:
            self._prev_request = self._event_request()
            self.mapping.prepare_event_map(self._prev_request)

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """Re-express the previous frame's pose in a moved world (mapping moved the map under it); an event map
        asked for ahead in the old world is asked for again when needed."""
        if self._prev_event is not None:
            ev_frame, frame, T_c_w = self._prev_event
            self._prev_event = (ev_frame, frame, T_c_w @ se3_inv(T_wnew_wold))
            self._prev_request = None

    def forget(self) -> None:
        """Drop the previous frame's surface (a new map: the next event map must not come from the old one)."""
        self._prev_event, self._prev_request = None, None


__all__ = ["EventSide"]
