"""Mapping (the PTAM split): keyframe insertion, culling and the snapshots tracking reads.

Tracking decides *when* a keyframe is needed (the nine-region rule against the reference health
the snapshot carries) and sends a :class:`KeyframeRequest`; the mapper owns the point map, selects
and back-projects new points where the tracked ones leave gaps, culls what tracking reported as
repeated outliers and what fell out of the keyframe window (retired, and taken back when the camera
returns over its ground: ``mapping.keyframe_culling``), and returns a new immutable
:class:`~atsvo_ros.core.mapping.map.MapSnapshot`. Nothing here reads tracking state directly, so the
mapper can run in the tracking thread (the replay), in a thread of its own or in another process.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.event_map import TemporaryEventMap, build_event_map
from atsvo_ros.core.events.frontend import EventFrame, select_event_frame
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.image.photometric import RGB_PATTERN, extract_patches
from atsvo_ros.core.mapping.depth_selection import select_depth_pixels
from atsvo_ros.core.mapping.keyframes import assess_health
from atsvo_ros.core.mapping.map import (
    MapSnapshot,
    PointMap,
    smoothed_depth,
    valid_depth_mask,
)
from atsvo_ros.core.mapping.refine import KeyframeView, WindowRefiner, WindowReport
from atsvo_ros.core.mapping.rgb_selection import select_rgb_pixels
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.errors import TrackingError


@dataclass(frozen=True)
class KeyframeRequest:
    """What tracking hands to mapping for one keyframe.

    ``outlier_runs`` counts, per photometric point of snapshot ``snapshot_id``, the consecutive
    frames in which it was an outlier; ``tracked_uv`` are the inlier points' pixels in this frame
    (new points fill the gaps between them). ``reset`` starts a new map from this frame; with ``keep_memory``
    (a re-initialisation after a loss: the world frame goes on) the old map's keyframes are kept aside and can come
    back (``mapping.keyframe_culling`` covisible), where a first map or its rebuild forgets them.
    ``rolling_shutter`` (with the frame's velocity) places points seen at other times than the stamp.
    ``geometry_only``: add depth points only (a coasting frame: its colour image did not hold the pose).
    ``refine``: run the local window optimisation after this keyframe (when mapping has one); false keeps the
    keyframe's image for later windows but leaves the poses where they are (the camera is turning fast).
    """

    snapshot_id: int
    frame: PreparedFrame
    T_c_w: np.ndarray
    affine: tuple[float, float]
    tracked_uv: np.ndarray
    outlier_runs: np.ndarray
    reset: bool = False
    rolling_shutter: RollingShutter | None = None
    geometry_only: bool = False
    refine: bool = True
    keep_memory: bool = False


@dataclass(frozen=True)
class EventMapRequest:
    """What tracking hands to mapping to build the temporary event map: one frame's surface and depth.

    ``fired`` (bool image on the surface's grid) are the pixels of the selection window's events: with
    it mapping runs the event pixel selection (Section II-B) itself, so the whole build can happen
    beside tracking; without it ``event_frame.selected`` is used as it is.
    """

    event_frame: EventFrame
    depth_m: np.ndarray  # the colour-aligned depth of the same frame, on the colour camera's pinhole grid
    T_c_w: np.ndarray  # the colour camera's pose of that frame
    fired: np.ndarray | None = None
    T_depth_rgb: np.ndarray | None = None  # where the depth was exposed (PreparedFrame.T_depth_rgb); None: at T_c_w


class Mapper:
    """Owns the map; turns keyframe requests into snapshots (and event-map requests into event maps)."""

    def __init__(self, config: AtsvoConfig, cameras: list[CameraModel], event_camera: CameraModel | None = None,
                 refiner: WindowRefiner | None = None) -> None:
        self.config = config
        #: moves the keyframes of the local map after each insertion (None: keyframes keep their tracked poses)
        self.refiner = refiner
        #: what the last window optimisation did (None before the first, or without a refiner)
        self.last_window: WindowReport | None = None
        #: window optimisations run and their total wall time (the benchmarks' mapping time per keyframe)
        self.n_windows = 0
        self.window_time_s = 0.0
        self._views: dict[int, KeyframeView] = {}  # per keyframe with photometric points: its image for the window
        self.event_camera = event_camera
        self.T_rgb_event = config.rig.T_rgb_event_matrix()
        self.camera = cameras[0]
        self.n_levels = len(cameras)
        self._map = PointMap(self.n_levels, len(RGB_PATTERN))
        self._snapshot_id = 0
        self.snapshot = MapSnapshot.empty(self.n_levels, len(RGB_PATTERN))
        #: Keyframes inserted since construction (re-initialisations included).
        self.n_keyframes = 0

    def insert(self, req: KeyframeRequest) -> MapSnapshot:
        """Insert one keyframe (or start a new map); returns (and keeps) the new snapshot.

        When the frame adds no point (no valid depth where the map has gaps), the snapshot is still
        renewed with the current health as reference, so the rule does not fire on every frame.
        """
        if req.frame.T_depth_rgb is not None:
            raise TrackingError("a keyframe's depth must be at its colour's time (RgbdFrontEnd.at_colour_time): "
                                "its points sit on colour pixels")
        mapping, sel = self.config.mapping, self.config.rgb_selection
        if req.reset:
            if req.keep_memory and mapping.keyframe_culling == "covisible" and mapping.memory_keyframes > 0:
                self._map.cull(0, mapping.max_points, None, mapping.memory_keyframes)  # all retired
            else:
                self._map = PointMap(self.n_levels, len(RGB_PATTERN))
            self._views = {}
        elif req.snapshot_id == self.snapshot.snapshot_id and len(req.outlier_runs) == len(self._map):
            self._map.remove_points(req.outlier_runs >= mapping.max_outlier_frames)
        frame = req.frame
        grey = frame.grey
        ok = valid_depth_mask(frame.depth_m, self.config.rig, mapping.depth_edge_ratio,
                              max(3, mapping.depth_window_px))
        uv = np.zeros((0, 2), np.int64) if req.geometry_only else select_rgb_pixels(grey, sel, mask=ok)
        tracked_uv = np.asarray(req.tracked_uv, dtype=np.float64).reshape(-1, 2)
        if len(uv) and len(tracked_uv):
            uv = uv[~self._covered(uv, tracked_uv, grey.shape)]
        geo_uv = select_depth_pixels(ok, mapping.depth_points)
        added = 0
        if len(uv) or ((req.reset or req.geometry_only) and len(geo_uv)):
            zs = smoothed_depth(frame.depth_m, ok, mapping.depth_window_px)
            affine = (0.0, 0.0) if req.reset else req.affine
            p_c = self.camera.backproject(uv.astype(np.float64), zs[uv[:, 1], uv[:, 0]].astype(np.float64))
            geo_c = self.camera.backproject(geo_uv.astype(np.float64),
                                            zs[geo_uv[:, 1], geo_uv[:, 0]].astype(np.float64))
            if req.rolling_shutter is not None:
                p_c = req.rolling_shutter.to_stamp(p_c, uv[:, 1], req.T_c_w)
                geo_c = req.rolling_shutter.to_stamp(geo_c, geo_uv[:, 1], req.T_c_w)
            patches = extract_patches(frame.pyramid, uv, RGB_PATTERN, affine)
            kf = self._map.add_keyframe(frame.stamp_ns, se3_inv(req.T_c_w), affine, p_c, patches, geo_c)
            self._map.cull(mapping.max_keyframes, mapping.max_points, self._cull_order(kf.kf_id, req.T_c_w),
                           mapping.memory_keyframes if mapping.keyframe_culling == "covisible" else 0)
            self.n_keyframes += 1
            added = len(uv)
            if self.refiner is not None and added:  # a geometry-only keyframe's image did not hold its pose
                self._keep_view(kf.kf_id, KeyframeView(frame, None if req.rolling_shutter is None
                                                       else req.rolling_shutter.frozen(req.T_c_w)))
                if req.refine:
                    self._refine()
        all_uv = np.concatenate([tracked_uv, uv.astype(np.float64)]) if added else tracked_uv
        ref = assess_health(all_uv, self.camera.width, self.camera.height, 1, mapping)
        self._snapshot_id += 1
        self.snapshot = self._map.snapshot(self._snapshot_id, max(1, ref.n_tracked), ref.healthy_regions)
        return self.snapshot

    def _cull_order(self, newest: int, T_c_w: np.ndarray) -> list[int]:
        """Keyframe ids from first to leave the map to last (``mapping.keyframe_culling``); ``max_keyframes`` stay.

        ``covisible``: the newest ``mapping.recent_keyframes`` stay; the other places go to the newest keyframes,
        in the map or retired, that see at least ``mapping.covisible_min_share`` of their points from the new
        keyframe's pose, then to the newest of the rest. A camera back over ground it mapped before (a flip's
        landing, a hand-held sweep) so tracks against those older, less drifted points again, not only against
        the keyframes made on the way.
        """
        mapping = self.config.mapping
        if mapping.keyframe_culling != "covisible":
            return sorted(self._map.keyframes)
        shares = self._map.visible_shares(T_c_w, self.camera, mapping.covisible_max_scale_change)
        newest_first = sorted(shares, reverse=True)
        recent, rest = newest_first[:mapping.recent_keyframes], newest_first[mapping.recent_keyframes:]
        seeing = [k for k in rest if shares[k] >= mapping.covisible_min_share]
        fill = [k for k in rest if shares[k] < mapping.covisible_min_share]
        places = max(0, mapping.max_keyframes - len(recent))
        kept_seeing, kept_fill = seeing[:places], fill[:max(0, places - len(seeing))]
        for k in kept_seeing + kept_fill:
            if k in self._map.retired:
                self._map.restore(k)
        keep = [*sorted(kept_fill), *sorted(kept_seeing), *sorted(recent)]  # excess points go in this order too
        return [k for k in sorted(self._map.keyframes) if k not in keep] + keep

    def _keep_view(self, kf_id: int, view: KeyframeView) -> None:
        """Keep the new keyframe's image for the window and drop those of keyframes the map no longer holds (a
        retired keyframe taken back is tracked against, not refined: keeping its image measured no gain)."""
        self._views = {k: v for k, v in self._views.items() if k in self._map.keyframes}
        if kf_id in self._map.keyframes:
            self._views[kf_id] = view

    def _refine(self) -> None:
        """Run the window optimisation over the keyframes the map still holds."""
        self.last_window = self.refiner.refine(self._map, self._views)
        self.n_windows += 1
        self.window_time_s += self.last_window.time_s

    def build_event_map(self, req: EventMapRequest) -> TemporaryEventMap:
        """The temporary event map of Eq. 4 from one frame (:func:`atsvo_ros.core.events.event_map.build_event_map`)."""
        if self.event_camera is None:
            raise TrackingError("the mapper has no event camera: it cannot build an event map")
        t0 = time.perf_counter()
        frame = req.event_frame
        if req.fired is not None:
            frame = select_event_frame(frame, req.fired, self.config.event_selection)
        event_map = build_event_map(frame, req.depth_m, self.camera, self.event_camera, se3_inv(req.T_c_w),
                                    self.T_rgb_event, req.T_depth_rgb)
        return dataclasses.replace(event_map, build_time_s=time.perf_counter() - t0)

    def _covered(self, uv: np.ndarray, tracked_uv: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """Candidates in a cell (of the size that spreads the target count) that a tracked point occupies."""
        h, w = shape
        cell = max(2, int(np.sqrt(h * w / max(1, self.config.rgb_selection.target_points))))
        occ = np.zeros((h // cell + 1, w // cell + 1), dtype=bool)
        t = np.round(tracked_uv).astype(np.int64)
        inside = (t[:, 0] >= 0) & (t[:, 0] < w) & (t[:, 1] >= 0) & (t[:, 1] < h)
        occ[t[inside, 1] // cell, t[inside, 0] // cell] = True
        return occ[uv[:, 1] // cell, uv[:, 0] // cell]


__all__ = ["EventMapRequest", "KeyframeRequest", "Mapper"]
