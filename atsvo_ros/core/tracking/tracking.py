"""Tracking (the PTAM split): one frame against the current map snapshot.

Builds the residual blocks of Eq. 4 for the frame (photometric RGB against the map's patches,
point-to-plane depth against the map's geometric points), runs the optimiser from the motion
model's guesses, judges the result (:mod:`.checks`), counts per-point outlier runs for the mapper's
culling and decides, by the nine-region rule, whether a keyframe is needed. It never edits the map:
it reads one immutable :class:`~atsvo_ros.core.mapping.map.MapSnapshot` until mapping hands it the next.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig, TrackerConfig
from atsvo_ros.core.events.event_map import TemporaryEventMap
from atsvo_ros.core.events.frontend import EventFrame
from atsvo_ros.core.geometry import project_to_so3, se3_exp
from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.image.photometric import ATS_PATTERN, RGB_PATTERN, sample_patches
from atsvo_ros.core.mapping.keyframes import MapHealth, assess_health
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.mapper import KeyframeRequest
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.core.tracking.checks import IMAGE_TERMS, Priors, Verdict, failing_image_terms, judge
from atsvo_ros.core.tracking.residuals import INLIER, OUTLIER, ResidualBlock
from atsvo_ros.core.tracking.residuals.geometric import GeometricBlock
from atsvo_ros.core.tracking.residuals.photometric import PhotometricBlock
from atsvo_ros.core.tracking.tracker import Tracker, TrackResult
from atsvo_ros.errors import TrackingError


@dataclass(frozen=True)
class TrackingOutcome:
    """One frame tracked against a snapshot: the estimate, the verdict on it and the map health."""

    result: TrackResult | None
    verdict: Verdict
    T_c_w: np.ndarray  # the estimate (or the first guess when there is none)
    affine: tuple[float, float]  # brightness of this frame relative to the map's scale
    zncc: float  # mean ZNCC of the inlier patches (level 0) after alignment, NaN without points
    health: MapHealth | None
    tracked_uv: np.ndarray


def rotation_hypotheses(T_c_w: np.ndarray, angle_deg: float) -> list[np.ndarray]:
    """``T_c_w`` turned by +-``angle_deg`` about each camera axis (the camera turning more or less than predicted)."""
    if angle_deg <= 0:
        return []
    a = np.radians(angle_deg)
    out = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            xi = np.zeros(6)
            xi[3 + axis] = sign * a
            out.append(se3_exp(xi) @ T_c_w)
    return out


def _mean_zncc(block: PhotometricBlock) -> float:
    """Mean ZNCC of a photometric block's inlier patches after the final linearisation (NaN without any)."""
    inl = block.state == INLIER
    z = block.zncc[inl]
    return float(np.nanmean(z)) if np.isfinite(z).any() else float("nan")


def rgb_block(cfg: TrackerConfig, points_w: np.ndarray, patches: np.ndarray, host_depth: np.ndarray,
              frame: PreparedFrame, cameras: list, rolling_shutter: RollingShutter | None = None,
              estimate_affine: bool = False) -> PhotometricBlock:
    """The RGB term of Eq. 4: map points (world frame, patches of their hosts) against ``frame``'s colour pyramid."""
    return PhotometricBlock(
        "rgb", points_w, patches, RGB_PATTERN, frame.pyramid, cameras, weight=cfg.w_rgb, sigma=cfg.photometric_sigma,
        huber=cfg.huber_delta, outlier=cfg.outlier_threshold, gradient_weight=cfg.gradient_weight,
        estimate_affine=estimate_affine, coarse_points=cfg.coarse_level_points, zero_mean=cfg.zero_mean_patches,
        ref_depth=host_depth, max_scale_change=cfg.max_scale_change, rolling_shutter=rolling_shutter)


class Tracking:
    """Per-frame tracking against the latest snapshot (see the module docstring)."""

    def __init__(self, config: AtsvoConfig, cameras: list, event_cameras: list | None = None,
                 T_event_rgb: np.ndarray | None = None) -> None:
        self.config = config
        self.cameras = cameras
        self.camera = cameras[0]
        self.event_cameras = event_cameras
        self.T_event_rgb = np.eye(4) if T_event_rgb is None else np.asarray(T_event_rgb, dtype=np.float64)
        self.tracker = Tracker(config.tracker)
        self.snapshot = MapSnapshot.empty(len(cameras), len(RGB_PATTERN))
        #: the temporary event map N of Eq. 4 (None: the event term is off)
        self.event_map: TemporaryEventMap | None = None
        self._outlier_runs = np.zeros(0, np.int32)
        #: the depth term's weight for this frame (:meth:`set_calm`)
        self.depth_weight = config.tracker.w_depth

    def set_calm(self, calm: bool) -> None:
        """Whether the camera turned little between the recent frames: the depth term then takes
        ``tracker.calm_depth_factor`` of its weight for the frames tracked from now on."""
        cfg = self.config.tracker
        self.depth_weight = cfg.w_depth * (cfg.calm_depth_factor if calm else 1.0)

    def set_event_map(self, event_map: TemporaryEventMap | None) -> None:
        """Use ``event_map`` for the event term from the next frame on (None: RGB-D only)."""
        self.event_map = event_map

    def uses_events(self, event_frame: EventFrame | None) -> bool:
        """Whether the event term takes part: a surface for this frame and a big enough temporary map."""
        return (event_frame is not None and self.event_map is not None and self.event_cameras is not None
                and self.config.tracker.w_event > 0 and len(self.event_map) >= self.config.fusion.min_points)

    def set_snapshot(self, snapshot: MapSnapshot) -> None:
        """Track against ``snapshot`` from now on (mapping's latest)."""
        if snapshot.snapshot_id != self.snapshot.snapshot_id:
            self._outlier_runs = np.zeros(len(snapshot), np.int32)
        self.snapshot = snapshot

    def colour_usable(self, frame: PreparedFrame) -> bool:
        """Whether the colour image shows anything (not a covered lens, darkness or saturation).

        Judged by contrast, not by gradients: motion blur mid-flip wipes out the gradients (0.01 % of pixels
        above the selection floor) while the RGB term still holds the pose; a blind image has no contrast.
        """
        return frame.contrast >= self.config.tracker.min_contrast

    @property
    def has_map(self) -> bool:
        return len(self.snapshot) > 0 or len(self.snapshot.geo_points_w) > 0

    def blocks(self, frame: PreparedFrame, rolling_shutter: RollingShutter | None = None,
               event_frame: EventFrame | None = None) -> list[ResidualBlock]:
        """The residual blocks of Eq. 4 for this frame: RGB, depth (weight and points), ATS (:meth:`uses_events`).

        ``rolling_shutter`` applies to the colour image only: modelling the same readout on a Kinect's
        registered depth made TUM fr1_rpy worse (ATE 1.9 vs 1.4 cm), and a D455's depth is global shutter.
        """
        cfg = self.config.tracker
        snap = self.snapshot
        out: list[ResidualBlock] = []
        if len(snap) and self.colour_usable(frame):
            # With zero-mean patches the gain is the frame's exposure relative to the map, measured from
            # patch means after the alignment, not fitted: blur lowers contrast, and a fitted gain
            # shrinks with it until the cost hardly depends on the pose.
            out.append(rgb_block(cfg, snap.points_w, snap.patches, snap.host_depth, frame, self.cameras,
                                 rolling_shutter, estimate_affine=cfg.affine_brightness and not cfg.zero_mean_patches))
        if self.depth_weight > 0 and len(snap.geo_points_w):
            out.append(GeometricBlock(
                "depth", snap.geo_points_w, frame.depth_pyramid, self.cameras,
                T_cam_rgb=np.eye(4) if frame.T_depth_rgb is None else frame.T_depth_rgb, weight=self.depth_weight,
                sigma_at_1m_m=cfg.depth_sigma_at_1m_m, sigma_min_m=cfg.depth_sigma_min_m, huber=cfg.depth_huber,
                outlier=cfg.depth_outlier, edge_ratio=self.config.mapping.depth_edge_ratio,
                coarse_points=cfg.coarse_level_points))
        if self.uses_events(event_frame):
            fu, em = self.config.fusion, self.event_map
            # The ATS is not an image of the scene's brightness: no gain, but zero-mean patches (the surface
            # level depends on the time since the last event, which differs between two frames).
            out.append(PhotometricBlock(
                "ats", em.points_w, em.patches, ATS_PATTERN, event_frame.pyramid, self.event_cameras,
                T_cam_rgb=self.T_event_rgb, weight=cfg.w_event, sigma=fu.sigma, huber=fu.huber, outlier=fu.outlier,
                gradient_weight=fu.gradient_weight, estimate_affine=False, zero_mean=True))
        return out

    def track(self, frame: PreparedFrame, guesses: list[np.ndarray], affine: tuple[float, float],
              reference: np.ndarray, rolling_shutter: RollingShutter | None = None,
              priors: Priors | None = None, event_frame: EventFrame | None = None) -> TrackingOutcome:
        """Align ``frame`` to the snapshot from ``guesses`` and judge the estimate.

        ``reference`` is the last trusted pose (for the step-size check); ``affine`` the brightness
        model carried from the previous frame; ``priors`` the motion's predictions the estimate must agree
        with (gyro rotation, constant-velocity centre); ``event_frame`` the event camera at this frame.
        """
        cfg = self.config.tracker
        blocks = self.blocks(frame, rolling_shutter, event_frame)
        if not blocks:
            return self._failed(guesses[0], affine, "no map point to track")
        hyp = rotation_hypotheses(guesses[0], cfg.rotation_hypotheses_deg)
        prior = priors.motion if priors else None
        try:
            res = self.tracker.track(blocks, [*guesses, *hyp], {"rgb": affine}, refine_best=cfg.refine_guesses,
                                     prior=prior)
            T_c_w, new_affine, znccs, verdict = self._assess(res, blocks, frame, affine, reference, priors)
            weak = failing_image_terms(self.config, res)
            if not verdict.ok and weak and any(n in IMAGE_TERMS and n not in weak for n in res.blocks):
                # A term too small to count may still steer: mid-flip, a dozen blurred colour patches pulled
                # the ATS term's pose 9 deg away. Align again from the same guesses without it. (Only then:
                # on good frames those few patches help the ATS term, backflip ATE 2-4 cm against 10-18.)
                alone = [b for b in blocks if b.name not in weak]
                res2 = self.tracker.track(alone, [*guesses, *hyp], {"rgb": affine}, refine_best=cfg.refine_guesses,
                                          prior=prior)
                second = self._assess(res2, alone, frame, affine, reference, priors)
                if second[3].ok:
                    res, blocks, (T_c_w, new_affine, znccs, verdict) = res2, alone, second
        except TrackingError as exc:
            return self._failed(guesses[0], affine, str(exc))
        if not verdict.ok and not verdict.coasting:
            coast = self._coast(blocks, frame, affine, reference, priors, verdict)
            if coast is not None:
                res, blocks, (T_c_w, new_affine, znccs, verdict) = coast
        zncc = max(znccs.values(), default=float("nan"), key=lambda z: -np.inf if np.isnan(z) else z)
        states = res.states.get("rgb", np.zeros(0, np.int8))
        inl = states == INLIER
        if len(states) == len(self._outlier_runs):
            self._outlier_runs = np.where(states == OUTLIER, self._outlier_runs + 1,
                                          np.where(states == INLIER, 0, self._outlier_runs)).astype(np.int32)
        uv = self._project(self.snapshot.points_w[inl], T_c_w)
        health = assess_health(uv, self.camera.width, self.camera.height, self.snapshot.n_reference,
                               self.config.mapping, self.snapshot.healthy_reference)
        return TrackingOutcome(res, verdict, T_c_w, new_affine, zncc, health, uv)

    def _coast(self, blocks: list[ResidualBlock], frame: PreparedFrame, affine: tuple[float, float],
               reference: np.ndarray, priors: Priors | None, verdict: Verdict
               ) -> tuple[TrackResult, list[ResidualBlock], tuple] | None:
        """The image terms misled the alignment (mid-flip: a few blurred patches, 1.2 deg off): align on the depth
        term and the motion prior alone from the prediction. ``(result, blocks, assessment)`` when that coasts,
        else None (no prior, no depth term, or the depth term does not hold either)."""
        depth = [b for b in blocks if b.name == "depth"]
        if not depth or priors is None or priors.motion is None:
            return None
        try:
            res = self.tracker.track(depth, [priors.motion.T_pred_rgb_w], {}, prior=priors.motion)
        except TrackingError:  # no map point in view: nothing to coast on
            return None
        why = f"the image terms did not hold ({verdict.reason})"
        out = self._assess(res, depth, frame, affine, reference, priors, why)
        return (res, depth, out) if out[3].coasting else None

    def _assess(self, res: TrackResult, blocks: list[ResidualBlock], frame: PreparedFrame,
                affine: tuple[float, float], reference: np.ndarray,
                priors: Priors | None, coast_reason: str | None = None
                ) -> tuple[np.ndarray, tuple[float, float], dict[str, float], Verdict]:
        """The estimate of ``res`` as a rotation-projected pose, its brightness, per-term ZNCC and verdict
        (``coast_reason``: the image terms were left out, see :func:`~atsvo_ros.core.tracking.checks.judge`)."""
        T_c_w = res.T_rgb_w.copy()
        T_c_w[:3, :3] = project_to_so3(T_c_w[:3, :3])
        inl = res.states.get("rgb", np.zeros(0, np.int8)) == INLIER
        new_affine = self._new_affine(res, frame, T_c_w, inl, affine)
        znccs = {b.name: _mean_zncc(b) for b in blocks if isinstance(b, PhotometricBlock)}
        return T_c_w, new_affine, znccs, judge(self.config, res, T_c_w, reference, affine, new_affine, znccs, priors,
                                                   coast_reason)

    def keyframe_request(self, frame: PreparedFrame, outcome: TrackingOutcome,
                         rolling_shutter: RollingShutter | None = None, geometry_only: bool = False,
                         refine: bool = True) -> KeyframeRequest:
        """A request to insert ``frame`` as a keyframe at the tracked pose (``geometry_only``: depth points only;
        ``refine``: run the local window after it)."""
        return KeyframeRequest(self.snapshot.snapshot_id, frame, outcome.T_c_w, outcome.affine, outcome.tracked_uv,
                               self._outlier_runs.copy(), rolling_shutter=rolling_shutter, geometry_only=geometry_only,
                               refine=refine)

    @staticmethod
    def reset_request(frame: PreparedFrame, T_c_w: np.ndarray, rolling_shutter: RollingShutter | None = None,
                      keep_memory: bool = False) -> KeyframeRequest:
        """A request to start a new map from ``frame`` at ``T_c_w`` (``keep_memory``: the old keyframes kept aside)."""
        return KeyframeRequest(-1, frame, T_c_w, (0.0, 0.0), np.zeros((0, 2)), np.zeros(0, np.int32), reset=True,
                               rolling_shutter=rolling_shutter, keep_memory=keep_memory)

    def _failed(self, T_c_w: np.ndarray, affine: tuple[float, float], reason: str) -> TrackingOutcome:
        return TrackingOutcome(None, Verdict.lost(reason), np.asarray(T_c_w, dtype=np.float64).copy(), affine,
                               float("nan"), None, np.zeros((0, 2)))

    def _project(self, points_w: np.ndarray, T_c_w: np.ndarray) -> np.ndarray:
        p = points_w @ T_c_w[:3, :3].T + T_c_w[:3, 3]
        uv, _ = self.camera.project(p)
        return uv

    def _new_affine(self, res: TrackResult, frame: PreparedFrame, T_c_w: np.ndarray, inliers: np.ndarray,
                    affine: tuple[float, float]) -> tuple[float, float]:
        """Brightness of this frame relative to the map's reference scale.

        With zero-mean patches it is the median ratio of the inlier patches' mean intensities (current /
        stored) on pyramid level 1, which blur does not change (contrast shrinks with blur, means do not,
        so the gain does not drift from keyframe to keyframe); otherwise the fitted ``(a, b)``.
        """
        cfg = self.config.tracker
        if not cfg.affine_brightness:
            return (0.0, 0.0)
        if not cfg.zero_mean_patches:
            return res.affine.get("rgb", affine)
        lvl = min(1, len(self.cameras) - 1)
        idx = np.flatnonzero(inliers)
        if len(idx) < 20:
            return affine
        idx = idx[:: max(1, len(idx) // 300)]  # a median over ~300 points is plenty
        p = self.snapshot.points_w[idx] @ T_c_w[:3, :3].T + T_c_w[:3, 3]
        uv, _ = self.cameras[lvl].project(p)
        cur, ok = sample_patches(frame.pyramid[lvl][..., 0], uv, RGB_PATTERN)
        ref = self.snapshot.patches[lvl][idx].mean(axis=1)
        ok &= ref > 5.0
        if ok.sum() < 20:
            return affine
        gain = float(np.median(cur[ok].mean(axis=1) / ref[ok]))
        return (float(np.log(max(gain, 1e-3))), 0.0)


__all__ = ["Tracking", "TrackingOutcome", "rgb_block", "rotation_hypotheses"]
