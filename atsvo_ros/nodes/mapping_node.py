"""ROS 2 mapping node: keyframe requests in, map snapshots back to tracking, the map as PointCloud2 for RViz.

The PTAM split over topics: ``tracking_node`` publishes a keyframe request (std_msgs/UInt8MultiArray
in the wire format of :mod:`atsvo_ros.io.wire`) whenever the nine-region rule asks for one and keeps
tracking against its last snapshot; this node inserts the keyframe (one mapper per tracking session,
:class:`~atsvo_ros.runtime.mapping_remote.MappingServer`) and publishes the new snapshot back (reliable,
transient local) and the map points in the odom frame as sensor_msgs/PointCloud2 (``topics.map``,
latched). In ``atsvo_node`` the same node runs without the topics: the mapper is a thread of the
tracking node and hands the snapshots over in memory (:meth:`MappingNode.publish_snapshot`).

    ros2 run atsvo_ros mapping_node --ros-args --params-file config/mini_cheetah.yaml
"""
from __future__ import annotations

import threading
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header, UInt8MultiArray

from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.errors import WireError
from atsvo_ros.io.ros_out import MAP_CLOUD_FIELDS, MAP_CLOUD_POINT_STEP, map_cloud_from_snapshot
from atsvo_ros.io.wire import uint8_multiarray_cdr, uint8_multiarray_payload
from atsvo_ros.nodes._params import declare_config
from atsvo_ros.nodes._ros import (
    LATCHED_QOS,
    OK,
    OUTPUT_QOS,
    REQUEST_QOS,
    WARN,
    Window,
    diagnostic_array,
    run_nodes,
    set_cpu_priority,
    uint8_array,
)
from atsvo_ros.runtime.mapping_remote import MappingServer
from atsvo_ros.runtime.warmup import warm_up


class MappingNode(Node):
    """Mapping (see the module docstring); ``serve=False`` only publishes snapshots handed over in memory."""

    def __init__(self, *, serve: bool = True, name: str = "atsvo_mapping") -> None:
        super().__init__(name)
        self.config = cfg = declare_config(self)
        topics = cfg.topics
        if serve:  # in atsvo_node the tracking node set it for the whole process
            set_cpu_priority(self, cfg.node)
        self._T_odom_world = cfg.rig.T_base_rgb_matrix()  # odom = base at the first frame, world = its camera
        self.map_pub = self.create_publisher(PointCloud2, topics.map, LATCHED_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", OUTPUT_QOS)
        self._lock = threading.Lock()
        self.n_snapshots = self.n_bad_requests = 0
        self.last_snapshot: MapSnapshot | None = None
        self.insert_ms = Window()
        self.server: MappingServer | None = None
        if serve:  # in atsvo_node the tracking node's warm-up ran the mapper already
            warm = warm_up(cfg, use_events=cfg.mode == "fused")
            self.get_logger().info(f"warm-up: mapping's kernels ready in {warm.seconds:.2f} s")
            self.server = MappingServer(cfg, logger=self._log)
            self.snapshot_pub = self.create_publisher(UInt8MultiArray, topics.map_snapshots, LATCHED_QOS)
            self.create_subscription(UInt8MultiArray, topics.keyframe_requests, self._on_request, REQUEST_QOS,
                                     raw=True)
        self.create_timer(cfg.node.diagnostics_period_s, self._publish_diagnostics)
        source = f"keyframe requests on {topics.keyframe_requests}" if serve else "in memory"
        self.get_logger().info(f"mapping: {source}; map (PointCloud2, frame {topics.odom_frame}) on {topics.map}")

    def _log(self, level: str, text: str) -> None:
        getattr(self.get_logger(), "warn" if level == "warn" else level)(text)

    def _on_request(self, raw: bytes) -> None:
        try:
            served = self.server.handle(uint8_multiarray_payload(raw))
        except WireError as exc:
            self.n_bad_requests += 1
            self.get_logger().error(f"{self.config.topics.keyframe_requests}: request skipped: {exc}",
                                    throttle_duration_sec=10.0)
            return
        self.snapshot_pub.publish(uint8_multiarray_cdr(served.answer))
        self.insert_ms.add(served.insert_time_s * 1e3)
        self.publish_snapshot(served.snapshot)

    def publish_snapshot(self, snapshot: MapSnapshot) -> None:
        """Publish a snapshot's points as the map (any thread: also the in-process mapping thread)."""
        with self._lock:
            self.n_snapshots += 1
            self.last_snapshot = snapshot
        data = map_cloud_from_snapshot(snapshot, self._T_odom_world)
        msg = PointCloud2(header=Header(stamp=self.get_clock().now().to_msg(), frame_id=self.config.topics.odom_frame),
                          height=1, width=len(data), is_bigendian=False, point_step=MAP_CLOUD_POINT_STEP,
                          row_step=MAP_CLOUD_POINT_STEP * len(data), is_dense=True,
                          fields=[PointField(name=n, offset=o, datatype=d, count=c) for n, o, d, c in MAP_CLOUD_FIELDS])
        msg.data = uint8_array(data)
        self.map_pub.publish(msg)

    def diagnostics_values(self) -> dict[str, Any]:
        snap = self.last_snapshot
        values: dict[str, Any] = {"snapshots": self.n_snapshots, "map_points": len(snap) if snap else 0,
                                  "geometric_points": len(snap.geo_points_w) if snap else 0,
                                  "keyframes_in_map": len(snap.keyframes) if snap else 0}
        if self.server is not None:
            values.update({"requests": self.server.n_requests, "bad_requests": self.n_bad_requests,
                           "tracking_sessions": self.server.n_sessions,
                           "keyframes_inserted": self.server.mapper.n_keyframes if self.server.mapper else 0,
                           "insert_ms_p50": self.insert_ms.percentile(50),
                           "insert_ms_max": self.insert_ms.percentile(100)})
        return values

    def _publish_diagnostics(self) -> None:
        v = self.diagnostics_values()
        level = OK if v["snapshots"] else WARN
        self.diag_pub.publish(diagnostic_array(self, [(f"{self.get_name()}: mapping", level,
                                                       f"{v['map_points']} map points" if v["snapshots"]
                                                       else "no map yet", v)]))


def main(args: list[str] | None = None) -> int:
    """``ros2 run atsvo_ros mapping_node`` (serves ``tracking_node``)."""
    return run_nodes("mapping_node", lambda: [MappingNode(serve=True)], args,
                     what="The mapping half of the PTAM split: keyframes and the event map for tracking_node.")


if __name__ == "__main__":
    raise SystemExit(main())
