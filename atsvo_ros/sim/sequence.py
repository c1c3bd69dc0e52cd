"""Sequence orchestration: scene + motion + sensor models -> a time-ordered stream of sensor data.

:func:`iter_sequence` is the in-memory API (tests, accuracy runs); ``atsvo-sim`` writes the same
stream to a bag. Streams, merged by stamp:

* ground truth ``GroundTruth(stamp_ns, T_world_base)`` at ``gt_rate_hz``;
* RGB-D ``RgbdFrame(stamp_ns, rgb, depth_mm)``: the stamp is the middle of the exposure (plus the
  host-stamping delay ``RgbModel.stamp_latency_s`` + ``stamp_jitter_s``, 0 by default); the
  colour image averages sub-frames spread over the exposure (no more than ``max_blur_step_px``
  apparent motion between two). The depth (``SequenceSpec.depth``): ``d455``, the D455's active
  stereo exposed ``StereoModel.phase_s`` away from the colour image and registered to it
  (:mod:`atsvo_ros.sim.stereo`, the robot layout's default), or ``sharp``, rendered at the stamp
  with noise growing with z^2 and holes at depth edges (MVSEC's default; the simulator before the D455
  model, kept to show what a too kind sensor flatters);
* events as :class:`EventBatch` packets of ``event_packet_s``, yielded when the packet is complete
  (merge key = packet end). The event camera is rendered at an adaptive rate: the next render time
  is chosen so that no scene point moves more than ``EventModel.max_step_px`` between renders
  (measured by re-projecting a grid of the last render's 3-D points with the pose change);
* IMU samples (layout robot, ``imu=True``) as one-sample :class:`ImuBatch` items at their stamps:
  the D455's BMI055 in the IMU frame ``T_rgb_imu`` of the config (:mod:`atsvo_ros.sim.imu`).

The rig comes from a config preset: cameras, ``T_base_rgb``, ``T_rgb_event``, ``T_rgb_imu``. Physically the
camera is mounted on the body as in ``config/synthetic.yaml``; the ground truth is reported for
the config's base frame (for MVSEC, base = camera), so camera = ``T_world_base @ T_base_rgb``.
"""
from __future__ import annotations

import hashlib
import heapq
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, replace

import numpy as np

from atsvo_ros.config import AtsvoConfig, load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.events import EventModel, EventSensor
from atsvo_ros.sim.imu import ImuModel, ImuSensor
from atsvo_ros.sim.motion import GRAVITY, SCENARIOS, Motion, make_motion
from atsvo_ros.sim.render import MotionProbe, Renderer
from atsvo_ros.sim.rgbd import ColorSensor, DepthModel, RgbModel, depth_to_mm, row_weights
from atsvo_ros.sim.scene import Scene, make_scene
from atsvo_ros.sim.stereo import DepthCapture, StereoDepthSensor, StereoModel, depth_phase_s, stereo_depth_to_mm

LAYOUTS = ("robot", "mvsec")
DEPTH_MODELS = ("d455", "sharp")
DEFAULT_START_NS = 1_700_000_000_000_000_000
#: Longest sequence: an hour. The bag grows by ~20 MB per simulated second at 320x240 (~75 GB an hour) and the
#: ground truth, event and frame statistics are kept in memory until the end; split longer runs by seed.
MAX_DURATION_S = 3600.0
#: Seeds: numpy's SeedSequence takes any integer >= 0; the usual 32-bit range keeps them portable.
MAX_SEED = 2**32 - 1
#: Frame rates (colour and ground truth) up to 1 kHz: RGB-D cameras run at <= 90 Hz, motion capture <= 1 kHz.
MAX_RATE_HZ = 1000.0
#: Shortest event packet: one tick of the event camera's 1 us clock.
MIN_EVENT_PACKET_S = 1e-6
#: Largest texture side: the scene's nine textures of 4096^2 texels with their mip levels take ~1 GB.
MAX_TEXTURE_SIZE = 4096
#: Bump whenever the simulator's output for an unchanged spec changes (sensor models, rendering, motion):
#: caches of generated sequences key on :func:`model_key`. 2: the DVXplorer's scanned readout and pixel reset.
#: 3: the D455's active-stereo depth with its own exposure time.
MODEL_VERSION = 3


@dataclass(frozen=True)
class SequenceSpec:
    """Everything that defines a synthetic sequence; equal specs give identical data."""

    scenario: str = "trot"
    duration_s: float = 5.0
    seed: int = 0
    layout: str = "robot"
    config: str | None = None  # preset or YAML; None = 'synthetic' (robot) or 'mvsec'
    width: int | None = None  # colour image size (None = the config's); intrinsics scale with it
    height: int | None = None
    rate_hz: float = 30.0
    exposure_s: float = 0.008
    gt_rate_hz: float = 200.0
    event_packet_s: float = 0.001
    event_scale: float = 1.0  # scales the event camera (tests use tiny sensors)
    texture_size: int = 512
    start_ns: int = DEFAULT_START_NS
    rgb_model: RgbModel = field(default_factory=RgbModel)
    depth_model: DepthModel = field(default_factory=DepthModel)
    event_model: EventModel = field(default_factory=EventModel)
    imu: bool = True  # simulate the colour camera's IMU (layout robot only; MVSEC's DAVIS IMU is not modelled)
    imu_model: ImuModel = field(default_factory=ImuModel)
    depth: str | None = None  # d455 or sharp; None = d455 (robot layout) or sharp (mvsec)
    stereo_model: StereoModel = field(default_factory=StereoModel)

    def __post_init__(self) -> None:
        if self.scenario not in SCENARIOS:
            raise SimulationError(f"unknown scenario {self.scenario!r} (choose one of {', '.join(SCENARIOS)})")
        if self.layout not in LAYOUTS:
            raise SimulationError(f"unknown layout {self.layout!r} (choose one of {', '.join(LAYOUTS)})")
        if not 0 < self.duration_s <= MAX_DURATION_S:
            raise SimulationError(f"duration must be in (0, {MAX_DURATION_S:g}] s, got {self.duration_s} (the bag "
                                  "grows by ~20 MB per simulated second at 320x240: split longer runs by seed)")
        if not isinstance(self.seed, (int, np.integer)) or not 0 <= self.seed <= MAX_SEED:
            raise SimulationError(f"seed must be an integer in [0, {MAX_SEED}] (2**32 - 1), got {self.seed!r}")
        for name, rate in (("frame rate", self.rate_hz), ("ground-truth rate", self.gt_rate_hz)):
            if not 0 < rate <= MAX_RATE_HZ:
                raise SimulationError(f"{name} must be in (0, {MAX_RATE_HZ:g}] Hz, got {rate}")
        if not MIN_EVENT_PACKET_S <= self.event_packet_s <= 1.0:
            raise SimulationError(f"event packet length must be in [{MIN_EVENT_PACKET_S:g}, 1] s (one tick of the "
                                  f"event clock to a second), got {self.event_packet_s}")
        if not 0.0 < self.exposure_s <= min(0.1, 1.0 / self.rate_hz):
            raise SimulationError(f"exposure {self.exposure_s} s must be positive and fit in one frame "
                                  f"period (1/{self.rate_hz} s)")
        if not 0.05 <= self.event_scale <= 4.0:
            raise SimulationError(f"event_scale must be in [0.05, 4], got {self.event_scale}")
        if self.depth is not None and self.depth not in DEPTH_MODELS:
            raise SimulationError(f"unknown depth model {self.depth!r} (choose one of {', '.join(DEPTH_MODELS)})")
        if self.depth == "d455" and self.layout == "mvsec":
            raise SimulationError("the D455 depth model needs the robot layout (MVSEC's depth is not a D455's)")
        for v in (self.width, self.height):
            if v is not None and not 8 <= v <= 4096:
                raise SimulationError(f"image size must be in [8, 4096] px, got {v}")
        ts = self.texture_size
        if not (isinstance(ts, (int, np.integer)) and 8 <= ts <= MAX_TEXTURE_SIZE and ts & (ts - 1) == 0):
            raise SimulationError(f"texture size must be a power of two in [8, {MAX_TEXTURE_SIZE}] texels, got {ts}")


    @property
    def depth_sensor(self) -> str:
        """The depth sensor: ``depth``, or the layout's own (D455 for the robot, sharp for MVSEC)."""
        return self.depth or ("sharp" if self.layout == "mvsec" else "d455")


@dataclass(frozen=True)
class FrameReport:
    """What the sensors gave for one RGB-D frame (``atsvo-sim``'s per-phase summary is made of these).

    ``depth_valid`` is the share of colour pixels with depth; ``depth_error`` the median of |measured -
    true| / true depth at the colour image's time (so it includes the depth frame's timing), over pixels
    with depth; ``colour_blur_px`` / ``ir_blur_px`` the largest apparent motion over the colour / IR
    exposure; ``ir_exposure_s`` 0 without an IR model.
    """

    stamp_ns: int
    depth_valid: float
    depth_error: float
    colour_blur_px: float
    ir_blur_px: float = 0.0
    ir_exposure_s: float = 0.0


@dataclass(frozen=True)
class RgbdFrame:
    """One colour + depth pair. ``depth_mm`` is 0 where invalid and lies on the colour image's own
    (raw) pixel grid in both layouts, as the D455's aligned depth and MVSEC's depth_image_raw do."""

    stamp_ns: int
    rgb: np.ndarray
    depth_mm: np.ndarray

    @property
    def depth_m(self) -> np.ndarray:
        """Depth in metres as float32, NaN where invalid."""
        d = self.depth_mm.astype(np.float32) * 0.001
        d[self.depth_mm == 0] = np.nan
        return d


@dataclass(frozen=True)
class GroundTruth:
    """Pose of the config's base frame in the world at ``stamp_ns``."""

    stamp_ns: int
    T_world_base: np.ndarray


@dataclass(frozen=True)
class SimRig:
    """Cameras and extrinsics of a sequence, as written to camera_info and /tf_static."""

    config: AtsvoConfig
    rgb_camera: CameraModel
    depth_camera: CameraModel
    event_camera: CameraModel
    T_base_rgb: np.ndarray
    T_rgb_event: np.ndarray
    T_body_rgb: np.ndarray  # physical mount of the colour camera on the robot body
    T_rgb_imu: np.ndarray = field(default_factory=lambda: np.eye(4))  # IMU frame in the colour optical frame

    @property
    def T_base_event(self) -> np.ndarray:
        return self.T_base_rgb @ self.T_rgb_event


def _scaled(cam: CameraModel, sx: float, sy: float, width: int, height: int) -> CameraModel:
    """Intrinsics of a resized image (pixel-centre convention); distortion coefficients unchanged."""
    return CameraModel(width, height, cam.fx * sx, cam.fy * sy, (cam.cx + 0.5) * sx - 0.5, (cam.cy + 0.5) * sy - 0.5,
                       cam.distortion_model, cam.D)


def sequence_rig(spec: SequenceSpec) -> SimRig:
    """The rig of a spec: config preset, resized colour camera, scaled event camera, extrinsics."""
    cfg = load_config(spec.config or ("mvsec" if spec.layout == "mvsec" else "synthetic"))
    rgb = CameraModel.from_config(cfg.rgb_camera)
    w = spec.width or (round(rgb.width * spec.height / rgb.height) if spec.height else rgb.width)
    h = spec.height or (round(rgb.height * w / rgb.width) if spec.width else rgb.height)
    rgb = _scaled(rgb, w / rgb.width, h / rgb.height, w, h)
    ev = CameraModel.from_config(cfg.event_camera)
    ew, eh = max(4, round(ev.width * spec.event_scale)), max(4, round(ev.height * spec.event_scale))
    ev = _scaled(ev, ew / ev.width, eh / ev.height, ew, eh)
    depth_cam = rgb  # both layouts: depth on the raw colour grid (D455 aligned depth, MVSEC depth_image_raw)
    if spec.layout == "robot" and rgb.is_distorted:
        raise SimulationError("layout robot needs an undistorted colour camera (depth is aligned to it)")
    mount = load_config("synthetic").rig.T_base_rgb_matrix()
    return SimRig(cfg, rgb, depth_cam, ev, cfg.rig.T_base_rgb_matrix(), cfg.rig.T_rgb_event_matrix(), mount,
                  cfg.rig.T_rgb_imu_matrix())


class Simulation:
    """A sequence being generated: scene, motion, rig and the per-sensor random streams."""

    def __init__(self, spec: SequenceSpec, scene: Scene | None = None) -> None:
        self.spec = spec
        self.rig = sequence_rig(spec)
        self.scene = scene or make_scene(spec.seed, spec.texture_size)
        self.motion: Motion = make_motion(spec.scenario, spec.duration_s, spec.seed, self.scene.free_xy,
                                          t0_ns=spec.start_ns)
        seeds = np.random.SeedSequence([spec.seed, 0x5E9]).spawn(6)
        self._rng_rgb, self._rng_depth, self._rng_events = (np.random.default_rng(s) for s in seeds[:3])
        self._stamp_seed = seeds[4]
        self._stereo_seed = seeds[5]
        self._imu_seed = seeds[3]
        dm = spec.depth_model
        self.depth_model = replace(dm, min_m=self.rig.config.rig.depth_min_m, max_m=self.rig.config.rig.depth_max_m)
        #: the D455 model: its IR images keep their own size whatever the colour image's (a smaller depth image is
        #: a noisier sensor, which the tracker's depth noise model would not expect)
        self.stereo_model = spec.stereo_model
        #: depth exposure centre minus colour exposure centre (the D455 model; 0 for sharp depth)
        self.depth_phase_s = 0.0 if spec.depth_sensor != "d455" else depth_phase_s(
            spec.stereo_model, spec.rate_hz, np.random.default_rng(self._stereo_seed.spawn(1)[0]))
        # Camera pose in the world = body pose x physical mount; ground truth for the config's base.
        self._T_rgb_base = se3_inv(self.rig.T_base_rgb)
        self.check_clearance()

    # ------------------------------------------------------------------ poses
    def T_world_rgb(self, t_ns) -> np.ndarray:
        return self.motion.T_world_base(t_ns) @ self.rig.T_body_rgb

    def T_world_event(self, t_ns) -> np.ndarray:
        return self.T_world_rgb(t_ns) @ self.rig.T_rgb_event

    def T_world_imu(self, t_ns) -> np.ndarray:
        return self.T_world_rgb(t_ns) @ self.rig.T_rgb_imu

    def T_world_base(self, t_ns) -> np.ndarray:
        """Ground truth: pose of the config's base frame."""
        return self.T_world_rgb(t_ns) @ self._T_rgb_base

    @property
    def t_start_ns(self) -> int:
        return self.motion.t0_ns

    @property
    def t_end_ns(self) -> int:
        return self.motion.t_end_ns

    def check_clearance(self, margin_m: float = 0.05) -> None:
        """Both cameras must stay inside the room and outside every box for the whole sequence."""
        ts = np.arange(self.t_start_ns, self.t_end_ns + 1, 10_000_000, dtype=np.int64)
        for name, fn in (("colour", self.T_world_rgb), ("event", self.T_world_event)):
            p = fn(ts)[:, :3, 3]
            bad = ~self.scene.inside_free_space(p, margin_m)
            if np.any(bad):
                t_bad = (ts[np.argmax(bad)] - self.t_start_ns) * 1e-9
                raise SimulationError(f"the {name} camera leaves the free space at t = {t_bad:.2f} s "
                                      f"(scenario {self.spec.scenario}, seed {self.spec.seed}); try another seed")

    # ------------------------------------------------------------------ streams
    def ground_truth(self) -> Iterator[GroundTruth]:
        n = int(np.floor(self.spec.duration_s * self.spec.gt_rate_hz + 1e-9)) + 1
        stamps = self.t_start_ns + np.round(np.arange(n) * 1e9 / self.spec.gt_rate_hz).astype(np.int64)
        for i0 in range(0, n, 256):
            chunk = stamps[i0:i0 + 256]
            for s, T in zip(chunk, self.T_world_base(chunk)):
                yield GroundTruth(int(s), T)

    @property
    def has_imu(self) -> bool:
        return self.spec.imu and self.spec.layout == "robot"

    def imu_sensor(self) -> ImuSensor:
        """A fresh IMU of this sequence (same seed, so the same samples every time)."""
        return ImuSensor(self.spec.imu_model, self.T_world_imu, self.t_start_ns, self.t_end_ns,
                         np.random.SeedSequence(self._imu_seed.entropy, spawn_key=self._imu_seed.spawn_key),
                         GRAVITY)

    def imu(self, stats: dict | None = None) -> Iterator[ImuBatch]:
        """IMU samples one at a time (empty without an IMU); ``stats['imu']`` describes the seed's draws."""
        if not self.has_imu:
            return
        sensor = self.imu_sensor()
        if stats is not None:
            stats["imu"] = sensor.describe()
        for chunk in sensor.batches():
            for i in range(len(chunk)):
                yield chunk.select(slice(i, i + 1))

    def stamp_delays_ns(self, n: int, jitter_s: float | None = None, latency_s: float | None = None) -> np.ndarray:
        """Delay of each of the first ``n`` frames' stamps after its exposure: ``latency_s`` plus a half-normal
        jitter of scale ``jitter_s`` (by default ``RgbModel.stamp_latency_s`` / ``stamp_jitter_s``; the same
        draws for the same seed whatever the scale)."""
        jitter_s = self.spec.rgb_model.stamp_jitter_s if jitter_s is None else float(jitter_s)
        latency_s = self.spec.rgb_model.stamp_latency_s if latency_s is None else float(latency_s)
        delays = np.full(n, int(round(latency_s * 1e9)), np.int64)
        if jitter_s > 0:
            rng = np.random.default_rng(self._stamp_seed)
            delays += np.round(np.abs(rng.standard_normal(n)) * (jitter_s * 1e9)).astype(np.int64)
        return delays

    def frames(self, stats: dict | None = None) -> Iterator[RgbdFrame]:
        """RGB-D frames at ``rate_hz`` (``stats['rgb_renders']`` counts the rendered sub-frames)."""
        spec, rig = self.spec, self.rig
        renderer = Renderer(self.scene, rig.rgb_camera)
        depth_renderer = None if rig.depth_camera == rig.rgb_camera else Renderer(self.scene, rig.depth_camera)
        sensor = ColorSensor(spec.rgb_model, spec.exposure_s, renderer.rays,
                             (rig.rgb_camera.height, rig.rgb_camera.width), self._rng_rgb)
        probe = MotionProbe(rig.rgb_camera, renderer.rays)
        n = int(np.floor(spec.duration_s * spec.rate_hz + 1e-9)) + 1
        readout_s = spec.rgb_model.readout_time_s
        # Sub-frames span the exposure, and with a rolling shutter the readout as well (each row then
        # averages the sub-frames inside its own exposure window; depth stays global shutter).
        half = int(round((spec.exposure_s + readout_s) * 0.5e9))
        delays_ns = self.stamp_delays_ns(n)
        stereo = None if spec.depth_sensor != "d455" else StereoDepthSensor(
            self.stereo_model, self.scene, rig.rgb_camera, self.T_world_rgb, self._rng_depth)
        phase_ns = int(round(self.depth_phase_s * 1e9))
        if stats is not None:
            stats["depth_phase_s"] = self.depth_phase_s
        depth_prev = None
        for k in range(n):
            stamp = self.t_start_ns + int(round(k * 1e9 / spec.rate_hz))
            if depth_prev is None:
                depth_prev = renderer.render(self.T_world_rgb(stamp))[1]
            moved = probe.max_motion_px(depth_prev, self.T_world_rgb(stamp - half), self.T_world_rgb(stamp + half))
            # Sub-frames no more than max_blur_step_px apart (a single one when the blur is below that);
            # an odd count puts the middle one at the stamp.
            step_px = spec.rgb_model.max_blur_step_px
            n_sub = 1 if moved <= step_px else min(int(np.ceil(moved / step_px)) + 1, spec.rgb_model.max_subframes)
            n_sub += 1 - n_sub % 2
            times = stamp + (np.linspace(-half, half, n_sub) if n_sub > 1 else np.zeros(1)).round().astype(np.int64)
            poses = self.T_world_rgb(times)
            weights = None if readout_s == 0 else row_weights((times - stamp) * 1e-9, rig.rgb_camera.height,
                                                                spec.exposure_s, readout_s)
            acc = None
            for j, T in enumerate(poses):
                _, depth, col = renderer.render(T, rgb=True)
                if weights is not None:
                    col = col * (weights[j] * n_sub).astype(np.float32)[:, None, None]
                acc = col if acc is None else np.add(acc, col, out=acc)
                if j == n_sub // 2:
                    depth_prev = depth
            if stats is not None:
                stats["rgb_renders"] = stats.get("rgb_renders", 0) + n_sub
            rgb = sensor.expose([acc * np.float32(1.0 / n_sub)], stamp)
            depth = depth_prev if depth_renderer is None else depth_renderer.render(poses[n_sub // 2])[1]
            if stereo is None:
                depth_mm, ir = depth_to_mm(depth, self.depth_model, self._rng_depth), None
            else:
                ir = stereo.capture(stamp + phase_ns)
                depth_mm = stereo_depth_to_mm(ir.depth_m, self.depth_model.min_m, self.depth_model.max_m)
            if stats is not None:
                stats.setdefault("frames", []).append(_report(stamp, depth_mm, depth, moved, ir))
            # the image is exposed on the frame clock; a host-stamping driver reports it when it arrives
            yield RgbdFrame(stamp + int(delays_ns[k]), rgb, depth_mm)

    def events(self, stats: dict | None = None) -> Iterator[EventBatch]:
        """Event packets of ``event_packet_s`` (empty packets are skipped), in time order.

        ``stats['event_renders']`` counts the renders; with ``stats['log_render_stamps'] = True`` the
        render stamps are listed in ``stats['event_render_stamps']``.
        """
        spec, cam = self.spec, self.rig.event_camera
        m = spec.event_model
        renderer = Renderer(self.scene, cam)
        probe = MotionProbe(cam, renderer.rays)
        sensor = EventSensor(m, cam.width, cam.height, self._rng_events)
        t, t_end = self.t_start_ns, self.t_end_ns
        T = self.T_world_event(t)
        grey, depth = renderer.render(T)
        sensor.reset(grey, t)
        packet_ns = int(round(spec.event_packet_s * 1e9))
        max_dt = max(int(m.max_render_interval_s * 1e9), 1000)
        dt = 100_000
        fractions = np.array([0.6, 0.8, 1.0, 1.25, 1.6])
        pending: list[EventBatch] = []
        w_start = t
        renders = 1
        render_log = stats.setdefault("event_render_stamps", [t]) if stats is not None and stats.get(
            "log_render_stamps") else None
        while t < t_end:
            # Several candidate render times in one pose evaluation: take the latest one that keeps
            # the apparent motion below max_step_px; shrink and retry when none does.
            for _ in range(20):
                steps = np.clip(np.round(dt * fractions), 1000, max_dt).astype(np.int64) // 1000 * 1000
                cands = np.minimum(t + steps, t_end)  # renders on the microsecond grid
                poses = self.T_world_event(cands)
                moved = probe.max_motion_px(depth, T, poses)
                ok = np.flatnonzero((moved <= m.max_step_px) | (cands - t <= 1000))
                if len(ok):
                    i = int(ok[-1])
                    break
                dt = max(int(dt * fractions[0] * 0.9 * m.max_step_px / moved[0]), 1000)
            t1, T1 = int(cands[i]), poses[i]
            step = t1 - t
            dt = int(np.clip(step * 0.9 * m.max_step_px / max(moved[i], 1e-6), 0.5 * step, 2.0 * step))
            dt = min(max(dt, 1000), max_dt)
            grey, depth = renderer.render(T1)
            renders += 1
            batch = sensor.step(grey, t1)
            if len(batch):
                pending.append(batch)
            t, T = t1, T1
            while pending and (w_start + packet_ns <= t or t >= t_end):
                w_end = w_start + packet_ns
                allb = EventBatch.concatenate(pending) if len(pending) > 1 else pending[0]
                cut = int(np.searchsorted(allb.t, w_end, side="left"))
                out, rest = allb.select(slice(0, cut)), allb.select(slice(cut, None))
                pending = [rest] if len(rest) else []
                if len(out):
                    yield out
                w_start = w_end
            if not pending:
                w_start = self.t_start_ns + (t - self.t_start_ns) // packet_ns * packet_ns
            if render_log is not None:
                render_log.append(t1)
        if stats is not None:
            stats["event_renders"] = renders


def _report(stamp_ns: int, depth_mm: np.ndarray, depth_true_m: np.ndarray, colour_blur_px: float,
            ir: DepthCapture | None) -> FrameReport:
    """One frame's :class:`FrameReport`: depth validity and error against the true depth at the colour time."""
    valid = depth_mm > 0
    z = depth_true_m[valid]
    err = float(np.median(np.abs(depth_mm[valid] * 1e-3 - z) / z)) if valid.any() else float("nan")
    return FrameReport(int(stamp_ns), float(valid.mean()), err, float(colour_blur_px),
                       0.0 if ir is None else ir.ir_blur_px, 0.0 if ir is None else ir.exposure_s)


def iter_sequence(spec: SequenceSpec, scene: Scene | None = None,
                  stats: dict | None = None) -> Iterator[RgbdFrame | EventBatch | GroundTruth | ImuBatch]:
    """Generate a sequence: ground truth, RGB-D frames, event packets and IMU samples merged in time order.

    Event packets are keyed by their end (they are complete then); frames, poses and IMU samples by
    their stamp. ``stats`` (optional dict) receives counters ``event_renders`` and ``rgb_renders``
    and the IMU's per-seed draws ``imu``.
    """
    sim = Simulation(spec, scene)
    packet_ns = int(round(spec.event_packet_s * 1e9))

    def keyed(it, order, key):
        for item in it:
            yield key(item), order, item

    def event_key(b: EventBatch) -> int:
        # End of the packet holding the batch (packets are aligned to the start of the sequence).
        k = (b.t_first_ns - sim.t_start_ns) // packet_ns + 1
        return min(sim.t_start_ns + k * packet_ns, sim.t_end_ns + 1)

    # The RGB-D frames (colour sub-frames, both IR imagers, stereo matching) are made in a thread of their own
    # while this one makes the events: the renderers and the matcher release the GIL, so two cores share the
    # work. Each stream draws from its own random generator: the data is the same as in one thread.
    streams = [keyed(sim.ground_truth(), 0, lambda g: g.stamp_ns),
               keyed(_ahead(sim.frames(stats)), 1, lambda f: f.stamp_ns),
               keyed(sim.events(stats), 2, event_key),
               keyed(sim.imu(stats), 3, lambda b: b.t_first_ns)]
    for _, _, item in heapq.merge(*streams, key=lambda x: (x[0], x[1])):
        yield item


def _ahead(items: Iterator, depth: int = 4) -> Iterator:
    """``items`` produced in a background thread, at most ``depth`` ahead; its errors are raised here."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def produce() -> None:
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        q.put((item, None), timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put((done, None))
        except BaseException as exc:  # handed to the consumer, which raises it
            q.put((done, exc))

    worker = threading.Thread(target=produce, name="atsvo-sim-frames", daemon=True)
    worker.start()
    try:
        while True:
            item, exc = q.get()
            if exc is not None:
                raise exc
            if item is done:
                return
            yield item
    finally:
        stop.set()


def with_sensors(spec: SequenceSpec, exposure_s: float | None = None, contrast: float | None = None,
                 noise_rate_hz: float | None = None, ambient_ir: float | None = None) -> SequenceSpec:
    """``spec`` with other sensor settings (None keeps the spec's): the colour exposure (blur), the event contrast
    threshold (C+ = C-), the event camera's background activity per pixel and second, and the room's IR light against
    the D455's projector (lower: a dimmer room, longer IR exposures, more smear). ``atsvo-sim`` and ``atsvo-bench
    tracking`` take them as ``--exposure``, ``--contrast``, ``--noise-rate`` and ``--ir-ambient``."""
    events: dict[str, float] = {}
    if contrast is not None:
        events.update(contrast_pos=float(contrast), contrast_neg=float(contrast))
    if noise_rate_hz is not None:
        events["noise_rate_hz"] = float(noise_rate_hz)
    return replace(
        spec, exposure_s=spec.exposure_s if exposure_s is None else float(exposure_s),
        event_model=replace(spec.event_model, **events),
        stereo_model=spec.stereo_model if ambient_ir is None else replace(spec.stereo_model,
                                                                                     ambient_ir=float(ambient_ir)))


def spec_key(spec: SequenceSpec, imu: bool = True) -> str:
    """``repr(spec)``, or with ``imu=False`` its fields but the IMU's (for what does not depend on the IMU)."""
    if imu:
        return repr(spec)
    return ", ".join(f"{f.name}={getattr(spec, f.name)!r}" for f in fields(spec) if f.name != "imu_model")


def model_key(imu: bool = True) -> str:
    """Identity of the simulator's models: ``m<MODEL_VERSION>-<hash of the default spec>``, so that a new model
    version or a changed default (e.g. an ``EventModel`` parameter) never reuses a sequence generated before.
    ``imu=False``: the identity of the camera streams alone (an IMU model's change leaves them as they are)."""
    digest = hashlib.sha1(f"{MODEL_VERSION}|{spec_key(SequenceSpec(), imu)}".encode()).hexdigest()[:8]
    return f"m{MODEL_VERSION}-{digest}"


def make_simulation(spec: SequenceSpec, scene: Scene | None = None) -> Simulation:
    """A :class:`Simulation` (poses, rig, per-sensor streams) without starting the merged iterator."""
    return Simulation(spec, scene)


__all__ = ["DEPTH_MODELS", "MAX_DURATION_S", "MAX_RATE_HZ", "MAX_SEED", "MAX_TEXTURE_SIZE", "MIN_EVENT_PACKET_S",
           "FrameReport", "GroundTruth", "ImuBatch", "ImuModel", "RgbdFrame", "SequenceSpec", "SimRig", "Simulation",
           "iter_sequence", "make_motion", "make_scene", "make_simulation", "model_key", "sequence_rig", "spec_key",
           "with_sensors"]
