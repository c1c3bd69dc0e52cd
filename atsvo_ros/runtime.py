"""OdometryRuntime: the one ROS-free driver of the odometry core (replay, benchmarks and the nodes).

Sensor data goes in as it arrives, in any interleaving: colour and depth images (arrays or
sensor_msgs messages), event batches (or event messages, decoded here with the vectorised
decoders), IMU samples and camera_info. The :class:`~atsvo_ros.io.sync.FrameAssembler` pairs colour
with depth and cuts the event stream at frame stamps; :meth:`OdometryRuntime.poll` runs the core on
every frame that became complete and returns one :class:`RuntimeOutput` per frame.

Bad input never stops it: an undecodable image, a duplicated or out-of-order frame, a broken event
packet or a frame the core rejects is skipped, counted in :attr:`OdometryRuntime.counters` and
reported once per kind through the logger (then at most every ``log_interval_s``, with the count).
A stamp that jumps back by more than a frame (``ros2 bag play --loop``, a simulator restart) is not
out of order but a clock jump: the frame goes to the core, which resets its motion model.
"""
from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events import EventBatch
from atsvo_ros.core.frame import OdometryResult, RgbdFrame
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.ros_out import body_twist
from atsvo_ros.io.sync import FrameAssembler

Logger = Callable[[str, str], None]  # (level: "info" | "warn" | "error", text)


class OdometryCore(Protocol):
    """What the runtime needs from the core (:class:`atsvo_ros.core.odometry.Odometry`, or a test double)."""

    def process_frame(self, frame: RgbdFrame) -> OdometryResult: ...

    def add_events(self, batch: EventBatch) -> None: ...

    def add_imu(self, batch: ImuBatch) -> None: ...


@dataclass(frozen=True)
class RuntimeOutput:
    """One processed frame: the core's result, the base twist since the previous output, the events it got."""

    result: OdometryResult
    twist: np.ndarray | None
    n_events: int


def _no_log(level: str, text: str) -> None:
    del level, text


def _default_core() -> Callable[..., OdometryCore]:
    from atsvo_ros.core.odometry import Odometry

    return Odometry


class OdometryRuntime:
    """Feeds the core from a sensor stream (see the module docstring)."""

    #: A stamp this far (or more) behind the last frame is a clock jump, not an out-of-order frame.
    CLOCK_JUMP_S = 1.0

    def __init__(self, config: AtsvoConfig, rgb_camera: CameraModel | None = None,
                 event_camera: CameraModel | None = None, *, use_events: bool | None = None,
                 logger: Logger | None = None, core_factory: Callable[..., OdometryCore] | None = None,
                 log_interval_s: float = 10.0) -> None:
        self.config = config
        self._log = logger or _no_log
        self._factory = core_factory or _default_core()
        self.use_events = config.mode == "fused" if use_events is None else bool(use_events)
        self.counters: Counter[str] = Counter()
        #: the first message of each kind of problem (what :attr:`counters` counts), for summaries
        self.first_problem: dict[str, str] = {}
        self.rgb_camera = rgb_camera if rgb_camera is not None else (
            None if config.rgb_camera.use_camera_info else config.rgb_camera.model())
        self.event_camera = event_camera if event_camera is not None else (
            None if config.event_camera.use_camera_info else config.event_camera.model())
        # events waiting for their frame: at most what the core would fold in over the assembler's wait
        wait_s = 0.25
        self.assembler = FrameAssembler(config.rig, with_events=self.use_events, max_event_wait_s=wait_s,
                                        max_buffered_events=int(config.fusion.max_event_rate_ev_s * wait_s))
        self.core: OdometryCore | None = None
        self._decoders: dict[str, Any] = {}
        self._imu_pending: list[ImuBatch] = []
        self._last_out: tuple[int, np.ndarray] | None = None
        self._last_stamp: int | None = None
        self._log_interval_s = float(log_interval_s)
        self._last_logged: dict[str, float] = {}
        self._logged_count: Counter[str] = Counter()

    # ------------------------------------------------------------------ reporting
    def _problem(self, kind: str, text: str, level: str = "warn") -> None:
        """Count a problem; log the first of each kind, then at most every ``log_interval_s`` with the count."""
        self.counters[kind] += 1
        self.first_problem.setdefault(kind, text)
        now = time.monotonic()
        last = self._last_logged.get(kind)
        if last is None or now - last >= self._log_interval_s:
            extra = self.counters[kind] - self._logged_count[kind] - 1
            more = f" (+{extra} more since the last report)" if extra > 0 else ""
            self._log(level, f"{text}{more}")
            self._last_logged[kind] = now
            self._logged_count[kind] = self.counters[kind]

    # ------------------------------------------------------------------ inputs
    def on_rgb_camera_info(self, msg: Any) -> None:
        """Colour camera_info: used once, when ``rgb_camera.use_camera_info`` is set and no model was given."""
        if self.rgb_camera is None:
            self.rgb_camera = self._camera(msg, "colour")

    def on_event_camera_info(self, msg: Any) -> None:
        """Event camera_info: used once, when ``event_camera.use_camera_info`` is set and no model was given."""
        if self.event_camera is None:
            self.event_camera = self._camera(msg, "event")

    def add_rgb(self, stamp_ns: int, image: np.ndarray) -> None:
        """A colour image (H, W, 3 RGB uint8, or grey) at its stamp."""
        self.assembler.add_rgb(int(stamp_ns), image)

    def add_depth(self, stamp_ns: int, depth_m: np.ndarray) -> None:
        """A depth image in float32 metres (0 / NaN = invalid) aligned to the colour image."""
        self.assembler.add_depth(int(stamp_ns), depth_m)

    def add_rgb_msg(self, msg: Any, topic: str = "colour") -> None:
        """sensor_msgs/Image or CompressedImage; an undecodable one is skipped and counted."""
        try:
            self.assembler.add_rgb_msg(msg)
        except AtsvoError as exc:
            self._problem("images_rejected", f"{topic}: image at {_msg_stamp(msg)} skipped: {exc}")

    def add_depth_msg(self, msg: Any, topic: str = "depth") -> None:
        """Depth image message (16UC1 scaled by ``rig.depth_scale_m``, or 32FC1 metres); bad ones are counted."""
        try:
            self.assembler.add_depth_msg(msg)
        except AtsvoError as exc:
            self._problem("images_rejected", f"{topic}: depth image at {_msg_stamp(msg)} skipped: {exc}")

    def add_events(self, batch: EventBatch, complete_to_ns: int | None = None) -> None:
        """A decoded, time-ordered event batch (``complete_to_ns``: the stream is known complete up to here)."""
        if self.use_events:
            self.counters["events"] += len(batch)
            self.assembler.add_events(batch, complete_to_ns=complete_to_ns)

    def add_event_msg(self, msg: Any, msgtype: str, topic: str = "events") -> None:
        """One event message, deserialized or as raw CDR bytes (an rclpy ``raw=True`` subscription)."""
        if not self.use_events:
            return
        from atsvo_ros.io.decode import EventDecoder
        from atsvo_ros.io.images import stamp_ns

        dec = self._decoders.get(topic)
        if dec is None:
            cam = self.event_camera or self.config.event_camera.model()
            dec = self._decoders[topic] = EventDecoder(msgtype, 2, cam.width, cam.height)
        self.counters["event_msgs"] += 1
        if isinstance(msg, (bytes, bytearray, memoryview)):
            batch = dec.decode_raw(msg)
            mark = _cdr_stamp_ns(msg)
        else:
            batch = dec.decode_message(msg)
            try:
                mark = stamp_ns(msg)
            except (AttributeError, TypeError):
                mark = None
        self.add_events(batch, complete_to_ns=mark)

    def add_imu(self, batch: ImuBatch) -> None:
        """IMU samples (time order); they predict each frame's rotation in the core."""
        if len(batch) == 0:
            return
        self.counters["imu_samples"] += len(batch)
        if self.core is None:
            self._imu_pending.append(batch)
            if len(self._imu_pending) > 1000:
                self._imu_pending.pop(0)
        else:
            self.core.add_imu(batch)

    def add_imu_msg(self, msg: Any, topic: str = "imu") -> None:
        """sensor_msgs/Imu; a malformed one is skipped and counted."""
        from atsvo_ros.io.imu import imu_from_msg

        try:
            self.add_imu(imu_from_msg(msg))
        except AtsvoError as exc:
            self._problem("imu_rejected", f"{topic}: IMU message skipped: {exc}")

    # ------------------------------------------------------------------ outputs
    def poll(self) -> list[RuntimeOutput]:
        """Run the core on every complete frame (oldest first); one output per processed frame."""
        return self._run(self.assembler.pop_ready())

    def flush(self) -> list[RuntimeOutput]:
        """End of stream: process every frame that can still be paired."""
        return self._run(self.assembler.flush())

    @property
    def decoder_stats(self) -> dict[str, Any]:
        """Event decoder statistics per topic (only for messages decoded here)."""
        return {t: d.stats.as_dict() for t, d in self._decoders.items()}

    @property
    def pending(self) -> int:
        """Images and pairs held back by the assembler (bounded)."""
        return self.assembler.pending

    # ------------------------------------------------------------------ internals
    def _camera(self, msg: Any, which: str) -> CameraModel | None:
        try:
            return CameraModel.from_camera_info(msg)
        except AtsvoError as exc:
            self._problem("bad_camera_info", f"{which} camera_info unusable: {exc}", "error")
            return None

    def _ensure_core(self) -> OdometryCore | None:
        if self.core is None:
            if self.rgb_camera is None:
                return None
            ev_cam = self.event_camera or self.config.event_camera.model()
            self.core = self._factory(self.config, self.rgb_camera, ev_cam if self.use_events else None)
            for b in self._imu_pending:
                self.core.add_imu(b)
            self._imu_pending.clear()
        return self.core

    def _run(self, pairs: list[tuple[RgbdFrame, EventBatch]]) -> list[RuntimeOutput]:
        out = []
        for frame, events in pairs:
            res = self._process(frame, events)
            if res is not None:
                out.append(res)
        return out

    def _process(self, frame: RgbdFrame, events: EventBatch) -> RuntimeOutput | None:
        core = self._ensure_core()
        if core is None:
            self._problem("frames_waiting_camera_info", "waiting for the colour camera_info; frame skipped")
            return None
        stamp = int(frame.stamp_ns)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            back_s = (self._last_stamp - stamp) * 1e-9
            if stamp == self._last_stamp:
                self._problem("frames_duplicate", f"frame at {stamp} ns repeats the previous stamp: skipped")
                return None
            if back_s < self.CLOCK_JUMP_S:
                self._problem("frames_out_of_order", f"frame at {stamp} ns is {back_s * 1e3:.1f} ms older than "
                              "the previous one: skipped")
                return None
            self._problem("clock_jumps", f"clock jumped back by {back_s:.3f} s at {stamp} ns (bag loop or "
                          "simulator restart?): motion model reset", "info")
            self._last_out = None
        if self.use_events and len(events):
            core.add_events(events)
        try:
            result = core.process_frame(frame)
        except AtsvoError as exc:
            self._problem("frames_failed", f"frame at {stamp} ns failed: {exc}", "error")
            return None
        self._last_stamp = stamp
        self.counters["frames"] += 1
        self.counters[f"status_{getattr(result.status, 'value', result.status)}"] += 1
        if result.events_dropped:
            self._problem("events_dropped", f"event flood: {result.events_dropped} events dropped before the frame "
                          f"at {stamp} ns (over fusion.max_event_rate_ev_s = "
                          f"{self.config.fusion.max_event_rate_ev_s:.3g})")
            self.counters["events_dropped"] += result.events_dropped - 1  # _problem counted one
        twist = None
        if self._last_out is not None and stamp > self._last_out[0]:
            twist = body_twist(self._last_out[1], result.T_odom_base, (stamp - self._last_out[0]) * 1e-9)
        self._last_out = (stamp, np.asarray(result.T_odom_base))
        return RuntimeOutput(result, twist, len(events))


def _msg_stamp(msg: Any) -> str:
    from atsvo_ros.io.images import stamp_ns

    try:
        return f"{stamp_ns(msg)} ns"
    except (AttributeError, TypeError, ValueError):
        return "an unknown stamp"


def _cdr_stamp_ns(raw: bytes | bytearray | memoryview) -> int | None:
    """header.stamp of a serialized ROS 2 message whose first field is a std_msgs/Header."""
    import struct

    if len(raw) < 12:
        return None
    order = "<" if bytes(raw[1:2]) == b"\x01" else ">"
    sec, nanosec = struct.unpack_from(order + "iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


__all__ = ["Logger", "OdometryCore", "OdometryRuntime", "RuntimeOutput"]
