"""TrackingPipeline: the tracking node's logic without ROS (messages in, odometry out).

The ROS node only wires topics to these methods and publishes what they return, so everything
here is tested with rosbags' message classes. It reuses the replay's building blocks: the
:class:`~atsvo_ros.io.sync.FrameAssembler` (events cut at frame stamps), the stateful
:class:`~atsvo_ros.io.decode.EventDecoder` and the core :class:`~atsvo_ros.core.odometry.Odometry`.
Failures are logged, counted in :attr:`TrackingPipeline.counters` and survived.
"""
from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.ros_out import body_twist

Logger = Callable[[str, str], None]


@dataclass(frozen=True)
class PipelineOutput:
    """One published estimate: the core's result plus the base twist from the previous estimate."""

    result: Any  # atsvo_ros.core.odometry.OdometryResult
    twist: np.ndarray | None


def _cdr_stamp_ns(raw: bytes | bytearray | memoryview) -> int | None:
    """header.stamp of a serialized ROS 2 message whose first field is a std_msgs/Header."""
    if len(raw) < 12:
        return None
    order = "<" if bytes(raw[1:2]) == b"\x01" else ">"
    sec, nanosec = struct.unpack_from(order + "iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


def _no_log(level: str, text: str) -> None:
    del level, text


class TrackingPipeline:
    """Feed camera_info, RGB/depth pairs and event messages; get :class:`PipelineOutput` per frame."""

    def __init__(self, config: AtsvoConfig, logger: Logger | None = None,
                 odometry_factory: Callable[..., Any] | None = None) -> None:
        from atsvo_ros.core.odometry import Odometry
        from atsvo_ros.io.sync import FrameAssembler

        self.config = config
        self._log = logger or _no_log
        self._factory = odometry_factory or Odometry
        self.use_events = config.mode == "fused" and bool(getattr(self._factory, "supports_events", False))
        self.counters: Counter[str] = Counter()
        self.rgb_camera: CameraModel | None = (None if config.rgb_camera.use_camera_info
                                               else config.rgb_camera.model())
        self.event_camera: CameraModel | None = (None if config.event_camera.use_camera_info
                                                 else config.event_camera.model())
        self.assembler = FrameAssembler(config.rig, with_events=self.use_events)
        self._decoder: Any = None
        self._odometry: Any = None
        self._last: tuple[int, np.ndarray] | None = None
        if config.mode == "fused" and not self.use_events:
            self._log("warn", "mode fused requested but the odometry core does not fuse events yet: RGB-D only")

    # ------------------------------------------------------------------ inputs
    def on_rgb_camera_info(self, msg: Any) -> None:
        """Colour camera_info: used once, when ``rgb_camera.use_camera_info`` is set."""
        if self.rgb_camera is None:
            self.rgb_camera = self._camera(msg, "colour")

    def on_event_camera_info(self, msg: Any) -> None:
        """Event camera_info: used once, when ``event_camera.use_camera_info`` is set."""
        if self.event_camera is None:
            self.event_camera = self._camera(msg, "event")

    def on_events(self, msg: Any, msgtype: str) -> None:
        """One event message (EventPacket or dvs/dv EventArray), decoded into the frame assembler.

        ``msg`` is a deserialized message or its serialized CDR bytes (what an rclpy subscription
        with ``raw=True`` delivers): the bytes path never builds one Python object per event.
        """
        if not self.use_events:
            return
        from atsvo_ros.io.decode import EventDecoder
        from atsvo_ros.io.images import stamp_ns

        if self._decoder is None:
            cam = self.event_camera or self.config.event_camera.model()
            self._decoder = EventDecoder(msgtype, 2, cam.width, cam.height)
        if isinstance(msg, (bytes, bytearray, memoryview)):
            batch = self._decoder.decode_raw(msg)
            # CDR: 4-byte encapsulation header, then header.stamp (int32 sec, uint32 nanosec).
            mark = _cdr_stamp_ns(msg)
        else:
            batch = self._decoder.decode_message(msg)
            try:
                mark = stamp_ns(msg)
            except (AttributeError, TypeError):
                mark = None
        self.counters["event_msgs"] += 1
        self.counters["events"] += len(batch)
        self.assembler.add_events(batch, complete_to_ns=mark)

    def on_rgbd(self, rgb_msg: Any, depth_msg: Any) -> PipelineOutput | None:
        """A synchronised colour + depth pair; returns the estimate of the newest completed frame."""
        try:
            self.assembler.add_rgb_msg(rgb_msg)
            self.assembler.add_depth_msg(depth_msg)
        except AtsvoError as exc:
            self.counters["frames_rejected"] += 1
            self._log("error", f"frame rejected: {exc}")
            return None
        out = None
        for frame, events in self.assembler.pop_ready():
            out = self._process(frame, events) or out
        return out

    @property
    def decoder_stats(self) -> dict[str, Any]:
        return self._decoder.stats.as_dict() if self._decoder is not None else {}

    # ------------------------------------------------------------------ internals
    def _camera(self, msg: Any, which: str) -> CameraModel | None:
        try:
            return CameraModel.from_camera_info(msg)
        except AtsvoError as exc:
            self.counters["bad_camera_info"] += 1
            self._log("error", f"{which} camera_info unusable: {exc}")
            return None

    def _process(self, frame: Any, events: Any) -> PipelineOutput | None:
        if self.rgb_camera is None:
            self.counters["frames_waiting_camera_info"] += 1
            self._log("warn", "waiting for the colour camera_info")
            return None
        if self._odometry is None:
            ev_cam = self.event_camera or self.config.event_camera.model()
            self._odometry = self._factory(self.config, self.rgb_camera, ev_cam if self.use_events else None)
        if self.use_events and len(events):
            self._odometry.add_events(events)
        try:
            result = self._odometry.process_frame(frame)
        except AtsvoError as exc:
            self.counters["frames_failed"] += 1
            self._log("error", f"frame {frame.stamp_ns} failed: {exc}")
            return None
        self.counters["frames"] += 1
        self.counters[f"status_{getattr(result.status, 'value', result.status)}"] += 1
        twist = None
        if self._last is not None:
            twist = body_twist(self._last[1], result.T_odom_base, (result.stamp_ns - self._last[0]) * 1e-9)
        self._last = (int(result.stamp_ns), np.asarray(result.T_odom_base))
        return PipelineOutput(result, twist)
