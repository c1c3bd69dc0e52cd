"""The event message packages built by .ci/build_ros_msgs.sh travel over DDS between two processes."""
from __future__ import annotations

import subprocess
import sys
import time
import uuid

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (pip install -e '.[ros]')")
_BUILD_HINT = "not importable: run `eval \"$(bash .ci/build_ros_msgs.sh)\"` (or source .ci/ros_env.sh)"
event_camera_msgs = pytest.importorskip("event_camera_msgs.msg", reason=f"event_camera_msgs {_BUILD_HINT}")
dvs_msgs = pytest.importorskip("dvs_msgs.msg", reason=f"dvs_msgs {_BUILD_HINT}")

from builtin_interfaces.msg import Time  # noqa: E402  (after the skips: needs rclpy's wheels)
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

# Latched (transient-local, reliable): the subscriber gets the sample whenever it matches, no race.
QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
PAYLOAD = bytes((i * 37 + 11) % 256 for i in range(40_000))

PUBLISHER = """
import sys
import rclpy
from builtin_interfaces.msg import Time
from dvs_msgs.msg import Event, EventArray
from event_camera_msgs.msg import EventPacket
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

topic, payload_len = sys.argv[1], int(sys.argv[2])
payload = bytes((i * 37 + 11) % 256 for i in range(payload_len))
qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
rclpy.init()
node = rclpy.create_node("event_msgs_publisher")
packet = EventPacket(height=480, width=640, seq=42, time_base=123456789012, encoding="evt3",
                     is_bigendian=False, events=payload)
packet.header.frame_id = "dvxplorer"
packet.header.stamp = Time(sec=1700000000, nanosec=5)
events = [Event(x=i % 640, y=i % 480, ts=Time(sec=1700000000, nanosec=1000 * i), polarity=bool(i % 2))
          for i in range(1000)]
array = EventArray(height=480, width=640, events=events)
array.header.frame_id = "davis"
node.create_publisher(EventPacket, topic + "/packet", qos).publish(packet)
node.create_publisher(EventArray, topic + "/array", qos).publish(array)
print("published", flush=True)
sys.stdin.read()  # stay alive (holding the latched samples) until the test closes stdin
node.destroy_node()
rclpy.try_shutdown()
"""


def test_event_packet_and_event_array_cross_processes():
    topic = f"/atsvo_test_{uuid.uuid4().hex[:8]}"
    context = Context()
    rclpy.init(context=context)
    publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER, topic, str(len(PAYLOAD))],
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        node = rclpy.create_node("event_msgs_subscriber", context=context)
        got: dict[str, object] = {}
        node.create_subscription(event_camera_msgs.EventPacket, topic + "/packet",
                                 lambda m: got.setdefault("packet", m), QOS)
        node.create_subscription(dvs_msgs.EventArray, topic + "/array", lambda m: got.setdefault("array", m), QOS)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 30.0
        while len(got) < 2 and time.monotonic() < deadline and publisher.poll() is None:
            executor.spin_once(timeout_sec=0.1)
        assert publisher.poll() is None, "publisher process died"
        assert set(got) == {"packet", "array"}, f"received only {sorted(got)} within 30 s"

        packet = got["packet"]
        assert (packet.height, packet.width, packet.seq, packet.time_base) == (480, 640, 42, 123456789012)
        assert (packet.encoding, packet.is_bigendian, packet.header.frame_id) == ("evt3", False, "dvxplorer")
        assert packet.header.stamp == Time(sec=1700000000, nanosec=5)
        assert bytes(packet.events) == PAYLOAD

        array = got["array"]
        assert (array.height, array.width, array.header.frame_id, len(array.events)) == (480, 640, "davis", 1000)
        ev = array.events[999]
        assert (ev.x, ev.y, ev.polarity, ev.ts.sec, ev.ts.nanosec) == (999 % 640, 999 % 480, True, 1700000000, 999000)
        executor.shutdown()
        node.destroy_node()
    finally:
        publisher.communicate(input="", timeout=30)
        rclpy.try_shutdown(context=context)
