"""ROS 2 tracking node: colour + aligned depth + camera_info + events (+ IMU) in, odometry, status and TF out.

The callbacks only ingest (image conversion, event decoding, pairing by the package's own
:class:`~atsvo_ros.runtime.runtime.OdometryRuntime`, which also cuts the event and IMU streams at frame
stamps) and put each complete frame into a bounded drop-oldest queue; a worker thread runs the
odometry and publishes. Mapping runs either in this process (``atsvo_node``: a mapping thread, the
snapshot shared in memory) or in ``mapping_node`` (keyframe requests and snapshots over topics, in the
wire format of :mod:`atsvo_ros.io.wire`). ``mapping.synchronous`` makes tracking wait for each keyframe,
as ``atsvo-replay`` does.

    ros2 run atsvo_ros tracking_node --ros-args --params-file config/mini_cheetah.yaml   # + mapping_node
"""
from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    Transform,
    TransformStamped,
    Twist,
    TwistWithCovariance,
    Vector3,
)
from nav_msgs.msg import Odometry as OdometryMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, Imu
from std_msgs.msg import Header, UInt8MultiArray
from std_srvs.srv import Trigger

from atsvo_ros.core.events.debug_images import render_debug_images
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.ports import ThreadedMapping
from atsvo_ros.core.odometry.odometry import Odometry
from atsvo_ros.errors import WireError
from atsvo_ros.io.ros_out import DEBUG_IMAGE_FRAME, MsgClasses, odometry_msg, transform_msg
from atsvo_ros.io.wire import uint8_multiarray_cdr, uint8_multiarray_payload
from atsvo_ros.nodes._params import declare_config
from atsvo_ros.nodes._ros import (
    ERROR,
    IMAGE_QOS,
    LATCHED_QOS,
    OK,
    OUTPUT_QOS,
    REQUEST_QOS,
    SENSOR_QOS,
    STREAM_QOS,
    TF_QOS,
    WARN,
    RateMeter,
    Window,
    diagnostic_array,
    event_message_class,
    input_qos,
    run_nodes,
    set_cpu_priority,
    stamp_msg,
    uint8_array,
)
from atsvo_ros.runtime.core_process import CoreHost
from atsvo_ros.runtime.frame_queue import DropOldestQueue, Worker
from atsvo_ros.runtime.kernel_watch import LateKernels
from atsvo_ros.runtime.mapping_remote import RemoteMapping, mapping_digest
from atsvo_ros.runtime.runtime import OdometryRuntime
from atsvo_ros.runtime.types import FrameInput, RuntimeOutput
from atsvo_ros.runtime.warmup import warm_up

_CLASSES = MsgClasses(Time, Header, OdometryMsg, PoseWithCovariance, Pose, Point, Quaternion, TwistWithCovariance,
                      Twist, Vector3, TransformStamped, Transform)

#: status -> diagnostic level of the per-frame status message (see the README)
#: Loss-free mode's queue: 10 s of frames at 30 Hz (2 MB each at 640x480) before the oldest would be dropped.
LOSS_FREE_QUEUE = 300
#: Loss-free mode: seconds a silent event or IMU stream (or all inputs, for the end of stream) is waited for
#: before frames go without it. A reliable stream that pauses is late, not lost: with node.imu_max_wait_s
#: (0.25 s) a loaded CI run sent one frame mid-stream without its events.
LOSS_FREE_WAIT_S = 1.5
STATUS_LEVEL = {"ok": OK, "initialising": WARN, "degraded": WARN, "relocalised": WARN, "reinitialised": WARN,
                "lost": ERROR}


class TrackingNode(Node):
    """Tracking (see the module docstring).

    ``mapping="topics"`` talks to a ``mapping_node`` over topics; ``mapping="memory"`` runs the mapper in a
    thread of this process and calls ``on_snapshot`` (from that thread) with every new snapshot.
    """

    def __init__(self, *, mapping: str = "topics", on_snapshot: Callable[[MapSnapshot], None] | None = None,
                 name: str = "atsvo_tracking") -> None:
        super().__init__(name)
        self.config = cfg = declare_config(self)
        topics, nc = cfg.topics, cfg.node
        log = self.get_logger()
        # before any thread of ours starts (warm-up, worker, mapping, the core's child process inherit it)
        set_cpu_priority(self, nc)
        self.fatal_error: BaseException | None = None
        self._mapping_mode = mapping
        self._on_snapshot = on_snapshot
        self._port: RemoteMapping | None = None

        # ---- events: the message package may be missing (pip route without the built messages)
        self.event_class = None
        use_events = cfg.mode == "fused"
        if use_events:
            self.event_class, why = event_message_class(nc.event_msg_type)
            if self.event_class is None:
                log.warn(f"events off: {why}; running RGB-D only")
                use_events = False

        # ---- warm-up before subscribing: no real frame pays for compiling (or loading) the numba kernels
        warm = warm_up(cfg, use_events=use_events)
        log.info(f"warm-up: the odometry ran {len(warm.statuses)} synthetic frames in {warm.seconds:.2f} s "
                 f"({'/'.join(sorted(set(warm.modes)))}); ready, subscribing")

        def make_core(config, rgb_camera, event_camera=None):
            return Odometry(config, rgb_camera, event_camera, mapping=self._make_mapping_port)

        # ---- node.core_process: the core in a child process of its own (atsvo_node's in-memory mapping only)
        self._core_host: CoreHost | None = None
        if nc.core_process and mapping != "memory":
            log.warn("node.core_process applies to atsvo_node (mapping in memory); tracking_node keeps the core here")
        elif nc.core_process:
            self._core_host = CoreHost(cfg, use_events, on_snapshot=on_snapshot)
            log.info(f"odometry core in process {self._core_host.pid} (warmed up in {self._core_host.warm_up_s:.2f} s)")

        # loss-free mode (reliable inputs, synchronous mapping: every frame must count, as in the replay): the queue
        # holds a backlog of LOSS_FREE_QUEUE frames instead of node.queue_size. It cannot block: the default
        # executor is single-threaded, and a blocked sensor callback would starve the map snapshots it waits for.
        # A stream that pauses (a loaded player, a stalled executor) is waited for LOSS_FREE_WAIT_S, not given up.
        self.loss_free = nc.sensor_qos == "reliable" and cfg.mapping.synchronous
        stall_wait_s = max(nc.imu_max_wait_s, LOSS_FREE_WAIT_S) if self.loss_free else None
        # arrival clock: a stream is stalled when silent, not merely behind (backlogs drain unevenly)
        factory = make_core if self._core_host is None else self._core_host.new_core  # the child builds the Odometry
        self.runtime = OdometryRuntime(cfg, use_events=use_events, logger=self._runtime_log, core_factory=factory,
                                       clock=time.monotonic_ns, expect_imu=nc.use_imu, stall_wait_s=stall_wait_s)
        self.queue: DropOldestQueue[FrameInput] = DropOldestQueue(
            max(nc.queue_size, LOSS_FREE_QUEUE) if self.loss_free else nc.queue_size,
            merge=lambda old, new: new.after(old))
        self.worker: Worker[FrameInput] = Worker(self.queue, self._process, "atsvo-tracking", self._worker_failed)

        # ---- outputs
        self.odom_pub = self.create_publisher(OdometryMsg, topics.odometry, OUTPUT_QOS)
        self.status_pub = self.create_publisher(DiagnosticArray, topics.status, OUTPUT_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", OUTPUT_QOS)
        self.debug_ats_pub = self.create_publisher(Image, topics.debug_ats, SENSOR_QOS)
        self.debug_sel_pub = self.create_publisher(Image, topics.debug_selection, SENSOR_QOS)
        self._tf_send, self.tf_route = self._tf_publisher() if nc.publish_tf else (None, "off (node.publish_tf)")

        # ---- inputs: one callback at a time (pairing state), never blocked by the worker
        sensors = MutuallyExclusiveCallbackGroup()
        image_qos, stream_qos = input_qos(nc.sensor_qos, IMAGE_QOS), input_qos(nc.sensor_qos, STREAM_QOS)
        self._control_group = MutuallyExclusiveCallbackGroup()
        self.create_subscription(Image, topics.rgb, self._on_rgb, image_qos, callback_group=sensors)
        self.create_subscription(Image, topics.depth, self._on_depth, image_qos, callback_group=sensors)
        self.create_subscription(CameraInfo, topics.rgb_info, self._on_rgb_info, SENSOR_QOS, callback_group=sensors)
        if use_events:
            self.create_subscription(CameraInfo, topics.event_info, self._on_event_info, SENSOR_QOS,
                                     callback_group=sensors)
            # raw=True: the callback gets the CDR bytes, decoded with numpy (no Python object per event)
            self.create_subscription(self.event_class, topics.events, self._on_events,
                                     stream_qos, raw=True,
                                     callback_group=sensors)
        if nc.use_imu:
            self.create_subscription(Imu, topics.imu, self._on_imu, stream_qos, callback_group=sensors)
        self.create_service(Trigger, topics.reset_service, self._on_reset, callback_group=self._control_group)
        # ---- end of stream: once every input has been silent for node.imu_max_wait_s, on two ticks in a row
        # (a stalled executor runs the callbacks it owes between them), the frames still waiting go out
        self._heard_ns = time.monotonic_ns()
        self._silent_ticks = 0
        end_wait_s = nc.imu_max_wait_s if stall_wait_s is None else stall_wait_s
        self._end_wait_ns = int(end_wait_s * 1e9)
        self.create_timer(max(0.05, nc.imu_max_wait_s / 2), self._on_silence_tick, callback_group=sensors)

        # ---- mapping over topics
        self.request_pub = None
        if mapping == "topics":
            self.request_pub = self.create_publisher(UInt8MultiArray, topics.keyframe_requests, REQUEST_QOS)
            self.create_subscription(UInt8MultiArray, topics.map_snapshots, self._on_snapshot_msg, LATCHED_QOS,
                                     raw=True, callback_group=MutuallyExclusiveCallbackGroup())
        elif mapping != "memory":
            raise ValueError(f"mapping must be 'topics' or 'memory', got {mapping!r}")

        # ---- statistics for /diagnostics
        self.rates = RateMeter()
        self.tracking_ms, self.latency_ms, self.stamp_latency_ms = Window(), Window(), Window()
        self.worker_ms = Window()  # per frame: odometry + keyframe request + publishing (what bounds the rate)
        # the worker thread's own CPU time for the same span: what is left of worker_ms went waiting for a core
        # or for the GIL (held by the executor's callbacks and the mapping thread)
        self.worker_cpu_ms = Window()
        self.frames_in = self.frames_out = self.bad_snapshots = 0
        self.rgb_received = self.depth_received = 0  # messages taken from DDS (what a transport loss lowers)
        self._drops_reported = 0
        self.last: RuntimeOutput | None = None
        self.create_timer(nc.diagnostics_period_s, self._publish_diagnostics, callback_group=self._control_group)
        # from here on no kernel should compile (in core_process mode they live in the child, warmed there)
        self.late_kernels = LateKernels() if self._core_host is None else None
        self.worker.start()
        log.info(f"tracking: mode {cfg.mode if use_events or cfg.mode == 'rgbd' else 'rgbd (no event messages)'}, "
                 f"mapping {'in this process' if mapping == 'memory' else 'in mapping_node (topics)'}"
                 f"{', synchronous' if cfg.mapping.synchronous else ''}; in: {topics.rgb}, {topics.depth}"
                 f"{', ' + topics.events + ' (' + nc.event_msg_type + ')' if use_events else ''}"
                 f"{', ' + topics.imu if nc.use_imu else ''}; out: {topics.odometry}, {topics.status}, "
                 f"TF {self.tf_route}; queue {self.queue.maxsize} "
                 f"({'loss-free: nothing dropped' if self.loss_free else 'drop oldest'}); sensor QoS {nc.sensor_qos}")

    # ------------------------------------------------------------------ setup helpers
    def _tf_publisher(self) -> tuple[Callable[[Any], None] | None, str]:
        try:
            from tf2_ros import TransformBroadcaster
        except ImportError:
            pass
        else:
            br = TransformBroadcaster(self)
            return br.sendTransform, "odom -> base_link via tf2_ros"
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self.get_logger().warn("no TF: neither tf2_ros nor tf2_msgs is installed; odometry messages only")
            return None, "off (no tf2_ros / tf2_msgs)"
        self.get_logger().info("tf2_ros is not installed: odom -> base_link goes to /tf with a plain tf2_msgs "
                               "publisher")
        pub = self.create_publisher(TFMessage, "/tf", TF_QOS)
        return (lambda t: pub.publish(TFMessage(transforms=[t]))), "odom -> base_link on /tf (tf2_msgs publisher)"

    def _make_mapping_port(self, mapper: Any) -> Any:
        cfg = self.config
        if self._mapping_mode == "memory":
            return ThreadedMapping(mapper, synchronous=cfg.mapping.synchronous, on_snapshot=self._on_snapshot)
        self._port = RemoteMapping(mapper, self._send_request, self._mapping_connected,
                                   synchronous=cfg.mapping.synchronous, timeout_s=cfg.node.mapping_timeout_s,
                                   config_digest=mapping_digest(cfg), logger=self._runtime_log)
        return self._port

    def _runtime_log(self, level: str, text: str) -> None:
        getattr(self.get_logger(), "warn" if level == "warn" else level)(text)

    # ------------------------------------------------------------------ ingest (executor thread)
    def _on_rgb_info(self, msg: CameraInfo) -> None:
        self.runtime.on_rgb_camera_info(msg)
        self._pump()

    def _on_event_info(self, msg: CameraInfo) -> None:
        self.runtime.on_event_camera_info(msg)
        self._pump()

    def _on_rgb(self, msg: Image) -> None:
        self.rates.add("rgb")
        self.rgb_received += 1
        self.runtime.add_rgb_msg(msg, self.config.topics.rgb)
        self._pump()

    def _on_depth(self, msg: Image) -> None:
        self.rates.add("depth")
        self.depth_received += 1
        self.runtime.add_depth_msg(msg, self.config.topics.depth)
        self._pump()

    def _on_events(self, raw: bytes) -> None:
        self.rates.add("event_msgs")
        before = self.runtime.counters["events"]
        self.runtime.add_event_msg(raw, self.config.node.event_msg_type, self.config.topics.events)
        self.rates.add("events", self.runtime.counters["events"] - before)
        self._pump()

    def _on_imu(self, msg: Imu) -> None:
        self.rates.add("imu")
        self.runtime.add_imu_msg(msg, self.config.topics.imu)
        self._pump()

    def _pump(self) -> None:
        self._heard_ns = time.monotonic_ns()
        self._silent_ticks = 0
        self._enqueue(self.runtime.pop_ready())

    def _enqueue(self, inputs: list[FrameInput]) -> None:
        for inp in inputs:
            self.frames_in += 1
            self.queue.put(inp)

    def _on_silence_tick(self) -> None:
        """End of stream: no input for node.imu_max_wait_s (loss-free: LOSS_FREE_WAIT_S), seen on two ticks.

        The last frame of a stream waits for events and IMU samples past its stamp that never come; the
        replay releases it at the end of the bag, the node once the silence has lasted this long.
        """
        rt = self.runtime
        if (rt.frames_waiting == 0 and rt.pending == 0) or time.monotonic_ns() - self._heard_ns <= self._end_wait_ns:
            self._silent_ticks = 0
            return
        self._silent_ticks += 1
        if self._silent_ticks >= 2:
            self._silent_ticks = 0
            self._enqueue(rt.flush_inputs())

    # ------------------------------------------------------------------ mapping over topics
    def _send_request(self, blob: bytes) -> None:
        self.request_pub.publish(uint8_multiarray_cdr(blob))

    def _mapping_connected(self) -> bool:
        return (self.request_pub is not None and self.request_pub.get_subscription_count() > 0
                and self.count_publishers(self.config.topics.map_snapshots) > 0)

    def _on_snapshot_msg(self, raw: bytes) -> None:
        port = self._port
        if port is None:
            return
        try:
            port.on_message(uint8_multiarray_payload(raw))
        except WireError as exc:
            self.bad_snapshots += 1
            self.get_logger().error(f"{self.config.topics.map_snapshots}: snapshot skipped: {exc}",
                                    throttle_duration_sec=10.0)

    # ------------------------------------------------------------------ worker thread
    def _process(self, inp: FrameInput) -> None:
        start, start_cpu = time.monotonic(), time.thread_time()
        out = self.runtime.process(inp)
        if out is None:
            return
        self._publish(out)
        done = time.monotonic()
        self.worker_ms.add((done - start) * 1e3)
        self.worker_cpu_ms.add((time.thread_time() - start_cpu) * 1e3)
        self.frames_out += 1
        self.last = out
        self.rates.add("odometry")
        self.tracking_ms.add(out.result.tracking_time_s * 1e3)
        self.latency_ms.add((done - inp.ready_s) * 1e3)
        self.stamp_latency_ms.add((self.get_clock().now().nanoseconds - out.result.stamp_ns) * 1e-6)
        if self.debug_ats_pub.get_subscription_count() or self.debug_sel_pub.get_subscription_count():
            self._publish_debug(out.result.stamp_ns)

    def _publish(self, out: RuntimeOutput) -> None:
        r, topics = out.result, self.config.topics
        self.odom_pub.publish(odometry_msg(_CLASSES, r.stamp_ns, r.T_odom_base, r.covariance, out.twist,
                                           topics.odom_frame, topics.base_frame))
        status = getattr(r.status, "value", str(r.status))
        values = {"mode": r.mode, "reason": r.reason or "", "tracking_time_ms": r.tracking_time_s * 1e3,
                  "map_points": r.n_points, "inliers": r.n_inliers, "keyframe": r.keyframe_inserted,
                  **{f"inliers_{k}": v for k, v in r.inliers.items()}}
        self.status_pub.publish(diagnostic_array(self, [("atsvo: odometry status", STATUS_LEVEL.get(status, WARN),
                                                         status, values)], stamp=stamp_msg(r.stamp_ns)))
        if self._tf_send is not None:
            self._tf_send(transform_msg(_CLASSES, r.stamp_ns, r.T_odom_base, topics.odom_frame, topics.base_frame))

    def _publish_debug(self, stamp_ns: int) -> None:
        events = getattr(self.runtime.core, "events", None)
        if events is None:
            return
        images = render_debug_images(events, stamp_ns, selection=self.debug_sel_pub.get_subscription_count() > 0)
        grey, rgb = images.ats, images.selection
        header = Header(stamp=stamp_msg(stamp_ns), frame_id=DEBUG_IMAGE_FRAME)
        h, w = grey.shape
        if self.debug_ats_pub.get_subscription_count():
            self.debug_ats_pub.publish(Image(header=header, height=h, width=w, encoding="mono8", step=w,
                                             data=uint8_array(grey)))
        if rgb is not None:
            self.debug_sel_pub.publish(Image(header=header, height=h, width=w, encoding="rgb8", step=3 * w,
                                             data=uint8_array(rgb)))

    def _worker_failed(self, exc: BaseException) -> None:
        self.get_logger().fatal("tracking worker failed (a bug): "
                                + "".join(traceback.format_exception(exc)).rstrip())
        self.fatal_error = exc

    # ------------------------------------------------------------------ services and diagnostics
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        # The worker resets between two frames; the callback does not wait (inputs keep flowing meanwhile).
        self.worker.call(self.runtime.reset)
        response.success = self.worker.alive
        response.message = ("odometry reset: the next frame starts a new map at the identity pose"
                            if response.success else "reset impossible: the tracking worker has stopped")
        self.get_logger().info(response.message)
        return response

    def diagnostics_values(self) -> dict[str, Any]:
        """What /diagnostics reports (also used by tests and the benchmark)."""
        rt = self.runtime
        rates = self.rates.rates()
        dec = rt.decoder_stats
        sync = rt.assembler.stats
        last = self.last
        port = self._port
        if self._mapping_mode == "memory":
            mapping = "in process"
        elif port is None:
            mapping = "connected" if self._mapping_connected() else "waiting for mapping_node"
        else:
            mapping = "connected" if self._mapping_connected() else "mapping_node not found"
        values: dict[str, Any] = {
            "mode": last.result.mode if last else "-", "status": last.result.status.value if last else "-",
            "reason": (last.result.reason or "") if last else "",
            "tracking_time_ms_p50": self.tracking_ms.percentile(50), "tracking_time_ms_max":
                self.tracking_ms.percentile(100),
            "worker_ms_p50": self.worker_ms.percentile(50), "worker_ms_mean": self.worker_ms.mean(),
            "worker_cpu_ms_mean": self.worker_cpu_ms.mean(),
            "core": "in process" if self._core_host is None else
                    f"child process {self._core_host.pid}{'' if self._core_host.alive else ' (dead)'}",
            "latency_ms_p50": self.latency_ms.percentile(50), "latency_ms_p99": self.latency_ms.percentile(99),
            "stamp_to_odometry_ms_p50": self.stamp_latency_ms.percentile(50),
            "rgb_received": self.rgb_received, "depth_received": self.depth_received,
            "frames_in": self.frames_in, "frames_out": self.frames_out, "frames_waiting": rt.frames_waiting,
            "queue_drops": self.queue.n_dropped,
            "queue_length": len(self.queue), "queue_size": self.queue.maxsize,
            "queue_mode": "loss-free" if self.loss_free else "drop oldest",
            "decoder_drops": sum(s["dropped_messages"] + s["dropped_out_of_range"] + s["dropped_backwards"]
                                 for s in dec.values()),
            "sync_dropped_rgb": sync.dropped_rgb, "sync_dropped_depth": sync.dropped_depth,
            "missing_rgb": sync.missing_rgb, "missing_depth": sync.missing_depth,
            "frames_without_events": sync.released_without_events, "late_events": sync.late_events,
            "event_time_offset_s": rt.event_time_offset_s,
            "bad_snapshots": self.bad_snapshots,
            "late_kernels": self.late_kernels.count if self.late_kernels is not None else 0,
            "keyframes": getattr(rt.core, "n_keyframes", 0) if rt.core is not None else 0,
            "mapping": mapping, "tf": self.tf_route, "worker": "running" if self.worker.alive else "stopped",
            **{f"rate_{k}_hz": v for k, v in rates.items()},
            **{f"count_{k}": v for k, v in sorted(rt.counters.items())},
        }
        if port is not None:
            values.update({f"mapping_{k}": v for k, v in port.stats.items()})
            if port.last_round_trip_s is not None:
                values["mapping_round_trip_ms"] = port.last_round_trip_s * 1e3
        return values

    def _publish_diagnostics(self) -> None:
        late = self.late_kernels.new() if self.late_kernels is not None else []
        if late:  # a path the warm-up missed: the frame that took it stalled while numba compiled
            self.get_logger().warn(f"numba compiled {len(late)} kernel(s) after the warm-up (a frame stalled for it): "
                                   f"{', '.join(late)}")
        v = self.diagnostics_values()
        status = v["status"]
        level = OK
        drops = v["queue_drops"] + v["missing_rgb"] + v["missing_depth"]
        new_drops, self._drops_reported = drops - self._drops_reported, drops
        if status in ("-", "initialising", "degraded", "relocalised", "reinitialised") or new_drops > 0:
            level = WARN
        if status == "lost" or not self.worker.alive or v["mapping"] == "mapping_node not found":
            level = ERROR
        message = status if status != "-" else "waiting for frames"
        if v["reason"]:
            message += f": {v['reason']}"
        clocks = [self.runtime.first_problem[k] for k in ("clock_events", "clock_imu")
                  if k in self.runtime.first_problem]
        if clocks:  # a stream on another clock: no frame gets it until the offset is set
            level = ERROR
            message += "; " + "; ".join(clocks)
        self.diag_pub.publish(diagnostic_array(self, [(f"{self.get_name()}: odometry", level, message, v)]))

    def close(self) -> None:
        """Stop the worker (the frame in progress finishes) and the mapping thread."""
        self.worker.stop()
        if self._port is not None:
            self._port.close()
        close = getattr(self.runtime.core, "close", None)
        if close is not None:
            close()
        if self._core_host is not None:
            self._core_host.close()


def main(args: list[str] | None = None) -> int:
    """``ros2 run atsvo_ros tracking_node`` (with ``mapping_node``; ``atsvo_node`` runs both in one process)."""
    return run_nodes("tracking_node", lambda: [TrackingNode(mapping="topics")], args,
                     what="The tracking half of the PTAM split (run mapping_node beside it); publishes the odometry.")


if __name__ == "__main__":
    raise SystemExit(main())
