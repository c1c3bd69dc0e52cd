"""The event camera's front end: time surface from the event stream, rendered, rectified and selected.

Events go into the time surface (the ATS of Eq. 1-2, or an ablation) on the sensor's raw pixel grid,
where the neighbour ring of Eq. 2 is defined; at each frame stamp the surface is rendered, rectified
onto the pinhole model with the same maps as the colour camera's images
(:class:`~atsvo_ros.core.image.frontend.ImageFrontEnd`: DVXplorer plumb_bob, MVSEC equidistant) and turned
into a pyramid with gradients for the photometric ATS term. The event pixel selection of Section
II-B runs on the rectified surface with the recent events' coordinates undistorted through a
per-pixel lookup table.
"""
from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig, EventSelectionConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events._selection_kernels import _event_pixels
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.selection import select_event_pixels
from atsvo_ros.core.events.time_surface import make_time_surface
from atsvo_ros.core.image.frontend import ImageFrontEnd


@dataclass(frozen=True)
class EventFrame:
    """The event camera at one frame stamp: the rectified surface, its pyramid, and its selected pixels."""

    stamp_ns: int
    surface: np.ndarray  # float32 0-255 on the pinhole grid
    pyramid: list[np.ndarray]  # per level (H, W, 3) float32 [I, Ix, Iy]
    selected: np.ndarray  # (N, 2) int pixel positions (pinhole grid), best first
    n_events: int  # pixels that fired in the selection window


class EventFrontEnd:
    """Time surface + rectification + pyramid + selection of one event camera (see the module docstring)."""

    #: Events kept beyond the selection window (a frame's selection may run a frame later).
    RETAIN_MARGIN_NS = 150_000_000
    #: The event-rate cap admits bursts of this much time at the full rate.
    BURST_NS = 50_000_000

    def __init__(self, raw_camera: CameraModel, config: AtsvoConfig, levels: int) -> None:
        self.config = config
        self.image = ImageFrontEnd(raw_camera, levels)
        self.camera = self.image.camera
        self.cameras = self.image.cameras
        w, h = raw_camera.width, raw_camera.height
        self.surface = make_time_surface(config.fusion.surface, w, h, config.ats)
        self._window_ns = self.surface.window_ns()
        self._keep_ns = int(round(config.event_selection.window_fraction * self._window_ns))
        # the previous frame's selection may run one frame later (when fast motion is detected): keep the
        # events of its window plus a margin of a few frame intervals
        self._retain_ns = self._keep_ns + self.RETAIN_MARGIN_NS
        self._recent: deque[EventBatch] = deque()
        # raw pixel -> rectified pixel (rounded); -1 where the pixel leaves the pinhole image
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        xy = raw_camera.pixel_to_normalized(np.column_stack([u.ravel(), v.ravel()]))
        pu = np.rint(self.camera.fx * xy[:, 0] + self.camera.cx)
        pv = np.rint(self.camera.fy * xy[:, 1] + self.camera.cy)
        inside = (pu >= 0) & (pu < self.camera.width) & (pv >= 0) & (pv < self.camera.height)
        self._lut_x = np.where(inside, pu, -1).astype(np.int32)
        self._lut_y = np.where(inside, pv, -1).astype(np.int32)
        self._raw_w, self._raw_h = w, h
        self._rate = float(config.fusion.max_event_rate_ev_s)
        self._capacity = self._rate * self.BURST_NS * 1e-9
        self._tokens = self._capacity
        self._token_ns: int | None = None
        #: events dropped by the rate cap (oldest of their batch first), since construction
        self.dropped_events = 0

    @property
    def n_levels(self) -> int:
        return self.image.n_levels

    def reset(self) -> None:
        """Forget every event (the surface starts black)."""
        self.surface.reset()
        self._recent.clear()

    def add_events(self, batch: EventBatch) -> None:
        """Fold a time-ordered batch into the surface; keep the last selection window for Eq. 3.

        A token bucket on the event clock caps the rate at ``fusion.max_event_rate_ev_s``: in a flood
        only the newest events of a batch go in (the surface at the next frame is made of the latest
        events anyway), the others are counted in :attr:`dropped_events`.
        """
        if len(batch) == 0:
            return
        batch = self._admit(batch)
        self.surface.update(batch)
        self._recent.append(batch)
        newest = batch.t_last_ns
        while self._recent and self._recent[0].t_last_ns < newest - self._retain_ns:
            self._recent.popleft()

    def _admit(self, batch: EventBatch) -> EventBatch:
        """The newest events of ``batch`` that the rate cap lets through."""
        t_last = batch.t_last_ns
        if self._token_ns is not None:
            elapsed_s = max(0, t_last - self._token_ns) * 1e-9
            self._tokens = min(self._capacity, self._tokens + self._rate * elapsed_s)
        self._token_ns = t_last if self._token_ns is None else max(self._token_ns, t_last)
        n, keep = len(batch), max(1, int(self._tokens))
        if n <= keep:
            self._tokens -= n
            return batch
        self._tokens -= keep
        self.dropped_events += n - keep
        return batch.select(slice(n - keep, n))

    def recent_pixels(self, t_ns: int) -> np.ndarray:
        """Bool image (pinhole grid) of the pixels hit in the selection window before ``t_ns``, undistorted."""
        out = np.zeros((self.camera.height, self.camera.width), np.bool_)
        t_from = int(t_ns) - self._keep_ns
        for b in self._recent:
            if b.t_last_ns > t_from and b.t_first_ns <= t_ns:
                _event_pixels(b.x, b.y, b.t, t_from, int(t_ns), self._lut_x, self._lut_y, self._raw_w, self._raw_h,
                              out)
        return out

    def render(self, t_ns: int) -> EventFrame:
        """The surface at ``t_ns`` on the pinhole grid and its pyramid (no pixels selected yet)."""
        img = self.image.rectify(self.surface.render(int(t_ns)))
        return EventFrame(int(t_ns), img, self.image.pyramid(img), np.zeros((0, 2), np.int64), 0)

    def select(self, frame: EventFrame) -> EventFrame:
        """``frame`` with the pixels of Section II-B (Eq. 3) on its surface, from the recent events."""
        return select_event_frame(frame, self.recent_pixels(frame.stamp_ns), self.config.event_selection)


def select_event_frame(frame: EventFrame, fired: np.ndarray, cfg: EventSelectionConfig) -> EventFrame:
    """``frame`` with the pixels of Section II-B (Eq. 3) selected among ``fired`` (pixels of the window's events).

    A pure function of its arguments, so mapping can run it in a thread of its own.
    """
    sel = select_event_pixels(frame.surface, fired, frame.stamp_ns, 0, cfg)
    return dataclasses.replace(frame, selected=sel, n_events=int(np.count_nonzero(fired)))


__all__ = ["EventFrame", "EventFrontEnd", "select_event_frame"]
