"""Publish a recorded sequence over DDS at its own rate (or faster) and watch what the odometry nodes answer.

What the node tests and ``atsvo-bench nodes`` use in place of a camera driver and a controller:
:class:`BagPlayer` publishes a bag's messages as they were recorded (the serialized bytes, no
re-encoding) with sensor-data QoS, at ``rate`` times real time, and records when each frame's
images went out; :class:`OdometryProbe` subscribes to the odometry (reliable, like a controller),
the per-frame status, the map, the diagnostics and calls the reset service.
"""
from __future__ import annotations

import importlib
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from atsvo_ros.nodes._ros import LATCHED_QOS, OUTPUT_QOS, SENSOR_QOS


def message_class(msgtype: str) -> Any:
    """``pkg/msg/Name`` -> the rclpy class."""
    pkg, _, name = msgtype.partition("/msg/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


@dataclass
class Played:
    """What a :class:`BagPlayer` sent."""

    frame_stamps_ns: list[int] = field(default_factory=list)  # colour image stamps, in publishing order
    frame_sent_s: dict[int, float] = field(default_factory=dict)  # stamp -> monotonic time both images were out
    scheduled_s: dict[int, float] = field(default_factory=dict)  # stamp -> monotonic time it was due
    n_messages: int = 0
    lag_s: list[float] = field(default_factory=list)  # how late each message went out


class BagPlayer:
    """Publishes a ROS 2 bag's messages on their topics (see the module docstring)."""

    def __init__(self, node: Node, bag: str | Path, topics: Iterable[str], rgb_topic: str, depth_topic: str) -> None:
        from rosbags.highlevel import AnyReader

        from atsvo_ros.io.msgtypes import register_event_types

        self.node = node
        self.rgb_topic, self.depth_topic = rgb_topic, depth_topic
        wanted = set(topics)
        self.messages: list[tuple[int, str, bytes, int | None]] = []  # (log time, topic, cdr, header stamp)
        self.publishers: dict[str, Any] = {}
        with AnyReader([Path(bag)]) as reader:
            register_event_types(reader.typestore, 2)
            conns = [c for c in reader.connections if c.topic in wanted]
            for c in conns:
                if c.topic not in self.publishers:
                    self.publishers[c.topic] = node.create_publisher(message_class(c.msgtype), c.topic, SENSOR_QOS)
            for conn, t, raw in reader.messages(connections=conns):
                raw = bytes(raw)
                stamp = None
                if conn.topic in (rgb_topic, depth_topic):
                    sec, nsec = np.frombuffer(raw, "<i4", 1, 4)[0], np.frombuffer(raw, "<u4", 1, 8)[0]
                    stamp = int(sec) * 1_000_000_000 + int(nsec)
                self.messages.append((int(t), conn.topic, raw, stamp))

    @property
    def n_frames(self) -> int:
        return sum(1 for m in self.messages if m[1] == self.rgb_topic)

    def wait_for_subscribers(self, timeout_s: float = 20.0, topics: Iterable[str] | None = None) -> bool:
        """True once every publisher (or those of ``topics``) is matched by a subscriber."""
        pubs = [self.publishers[t] for t in (topics or self.publishers)]
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in pubs):
                return True
            time.sleep(0.05)
        return False

    def play(self, rate: float = 1.0, first: int = 0, last: int | None = None) -> Played:
        """Publish messages ``first:last`` at ``rate`` x their recorded timing; blocks until done."""
        msgs = self.messages[first:last]
        out = Played()
        if not msgs:
            return out
        t_bag0 = msgs[0][0]
        t0 = time.monotonic() + 0.05
        pending: dict[int, int] = {}
        for t, topic, raw, stamp in msgs:
            due = t0 + (t - t_bag0) * 1e-9 / rate
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            self.publishers[topic].publish(raw)
            now = time.monotonic()
            out.lag_s.append(now - due)
            out.n_messages += 1
            if stamp is not None:
                if topic == self.rgb_topic:
                    out.frame_stamps_ns.append(stamp)
                    out.scheduled_s[stamp] = t0 + (stamp - t_bag0) * 1e-9 / rate
                pending[stamp] = pending.get(stamp, 0) + 1
                if pending[stamp] == 2:
                    out.frame_sent_s[stamp] = now
        return out


class OdometryProbe:
    """Subscribes to what the odometry nodes publish, the way a controller and a dashboard would."""

    def __init__(self, node: Node, config: Any, debug_images: bool = False) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Image, PointCloud2

        topics = config.topics
        self.node = node
        self._lock = threading.Lock()
        self.odometry: list[tuple[float, Any]] = []  # (monotonic receipt time, msg)
        self.status: list[Any] = []
        self.maps: list[Any] = []
        self.diagnostics: dict[str, dict[str, str]] = {}  # status name -> latest values
        self.diagnostics_count = 0
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(Odometry, topics.odometry, self._on_odom, reliable)
        node.create_subscription(DiagnosticArray, topics.status, self._on_status, reliable)
        node.create_subscription(PointCloud2, topics.map, self._on_map, LATCHED_QOS)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, OUTPUT_QOS)
        self.debug: dict[str, list[Any]] = {"ats": [], "selection": []}
        if debug_images:
            for key, topic in (("ats", topics.debug_ats), ("selection", topics.debug_selection)):
                node.create_subscription(Image, topic, self.debug[key].append, SENSOR_QOS)
        from std_srvs.srv import Trigger

        self.reset_client = node.create_client(Trigger, topics.reset_service)

    def _on_odom(self, msg: Any) -> None:
        with self._lock:
            self.odometry.append((time.monotonic(), msg))

    def _on_status(self, msg: Any) -> None:
        with self._lock:
            self.status.append(msg)

    def _on_map(self, msg: Any) -> None:
        with self._lock:
            self.maps.append(msg)

    def _on_diag(self, msg: Any) -> None:
        with self._lock:
            self.diagnostics_count += 1
            for s in msg.status:
                self.diagnostics[s.name] = {kv.key: kv.value for kv in s.values} | {"_message": s.message,
                                                                                     "_level": int(s.level[0])}

    def diag(self, name_part: str) -> dict[str, str] | None:
        """The latest diagnostics values of the status whose name contains ``name_part``."""
        with self._lock:
            for name, values in self.diagnostics.items():
                if name_part in name:
                    return dict(values)
        return None

    def wait(self, predicate, timeout_s: float) -> bool:
        """Poll ``predicate()`` until it holds (True) or ``timeout_s`` passes (False)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(0.05)
        return predicate()

    def wait_idle(self, expected: int, idle_s: float = 3.0, timeout_s: float = 60.0) -> int:
        """Wait until ``expected`` odometry messages arrived or none came for ``idle_s``; how many came."""
        deadline = time.monotonic() + timeout_s
        last_n, last_change = -1, time.monotonic()
        while time.monotonic() < deadline:
            n = len(self.odometry)
            if n >= expected:
                return n
            if n != last_n:
                last_n, last_change = n, time.monotonic()
            elif time.monotonic() - last_change > idle_s:
                break
            time.sleep(0.05)
        return len(self.odometry)

    def poses(self, since: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (ns) and 4x4 ``T_odom_base`` of the odometry received (from index ``since``)."""
        from atsvo_ros.core.geometry import pose_from_tq

        with self._lock:
            msgs = [m for _, m in self.odometry[since:]]
        stamps = np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs], np.int64)
        T = np.stack([pose_from_tq(np.array([m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]),
                                   np.array([m.pose.pose.orientation.x, m.pose.pose.orientation.y,
                                             m.pose.pose.orientation.z, m.pose.pose.orientation.w]))
                      for m in msgs]) if msgs else np.zeros((0, 4, 4))
        return stamps, T

    def reset(self, timeout_s: float = 10.0) -> Any:
        """Call the reset service; the response (None when no answer)."""
        from std_srvs.srv import Trigger

        if not self.reset_client.wait_for_service(timeout_sec=timeout_s):
            return None
        future = self.reset_client.call_async(Trigger.Request())
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.02)
        return future.result() if future.done() else None


__all__ = ["BagPlayer", "OdometryProbe", "Played", "message_class"]
