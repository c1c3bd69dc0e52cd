"""The debug images of the event front end: the time surface and the selected event pixels, as uint8.

One renderer for every consumer (the tracking node's debug topics, ``atsvo-replay --record``), so
what a bag shows is what the robot publishes. Rendering only reads the front end (its surface and
recent events), so calling it between frames does not change the odometry.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.core.events.frontend import EventFrontEnd

#: Colour of the selected event pixels on the grey surface (RGB).
SELECTED_RGB = (255, 0, 0)


@dataclass(frozen=True)
class DebugImages:
    """The time surface at a stamp (``ats``: H x W mono8) and, when asked for, the selection on it (H x W x 3 rgb8)."""

    stamp_ns: int
    ats: np.ndarray
    selection: np.ndarray | None


def render_debug_images(events: EventFrontEnd, stamp_ns: int, selection: bool = True) -> DebugImages:
    """The rectified surface at ``stamp_ns`` as mono8 and, with ``selection``, the Section II-B pixels in red.

    The selection image is the surface in grey with every selected pixel painted :data:`SELECTED_RGB`;
    it costs a selection run, so the node asks for it only while someone subscribes.
    """
    frame = events.render(int(stamp_ns))
    grey = np.clip(frame.surface, 0, 255).astype(np.uint8)
    if not selection:
        return DebugImages(int(stamp_ns), grey, None)
    sel = events.select(frame).selected
    rgb = np.repeat(grey[..., None], 3, axis=2)
    if len(sel):
        rgb[sel[:, 1], sel[:, 0]] = SELECTED_RGB
    return DebugImages(int(stamp_ns), grey, rgb)


__all__ = ["SELECTED_RGB", "DebugImages", "render_debug_images"]
