"""The odometry facade: RGB-D frames (events, IMU samples) in, ``odom -> base`` poses out.

Composes the PTAM split of Fig. 2 in one thread: the colour camera's front end, the motion model,
:class:`~atsvo_ros.core.tracking.Tracking` against the latest map snapshot and the
:class:`~atsvo_ros.core.mapper.Mapper`, which inserts a keyframe whenever tracking asks for one and
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
"""
from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.checks import DEGRADED, OK, Priors
from atsvo_ros.core.event_frontend import EventFrame, EventFrontEnd
from atsvo_ros.core.events import EventBatch
from atsvo_ros.core.frame import OdometryResult, RgbdFrame, TrackingStatus
from atsvo_ros.core.frame_clock import FrameClock
from atsvo_ros.core.frontend import PreparedFrame, RgbdFrontEnd
from atsvo_ros.core.geometry import hat, se3_exp, se3_inv, so3_log
from atsvo_ros.core.imu import ImuBatch, gyro_rotation
from atsvo_ros.core.mapper import EventMapRequest, KeyframeRequest, Mapper
from atsvo_ros.core.mapping_port import InlineMapping, MappingPort
from atsvo_ros.core.motion import MotionModel
from atsvo_ros.core.residuals import RollingShutter
from atsvo_ros.core.residuals.prior import MotionPrior
from atsvo_ros.core.tracking import Tracking, TrackingOutcome, rotation_hypotheses
from atsvo_ros.errors import ImuError


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


def _adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint of a pose acting on twists (translation first)."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[:3, 3:] = hat(t) @ R
    return A


class Odometry:
    """Direct RGB-D (+ event) odometry: Eq. 4 with the RGB, depth and, during fast motion, ATS terms."""

    #: A gap between frames longer than this resets the motion model (constant motion is meaningless).
    MAX_GAP_S = 1.0
    #: IMU kept for the gyro prediction: long enough to carry the rotation across a camera dropout of a few
    #: seconds (~1,200 samples at 400 Hz), when the constant-motion model knows nothing any more
    _IMU_BUFFER_NS = 3_000_000_000

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
        self.events: EventFrontEnd | None = None
        event_cams = None
        if event_camera is not None and config.mode == "fused":
            self.events = EventFrontEnd(event_camera, config, config.tracker.pyramid_levels)
            event_cams = self.events.cameras
        T_event_rgb = se3_inv(config.rig.T_rgb_event_matrix())
        self.tracking = Tracking(config, self.cameras, event_cams, T_event_rgb)
        self.mapper = Mapper(config, self.cameras, None if self.events is None else self.events.camera)
        self.mapping: MappingPort = (mapping or InlineMapping)(self.mapper)
        self._event_time_s = 0.0  # ATS updates since the last frame (counted in its tracking time)
        # the previous frame's event surface, depth and pose: what a temporary event map is built from
        self._prev_event: tuple[EventFrame, np.ndarray, np.ndarray] | None = None
        self._prev_request: EventMapRequest | None = None  # its event map, asked for ahead of the next frame
        self._events_since_frame = 0
        self._dropped_reported = 0  # the event front end's drop count at the last result
        self._events_per_frame: deque[int] = deque(maxlen=2)
        self._imu: deque[ImuBatch] = deque()
        self._affine = (0.0, 0.0)
        # the newest keyframe was taken while the camera turned fast: its colour patches are motion-blurred
        self._blurred_keyframe = False
        self._coast_start_ns: int | None = None  # first frame of the current run of coasting frames
        self._last_stamp: int | None = None
        self._offset_ns = int(round(config.rgb_camera.time_offset_s * 1e9))
        self._clock = FrameClock(config.rgb_camera.frame_clock_frames)
        self._shift_ns = 0  # frame-clock time minus stamp of the frame being processed (its stamp jitter)
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

    # ------------------------------------------------------------------ inputs
    def add_events(self, batch: EventBatch) -> None:
        """Fold a time-ordered event batch into the time surface (ignored without an event camera)."""
        if self.events is None or len(batch) == 0:
            return
        t0 = time.perf_counter()
        self.events.add_events(batch)
        self._events_since_frame += len(batch)
        self._event_time_s += time.perf_counter() - t0

    def add_imu(self, batch: ImuBatch) -> None:
        """Buffer IMU samples (time order; the last 3 s are kept): their gyro predicts each frame's rotation."""
        if len(batch) == 0:
            return
        self._imu.append(batch)
        newest = batch.t_last_ns
        while self._imu and self._imu[0].t_last_ns < newest - self._IMU_BUFFER_NS:
            self._imu.popleft()

    # ------------------------------------------------------------------ main entry
    def process_frame(self, frame: RgbdFrame) -> OdometryResult:
        """Track one frame, insert a keyframe when needed, return the pose estimate."""
        # the event surface's updates since the last frame count towards this frame's tracking time
        t0 = time.perf_counter() - self._event_time_s
        self._event_time_s = 0.0
        n_events = self._events_since_frame
        # Internally a frame lives at the time its image was exposed (middle row: the frame clock's time of
        # the stamp plus the configured offset). The pose is published at the stamp plus the offset, the
        # exposure time on the stamps' clock: only the stamp's jitter off the frame clock is extrapolated
        # over (see _result), as moving it by the offset too would add the velocity's noise for nothing.
        on_clock = self._clock(frame.stamp_ns)
        self._shift_ns = on_clock - int(frame.stamp_ns)
        stamp = on_clock + self._offset_ns
        prepared = self.frontend.prepare(frame)
        newer = self.mapping.latest()  # a keyframe mapping finished meanwhile (threaded or remote mapping)
        if newer is not None:
            self.tracking.set_snapshot(newer)
        note = self._check_clock(stamp)
        self._last_stamp = stamp
        predicted = self.motion.predict(stamp)
        # a silent event camera (dropout, cap on) leaves a stale surface that would pull towards zero motion
        live = self.events is not None and n_events >= self.config.fusion.min_points
        ev_frame = self.events.render(stamp) if live else None
        if not self.tracking.has_map:
            self._end_frame(n_events)
            return self._initialise(prepared, stamp, predicted, t0, note, ev_frame)
        gyro = self._gyro_prediction(stamp)
        fast = self._is_fast()
        guesses = self._guesses(stamp, predicted, gyro, fast)
        last = self.motion.last[1] if self.motion.last else predicted
        rs = self._rolling_shutter(stamp)
        priors = self._priors(stamp, gyro)
        # Eq. 4 with the event term when the last two frames moved fast (the paper's relative-motion factor)
        self.tracking.set_event_map(self._event_map() if fast else None)
        fused = self.tracking.uses_events(ev_frame)
        out = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
        status = TrackingStatus.OK
        if out.verdict.level != OK and self.mapping.busy():
            # The camera outran the map while mapping still inserts a keyframe (asynchronous mapping behind):
            # wait for that keyframe rather than relocalise against a map the camera has left.
            newer = self.mapping.await_pending()
            if newer is not None:
                self.tracking.set_snapshot(newer)
                out = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
        if out.verdict.level != OK:
            # Not trusted: try harder before accepting a degraded pose or starting a new map.
            attempts = [(out, fused, TrackingStatus.DEGRADED)]
            if not fused and self._prev_event is not None:
                # RGB-D alone could not hold the pose (a sudden push-off): the events saw the motion
                self.tracking.set_event_map(self._event_map())
                if self.tracking.uses_events(ev_frame):
                    retry = self.tracking.track(prepared, guesses, self._affine, last, rs, priors, ev_frame)
                    attempts.append((retry, True, TrackingStatus.DEGRADED))
            if all(a[0].verdict.level != OK for a in attempts):
                reloc = self._relocalise(prepared, guesses[0], last, rs, priors, ev_frame)
                attempts.append((reloc, self.tracking.uses_events(ev_frame), TrackingStatus.RELOCALISED))
            best = _best_attempt(attempts)
            if best is None:
                self.last_loss_reason = out.verdict.reason
                self._end_frame(n_events)
                return self._reinitialise(prepared, stamp, predicted, t0, out.verdict.reason, ev_frame)
            out, fused, status = best
        if not self.tracking.colour_usable(prepared) and status is not TrackingStatus.DEGRADED:
            # one sensor is blind: the pose rests on depth (and events) alone, and the map is left as it is
            status = TrackingStatus.DEGRADED
            blind = (f"colour image without contrast (grey standard deviation {prepared.contrast:.1f}: "
                     "lens covered, dark or saturated?): tracked on depth alone")
            note = f"{note}; {blind}" if note else blind
        t_track = time.perf_counter() - t0
        self.last_loss_reason = out.verdict.reason or note
        kf = False
        if status is not TrackingStatus.DEGRADED:
            self._affine = out.affine
            # Keyframes taken mid-flip hold blurred colour patches; the first trusted frame after the turn slows
            # replaces them, or tracking goes on against blur (measured: 1-2 cm of jitter per frame after a landing)
            refresh = self._blurred_keyframe and not fast and status is TrackingStatus.OK
            if out.health is not None and (out.health.needs_keyframe or refresh):
                kf = self._insert(self.tracking.keyframe_request(prepared, out, rs))
                if kf:
                    self._blurred_keyframe = fast
        coasts = self._coasts(out, stamp)
        if coasts:
            # Depth is blur-free: its points keep the depth term in view for the next coasting frames, where a
            # re-initialisation would start a new map from the same predicted pose and drop the old one.
            kf = self._insert(self.tracking.keyframe_request(prepared, out, rs, geometry_only=True))
            self._blurred_keyframe = kf or self._blurred_keyframe
        self.motion.push(stamp, out.T_c_w, trusted=status is not TrackingStatus.DEGRADED or coasts)
        if ev_frame is not None:
            self._remember_event(ev_frame, prepared.depth_m, out.T_c_w)
        self._end_frame(n_events)
        return self._result(stamp, out.T_c_w, out, status, t_track, kf, fused)

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

    def _end_frame(self, n_events: int) -> None:
        self._events_per_frame.append(n_events)
        self._events_since_frame = 0

    # ------------------------------------------------------------------ steps
    def _check_clock(self, stamp: int) -> str | None:
        """A stamp not after the previous one, or a long gap: the velocity is unknown, reset the motion model."""
        if self._last_stamp is None:
            return None
        dt_s = (stamp - self._last_stamp) * 1e-9
        if dt_s <= 0:
            self.motion.reset()
            return f"clock jumped back by {-dt_s:.3f} s: motion model reset"
        if dt_s > self.MAX_GAP_S:
            self.motion.reset()
            return f"{dt_s:.1f} s since the previous frame: motion model reset"
        return None

    def _rolling_shutter(self, stamp: int) -> RollingShutter | None:
        """Row timing of the colour (and depth) image when the camera has a rolling shutter."""
        cam = self.config.rgb_camera
        last = self.motion.last
        if cam.readout_time_s == 0.0 or last is None or stamp <= last[0]:
            return None
        return RollingShutter.centred(cam.readout_time_s, self.camera.height, last[1], (stamp - last[0]) * 1e-9)

    def _gyro_prediction(self, stamp: int) -> np.ndarray | None:
        """``T_c_w`` with the rotation since the last frame from the gyro, or None when the IMU does not cover it.

        Gyro integration over one frame is accurate to a small fraction of a degree even in a backflip
        (turn-on bias ~1 deg/s adds ~0.03 deg per frame), far inside the photometric basin.
        """
        last = self.motion.last
        if last is None or not self._imu:
            return None
        try:
            R_i0_i1 = gyro_rotation(ImuBatch.concatenate(list(self._imu)), last[0], stamp)
        except ImuError:
            return None
        R_c0_c1 = self.R_rgb_imu @ R_i0_i1 @ self.R_rgb_imu.T
        return self.motion.predict_with_rotation(stamp, R_c0_c1.T)

    def _guesses(self, stamp: int, predicted: np.ndarray, gyro: np.ndarray | None, fast: bool) -> list[np.ndarray]:
        """Starting points: the gyro's prediction (with an IMU), constant motion, zero motion, and while the
        camera turns fast (or the events say it speeds up) the constant motion scaled."""
        guesses = [predicted] if gyro is None else [gyro, predicted]
        if self.motion.last is None or np.allclose(self.motion.last[1], predicted):
            return guesses
        guesses.append(self.motion.last[1])  # zero motion
        if gyro is not None:
            return guesses
        scales = list(self.config.tracker.velocity_scales) if fast else []
        ratio = self._event_rate_ratio()
        if ratio is not None and ratio > 1.5:
            # Events per frame grow with the image motion: a surge of events says the turn sped up.
            scales += [0.75 * ratio, ratio, 1.25 * ratio]
        return guesses + [self.motion.predict_scaled(stamp, k) for k in scales]

    def _event_rate_ratio(self) -> float | None:
        """Events since the last frame over events in the frame interval before (None without both)."""
        if len(self._events_per_frame) < 2 or self._events_per_frame[-2] < 1000:
            return None
        return float(np.clip(self._events_since_frame / self._events_per_frame[-1], 0.2, 8.0)) \
            if self._events_per_frame[-1] > 0 else None

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

    def _priors(self, stamp: int, gyro: np.ndarray | None) -> Priors:
        """What the motion says this frame's pose should be: the gyro's prediction and, after two trusted frames,
        the constant-velocity camera centre with the reach of ``tracker.max_acceleration_m_s2``."""
        cfg = self.config.tracker
        centre = self.motion.centre_prior(stamp, cfg.max_acceleration_m_s2, cfg.motion_noise_m)
        prior = None
        a_m, a_rad = cfg.motion_prior_acceleration_m_s2, cfg.motion_prior_angular_acceleration_rad_s2
        spread = self.motion.prediction_spread(stamp) if a_m > 0 and a_rad > 0 else None
        if spread is not None:  # the last two poses are trusted
            # Centred on constant velocity even with a gyro (which stays a guess and a check): a node that releases
            # a frame before its IMU arrives would otherwise track it against another prior than the replay (1.5 mm
            # apart in CI).
            prior = MotionPrior(self.motion.predict(stamp), a_m * spread, a_rad * spread, cfg.motion_prior_huber)
        if centre is None:
            return Priors(gyro, motion=prior)
        return Priors(gyro, *centre, motion=prior)

    def motion_rates(self) -> tuple[float, float] | None:
        """The paper's relative-motion factor: camera angular rate (rad/s) and speed (m/s) over the last two frames.

        The angular rate comes from the gyro when it covers the interval (measured, not estimated), else
        from the two poses; None before two frames.
        """
        rel = self.motion.relative_motion()
        if rel is None:
            return None
        ang, speed = rel
        hist = self.motion.history
        if self._imu and len(hist) == 2:
            try:
                R = gyro_rotation(ImuBatch.concatenate(list(self._imu)), hist[0][0], hist[1][0])
                ang = float(np.linalg.norm(so3_log(R))) / max((hist[1][0] - hist[0][0]) * 1e-9, 1e-9)
            except ImuError:
                pass
        return ang, speed

    def _is_fast(self) -> bool:
        """The relative-motion factor of the last two frames is above a threshold (angular rate or speed)."""
        rates = self.motion_rates()
        fu = self.config.fusion
        return rates is not None and (np.degrees(rates[0]) > fu.rate_threshold_deg_s
                                      or rates[1] > fu.speed_threshold_m_s)

    def _event_map(self):
        """The temporary event map built (by mapping) from the previous frame's surface, depth and pose, or None."""
        if self._prev_event is None:
            return None
        request, self._prev_request = self._prev_request or self._event_request(), None
        return self.mapping.event_map(request)

    def _event_request(self) -> EventMapRequest:
        """The event-map request of the previous frame (mapping selects its pixels among those that fired)."""
        ev_frame, depth, T_c_w = self._prev_event
        return EventMapRequest(ev_frame, depth, T_c_w, self.events.recent_pixels(ev_frame.stamp_ns))

    def _remember_event(self, ev_frame: EventFrame, depth_m: np.ndarray, T_c_w: np.ndarray) -> None:
        """Keep this frame's surface for the next frame's event map, and have it built now if that frame will
        fuse (the relative-motion factor of the poses so far is what the next frame tests): the build then
        runs while tracking waits for the next frame, not after it arrives."""
        self._prev_event = (ev_frame, depth_m, T_c_w)
        self._prev_request = None
        if self._is_fast():
            self._prev_request = self._event_request()
            self.mapping.prepare_event_map(self._prev_request)

    def _insert(self, request: KeyframeRequest) -> bool:
        """Ask mapping for a keyframe (one at a time; a reset waits for its answer); True when it was asked."""
        if not request.reset and self.mapping.busy():
            return False
        snap = self.mapping.insert(request, wait=request.reset)
        if snap is not None:
            self.tracking.set_snapshot(snap)
        return True

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
                    note: str | None, ev_frame: EventFrame | None = None) -> OdometryResult:
        first = self.mapping.n_keyframes == 0  # never had a map: still initialising (e.g. no depth yet)
        why_not = self._unmappable(prepared, T_c_w)
        ok = why_not is None and self._insert(Tracking.reset_request(prepared, T_c_w)) and self.tracking.has_map
        t_track = time.perf_counter() - t0
        if ok:
            self._affine = (0.0, 0.0)
            status = TrackingStatus.INITIALISING if first else TrackingStatus.REINITIALISED
            self.last_loss_reason = note
        else:
            status = TrackingStatus.INITIALISING if first else TrackingStatus.LOST
            self.last_loss_reason = why_not
        self.motion.push(stamp, T_c_w, trusted=first)  # the first pose defines odom; a later one is a guess
        if ev_frame is not None:
            self._remember_event(ev_frame, prepared.depth_m, T_c_w)
        return self._result(stamp, T_c_w, None, status, t_track, ok)

    def _reinitialise(self, prepared: PreparedFrame, stamp: int, predicted: np.ndarray, t0: float,
                      reason: str | None, ev_frame: EventFrame | None = None) -> OdometryResult:
        """Tracking and relocalisation failed: a new map from this frame at the predicted pose (no jump, no NaN).

        A frame that cannot anchor a map (:meth:`_unmappable`) leaves the old map in place: the frame is
        lost, the pose follows the motion model, and the next good frame is tracked against the old map.
        """
        why_not = self._unmappable(prepared, predicted)
        ok = why_not is None and self._insert(Tracking.reset_request(prepared, predicted)) and self.tracking.has_map
        t_track = time.perf_counter() - t0
        if ok:
            self._affine = (0.0, 0.0)
            self._blurred_keyframe = self._is_fast()  # a new map from mid-turn: replace it once the turn slows
            self.motion.reset()
        else:
            reason = f"{reason}; {why_not}" if reason else why_not
        self.motion.push(stamp, predicted, trusted=False)
        # the new map and this frame's event surface share the predicted pose: a consistent base for the next
        self._prev_event, self._prev_request = None, None
        if ok and ev_frame is not None:
            self._remember_event(ev_frame, prepared.depth_m, predicted)
        status = TrackingStatus.REINITIALISED if ok else TrackingStatus.LOST
        self.last_loss_reason = reason
        return self._result(stamp, predicted, None, status, t_track, ok)

    # ------------------------------------------------------------------ output
    def _result(self, stamp: int, T_c_w: np.ndarray, out: TrackingOutcome | None, status: TrackingStatus,
                t_track: float, kf: bool, fused: bool = False) -> OdometryResult:
        """The published result, in odom/base, at the stamp plus ``time_offset_s`` (pose moved off the frame clock)."""
        if self._shift_ns:
            T_c_w = se3_exp(-self._shift_ns * 1e-9 * self.motion.twist_per_s()) @ T_c_w
            stamp -= self._shift_ns
        T_w_c = se3_inv(T_c_w)
        T_odom_cam = self.T_base_rgb @ T_w_c
        T_odom_base = T_odom_cam @ self.T_rgb_base
        res = out.result if out is not None else None
        if res is None:
            cov = np.eye(6) * 1e3  # no measurement: a large, honest uncertainty
        else:
            A = _adjoint(self.T_base_rgb)
            cov = A @ res.covariance @ A.T
            if status is TrackingStatus.DEGRADED and out.verdict.level != OK:  # doubted, not merely one-eyed
                cov = cov * self.config.tracker.degraded_covariance_scale
        inliers = {k: v.n_inliers for k, v in res.blocks.items()} if res is not None else {}
        n_points = len(self.tracking.snapshot)
        dropped = 0
        if self.events is not None:
            dropped = self.events.dropped_events - self._dropped_reported
            self._dropped_reported = self.events.dropped_events
        em = self.tracking.event_map
        em_time_s = em.build_time_s if fused and em is not None else 0.0
        return OdometryResult(stamp, T_odom_base, T_odom_cam, cov, status, "fused" if fused else "rgbd",
                              float(t_track), int(n_points),
                              int(inliers.get("rgb", 0)), bool(kf), self.last_loss_reason, inliers, int(dropped),
                              float(em_time_s))


__all__ = ["Odometry", "OdometryResult", "RgbdFrame", "TrackingStatus"]
