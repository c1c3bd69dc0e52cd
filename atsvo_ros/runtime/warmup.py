"""Warm-up: run the odometry once on a few synthetic frames, so no real frame pays for numba's compilation.

A node that subscribes before its kernels are compiled (or loaded from numba's cache) stalls on its
first frames; the robot moves meanwhile and the second frame is tracked against a scene 20-30 cm
away. The nodes call :func:`warm_up` before they subscribe and log when they are ready. The frames are
a smooth random texture on a plane 2 m away, shifted a pixel a frame, with events where the log
intensity changed and a still IMU; the event term is forced on (gates at 0) so the fused path compiles too.
The event decoders of ``node.event_msg_type`` (every EventPacket encoding) decode one small message each:
loading their kernels from numba's cache took 0.35 s on the first event message before.
"""
from __future__ import annotations

import dataclasses
import time

import cv2
import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.encode import ENCODINGS, serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.runtime.runtime import OdometryRuntime

#: Frames fed: the first initialises, the next track (the third and later through the fused path).
N_FRAMES = 4
FRAME_PERIOD_NS = 33_333_333
CONTRAST = 0.05  # log-intensity step of an event


def _texture(camera: CameraModel, rng: np.random.Generator) -> np.ndarray:
    """A smooth random grey texture, larger than the image by the shifts to come."""
    noise = rng.normal(0.0, 1.0, (camera.height, camera.width + N_FRAMES)).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 2.0)
    smooth = (smooth - smooth.min()) / max(float(np.ptp(smooth)), 1e-6)
    return (40 + 180 * smooth).astype(np.uint8)


@dataclasses.dataclass(frozen=True)
class WarmUp:
    """What the warm-up did: wall time, and each frame's status and mode (the paths it went through)."""

    seconds: float
    statuses: tuple[str, ...]
    modes: tuple[str, ...]


def _edge_events(texture: np.ndarray, k: int, rgb_cam: CameraModel, ev_cam: CameraModel, stamp_ns: int,
                 rng: np.random.Generator) -> EventBatch:
    """Events where the log intensity changed from the previous shift by more than a contrast step."""
    width = rgb_cam.width
    now = np.log1p(texture[:, k:k + width].astype(np.float32))
    before = np.log1p(texture[:, max(k - 1, 0):max(k - 1, 0) + width].astype(np.float32))
    change = cv2.resize(now - before, (ev_cam.width, ev_cam.height), interpolation=cv2.INTER_AREA)
    y, x = np.nonzero(np.abs(change) > CONTRAST)
    t = np.sort(rng.integers(stamp_ns - FRAME_PERIOD_NS, stamp_ns, len(x))).astype(np.int64)
    order = rng.permutation(len(x))
    return EventBatch(x[order].astype(np.uint16), y[order].astype(np.uint16), t,
                      (change[y, x][order] > 0).astype(np.uint8), ev_cam.width, ev_cam.height)


def warm_decoders(msgtype: str, batch: EventBatch) -> int:
    """Decode ``batch`` (time-sorted) as ``msgtype`` raw CDR messages (each EventPacket encoding).

    Returns the events decoded, summed over the messages.

    ``event_array_msgs/msg/EventArray`` has no encoder here, so it is not warmed (0).
    """
    if msgtype == "event_camera_msgs/msg/EventPacket":
        raws = [serialize_event_packet(batch, encoding, stamp_ns=int(batch.t_last_ns)) for encoding in ENCODINGS]
    elif msgtype in ("dvs_msgs/msg/EventArray", "dv_ros2_msgs/msg/EventArray"):
        raws = [serialize_dvs_event_array(batch, stamp_ns=int(batch.t_last_ns))]
    else:
        return 0
    return sum(len(EventDecoder(msgtype, 2, batch.width, batch.height).decode_raw(bytes(raw))) for raw in raws)


def warm_up(config: AtsvoConfig, use_events: bool = True, seed: int = 0) -> WarmUp:
    """Run the odometry on :data:`N_FRAMES` synthetic frames: what it took and went through.

    Args:
        config: The node's configuration (its cameras give the image sizes; camera_info is not waited for).
        use_events: Warm the fused path (events, ATS, event map) as well as the RGB-D one.
        seed: Seed of the texture and the events.

    Returns:
        The seconds spent (most of it compiling or loading numba's cached kernels, the first time) and
        the frames' statuses and modes.
    """
    t0 = time.perf_counter()
    fusion = dataclasses.replace(config.fusion, rate_threshold_deg_s=0.0, rate_threshold_gyro_deg_s=0.0,
                                 speed_threshold_m_s=0.0)
    cfg = dataclasses.replace(config, fusion=fusion)
    rgb_cam = CameraModel.from_config(cfg.rgb_camera)
    ev_cam = CameraModel.from_config(cfg.event_camera)
    runtime = OdometryRuntime(cfg, rgb_cam, ev_cam, use_events=use_events)
    rng = np.random.default_rng(seed)
    texture = _texture(rgb_cam, rng)
    depth_m = np.full((rgb_cam.height, rgb_cam.width), 2.0, np.float32)
    t_start = 1_000_000_000
    imu_t = np.arange(t_start - FRAME_PERIOD_NS, t_start + (N_FRAMES + 1) * FRAME_PERIOD_NS, 5_000_000, np.int64)
    runtime.add_imu(ImuBatch(imu_t, np.zeros((len(imu_t), 3)), np.tile([0.0, 0.0, 9.81], (len(imu_t), 1))))
    outputs = []
    for k in range(N_FRAMES):
        stamp = t_start + k * FRAME_PERIOD_NS
        grey = texture[:, k:k + rgb_cam.width]
        runtime.add_rgb(stamp, np.repeat(grey[:, :, None], 3, axis=2))
        runtime.add_depth(stamp, depth_m)
        if use_events:
            events = _edge_events(texture, k, rgb_cam, ev_cam, stamp, rng)
            if k == 0:
                warm_decoders(cfg.node.event_msg_type, events)
            runtime.add_events(events, complete_to_ns=stamp)
        outputs += runtime.poll()
    outputs += runtime.flush()
    return WarmUp(time.perf_counter() - t0, tuple(o.result.status.value for o in outputs),
                  tuple(o.result.mode for o in outputs))


__all__ = ["WarmUp", "warm_decoders", "warm_up"]
