"""OdometryRuntime: the one ROS-free driver of the odometry core (replay, benchmarks and the nodes).

Sensor data goes in as it arrives, in any interleaving: colour and depth images (arrays or
sensor_msgs messages), event batches (or event messages, decoded here with the vectorised
decoders), IMU samples and camera_info. The :class:`~atsvo_ros.io.sync.FrameAssembler` pairs colour
with depth and cuts the event stream at frame stamps; the IMU stream is cut at the same stamps (a
frame waits until the IMU has passed it, unless the IMU is ``node.imu_max_wait_s`` behind in stamp
time and, given an arrival ``clock`` (the node), has been silent that long: a starved node's backlogs
drain one message per topic per executor cycle, so images get ahead of a stream that is only late),
so the core sees, for every frame, exactly the samples up to its exposure time whatever order they
arrived in (the replay and the ROS node give the same poses). :meth:`OdometryRuntime.poll` runs the
core on every frame that became complete and returns one :class:`RuntimeOutput` per frame; output
sinks (e.g. ``atsvo-replay --record``) get each output right after its frame, while the core still
holds that frame's state.

The two halves can run in different threads (the ROS node): :meth:`~OdometryRuntime.pop_ready`
(cheap: pairing, event decoding and cutting) in the thread that receives the data, and
:meth:`~OdometryRuntime.process` (the core) in a worker, with a queue of :class:`FrameInput` s in
between. Frames that complete before the colour camera_info has arrived are held (bounded), not
dropped: the first frame defines the odom origin.

Bad input never stops it: an undecodable image, a duplicated or out-of-order frame, a broken event
packet or a frame the core rejects is skipped, counted in :attr:`OdometryRuntime.counters` and
reported once per kind through the logger (then at most every ``log_interval_s``, with the count).
A stamp that jumps back by more than a frame (``ros2 bag play --loop``, a simulator restart) is not
out of order but a clock jump: the frame goes to the core, which resets its motion model.
"""
from __future__ import annotations

import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events import EventBatch
from atsvo_ros.core.frame import OdometryResult, RgbdFrame
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.restamp import cdr_stamp_ns
from atsvo_ros.io.ros_out import body_twist
from atsvo_ros.io.sync import FrameAssembler

Logger = Callable[[str, str], None]  # (level: "info" | "warn" | "error", text)


class OdometryCore(Protocol):
    """What the runtime needs from the core (:class:`atsvo_ros.core.odometry.Odometry`, or a test double)."""

    def process_frame(self, frame: RgbdFrame) -> OdometryResult: ...

    def add_events(self, batch: EventBatch) -> None: ...

    def add_imu(self, batch: ImuBatch) -> None: ...


@dataclass(frozen=True)
class FrameInput:
    """One frame ready for the core: the colour/depth pair and the events and IMU samples since the previous one.

    ``ready_s`` is ``time.monotonic()`` when the frame became complete (queue age and latency).
    """

    frame: RgbdFrame
    events: EventBatch
    imu: ImuBatch
    ready_s: float

    @property
    def stamp_ns(self) -> int:
        return int(self.frame.stamp_ns)

    def after(self, dropped: FrameInput) -> FrameInput:
        """This frame, also carrying the events and IMU samples of an earlier frame that is dropped.

        The time surface and the gyro need every event and sample in order; only images may be skipped.
        """
        events = EventBatch.concatenate([dropped.events, self.events]) if len(dropped.events) else self.events
        imu = ImuBatch.concatenate([dropped.imu, self.imu]) if len(dropped.imu) else self.imu
        return FrameInput(self.frame, events, imu, self.ready_s)


@dataclass(frozen=True)
class RuntimeOutput:
    """One processed frame: the core's result, the base twist since the previous output, the events it got."""

    result: OdometryResult
    twist: np.ndarray | None
    n_events: int


#: An output sink (e.g. the bag recorder of ``atsvo-replay --record``): ``sink(output, core)`` after each frame.
Sink = Callable[[RuntimeOutput, OdometryCore], None]


def _no_log(level: str, text: str) -> None:
    del level, text


def _default_core() -> Callable[..., OdometryCore]:
    from atsvo_ros.core.odometry import Odometry

    return Odometry


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

    def __init__(self, config: AtsvoConfig, rgb_camera: CameraModel | None = None,
                 event_camera: CameraModel | None = None, *, use_events: bool | None = None,
                 logger: Logger | None = None, core_factory: Callable[..., OdometryCore] | None = None,
                 log_interval_s: float = 10.0, sinks: Sequence[Sink] = (),
                 clock: Callable[[], int] | None = None) -> None:
        """``clock``: arrival time in ns (the node: ``time.monotonic_ns``); None (replay) judges stalls by stamps."""
        self.config = config
        self._clock = clock
        #: called with every output, right after its frame (the core holds that frame's state: surface, map)
        self.sinks: tuple[Sink, ...] = tuple(sinks)
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
                                        max_buffered_events=int(config.fusion.max_event_rate_ev_s * wait_s),
                                        clock=clock)
        self.core: OdometryCore | None = None
        self._decoders: dict[str, Any] = {}
        self._imu: list[ImuBatch] = []  # samples after the last frame's cut
        self._imu_cut_ns: int | None = None
        self._imu_mark_ns: int | None = None  # newest IMU stamp received
        self._imu_heard_ns: int | None = None  # arrival time (``clock``) of the last IMU samples
        self._await_imu: deque[tuple[RgbdFrame, EventBatch]] = deque()  # paired frames waiting for the IMU
        self._offset_ns = int(round(config.rgb_camera.time_offset_s * 1e9))
        self._imu_wait_ns = int(round(config.node.imu_max_wait_s * 1e9))  # then the IMU counts as silent
        self._held: deque[FrameInput] = deque()  # frames waiting for the colour camera_info
        self._held_events: deque[tuple[Any, str, str]] = deque()  # event messages waiting for the event camera
        self._last_out: tuple[int, np.ndarray] | None = None
        self._last_stamp: int | None = None
        self._log_interval_s = float(log_interval_s)
        self._last_logged: dict[str, float] = {}
        self._logged_count: Counter[str] = Counter()
        self._report_lock = threading.Lock()  # problems are reported from the ingest and the worker thread

    # ------------------------------------------------------------------ reporting
    def _problem(self, kind: str, text: str, level: str = "warn", count: int = 1) -> None:
        """Count a problem; log the first of each kind, then at most every ``log_interval_s`` with the count."""
        with self._report_lock:
            self.counters[kind] += count
            self.first_problem.setdefault(kind, text)
            now = time.monotonic()
            last = self._last_logged.get(kind)
            if last is None or now - last >= self._log_interval_s:
                extra = self.counters[kind] - self._logged_count[kind] - count
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
            if self.event_camera is not None:
                self._decode_held_events()

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
        if self.event_camera is None and self.config.event_camera.use_camera_info:
            # The decoder needs the sensor size: hold the stream until the camera_info (bounded).
            self._held_events.append((msg, msgtype, topic))
            first = self._held_events[0][0]
            span_ns = (_any_stamp_ns(msg) or 0) - (_any_stamp_ns(first) or 0)
            if len(self._held_events) < self.MAX_HELD_EVENT_MSGS and span_ns < 1_000_000_000:
                return
            self._problem("event_camera_info_missing", f"{topic}: no event camera_info after "
                          f"{len(self._held_events)} event messages: using event_camera from the configuration")
            self.event_camera = self.config.event_camera.model()
            self._decode_held_events()
            return
        self._decode_event_msg(msg, msgtype, topic)

    def _decode_held_events(self) -> None:
        while self._held_events:
            self._decode_event_msg(*self._held_events.popleft())

    def _decode_event_msg(self, msg: Any, msgtype: str, topic: str) -> None:
        from atsvo_ros.io.decode import EventDecoder
        from atsvo_ros.io.images import stamp_ns

        dec = self._decoders.get(topic)
        if dec is None:
            cam = self.event_camera or self.config.event_camera.model()
            dec = self._decoders[topic] = EventDecoder(msgtype, 2, cam.width, cam.height)
        self.counters["event_msgs"] += 1
        if isinstance(msg, (bytes, bytearray, memoryview)):
            batch = dec.decode_raw(msg)
            mark = cdr_stamp_ns(msg)
        else:
            batch = dec.decode_message(msg)
            try:
                mark = stamp_ns(msg)
            except (AttributeError, TypeError):
                mark = None
        self.add_events(batch, complete_to_ns=mark)

    def add_imu(self, batch: ImuBatch) -> None:
        """IMU samples (time order); each frame takes those up to its exposure time to predict its rotation.

        Samples at or before a frame that was already handed out are late: dropped and counted (unless
        the clock jumped back by more than :attr:`CLOCK_JUMP_S`: then the stream starts over).
        """
        if len(batch) == 0:
            return
        if self._clock is not None:
            self._imu_heard_ns = self._clock()  # alive, even when its samples turn out late
        self.counters["imu_samples"] += len(batch)
        cut = self._imu_cut_ns
        if cut is not None and batch.t_first_ns <= cut:
            if batch.t_last_ns < cut - int(self.CLOCK_JUMP_S * 1e9):
                self._imu.clear()  # clock jump (bag loop): the samples belong to the new timeline
                self._imu_cut_ns = self._imu_mark_ns = None
            else:
                late = batch.stamps_ns <= cut
                n_late = int(np.count_nonzero(late))
                self._problem("imu_late", f"{n_late} IMU sample(s) arrived after the frame at {cut} ns they belong "
                              "to had been released: dropped", count=n_late)
                batch = batch.select(~late)
                if len(batch) == 0:
                    return
        self._imu.append(batch)
        newest = batch.t_last_ns
        self._imu_mark_ns = newest if self._imu_mark_ns is None else max(self._imu_mark_ns, newest)
        while len(self._imu) > 1 and self._imu[0].t_last_ns < newest - self.IMU_KEEP_NS:
            self._imu.pop(0)

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
        return self._run(self.pop_ready())

    def flush(self) -> list[RuntimeOutput]:
        """End of stream: process every frame that can still be paired."""
        return self._run(self.flush_inputs())

    def pop_ready(self) -> list[FrameInput]:
        """The frames that became complete (oldest first), for :meth:`process` (possibly in another thread)."""
        self._await_imu.extend(self.assembler.pop_ready())
        return self._release(self._imu_ready(final=False))

    def flush_inputs(self) -> list[FrameInput]:
        """End of stream: every frame that can still be paired, for :meth:`process`."""
        self._await_imu.extend(self.assembler.flush())
        return self._release(self._imu_ready(final=True))

    def process(self, inp: FrameInput) -> RuntimeOutput | None:
        """Run the core on one frame (its IMU samples and events first); None when the frame is skipped.

        The output also goes to every sink (:attr:`sinks`) before it is returned.
        """
        core = self._ensure_core()
        if core is None:
            self._problem("frames_waiting_camera_info", "waiting for the colour camera_info; frame skipped")
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
        return {t: d.stats.as_dict() for t, d in self._decoders.items()}

    @property
    def pending(self) -> int:
        """Images and pairs held back by the assembler (bounded)."""
        return self.assembler.pending

    @property
    def frames_waiting(self) -> int:
        """Paired frames not handed out yet: waiting for events, IMU samples or the camera_info (bounded)."""
        return self.assembler.n_pairs + len(self._await_imu) + len(self._held)

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
        return self.core

    def _imu_ready(self, final: bool) -> list[tuple[RgbdFrame, EventBatch]]:
        """Paired frames whose IMU samples are all in: the IMU passed the frame, is silent, or never spoke."""
        out = []
        mark = self._imu_mark_ns
        newest = self.assembler.newest_ns
        silent = self._clock is None or self._imu_heard_ns is None or \
            self._clock() - self._imu_heard_ns > self._imu_wait_ns
        stalled = mark is None or (newest is not None and newest - mark > self._imu_wait_ns and silent) or \
            len(self._await_imu) > self.assembler.max_pending
        while self._await_imu:
            behind = mark is None or mark < int(self._await_imu[0][0].stamp_ns) + self._offset_ns
            if behind and not (final or stalled):
                break
            if behind and mark is not None and not final:
                self.counters["frames_without_imu"] += 1  # released before the IMU passed it
            out.append(self._await_imu.popleft())
        return out

    def _cut_imu(self, stamp_ns: int) -> ImuBatch:
        """The buffered IMU samples up to a frame's exposure time (its stamp plus the colour time offset)."""
        cut = int(stamp_ns) + self._offset_ns
        self._imu_cut_ns = cut if self._imu_cut_ns is None else max(self._imu_cut_ns, cut)
        if not self._imu:
            return ImuBatch.empty()
        buf = ImuBatch.concatenate(self._imu) if len(self._imu) > 1 else self._imu[0]
        k = int(np.searchsorted(buf.stamps_ns, cut, side="right"))
        rest = buf.select(slice(k, None))
        self._imu = [rest] if len(rest) else []
        return buf.select(slice(0, k))

    def _release(self, pairs: list[tuple[RgbdFrame, EventBatch]]) -> list[FrameInput]:
        now = time.monotonic()
        inputs = [FrameInput(frame, events, self._cut_imu(frame.stamp_ns), now) for frame, events in pairs]
        if self.rgb_camera is None:
            for inp in inputs:
                self._problem("frames_waiting_camera_info", "waiting for the colour camera_info: frames held")
                self._held.append(inp)
                if len(self._held) > self.MAX_HELD_FRAMES:
                    oldest = self._held.popleft()
                    self._held[0] = self._held[0].after(oldest)
                    self.counters["frames_dropped_waiting_camera_info"] += 1
            return []
        if self._held:
            inputs = [*self._held, *inputs]
            self._held.clear()
        return inputs

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
                          f"{self.config.fusion.max_event_rate_ev_s:.3g})", count=result.events_dropped)
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


def _any_stamp_ns(msg: Any) -> int | None:
    """header.stamp of a message object or of its serialized bytes (None when there is none)."""
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return cdr_stamp_ns(msg)
    from atsvo_ros.io.images import stamp_ns

    try:
        return stamp_ns(msg)
    except (AttributeError, TypeError, ValueError):
        return None


__all__ = ["FrameInput", "Logger", "OdometryCore", "OdometryRuntime", "RuntimeOutput", "Sink"]
