"""Read and shift the time of serialized ROS 2 messages without deserializing them.

:func:`cdr_stamp_ns` reads the header stamp (the runtime's arrival bookkeeping, the node player).
Shifting is what a player needs to loop a recording with time running on (a long soak test from a short bag):
the header stamp of any message whose first field is a ``std_msgs/Header`` (images, camera_info,
IMU), and for ``event_camera_msgs/EventPacket`` also its ``time_base``, which every encoding but
evt3 counts its event times from. Byte patches on the CDR, so a 1 MB image costs one copy.
"""
from __future__ import annotations

import struct

from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode.layout import align

_NS = 1_000_000_000
_STAMP_OFFSET = 4  # after the 4-byte CDR encapsulation header


def _order(raw: bytes | bytearray | memoryview) -> str:
    """struct byte order of a CDR buffer from its encapsulation header (0x0001 little, 0x0000 big endian)."""
    return "<" if bytes(raw[1:2]) == b"\x01" else ">"


def cdr_stamp_ns(raw: bytes | bytearray | memoryview) -> int | None:
    """header.stamp (ns) of a serialized ROS 2 message whose first field is a std_msgs/Header; None if too short."""
    if len(raw) < 12:
        return None
    sec, nanosec = struct.unpack_from(_order(raw) + "iI", raw, _STAMP_OFFSET)
    return int(sec) * _NS + int(nanosec)


def _shift_stamp(buf: bytearray, shift_ns: int) -> str:
    """Move the header stamp in ``buf``; the buffer's byte order."""
    order = _order(buf)
    sec, nsec = struct.unpack_from(order + "iI", buf, _STAMP_OFFSET)
    ns = int(sec) * _NS + int(nsec) + int(shift_ns)
    if ns < 0:
        raise DecodeError(f"shifting a header stamp by {shift_ns} ns makes it negative")
    struct.pack_into(order + "iI", buf, _STAMP_OFFSET, ns // _NS, ns % _NS)
    return order


def restamp_header(raw: bytes, shift_ns: int) -> bytes:
    """``raw`` (CDR, a Header first) with its header stamp moved by ``shift_ns``."""
    if len(raw) < 12:
        raise DecodeError(f"{len(raw)} bytes: too short for a CDR message with a header")
    buf = bytearray(raw)
    _shift_stamp(buf, shift_ns)
    return bytes(buf)


def _time_base_offset(buf: bytearray, order: str) -> int:
    """Byte offset of EventPacket.time_base: header (stamp, frame_id), height, width, seq, time_base."""
    (n_fid,) = struct.unpack_from(order + "I", buf, 12)
    body = 12 + n_fid  # CDR body offset (alignment counts from after the encapsulation header)
    body = align(body, 4) + 8  # height, width (uint32)
    body = align(body, 8) + 8  # seq (uint64)
    return 4 + body


def restamp_event_packet(raw: bytes, shift_ns: int, encoding: str) -> bytes:
    """A CDR ``EventPacket`` with its stamp and event times moved by ``shift_ns``.

    Raises :class:`DecodeError` for evt3, whose payload carries the sensor clock itself.
    """
    if encoding == "evt3":
        raise DecodeError("evt3 event times are in the payload (sensor clock): they cannot be shifted by a "
                          "byte patch; re-encode the events instead")
    if len(raw) < 16:
        raise DecodeError(f"{len(raw)} bytes: too short for an EventPacket")
    buf = bytearray(raw)
    order = _shift_stamp(buf, shift_ns)
    off = _time_base_offset(buf, order)
    if off + 8 > len(buf):
        raise DecodeError(f"{len(raw)} bytes: too short for an EventPacket (time_base at byte {off})")
    (tb,) = struct.unpack_from(order + "Q", buf, off)
    struct.pack_into(order + "Q", buf, off, tb + int(shift_ns))
    return bytes(buf)


__all__ = ["cdr_stamp_ns", "restamp_event_packet", "restamp_header"]
