"""event_camera_msgs/EventPacket: the fields around the payload, parsed from the serialized bytes."""
from __future__ import annotations

import array
import struct
from dataclasses import dataclass

import numpy as np

from atsvo_ros.io.decode.dvs import _need, parse_cdr_header, parse_ros1_header
from atsvo_ros.io.decode.layout import align


@dataclass
class PacketFields:
    """Everything of an EventPacket except the decoded events; ``events`` is a zero-copy view."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    seq: int
    time_base: int
    encoding: str
    is_bigendian: bool
    events: np.ndarray


def parse_packet_raw(rawdata: bytes | memoryview, ros_version: int) -> PacketFields:
    """Parse a serialized EventPacket (ROS 1 or CDR) without copying the payload."""
    buf = memoryview(rawdata).cast("B")
    if ros_version == 1:
        stamp, frame_id, pos = parse_ros1_header(buf)
        _need(buf, pos + 28, "packet fields")
        height, width, seq, time_base, n = struct.unpack_from("<IIQQI", buf, pos)
        pos += 28
        _need(buf, pos + n + 5, "encoding")
        encoding = bytes(buf[pos:pos + n]).decode(errors="replace")
        pos += n
        big = bool(buf[pos])
        (size,) = struct.unpack_from("<I", buf, pos + 1)
        pos += 5
        _need(buf, pos + size, f"{size} payload bytes")
        return PacketFields(stamp, frame_id, height, width, seq, time_base, encoding, big,
                            np.frombuffer(buf, np.uint8, count=size, offset=pos))
    e, stamp, frame_id, pos = parse_cdr_header(buf)
    pos = align(pos, 4)
    _need(buf, 4 + pos + 8, "height/width")
    height, width = struct.unpack_from(f"{e}II", buf, 4 + pos)
    pos = align(pos + 8, 8)
    _need(buf, 4 + pos + 20, "seq/time_base/encoding")
    seq, time_base, n = struct.unpack_from(f"{e}QQI", buf, 4 + pos)
    pos += 20
    _need(buf, 4 + pos + n + 1, "encoding")
    encoding = bytes(buf[4 + pos:4 + pos + n]).rstrip(b"\x00").decode(errors="replace")
    pos += n
    big = bool(buf[4 + pos])
    pos = align(pos + 1, 4)
    _need(buf, 4 + pos + 4, "payload length")
    (size,) = struct.unpack_from(f"{e}I", buf, 4 + pos)
    pos += 4
    _need(buf, 4 + pos + size, f"{size} payload bytes")
    return PacketFields(stamp, frame_id, height, width, seq, time_base, encoding, big,
                        np.frombuffer(buf, np.uint8, count=size, offset=4 + pos))


def packet_fields_from_message(msg) -> PacketFields:
    """Duck-typed EventPacket (rosbags or rclpy object) -> :class:`PacketFields`."""
    st = msg.header.stamp
    ev = msg.events
    if isinstance(ev, np.ndarray):
        events = ev.view(np.uint8).reshape(-1)
    elif isinstance(ev, (bytes, bytearray, memoryview, array.array)):  # rclpy gives array('B') or bytes
        events = np.frombuffer(ev, np.uint8)
    else:
        events = np.frombuffer(bytes(ev), np.uint8)
    return PacketFields(st.sec * 1_000_000_000 + st.nanosec, msg.header.frame_id, int(msg.height), int(msg.width),
                        int(msg.seq), int(msg.time_base), str(msg.encoding), bool(msg.is_bigendian), events)
