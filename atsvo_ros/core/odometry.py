"""The odometry pipeline facade: RGB-D frames (and event batches) in, ``odom -> base`` poses out.

Used by the ROS node and the replay tool alike. The PTAM-style split of Fig. 2: every frame is
*tracked* against the local map (direct sparse photometric alignment, :mod:`.tracker`); *mapping*
runs only when the nine-region health rule (:mod:`.keyframes`) asks for a keyframe.

Frames: the internal world frame is the colour optical frame of the first frame; the published
``odom`` frame is the base frame at the first frame (REP 105: odom starts where the robot is), so
``T_odom_base`` of the first frame is the identity and ``T_odom_world = T_base_rgb``.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events import EventBatch
from atsvo_ros.core.geometry import hat, project_to_so3, relative_motion, se3_exp, se3_inv, se3_log
from atsvo_ros.core.keyframes import assess_health
from atsvo_ros.core.map import PointMap, extract_patches, smoothed_depth, valid_depth_mask
from atsvo_ros.core.photometric import RGB_PATTERN, sample_patches
from atsvo_ros.core.pyramid import build_pyramid, pyramid_cameras
from atsvo_ros.core.selection.rgb import select_rgb_pixels
from atsvo_ros.core.tracker import ResidualBlock, Tracker, TrackResult, image_pyramid_with_gradients
from atsvo_ros.errors import ImageError, TrackingError


@dataclass(frozen=True)
class RgbdFrame:
    """One synchronised colour + depth pair.

    ``rgb``: HxWx3 uint8 RGB or HxW uint8/float32 grey, *raw* (still distorted) colour image;
    ``depth_m``: HxW float32 metres aligned to the colour image (0 or NaN = invalid).
    ``depth_rectified``: the depth already lies on the undistorted pinhole grid with the colour
    camera's own K (``CameraModel.pinhole()``) instead of the raw colour grid (only matters for a
    distorted colour camera). MVSEC's ``depth_image_rect`` is *not* such a grid (stereo rectified:
    other K and a rotation); use its ``depth_image_raw``, which lies on the raw grid.
    """

    stamp_ns: int
    rgb: np.ndarray
    depth_m: np.ndarray
    depth_rectified: bool = False


class TrackingStatus(str, Enum):
    INITIALISING = "initialising"
    OK = "ok"
    LOST = "lost"
    REINITIALISED = "reinitialised"


@dataclass(frozen=True)
class OdometryResult:
    """Pose estimate of one frame.

    ``covariance`` is 6x6 over a body-frame perturbation of ``T_odom_base`` (``T exp(eps)``), ROS
    order x y z rot_x rot_y rot_z. ``tracking_time_s`` covers preprocessing and tracking (what a
    new frame waits for), not keyframe insertion.
    """

    stamp_ns: int
    T_odom_base: np.ndarray
    T_odom_camera: np.ndarray
    covariance: np.ndarray
    status: TrackingStatus
    mode: str
    tracking_time_s: float
    n_points: int
    n_inliers: int
    keyframe_inserted: bool


def _adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint of a pose acting on twists (translation first)."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[:3, 3:] = hat(t) @ R
    return A


class Odometry:
    """Direct RGB-D odometry (RGB-only mode of Eq. 4, ``w2 = 0``)."""

    #: Event fusion is not implemented yet: events are buffered and ignored.
    supports_events: bool = False

    _EVENT_BUFFER_NS = 1_000_000_000

    def __init__(self, config: AtsvoConfig, rgb_camera: CameraModel, event_camera: CameraModel | None = None) -> None:
        self.config = config
        self.raw_camera = rgb_camera
        self.camera = rgb_camera.pinhole()
        self.event_camera = event_camera
        self._rectify = rgb_camera.rectify_maps() if rgb_camera.is_distorted else None
        levels = config.tracker.pyramid_levels
        while levels > 1 and min(self.camera.width, self.camera.height) >> (levels - 1) < 16:
            levels -= 1
        self.n_levels = levels
        self.cameras = pyramid_cameras(self.camera, levels)
        self.T_base_rgb = config.rig.T_base_rgb_matrix()
        self.T_rgb_base = se3_inv(self.T_base_rgb)
        self.tracker = Tracker(config.tracker)
        self.map = PointMap(levels, len(RGB_PATTERN))
        self._events: deque[EventBatch] = deque()
        # Pose history of the colour camera: (stamp_ns, T_c_w) of the last good frames, newest last.
        self._history: deque[tuple[int, np.ndarray]] = deque(maxlen=2)
        self._affine = (0.0, 0.0)
        self._n_reference = 0
        self._healthy_reference = 9
        self._last_stamp: int | None = None
        self._initialised = False
        #: Why the last frame was not tracked (None when it was): for logs and diagnostics.
        self.last_loss_reason: str | None = None
        #: Keyframes inserted since construction (re-initialisations included).
        self.n_keyframes = 0

    # ------------------------------------------------------------------ inputs
    def add_events(self, batch: EventBatch) -> None:
        """Buffer an event batch (time order); the RGB-only mode keeps only the last second."""
        if len(batch) == 0:
            return
        self._events.append(batch)
        newest = batch.t_last_ns
        while self._events and self._events[0].t_last_ns < newest - self._EVENT_BUFFER_NS:
            self._events.popleft()

    def _preprocess(self, frame: RgbdFrame) -> tuple[np.ndarray, np.ndarray]:
        rgb = np.asarray(frame.rgb)
        if rgb.ndim == 3 and rgb.shape[2] == 3:
            grey = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)
        elif rgb.ndim == 2:
            grey = rgb
        else:
            raise ImageError(f"colour image must be HxWx3 RGB or HxW grey, got shape {rgb.shape}")
        if grey.shape != (self.raw_camera.height, self.raw_camera.width):
            raise ImageError(f"colour image is {grey.shape[1]}x{grey.shape[0]} but the camera model is "
                             f"{self.raw_camera.width}x{self.raw_camera.height}; check the camera_info / config")
        depth = np.asarray(frame.depth_m, dtype=np.float32)
        if depth.shape != grey.shape:
            raise ImageError(f"depth image shape {depth.shape} differs from the colour image {grey.shape}: "
                             "the depth must be aligned to colour")
        grey = grey.astype(np.float32)
        if self._rectify is not None:
            mx, my = self._rectify
            grey = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            if not frame.depth_rectified:
                depth = cv2.remap(depth, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                                  borderValue=0.0)
        return grey, depth

    # ------------------------------------------------------------------ main entry
    def process_frame(self, frame: RgbdFrame) -> OdometryResult:
        """Track one frame, insert a keyframe when needed, return the pose estimate."""
        t0 = time.perf_counter()
        stamp = int(frame.stamp_ns)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            raise TrackingError(f"frame stamp {stamp} ns is not after the previous one ({self._last_stamp} ns); "
                                "feed frames in time order")
        grey, depth = self._preprocess(frame)
        pyr = image_pyramid_with_gradients(build_pyramid(grey, self.n_levels))
        self._last_stamp = stamp
        predicted = self._predict(stamp)

        if not self._initialised or len(self.map) == 0:
            first = self.n_keyframes == 0  # never had a map: still initialising (e.g. no depth yet)
            T_c_w = predicted
            t_track = time.perf_counter() - t0
            n_new = self._insert_keyframe(stamp, T_c_w, pyr, depth, tracked_uv=np.zeros((0, 2)), reset=True)
            if n_new > 0:
                self._initialised = True
                status = TrackingStatus.INITIALISING if first else TrackingStatus.REINITIALISED
            else:
                status = TrackingStatus.INITIALISING if first else TrackingStatus.LOST
            self._push(stamp, T_c_w)
            return self._result(stamp, T_c_w, None, status, t_track, len(self.map), 0, n_new > 0)

        result = self._track(pyr, predicted)
        self.last_loss_reason = self._loss_reason(result)
        t_track = time.perf_counter() - t0
        if self.last_loss_reason is not None:
            return self._lost(stamp, predicted, pyr, depth, t_track, result)

        T_c_w = result.T_rgb_w
        T_c_w[:3, :3] = project_to_so3(T_c_w[:3, :3])
        states = result.states["rgb"]
        inl = states == 1
        affine = self._new_affine(result, pyr, T_c_w, inl)
        if abs(affine[0] - self._affine[0]) > np.log(self.config.tracker.max_gain_ratio):
            self.last_loss_reason = f"brightness gain jumped by x{np.exp(affine[0] - self._affine[0]):.2f}"
            return self._lost(stamp, predicted, pyr, depth, t_track, result)
        self._affine = affine
        self.map.update_observations(states)
        uv_in = self._project(self.map.points_w[inl], T_c_w)
        health = assess_health(uv_in, self.camera.width, self.camera.height, self._n_reference,
                               self.config.mapping, self._healthy_reference)
        kf = False
        if health.needs_keyframe:
            kf = self._insert_keyframe(stamp, T_c_w, pyr, depth, tracked_uv=uv_in, reset=False) > 0
            if not kf:  # nothing new to add: keep the reference so the rule does not fire every frame
                self._n_reference = max(1, health.n_tracked)
                self._healthy_reference = health.healthy_regions
        self.map.cull(self.config.mapping)
        self._push(stamp, T_c_w)
        return self._result(stamp, T_c_w, result.covariance, TrackingStatus.OK, t_track, len(self.map),
                            result.n_inliers, kf)

    def _lost(self, stamp: int, predicted: np.ndarray, pyr: list[np.ndarray], depth: np.ndarray,
              t_track: float, result: TrackResult | None) -> OdometryResult:
        """Tracking lost: rebuild the map from this frame at the motion-model pose (no jump, no NaN)."""
        n_new = self._insert_keyframe(stamp, predicted, pyr, depth, tracked_uv=np.zeros((0, 2)), reset=True)
        status = TrackingStatus.REINITIALISED if n_new > 0 else TrackingStatus.LOST
        self._initialised = n_new > 0
        self._push(stamp, predicted)
        return self._result(stamp, predicted, None, status, t_track, len(self.map),
                            0 if result is None else result.n_inliers, n_new > 0)

    def _new_affine(self, result: TrackResult, pyr: list[np.ndarray], T_c_w: np.ndarray,
                    inliers: np.ndarray) -> tuple[float, float]:
        """Brightness parameters of this frame relative to the map's reference scale.

        With zero-mean patches the gain fitted by the alignment is a contrast ratio, which blur and
        interpolation shrink; propagated into keyframes it would drift. So the gain kept for the
        map (and the next frame) is measured after the alignment as the median ratio of the inlier
        patches' mean intensities (current / stored) on pyramid level 1, which blur does not change.
        """
        cfg = self.config.tracker
        if not cfg.affine_brightness:
            return (0.0, 0.0)
        if not cfg.zero_mean_patches:
            return result.affine["rgb"]
        lvl = min(1, self.n_levels - 1)
        idx = np.flatnonzero(inliers)
        if len(idx) < 20:
            return self._affine
        idx = idx[:: max(1, len(idx) // 300)]  # a median over ~300 points is plenty
        cam = self.cameras[lvl]
        p = self.map.points_w[idx] @ T_c_w[:3, :3].T + T_c_w[:3, 3]
        uv, _ = cam.project(p)
        cur, ok = sample_patches(pyr[lvl][..., 0], uv, RGB_PATTERN)
        ref = self.map.patches[lvl][idx].mean(axis=1)
        ok &= ref > 5.0
        if ok.sum() < 20:
            return self._affine
        gain = float(np.median(cur[ok].mean(axis=1) / ref[ok]))
        return (float(np.log(max(gain, 1e-3))), 0.0)

    # ------------------------------------------------------------------ tracking
    def _predict(self, stamp: int) -> np.ndarray:
        """Constant-motion prediction of ``T_c_w`` (identity before the first frame)."""
        if not self._history:
            return np.eye(4)
        s1, T1 = self._history[-1]
        if len(self._history) < 2:
            return T1.copy()
        s0, T0 = self._history[0]
        delta = T1 @ se3_inv(T0)
        ratio = (stamp - s1) / max(1, s1 - s0)
        ratio = float(np.clip(ratio, 0.0, 3.0))
        if abs(ratio - 1.0) > 1e-6:
            delta = se3_exp(ratio * se3_log(delta))
        return delta @ T1

    def _push(self, stamp: int, T_c_w: np.ndarray) -> None:
        self._history.append((stamp, np.asarray(T_c_w, dtype=np.float64).copy()))

    def _block(self, pyr: list[np.ndarray]) -> ResidualBlock:
        return ResidualBlock("rgb", self.map.points_w, self.map.patches, RGB_PATTERN, pyr, self.cameras,
                             weight=self.config.tracker.w_rgb, estimate_affine=self.config.tracker.affine_brightness,
                             coarse_points=self.config.tracker.coarse_level_points,
                             zero_mean=self.config.tracker.zero_mean_patches, ref_depth=self.map.host_depth,
                             max_scale_change=self.config.tracker.max_scale_change)

    def _track(self, pyr: list[np.ndarray], predicted: np.ndarray) -> TrackResult | None:
        last = self._history[-1][1]
        guesses = [predicted, last] if len(self._history) >= 2 else [last]
        try:
            return self.tracker.track([self._block(pyr)], guesses, {"rgb": self._affine})
        except TrackingError:
            return None

    def _loss_reason(self, res: TrackResult | None) -> str | None:
        """Why a tracking result cannot be trusted (None = good)."""
        cfg = self.config.tracker
        if res is None or not res.ok:
            return "no estimate (NaN or no map point visible)"
        if res.n_inliers < max(cfg.min_inliers, cfg.min_inlier_fraction * res.n_visible):
            return f"{res.n_inliers} inliers of {res.n_visible} visible map points"
        std = float(np.sqrt(np.linalg.eigvalsh(res.covariance[:3, :3]).max()))
        if std > cfg.max_position_std_m:
            return f"degenerate geometry (position std {std:.3f} m)"
        rot, trans = relative_motion(se3_inv(self._history[-1][1]), se3_inv(res.T_rgb_w))
        if trans > cfg.max_step_m or np.degrees(rot) > cfg.max_step_rot_deg:
            return f"jump of {trans:.3f} m / {np.degrees(rot):.1f} deg in one frame"
        return None

    def _project(self, points_w: np.ndarray, T_c_w: np.ndarray) -> np.ndarray:
        p = points_w @ T_c_w[:3, :3].T + T_c_w[:3, 3]
        uv, _ = self.camera.project(p)
        return uv

    # ------------------------------------------------------------------ mapping
    def _insert_keyframe(self, stamp: int, T_c_w: np.ndarray, pyr: list[np.ndarray], depth: np.ndarray,
                         tracked_uv: np.ndarray, reset: bool) -> int:
        """Select new points where the tracked ones leave gaps, back-project them, add a keyframe."""
        if reset:
            self.map = PointMap(self.n_levels, len(RGB_PATTERN))
        mapping, sel = self.config.mapping, self.config.rgb_selection
        grey = pyr[0][..., 0]
        ok = valid_depth_mask(depth, self.config.rig, mapping.depth_edge_ratio, max(3, mapping.depth_window_px))
        uv = select_rgb_pixels(grey, sel, mask=ok)
        if len(uv) and len(tracked_uv):
            h, w = grey.shape
            cell = max(2, int(np.sqrt(h * w / max(1, sel.target_points))))
            occ = np.zeros((h // cell + 1, w // cell + 1), dtype=bool)
            t = np.round(tracked_uv).astype(np.int64)
            inside = (t[:, 0] >= 0) & (t[:, 0] < w) & (t[:, 1] >= 0) & (t[:, 1] < h)
            occ[t[inside, 1] // cell, t[inside, 0] // cell] = True
            uv = uv[~occ[uv[:, 1] // cell, uv[:, 0] // cell]]
        if len(uv) == 0:
            return 0
        z = smoothed_depth(depth, ok, mapping.depth_window_px)[uv[:, 1], uv[:, 0]].astype(np.float64)
        p_c = self.camera.backproject(uv.astype(np.float64), z)
        patches = extract_patches(pyr, uv, RGB_PATTERN, self._affine if not reset else (0.0, 0.0))
        if reset:
            self._affine = (0.0, 0.0)
        self.map.add_keyframe(stamp, se3_inv(T_c_w), self._affine, p_c, patches)
        self.n_keyframes += 1
        all_uv = np.concatenate([np.asarray(tracked_uv, dtype=np.float64).reshape(-1, 2), uv.astype(np.float64)])
        ref = assess_health(all_uv, self.camera.width, self.camera.height, 1, self.config.mapping)
        self._n_reference = max(1, ref.n_tracked)
        self._healthy_reference = ref.healthy_regions
        return len(uv)

    # ------------------------------------------------------------------ output
    def _result(self, stamp: int, T_c_w: np.ndarray, cov_c: np.ndarray | None, status: TrackingStatus,
                t_track: float, n_points: int, n_inliers: int, kf: bool) -> OdometryResult:
        T_w_c = se3_inv(T_c_w)
        T_odom_cam = self.T_base_rgb @ T_w_c
        T_odom_base = T_odom_cam @ self.T_rgb_base
        if cov_c is None:
            cov = np.eye(6) * 1e3  # no measurement: a large, honest uncertainty
        else:
            A = _adjoint(self.T_base_rgb)
            cov = A @ cov_c @ A.T
        return OdometryResult(stamp, T_odom_base, T_odom_cam, cov, status, "rgbd", float(t_track),
                              int(n_points), int(n_inliers), bool(kf))


__all__ = ["Odometry", "OdometryResult", "RgbdFrame", "TrackingStatus"]
