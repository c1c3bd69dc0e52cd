"""The odometry facade: RGB-D frames (events, IMU samples) in, ``odom -> base`` poses out.

Composes the PTAM split of Fig. 2 in one thread: the colour camera's front end, the motion model,
:class:`~atsvo_ros.core.tracking.tracking.Tracking` against the latest map snapshot and the
:class:`~atsvo_ros.core.mapping.mapper.Mapper`, which inserts a keyframe whenever tracking asks for one and
hands back a new snapshot before the next frame (what the replay does; the nodes can run the
mapper elsewhere and pass snapshots back).

Frames: the internal world frame is the colour optical frame of the first frame; the published
``odom`` frame is the base frame at the first frame (REP 105: odom starts where the robot is), so
``T_odom_base`` of the first frame is the identity and ``T_odom_world = T_base_rgb``.

Per frame: predictions (constant motion, zero motion, the gyro's rotation when an IMU is fed, and
rotated hypotheses when configured) -> tracking -> checks. A frame the checks reject is tracked
again from the poses of the recent keyframes (relocalisation); only if that fails too is a new map
started at the predicted pose (re-initialisation). Clock jumps (a stamp not after the previous one,
or a gap over :attr:`Odometry.MAX_GAP_S`) reset the motion model instead of stopping the odometry.

The parts live beside this module: the predictions in :mod:`~atsvo_ros.core.odometry.prediction` (with
the IMU buffer of :mod:`~atsvo_ros.core.odometry.gyro`), the event camera's state between frames in
:mod:`~atsvo_ros.core.odometry.event_side`, the frame clock and the published stamp in
:mod:`~atsvo_ros.core.odometry.timing`, the published result in :mod:`~atsvo_ros.core.odometry.output`.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig, TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.frontend import EventFrame, EventFrontEnd
from atsvo_ros.core.frame import OdometryResult, RgbdFrame, TrackingStatus
from atsvo_ros.core.geometry import camera_centre, se3_inv
from atsvo_ros.core.image.frontend import PreparedFrame, RgbdFrontEnd
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.mapper import KeyframeRequest, Mapper
from atsvo_ros.core.mapping.ports import InlineMapping, MappingPort
from atsvo_ros.core.odometry.calm import TurnHistory
from atsvo_ros.core.odometry.depth_timing import DepthTiming
from atsvo_ros.core.odometry.event_side import EventSide
from atsvo_ros.core.odometry.feature_assist import FeatureAssist, rotation_between_deg
from atsvo_ros.core.odometry.gyro import GyroBuffer
from atsvo_ros.core.odometry.imu_state import VelocityWindow
from atsvo_ros.core.odometry.inertial import STANDARD_GRAVITY, CameraMotion, InertialPredictor
from atsvo_ros.core.odometry.output import ResultBuilder
from atsvo_ros.core.odometry.prediction import Predictor
from atsvo_ros.core.odometry.timing import FrameTiming
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.core.tracking.checks import DEGRADED, OK, Priors, Verdict
from atsvo_ros.core.tracking.motion import MotionModel
from atsvo_ros.core.tracking.tracking import Tracking, TrackingOutcome, rotation_hypotheses
from atsvo_ros.core.tracking.window import window_refiner


@dataclass(frozen=True)
class _Anchor:
    """The frame a map was started from, its depth as it came: rebuilt once that depth can be moved in time."""

    stamp_ns: int
    raw: PreparedFrame
    T_c_w: np.ndarray
    turned: bool  # the map's depth was turned by the gyro (False: no gyro over its offset yet)


def _starved_map(out: TrackingOutcome, cfg: TrackerConfig) -> bool:
    """Whether colour tracking failed for want of map points alone: fewer visible than ``tracker.min_inliers``, and
    the visible ones agreeing with the image (inliers above ``tracker.min_inlier_fraction``)."""
    rgb = None if out.result is None else out.result.blocks.get("rgb")
    return (rgb is not None and 0 < rgb.n_visible < cfg.min_inliers
            and rgb.inlier_fraction >= cfg.min_inlier_fraction)


def _best_attempt(attempts: list[tuple[TrackingOutcome, bool, TrackingStatus]]
                  ) -> tuple[TrackingOutcome, bool, TrackingStatus] | None:
    """The first trusted attempt; else the degraded one whose patches match best; None if every one is lost."""
    for a in attempts:
        if a[0].verdict.level == OK:
            return a
    degraded = [(a[0], a[1], TrackingStatus.DEGRADED) for a in attempts if a[0].verdict.level == DEGRADED]
    if not degraded:
        return None
    return max(degraded, key=lambda a: -1.0 if np.isnan(a[0].zncc) else a[0].zncc)


class Odometry:
    """Direct RGB-D (+ event) odometry: Eq. 4 with the RGB, depth and, during fast motion, ATS terms."""

    #: A gap between frames longer than this resets the motion model (constant motion is meaningless).
    MAX_GAP_S = 1.0

    def __init__(self, config: AtsvoConfig, rgb_camera: CameraModel, event_camera: CameraModel | None = None,
                 mapping: Callable[[Mapper], MappingPort] | None = None) -> None:
        """``mapping`` wraps the mapper into the port tracking talks to (default: :class:`InlineMapping`)."""
        self.config = config
        self.raw_camera = rgb_camera
        self.frontend = RgbdFrontEnd(rgb_camera, config.tracker.pyramid_levels, config.rig.depth_min_m,
                                     config.rig.depth_max_m, config.mapping.depth_edge_ratio)
        self.camera = self.frontend.camera
        self.cameras = self.frontend.cameras
        self.n_levels = self.frontend.n_levels
        self.event_camera = event_camera
        self.T_base_rgb = config.rig.T_base_rgb_matrix()
        self.T_rgb_base = se3_inv(self.T_base_rgb)
        self.R_rgb_imu = config.rig.T_rgb_imu_matrix()[:3, :3]
        self.motion = MotionModel()
        #: the recent turns between frames: the local window and the lighter depth term run only while they are small
        self.turns = TurnHistory(int(config.tracker.calm_s * 1e9))
        self._calm_used = config.mapping.window_iterations > 0 or config.tracker.calm_depth_factor != 1
        self.events: EventFrontEnd | None = None
        event_cams = None
        if event_camera is not None and config.mode == "fused":
            self.events = EventFrontEnd(event_camera, config, config.tracker.pyramid_levels)
            event_cams = self.events.cameras
        T_event_rgb = se3_inv(config.rig.T_rgb_event_matrix())
        self.tracking = Tracking(config, self.cameras, event_cams, T_event_rgb)
        self.mapper = Mapper(config, self.cameras, None if self.events is None else self.events.camera,
                             window_refiner(config, self.cameras))
        self.mapping: MappingPort = (mapping or InlineMapping)(self.mapper)
        #: The event front end's state between frames: event counts, the previous surface for the event map.
        self.event_side = EventSide(config, self.events, self.mapping)
        #: The IMU samples of the last seconds (the gyro's rotation between frames).
        self.gyro = GyroBuffer(self.R_rgb_imu)
        #: The accelerometer's camera centres and velocities and the gravity estimate they need
        #: (``tracker.imu_translation``, ``tracker.depth_time_translation``).
        uses_accel = config.tracker.imu_translation or config.tracker.depth_time_translation
        #: The trusted poses of the last ``tracker.imu_velocity_window_s`` and the IMU state fitted to them.
        self.velocity = VelocityWindow(config.rig.T_rgb_imu_matrix(),
                                       int(config.tracker.imu_velocity_window_s * 1e9)) if uses_accel else None
        self.inertial = InertialPredictor(config.rig.T_rgb_imu_matrix(),
                                          self.velocity if config.tracker.imu_prior_sigma_m > 0 else None,
                                          config.rig.imu_accel_range_m_s2) if uses_accel else None
        #: The camera's motion between the colour and the depth exposure (``tracker.depth_time_translation``).
        self.depth_timing = DepthTiming(self.velocity) \
            if config.tracker.depth_time_translation and config.rig.depth_time_offset_s != 0 else None
        # until the online estimate exists: the base upright at the first frame (REP 103: base z up)
        self._gravity_prior_w = -STANDARD_GRAVITY * self.T_rgb_base[:3, 2]
        self._anchor: _Anchor | None = None  # the current map's first frame while its depth is not moved in time
        self.predictor = Predictor(config, self.motion, self.gyro, self.camera.height, self.inertial)
        self.timing = FrameTiming(config.rgb_camera.time_offset_s, config.rgb_camera.frame_clock_frames)
        #: ORB matches to the last trusted frame, for frames whose direct pose is in doubt
        self.features = FeatureAssist(config, self.cameras, self.frontend.at_colour_time)
        self._results = ResultBuilder(config, self.T_base_rgb, self.T_rgb_base)
        self._affine = (0.0, 0.0)
        # the newest keyframe was taken while the camera turned fast: its colour patches are motion-blurred
        self._blurred_keyframe = False
        self._asked: tuple[int, np.ndarray] | None = None  # the pending keyframe's stamp and the T_w_c it was asked at
        self._frame_shift: np.ndarray | None = None  # the world's move since the frame was tracked
        self._coast_start_ns: int | None = None  # first frame of the current run of coasting frames
        #: Why the last frame was not ``ok`` (None when it was): for logs and diagnostics.
        self.last_loss_reason: str | None = None

    @property
    def n_keyframes(self) -> int:
        """Keyframes inserted since construction (re-initialisations included)."""
        return self.mapping.n_keyframes

    @property
    def map(self):
        """The snapshot tracking currently reads."""
        return self.tracking.snapshot

    def close(self) -> None:
        """Stop the mapping worker, if any (the inline mapping has none)."""
        self.mapping.close()

    def motion_rates(self) -> tuple[float, float] | None:
        """The paper's relative-motion factor: camera angular rate (rad/s) and speed (m/s) over the last two frames.

        The angular rate comes from the gyro when it covers the interval (measured, not estimated), else
        from the two poses; None before two frames.
        """
        return self.predictor.motion_rates()

    # ------------------------------------------------------------------ inputs
    def add_events(self, batch: EventBatch) -> None:
        """Fold a time-ordered event batch into the time surface (ignored without an event camera)."""
        self.event_side.add(batch)

    def add_imu(self, batch: ImuBatch) -> None:
        """Buffer IMU samples (time order; the last 3 s are kept): their gyro predicts each frame's rotation."""
        self.gyro.add(batch)

    # ------------------------------------------------------------------ main entry
    def process_frame(self, frame: RgbdFrame) -> OdometryResult:
        """Track one frame, insert a keyframe when needed, return the pose estimate."""
        # the event surface's updates since the last frame count towards this frame's tracking time
        event_time_s, n_events = self.event_side.start_frame()
        t0 = time.perf_counter() - event_time_s
        # internally a frame lives at its exposure time off the frame clock (see FrameTiming)
        stamp = self.timing.exposure(frame.stamp_ns)
        prepared = self.frontend.prepare(frame)
        newer = self.mapping.latest()  # a keyframe mapping finished meanwhile (threaded or remote mapping)
        if newer is not None:
            self._take_snapshot(newer)
        note = self.timing.check(stamp, self.MAX_GAP_S)
        if note is not None:
            self.motion.reset()
            if self.inertial is not None:
                self.inertial.reset()
            if self.velocity is not None:
                self.velocity.reset()
        predicted = self.motion.predict(stamp)
        raw = prepared
        prepared, moved = self._place_depth(raw, stamp)
        ev_frame = self.event_side.render(stamp, n_events)  # None while the event camera is silent
        if not self.tracking.has_map:
            self.event_side.end_frame(n_events)
            return self._initialise(prepared, stamp, predicted, t0, note, ev_frame, raw, moved)
        if self._anchor is not None and not self._anchor.turned:
            self._turn_anchor()
        predicted, gyro, fast, guesses, last, rs, priors = self._predict(stamp)
        # Eq. 4 with the event term when the last two frames moved fast (the paper's relative-motion factor)
        self.tracking.set_event_map(self.event_side.event_map() if fast else None)
        # the depth term's weight: reduced while the motion is known and slow (tracker.calm_depth_factor)
        calm_turn = self.config.tracker.calm_turn_deg
        calm = self._calm_used and self.motion.velocity_trusted and self.turns.calm(stamp, predicted, calm_turn)
        self.tracking.set_calm(calm)
        fused = self.tracking.uses_events(ev_frame)
        out = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
        if calm and self.config.tracker.calm_depth_factor != 1 and not self.turns.calm(stamp, out.T_c_w, calm_turn):
            # the turn started this frame: the prediction called it calm, the tracked pose does not
            self.tracking.set_calm(False)
            out = self.tracking.track(prepared, [out.T_c_w, *guesses], self._affine, last, rs, priors, ev_frame)
        status = TrackingStatus.OK
        if out.verdict.level != OK:
            # The camera outran the map while mapping still inserts a keyframe (asynchronous mapping behind):
            # wait for that keyframe rather than relocalise against a map the camera has left. A keyframe that
            # mapping finished while this frame was tracked is taken too (it was not ready when the frame began).
            newer = self.mapping.await_pending() if self.mapping.busy() else self.mapping.latest()
            if newer is not None:
                if self._take_snapshot(newer) is not None:  # the odometry's poses moved with the map
                    predicted, gyro, fast, guesses, last, rs, priors = self._predict(stamp)
                out = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
        if out.verdict.level != OK:
            # Not trusted: try harder before accepting a degraded pose or starting a new map.
            attempts = [(out, fused, TrackingStatus.DEGRADED)]
            if not fused and self.event_side.has_previous:
                # RGB-D alone could not hold the pose (a sudden push-off): the events saw the motion
                self.tracking.set_event_map(self.event_side.event_map())
                if self.tracking.uses_events(ev_frame):
                    retry = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
                    # A slow frame whose colour agreed with the few map points it saw: the map ran out (a long
                    # flight's keyframes took blurred colour), not the image. Trusted, it can refill the map.
                    starved = not fast and _starved_map(out, self.config.tracker)
                    attempts.append((retry, True, TrackingStatus.OK if starved else TrackingStatus.DEGRADED))
            if all(a[0].verdict.level != OK for a in attempts):
                # Direct alignment settled wrong from the predictions: start it where the feature matches put the
                # frame (a fast turn's answer lies outside its basin of convergence)
                matched = self.features.guesses(prepared, camera_centre(guesses[0]))
                if matched:
                    rescue = self.tracking.track(prepared, matched, self._affine, last, rs, priors, ev_frame)
                    attempts.append((rescue, self.tracking.uses_events(ev_frame), TrackingStatus.OK))
            if all(a[0].verdict.level != OK for a in attempts):
                reloc = self._relocalise(prepared, guesses[0], last, rs, priors, ev_frame)
                attempts.append((reloc, self.tracking.uses_events(ev_frame), TrackingStatus.RELOCALISED))
            best = _best_attempt(attempts)
            if best is None:
                self.last_loss_reason = out.verdict.reason
                self.event_side.end_frame(n_events)
                # the new map starts where the gyro (and the IMU since the last trusted frame) put the camera
                start = predicted if gyro is None else gyro
                return self._reinitialise(prepared, stamp, start, t0, out.verdict.reason, ev_frame, raw, moved)
            out, fused, status = best
        # without a gyro nothing else vouches for a fast frame's rotation (with one, the gyro check does)
        if (status is not TrackingStatus.DEGRADED and gyro is None
                and self.features.wants_check(out.T_c_w, last, predicted)):
            out, status = self._feature_check(prepared, out, status, last, rs, priors, ev_frame)
        if not self.tracking.colour_usable(prepared) and status is not TrackingStatus.DEGRADED:
            # one sensor is blind: the pose rests on depth (and events) alone, and the map is left as it is
            status = TrackingStatus.DEGRADED
            blind = (f"colour image without contrast (grey standard deviation {prepared.contrast:.1f}: "
                     "lens covered, dark or saturated?): tracked on depth alone")
            note = f"{note}; {blind}" if note else blind
        t_track = time.perf_counter() - t0
        self.last_loss_reason = out.verdict.reason or note
        kf = False
        self._frame_shift = None
        if status is not TrackingStatus.DEGRADED:
            self._affine = out.affine
            # Keyframes taken mid-flip hold blurred colour patches; the first trusted frame after the turn slows
            # replaces them, or tracking goes on against blur (measured: 1-2 cm of jitter per frame after a landing)
            refresh = self._blurred_keyframe and not fast and status is TrackingStatus.OK
            if out.health is not None and (out.health.needs_keyframe or refresh):
                calm = self._calm_used and self.turns.calm(stamp, out.T_c_w, self.config.tracker.calm_turn_deg)
                kf = self._insert(self.tracking.keyframe_request(self.frontend.at_colour_time(prepared), out, rs,
                                                                 refine=calm))
                if kf:
                    self._blurred_keyframe = fast
        coasts = self._coasts(out, stamp)
        if coasts:
            # Depth is blur-free: its points keep the depth term in view for the next coasting frames, where a
            # re-initialisation would start a new map from the same predicted pose and drop the old one.
            kf = self._insert(self.tracking.keyframe_request(self.frontend.at_colour_time(prepared), out, rs,
                                                             geometry_only=True))
            self._blurred_keyframe = kf or self._blurred_keyframe
        if self._frame_shift is not None:  # the keyframe made from this frame was moved by the local window
            out = dataclasses.replace(out, T_c_w=out.T_c_w @ se3_inv(self._frame_shift))
        self.motion.push(stamp, out.T_c_w, trusted=status is not TrackingStatus.DEGRADED or coasts)
        if self._calm_used:
            self.turns.push(stamp, out.T_c_w)
        self._observe_inertial(stamp, out.T_c_w, trusted=status is TrackingStatus.OK)
        if moved and self._anchor is not None and status is TrackingStatus.OK:
            kf = self._reanchor(prepared, out.T_c_w) or kf
        self.features.end_frame(prepared, out.T_c_w, trusted=status is not TrackingStatus.DEGRADED)
        if ev_frame is not None:
            self._remember_event(ev_frame, prepared, out.T_c_w)
        self.event_side.end_frame(n_events)
        return self._result(stamp, out.T_c_w, out, status, t_track, kf, fused)

    def _observe_inertial(self, stamp: int, T_c_w: np.ndarray, trusted: bool) -> None:
        """Hand a frame's pose to the gravity estimate (``ok`` frames only: a coasting pose is a prediction)."""
        if self.inertial is not None and self.gyro:
            self.inertial.observe(self.gyro.samples(), stamp, T_c_w, trusted)
        if self.velocity is not None and trusted:
            self.velocity.observe(stamp, T_c_w)

    def _place_depth(self, prepared: PreparedFrame, stamp: int) -> tuple[PreparedFrame, bool]:
        """Place a depth image exposed ``rig.depth_time_offset_s`` off the colour: the camera's pose at its exposure.

        The gyro gives the rotation between the two exposures; with ``tracker.depth_time_translation`` the
        translation comes from :class:`~atsvo_ros.core.odometry.depth_timing.DepthTiming` once it has the trusted
        poses it needs (True is returned then: the depth was placed by both). The frame carries it as
        ``T_depth_rgb``: tracking's depth term reads the depth where it was exposed, and only what mapping gets is
        warped to the colour's time (``RgbdFrontEnd.at_colour_time``). Without gyro samples over the interval
        the depth is left as it is: the constant-motion prediction's rotation made the flips worse (tuning seeds
        0-4, mean ATE 26 cm against 17), the true rotation better (6.6).
        """
        offset_ns = int(round(self.config.rig.depth_time_offset_s * 1e9))
        if offset_ns == 0:
            return prepared, False
        T_c_d = self._depth_motion(stamp, offset_ns)
        if T_c_d is not None:
            return dataclasses.replace(prepared, T_depth_rgb=se3_inv(T_c_d)), True
        if offset_ns > 0:
            R_c_d = self.gyro.camera_rotation(stamp, stamp + offset_ns)
        else:
            R_d_c = self.gyro.camera_rotation(stamp + offset_ns, stamp)
            R_c_d = None if R_d_c is None else R_d_c.T
        if R_c_d is None:
            return prepared, False
        T_d_c = np.eye(4)
        T_d_c[:3, :3] = R_c_d.T
        return dataclasses.replace(prepared, T_depth_rgb=T_d_c), False

    def _depth_motion(self, stamp: int, offset_ns: int) -> np.ndarray | None:
        """``T_c_d``: the camera at the depth's exposure in the camera at the colour's, or None (see DepthTiming)."""
        if self.depth_timing is None or not self.gyro:
            return None
        g_w = None if self.inertial is None else self.inertial.gravity_w
        return self.depth_timing.camera_motion(self.gyro.samples(), self._gravity_prior_w if g_w is None else g_w,
                                               stamp, stamp + offset_ns)

    def _reanchor(self, prepared: PreparedFrame, T_c_w: np.ndarray) -> bool:
        """Rebuild the map from its first frame, that frame's depth now moved to its colour's time (True: rebuilt).

        The map was started before the camera's velocity was known, from depth off by the motion over the offset;
        tracking against it with moved depth would mix the two (tuning bound seed 0, RGB-D: moving the depth from
        the third frame on without rebuilding gave 12.7 cm against 6.1 never moving it, 2.4 rebuilt). A first frame
        that left the velocity window gives way to this frame, its depth moved, at its tracked pose.
        """
        anchor, self._anchor = self._anchor, None
        offset_ns = int(round(self.config.rig.depth_time_offset_s * 1e9))
        frame, T_frame_w = prepared, T_c_w
        oldest = self.depth_timing.oldest_ns if self.depth_timing is not None else None
        if anchor is not None and oldest is not None and anchor.stamp_ns >= oldest:
            T_a_d = self._depth_motion(anchor.stamp_ns, offset_ns)
            if T_a_d is not None:
                frame = dataclasses.replace(anchor.raw, T_depth_rgb=se3_inv(T_a_d))
                T_frame_w = anchor.T_c_w
        return self._insert(Tracking.reset_request(self.frontend.at_colour_time(frame), T_frame_w))

    def _turn_anchor(self) -> None:
        """Rebuild the map from its first frame once the gyro covers that frame's depth offset (before tracking).

        Streams that start together hand the first frame over before the IMU's first sample: its depth, exposed
        ``rig.depth_time_offset_s`` off the colour, went into the map unturned. Mid-turn that is degrees (tuning
        bounds start at ~250 deg/s: 2-4 deg over the offset) and the next frame, tracked against it, came out
        6-7 cm off.
        """
        anchor = self._anchor
        turned, moved = self._place_depth(anchor.raw, anchor.stamp_ns)
        done = None if moved or self.depth_timing is None else dataclasses.replace(anchor, turned=True)
        if turned is anchor.raw:
            if self.gyro:  # the samples came, but too late to reach it (30 ms): the map stays, no more tries
                self._anchor = done
            return
        self._anchor = done
        self._insert(Tracking.reset_request(self.frontend.at_colour_time(turned), anchor.T_c_w))

    def _coasts(self, out: TrackingOutcome, stamp: int) -> bool:
        """Whether a degraded frame held by depth and the motion prior alone keeps the motion trusted.

        Its pose follows the prediction where the data is silent, so the prediction (and the prior) go on
        into the next frame, for at most ``tracker.max_coast_s`` in a row.
        """
        if not out.verdict.coasting:
            self._coast_start_ns = None
            return False
        if self._coast_start_ns is None:
            self._coast_start_ns = stamp
        return (stamp - self._coast_start_ns) * 1e-9 < self.config.tracker.max_coast_s

    # ------------------------------------------------------------------ steps
    def _relocalise(self, prepared: PreparedFrame, predicted: np.ndarray, last: np.ndarray,
                    rs: RollingShutter | None, priors: Priors,
                    ev_frame: EventFrame | None) -> TrackingOutcome:
        """Track again from wider starting points: the recent keyframes' poses and doubled rotation hypotheses
        (``tracker.relocalisation_rings`` of them when the last motion is not trusted)."""
        cfg = self.config.tracker
        guesses = [predicted, *(se3_inv(kf.T_w_c) for kf in reversed(self.tracking.snapshot.keyframes[-3:]))]
        step = max(2.0 * cfg.rotation_hypotheses_deg, 4.0)
        # without a trusted velocity the prediction may be a whole frame's turn off (tracking starts mid-bound)
        rings = 1 if self.motion.velocity_trusted else cfg.relocalisation_rings
        for k in range(1, rings + 1):
            guesses += rotation_hypotheses(predicted, k * step)
        return self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)

    def _feature_check(self, prepared: PreparedFrame, out: TrackingOutcome, status: TrackingStatus,
                       last: np.ndarray, rs: RollingShutter | None, priors: Priors, ev_frame: EventFrame | None
                       ) -> tuple[TrackingOutcome, TrackingStatus]:
        """A fast frame's direct pose against the feature matches' PnP pose (:mod:`.feature_assist`).

        No matches to check against on a turn over ``tracker.feature_unverified_deg``: degraded. They agree within
        max(``tracker.feature_disagreement_deg``, ``feature_disagreement_share`` of the frame's rotation) and
        ``tracker.feature_disagreement_m`` of camera centre: kept. Otherwise direct tracking starts again from the
        direct and the matched poses and keeps the better fit: a pose the matches agree with (a better optimum
        the predictions missed), the first pose again (confirmed), or neither (degraded).
        """
        cfg = self.config.tracker
        turn_deg = rotation_between_deg(out.T_c_w, last)
        candidates = self.features.guesses(prepared, camera_centre(out.T_c_w))
        if not candidates:
            if 0 < cfg.feature_unverified_deg < turn_deg:
                why = (f"turned {turn_deg:.1f} deg since the last trusted frame and no feature match vouches for it "
                       "(beyond direct alignment's basin)")
                return dataclasses.replace(out, verdict=Verdict(DEGRADED, why)), TrackingStatus.DEGRADED
            return out, status
        tol_deg = max(cfg.feature_disagreement_deg, cfg.feature_disagreement_share * turn_deg)

        def agree(T_a: np.ndarray, T_b: np.ndarray) -> bool:
            return (rotation_between_deg(T_a, T_b) <= tol_deg and
                    float(np.linalg.norm(camera_centre(T_a) - camera_centre(T_b))) <= cfg.feature_disagreement_m)

        matched = candidates[0]
        if agree(out.T_c_w, matched):
            return out, status
        again = self.tracking.track(prepared, [out.T_c_w, *candidates], self._affine, last, rs, priors, ev_frame)
        if again.verdict.level == OK:
            if agree(again.T_c_w, matched):
                return again, status
            if agree(again.T_c_w, out.T_c_w):
                return out, status
        off_cm = float(np.linalg.norm(camera_centre(out.T_c_w) - camera_centre(matched))) * 100
        why = (f"the direct pose and ORB matches to the last trusted frame disagree by "
               f"{rotation_between_deg(out.T_c_w, matched):.1f} deg, {off_cm:.1f} cm")
        return dataclasses.replace(out, verdict=Verdict(DEGRADED, why)), TrackingStatus.DEGRADED

    def _remember_event(self, ev_frame: EventFrame, prepared: PreparedFrame, T_c_w: np.ndarray) -> None:
        """Keep this frame's surface for the next frame's event map (built ahead when the next frame will fuse)."""
        self.event_side.remember(ev_frame, prepared, T_c_w, self.predictor.is_fast())

    def _insert(self, request: KeyframeRequest) -> bool:
        """Ask mapping for a keyframe (one at a time; a reset waits for its answer); True when it was asked."""
        if not request.reset and self.mapping.busy():
            return False
        # the pose it was asked at: the local window may move it (see _take_snapshot)
        self._asked = None if request.reset else (request.frame.stamp_ns, se3_inv(request.T_c_w))
        snap = self.mapping.insert(request, wait=request.reset)
        if snap is not None:
            self._take_snapshot(snap)
        return True

    def _take_snapshot(self, snap: MapSnapshot) -> np.ndarray | None:
        """Track against ``snap`` from now on. When mapping's local window moved the newest keyframe from the pose
        it was asked at, the odometry's poses (the motion, the IMU's windows, the previous frame's) move with it,
        as DSO's frames follow their tracking reference: the next frames are tracked against the moved map, and a
        velocity taken across the move would carry it. Returns the move ``T_wnew_wold`` (None: nothing moved).
        """
        self.tracking.set_snapshot(snap)
        kf = snap.last_keyframe
        if kf is None or self._asked is None or kf.stamp_ns != self._asked[0]:
            return None
        T_wold_c, self._asked = self._asked[1], None
        if np.array_equal(kf.T_w_c, T_wold_c):  # not moved (no window, or it kept the pose)
            return None
        T_wnew_wold = kf.T_w_c @ se3_inv(T_wold_c)
        self.motion.shift_world(T_wnew_wold)
        self.turns.shift_world(T_wnew_wold)
        for part in (self.velocity, self.inertial):
            if part is not None:
                part.shift_world(T_wnew_wold)
        self.features.shift_world(T_wnew_wold)
        self.event_side.shift_world(T_wnew_wold)
        if self._anchor is not None:
            self._anchor = dataclasses.replace(self._anchor, T_c_w=self._anchor.T_c_w @ se3_inv(T_wnew_wold))
        self._frame_shift = T_wnew_wold if self._frame_shift is None else T_wnew_wold @ self._frame_shift
        return T_wnew_wold

    def _predict(self, stamp: int) -> tuple[np.ndarray, np.ndarray | None, bool, list[np.ndarray], np.ndarray,
                                          RollingShutter | None, Priors]:
        """The frame's predictions: constant motion, the gyro's pose, whether the motion is fast, the starting
        guesses, the last pose, the row timing and the priors."""
        predicted = self.motion.predict(stamp)
        imu = self.predictor.imu_motion(stamp) if self.config.tracker.imu_translation else None
        gyro = self.predictor.gyro_pose(stamp, None if imu is None else imu.centre_w)
        reckoned = self._dead_reckoned(stamp) if imu is None else None
        if reckoned is not None:
            gyro, imu = reckoned
        fast = self.predictor.is_fast()
        guesses = self.predictor.guesses(stamp, predicted, gyro, fast, self.event_side.rate_ratio())
        last = self.motion.last[1] if self.motion.last else predicted
        rs = self.predictor.rolling_shutter(stamp)
        priors = self.predictor.priors(stamp, gyro, imu)
        return predicted, gyro, fast, guesses, last, rs, priors

    def _dead_reckoned(self, stamp: int) -> tuple[np.ndarray, CameraMotion] | None:
        """After frames that were not trusted (lost, degraded): the pose from the IMU alone since the last trusted
        frame, at most ``tracker.imu_dead_reckoning_s`` back; None when constant motion is to be used."""
        limit_s = self.config.tracker.imu_dead_reckoning_s
        if (limit_s <= 0 or self.inertial is None or self.velocity is None or not self.gyro
                or self.motion.velocity_trusted or not self.config.tracker.imu_translation):
            return None
        return self.inertial.dead_reckon(self.gyro.samples(), self.velocity, stamp, int(limit_s * 1e9))

    def _unmappable(self, prepared: PreparedFrame, T_c_w: np.ndarray) -> str | None:
        """Why a map built from this frame alone would not constrain the pose (None when it would).

        A textureless wall, a covered lens with no depth, a frame of sky: mapping it would give a map
        that no later frame can be tracked against. The test is the frame tracked against its own
        candidate map at its own pose: the same checks (singular system, degenerate geometry) as any frame.
        """
        why = "this frame cannot anchor a map: "
        if prepared.n_valid_depth == 0:
            return why + ("no valid depth in this frame (check the depth topic's encoding and scale, "
                          "and rig.depth_min_m / depth_max_m)")
        candidate = Mapper(self.config, self.cameras).insert(Tracking.reset_request(prepared, T_c_w))
        probe = Tracking(self.config, self.cameras)
        probe.set_snapshot(candidate)
        if not probe.has_map:
            return why + "no map point could be selected (no texture, no depth structure)"
        verdict = probe.track(prepared, [T_c_w], (0.0, 0.0), T_c_w).verdict
        return None if verdict.level == OK else why + str(verdict.reason)

    def _initialise(self, prepared: PreparedFrame, stamp: int, T_c_w: np.ndarray, t0: float,
                    note: str | None, ev_frame: EventFrame | None = None, raw: PreparedFrame | None = None,
                    moved: bool = False) -> OdometryResult:
        first = self.mapping.n_keyframes == 0  # never had a map: still initialising (e.g. no depth yet)
        prepared = self.frontend.at_colour_time(prepared)  # the map's points sit on colour pixels
        why_not = self._unmappable(prepared, T_c_w)
        ok = why_not is None and self._insert(Tracking.reset_request(prepared, T_c_w)) and self.tracking.has_map
        t_track = time.perf_counter() - t0
        if ok:
            self._affine = (0.0, 0.0)
            self._new_map(stamp, raw if raw is not None else prepared, T_c_w, moved, prepared is not raw)
            status = TrackingStatus.INITIALISING if first else TrackingStatus.REINITIALISED
            self.last_loss_reason = note
        else:
            status = TrackingStatus.INITIALISING if first else TrackingStatus.LOST
            self.last_loss_reason = why_not
        self.motion.push(stamp, T_c_w, trusted=first)  # the first pose defines odom; a later one is a guess
        self._observe_inertial(stamp, T_c_w, trusted=first)
        if ok:  # the map's own frame: later frames' matches start from it
            self.features.end_frame(prepared, T_c_w, trusted=True)
        if ev_frame is not None:
            self._remember_event(ev_frame, prepared, T_c_w)
        return self._result(stamp, T_c_w, None, status, t_track, ok)

    def _reinitialise(self, prepared: PreparedFrame, stamp: int, predicted: np.ndarray, t0: float,
                      reason: str | None, ev_frame: EventFrame | None = None, raw: PreparedFrame | None = None,
                      moved: bool = False) -> OdometryResult:
        """Tracking and relocalisation failed: a new map from this frame at the predicted pose (no jump, no NaN).

        A frame that cannot anchor a map (:meth:`_unmappable`) leaves the old map in place: the frame is
        lost, the pose follows the motion model, and the next good frame is tracked against the old map.
        """
        prepared = self.frontend.at_colour_time(prepared)  # the map's points sit on colour pixels
        why_not = self._unmappable(prepared, predicted)
        ok = (why_not is None and self._insert(Tracking.reset_request(prepared, predicted, keep_memory=True))
              and self.tracking.has_map)
        t_track = time.perf_counter() - t0
        if ok:
            self._affine = (0.0, 0.0)
            self._blurred_keyframe = self.predictor.is_fast()  # a new map from mid-turn: replace it once the turn slows
            self.motion.reset()
            # The world goes on (the new map starts at the predicted pose): with dead reckoning the IMU's trusted
            # poses stay, so the frames after this one are predicted from the last trusted state, not from this guess
            keep_imu = self.config.tracker.imu_dead_reckoning_s > 0
            if self.inertial is not None and not keep_imu:
                self.inertial.reset()
            self._new_map(stamp, raw if raw is not None else prepared, predicted, moved, prepared is not raw)
            if self.velocity is not None and not keep_imu:
                self.velocity.reset()
        else:
            reason = f"{reason}; {why_not}" if reason else why_not
        self.motion.push(stamp, predicted, trusted=False)
        self.features.forget()
        if ok:  # the new map's anchor
            self.features.end_frame(prepared, predicted, trusted=True)
        # the new map and this frame's event surface share the predicted pose: a consistent base for the next
        self.event_side.forget()
        if ok and ev_frame is not None:
            self._remember_event(ev_frame, prepared, predicted)
        status = TrackingStatus.REINITIALISED if ok else TrackingStatus.LOST
        self.last_loss_reason = reason
        return self._result(stamp, predicted, None, status, t_track, ok)

    def _new_map(self, stamp: int, raw: PreparedFrame, T_c_w: np.ndarray, moved: bool, turned: bool) -> None:
        """A map was started from this frame: kept for :meth:`_turn_anchor` (its depth not yet turned by the gyro)
        and :meth:`_reanchor` (not yet moved) while its depth is not at its colour's time."""
        offset = self.config.rig.depth_time_offset_s != 0.0
        keep = offset and not moved and (self.depth_timing is not None or not turned)
        self._anchor = _Anchor(stamp, raw, T_c_w, turned) if keep else None

    # ------------------------------------------------------------------ output
    def _result(self, stamp: int, T_c_w: np.ndarray, out: TrackingOutcome | None, status: TrackingStatus,
                t_track: float, kf: bool, fused: bool = False) -> OdometryResult:
        """The published result, in odom/base, at the stamp plus ``time_offset_s`` (pose moved off the frame clock)."""
        stamp, T_c_w = self.timing.published(stamp, T_c_w, self.motion)
        em = self.tracking.event_map
        return self._results(stamp, T_c_w, out, status, t_track=t_track, kf=kf, fused=fused,
                             n_points=len(self.tracking.snapshot), dropped=self.event_side.take_dropped(),
                             event_map_time_s=em.build_time_s if fused and em is not None else 0.0,
                             reason=self.last_loss_reason)


__all__ = ["Odometry", "OdometryResult", "RgbdFrame", "TrackingStatus"]
