"""OdometryRuntime: the one ROS-free driver of the odometry core (replay, benchmarks and the nodes).

Sensor data goes in as it arrives, in any interleaving: colour and depth images (arrays or
sensor_msgs messages), event batches (or event messages, decoded by :class:`~.ingest.EventIngest`
with the vectorised decoders), IMU samples and camera_info. The :class:`~atsvo_ros.io.sync.FrameAssembler`
pairs colour with depth and cuts the event stream at frame stamps; :class:`~.release.FrameRelease` cuts
the IMU stream at the same stamps (a frame waits until the IMU has passed it, unless the IMU is
``node.imu_max_wait_s`` behind in stamp time and, given an arrival ``clock`` (the node), has been silent
that long: a starved node's backlogs drain one message per topic per executor cycle, so images get
ahead of a stream that is only late), so the core sees, for every frame, exactly the samples up to its
exposure time whatever order they arrived in (the replay and the ROS node give the same poses).
:meth:`OdometryRuntime.poll` runs the core on every frame that became complete and returns one
:class:`RuntimeOutput` per frame; output sinks (e.g. ``atsvo-replay --record``) get each output right
after its frame, while the core still holds that frame's state.

The two halves can run in different threads (the ROS node): :meth:`~OdometryRuntime.pop_ready`
(cheap: pairing, event decoding and cutting) in the thread that receives the data, and
:meth:`~OdometryRuntime.process` (the core, this module's per-frame pipeline) in a worker, with a queue
of :class:`FrameInput` s in between. Frames that complete before the colour camera_info has arrived are
held (bounded, by :class:`~.release.FrameRelease`), not dropped: the first frame defines the odom origin.

Bad input never stops it: an undecodable image, a duplicated or out-of-order frame, a broken event
packet or a frame the core rejects is skipped, counted in :attr:`OdometryRuntime.counters` and
reported once per kind through the logger (then at most every ``log_interval_s``, with the count;
see :class:`~.problems.ProblemLog`).
A stamp that jumps back by more than a frame (``ros2 bag play --loop``, a simulator restart) is not
out of order but a clock jump: the frame goes to the core, which resets its motion model.

The interface types (:class:`FrameInput`, :class:`RuntimeOutput`, :class:`OdometryCore`, ``Sink``,
``Logger``) live in :mod:`.types`.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.odometry.odometry import Odometry
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.images import colour_from_msg
from atsvo_ros.io.images import stamp_ns as msg_stamp_ns
from atsvo_ros.io.imu import imu_from_msg
from atsvo_ros.io.ros_out import body_twist
from atsvo_ros.io.sync import FrameAssembler
from atsvo_ros.runtime.clock_check import ClockCheck, EventClock
from atsvo_ros.runtime.ingest import EventIngest, stamp_text
from atsvo_ros.runtime.offset_search import EventOffsetSearch
from atsvo_ros.runtime.problems import ProblemLog
from atsvo_ros.runtime.release import FrameRelease
from atsvo_ros.runtime.types import FrameInput, Logger, OdometryCore, RuntimeOutput, Sink


class OdometryRuntime:
    """Feeds the core from a sensor stream (see the module docstring)."""

    #: A stamp this far (or more) behind the last frame is a clock jump, not an out-of-order frame.
    CLOCK_JUMP_S = 1.0
    #: Frames held while the colour camera_info is missing (the oldest beyond are dropped, events kept).
    MAX_HELD_FRAMES = 30
    #: Event messages held while the event camera_info is missing; beyond this many (or 1 s of stream) the
    #: config's event camera is used instead.
    MAX_HELD_EVENT_MSGS = 2000
    #: IMU samples kept waiting for a frame (a stream without frames does not grow memory).
    IMU_KEEP_NS = 2_000_000_000
    #: Without an arrival clock (a replay), how far in stamp time the images may run ahead of the event
    #: stream before a frame goes without its events: event messages logged up to this late still count.
    REPLAY_EVENT_WAIT_S = 1.5

    def __init__(self, config: AtsvoConfig, rgb_camera: CameraModel | None = None,
                 event_camera: CameraModel | None = None, *, use_events: bool | None = None,
                 logger: Logger | None = None, core_factory: Callable[..., OdometryCore] | None = None,
                 log_interval_s: float = 10.0, sinks: Sequence[Sink] = (),
                 clock: Callable[[], int] | None = None, expect_imu: bool = False,
                 stall_wait_s: float | None = None) -> None:
        """``clock``: arrival time in ns (the node: ``time.monotonic_ns``); None (replay) judges stalls by stamps.
        ``expect_imu``: IMU messages will come (the first frames wait for the first of them, see FrameRelease).
        ``stall_wait_s``: how long the event and IMU streams may lag and be silent before a frame goes without
        them (the node's loss-free mode waits longer); None: 0.25 s for events (``REPLAY_EVENT_WAIT_S`` without
        a clock) and ``node.imu_max_wait_s`` for the IMU."""
        self.config = config
        #: called with every output, right after its frame (the core holds that frame's state: surface, map)
        self.sinks: tuple[Sink, ...] = tuple(sinks)
        self._factory = core_factory or Odometry
        self.use_events = config.mode == "fused" if use_events is None else bool(use_events)
        self._problems = ProblemLog(logger, log_interval_s)
        self.rgb_camera = rgb_camera if rgb_camera is not None else (
            None if config.rgb_camera.use_camera_info else CameraModel.from_config(config.rgb_camera))
        self._events = EventIngest(config, event_camera if event_camera is not None else (
            None if config.event_camera.use_camera_info else CameraModel.from_config(config.event_camera)),
            self.add_events, self._problems, max_held_msgs=self.MAX_HELD_EVENT_MSGS)
        # events waiting for their frame: at most what the core would fold in over the assembler's wait. A
        # replay (no arrival clock) has no deadline: it waits longer for event messages logged late
        wait_s = stall_wait_s if stall_wait_s is not None else 0.25 if clock is not None else self.REPLAY_EVENT_WAIT_S
        self.assembler = FrameAssembler(config.rig, with_events=self.use_events, max_event_wait_s=wait_s,
                                        max_pending=max(30, int(round(wait_s * 60))),  # frames of up to 60 Hz
                                        max_buffered_events=int(config.fusion.max_event_rate_ev_s * wait_s),
                                        clock=clock)
        self._release = FrameRelease(config, self.assembler, self._problems, clock=clock,
                                     clock_jump_s=self.CLOCK_JUMP_S, imu_keep_ns=self.IMU_KEEP_NS,
                                     max_held_frames=self.MAX_HELD_FRAMES, expect_imu=expect_imu,
                                     imu_wait_s=stall_wait_s)
        self._clocks = ClockCheck(self._problems)
        self._event_clock = EventClock(config.event_camera.time_offset_s, self._problems)
        self._offset_search = EventOffsetSearch(config.event_camera.time_offset_search_s if self.use_events else 0.0,
                                                self._problems)
        self._imu_offset_ns = int(round(config.rig.imu_time_offset_s * 1e9))
        self.core: OdometryCore | None = None
        self._last_out: tuple[int, np.ndarray] | None = None
        self._last_stamp: int | None = None

    @property
    def event_time_offset_s(self) -> float:
        """The offset added to event times: ``event_camera.time_offset_s``, plus the start-up estimate once taken."""
        return self._event_clock.offset_s

    @property
    def counters(self) -> Counter[str]:
        """Counts of frames, events, IMU samples, resets and of each kind of problem."""
        return self._problems.counters

    @property
    def first_problem(self) -> dict[str, str]:
        """The first message of each kind of problem (what :attr:`counters` counts), for summaries."""
        return self._problems.first_problem

    @property
    def event_camera(self) -> CameraModel | None:
        """The event camera model (None while waiting for the event camera_info)."""
        return self._events.camera

    @event_camera.setter
    def event_camera(self, camera: CameraModel | None) -> None:
        self._events.camera = camera

    # ------------------------------------------------------------------ inputs
    def on_rgb_camera_info(self, msg: Any) -> None:
        """Colour camera_info: used once, when ``rgb_camera.use_camera_info`` is set and no model was given."""
        if self.rgb_camera is None:
            self.rgb_camera = self._camera(msg, "colour")

    def on_event_camera_info(self, msg: Any) -> None:
        """Event camera_info: used once, when ``event_camera.use_camera_info`` is set and no model was given."""
        if self.event_camera is None:
            self._events.set_camera(self._camera(msg, "event"))

    def add_rgb(self, stamp_ns: int, image: np.ndarray) -> None:
        """A colour image (H, W, 3 RGB uint8, or grey) at its stamp."""
        self.assembler.add_rgb(int(stamp_ns), image)
        self._clocks.image(int(stamp_ns))
        if self._offset_search.active:
            delta_ns = self._offset_search.add_image(int(stamp_ns), image)
            if delta_ns is not None:
                self._event_clock.adjust(delta_ns)

    def add_depth(self, stamp_ns: int, depth_m: np.ndarray) -> None:
        """A depth image in float32 metres (0 / NaN = invalid) aligned to the colour image."""
        self.assembler.add_depth(int(stamp_ns), depth_m)

    def add_rgb_msg(self, msg: Any, topic: str = "colour") -> None:
        """sensor_msgs/Image or CompressedImage; an undecodable one is skipped and counted."""
        try:
            image = colour_from_msg(msg)
        except AtsvoError as exc:
            self._problems.report("images_rejected", f"{topic}: image at {stamp_text(msg)} skipped: {exc}")
            return
        self.add_rgb(msg_stamp_ns(msg), image)

    def add_depth_msg(self, msg: Any, topic: str = "depth") -> None:
        """Depth image message (16UC1 scaled by ``rig.depth_scale_m``, or 32FC1 metres); bad ones are counted."""
        try:
            self.assembler.add_depth_msg(msg)
        except AtsvoError as exc:
            self._problems.report("images_rejected", f"{topic}: depth image at {stamp_text(msg)} skipped: {exc}")

    def skip_input(self, kind: str, text: str) -> None:
        """An input the source could not read (a missing or corrupt file): counted and reported like a bad message."""
        self._problems.report(kind, text)

    def add_events(self, batch: EventBatch, complete_to_ns: int | None = None) -> None:
        """A decoded, time-ordered event batch; ``complete_to_ns``: its message's header stamp (the stream is
        known complete up to there). The times are put on the colour images' clock first (:class:`EventClock`)."""
        if self.use_events:
            self.counters["events"] += len(batch)
            batch, complete_to_ns = self._event_clock.place(batch, complete_to_ns)
            if len(batch):
                self._clocks.stream("events", batch.t_last_ns)
                self._offset_search.add_events(batch)
            self.assembler.add_events(batch, complete_to_ns=complete_to_ns)

    def add_event_msg(self, msg: Any, msgtype: str, topic: str = "events") -> None:
        """One event message, deserialized or as raw CDR bytes (an rclpy ``raw=True`` subscription)."""
        if self.use_events:
            self._events.add_msg(msg, msgtype, topic)

    def add_imu(self, batch: ImuBatch) -> None:
        """IMU samples (time order); each frame takes those up to its exposure time to predict its rotation.

        Samples at or before a frame that was already handed out are late: dropped and counted (unless
        the clock jumped back by more than :attr:`CLOCK_JUMP_S`: then the stream starts over). The stamps
        are moved by ``rig.imu_time_offset_s`` first.
        """
        if self._imu_offset_ns and len(batch):
            batch = ImuBatch(batch.stamps_ns + self._imu_offset_ns, batch.gyro_rad_s, batch.accel_m_s2)
        if len(batch):
            self._clocks.stream("imu", batch.t_last_ns)
        self._release.add_imu(batch)

    def add_imu_msg(self, msg: Any, topic: str = "imu") -> None:
        """sensor_msgs/Imu; a malformed one is skipped and counted."""
        try:
            self.add_imu(imu_from_msg(msg))
        except AtsvoError as exc:
            self._problems.report("imu_rejected", f"{topic}: IMU message skipped: {exc}")

    # ------------------------------------------------------------------ outputs
    def poll(self) -> list[RuntimeOutput]:
        """Run the core on every complete frame (oldest first); one output per processed frame."""
        return self._run(self.pop_ready())

    def flush(self) -> list[RuntimeOutput]:
        """End of stream: process every frame that can still be paired."""
        return self._run(self.flush_inputs())

    def pop_ready(self) -> list[FrameInput]:
        """The frames that became complete (oldest first), for :meth:`process` (possibly in another thread)."""
        return self._release.release(self.assembler.pop_ready(), final=False, hold=self.rgb_camera is None)

    def flush_inputs(self) -> list[FrameInput]:
        """End of stream: every frame that can still be paired, for :meth:`process`."""
        return self._release.release(self.assembler.flush(), final=True, hold=self.rgb_camera is None)

    def process(self, inp: FrameInput) -> RuntimeOutput | None:
        """Run the core on one frame (its IMU samples and events first); None when the frame is skipped.

        The output also goes to every sink (:attr:`sinks`) before it is returned.
        """
        core = self._ensure_core()
        if core is None:
            self._problems.report("frames_waiting_camera_info", "waiting for the colour camera_info; frame skipped")
            return None
        if len(inp.imu):
            core.add_imu(inp.imu)
        out = self._process(core, inp.frame, inp.events)
        if out is not None:
            for sink in self.sinks:
                sink(out, core)
        return out

    def reset(self) -> None:
        """Start over: the next frame builds a new core (new map, pose back to the identity).

        Call it from the thread that calls :meth:`process`.
        """
        close = getattr(self.core, "close", None)
        if close is not None:
            close()
        self.core = None
        self._last_out = None
        self._last_stamp = None
        self.counters["resets"] += 1

    @property
    def decoder_stats(self) -> dict[str, Any]:
        """Event decoder statistics per topic (only for messages decoded here)."""
        return self._events.decoder_stats

    @property
    def pending(self) -> int:
        """Images and pairs held back by the assembler (bounded)."""
        return self.assembler.pending

    @property
    def frames_waiting(self) -> int:
        """Paired frames not handed out yet: waiting for events, IMU samples or the camera_info (bounded)."""
        return self.assembler.n_pairs + self._release.n_waiting

    # ------------------------------------------------------------------ internals
    def _camera(self, msg: Any, which: str) -> CameraModel | None:
        try:
            return CameraModel.from_camera_info(msg)
        except AtsvoError as exc:
            self._problems.report("bad_camera_info", f"{which} camera_info unusable: {exc}", "error")
            return None

    def _ensure_core(self) -> OdometryCore | None:
        if self.core is None:
            if self.rgb_camera is None:
                return None
            ev_cam = self.event_camera or CameraModel.from_config(self.config.event_camera)
            self.core = self._factory(self.config, self.rgb_camera, ev_cam if self.use_events else None)
        return self.core

    def _run(self, inputs: list[FrameInput]) -> list[RuntimeOutput]:
        out = []
        for inp in inputs:
            res = self.process(inp)
            if res is not None:
                out.append(res)
        return out

    def _process(self, core: OdometryCore, frame: RgbdFrame, events: EventBatch) -> RuntimeOutput | None:
        stamp = int(frame.stamp_ns)
        if self._last_stamp is not None and stamp <= self._last_stamp:
            back_s = (self._last_stamp - stamp) * 1e-9
            if stamp == self._last_stamp:
                self._problems.report("frames_duplicate", f"frame at {stamp} ns repeats the previous stamp: skipped")
                return None
            if back_s < self.CLOCK_JUMP_S:
                self._problems.report("frames_out_of_order", f"frame at {stamp} ns is {back_s * 1e3:.1f} ms older "
                                      "than the previous one: skipped")
                return None
            self._problems.report("clock_jumps", f"clock jumped back by {back_s:.3f} s at {stamp} ns (bag loop or "
                                  "simulator restart?): motion model reset", "info")
            self._last_out = None
        if self.use_events and len(events):
            core.add_events(events)
        try:
            result = core.process_frame(frame)
        except AtsvoError as exc:
            self._problems.report("frames_failed", f"frame at {stamp} ns failed: {exc}", "error")
            return None
        self._last_stamp = stamp
        self.counters["frames"] += 1
        self.counters[f"status_{getattr(result.status, 'value', result.status)}"] += 1
        if result.events_dropped:
            self._problems.report("events_dropped", f"event flood: {result.events_dropped} events dropped before the "
                                  f"frame at {stamp} ns (over fusion.max_event_rate_ev_s = "
                                  f"{self.config.fusion.max_event_rate_ev_s:.3g})", count=result.events_dropped)
        twist = None
        if self._last_out is not None and stamp > self._last_out[0]:
            twist = body_twist(self._last_out[1], result.T_odom_base, (stamp - self._last_out[0]) * 1e-9)
        self._last_out = (stamp, np.asarray(result.T_odom_base))
        return RuntimeOutput(result, twist, len(events))


__all__ = ["OdometryRuntime"]
