"""The event camera's side: event batches, time surfaces, event pixel selection, the temporary event map.

Owns everything from decoded events to what the event term of Eq. 4 reads: the adaptive time surface
(Eq. 1-2) and its baselines, the pixels selected on it (Section II-B), the event front end that renders
and rectifies the surface at a frame's time, and the temporary event map N built from one surface with depth.
"""
from __future__ import annotations

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.debug_images import DebugImages, render_debug_images
from atsvo_ros.core.events.event_map import TemporaryEventMap, build_event_map, depth_in_camera
from atsvo_ros.core.events.frontend import EventFrame, EventFrontEnd, select_event_frame
from atsvo_ros.core.events.selection import EventSelection, select_event_pixels, select_event_pixels_detailed
from atsvo_ros.core.events.time_surface import (
    AdaptiveTimeSurface,
    ConstantTimeSurface,
    SpeedInvariantTimeSurface,
    TimeSurface,
    make_time_surface,
)

__all__ = ["AdaptiveTimeSurface", "ConstantTimeSurface", "DebugImages", "EventBatch", "EventFrame", "EventFrontEnd",
           "EventSelection", "SpeedInvariantTimeSurface", "TemporaryEventMap", "TimeSurface", "build_event_map",
           "depth_in_camera", "make_time_surface", "render_debug_images", "select_event_frame",
           "select_event_pixels", "select_event_pixels_detailed"]
