"""dvs_msgs / dv_ros_msgs / dv_ros2_msgs EventArray decoding, straight from the serialized bytes.

``Header header, uint32 height, uint32 width, Event[] events`` with ``Event = uint16 x, uint16 y,
time ts, bool polarity``. The event array is read as a numpy structured view (ROS 1: packed 13
bytes; CDR: see :mod:`.layout`), so no Python object is created per event.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode._kernels import _dvs_fields
from atsvo_ros.io.decode.layout import ROS1_DVS_EVENT, align, dvs_cdr_layout


@dataclass
class DvsArray:
    """Decoded fields of a dvs EventArray."""

    stamp_ns: int
    frame_id: str
    width: int
    height: int
    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray


def _need(buf: memoryview, end: int, what: str) -> None:
    if end > len(buf):
        raise DecodeError(f"truncated message: {what} needs {end} bytes, buffer has {len(buf)}", "truncated")


def parse_ros1_header(buf: memoryview, pos: int = 0) -> tuple[int, str, int]:
    """std_msgs/Header in ROS 1: (stamp_ns, frame_id, offset after it)."""
    _need(buf, pos + 16, "header")
    _, sec, nsec, n = struct.unpack_from("<IIII", buf, pos)
    pos += 16
    _need(buf, pos + n, "header.frame_id")
    return sec * 1_000_000_000 + nsec, bytes(buf[pos:pos + n]).decode(errors="replace"), pos + n


def parse_cdr_header(buf: memoryview) -> tuple[str, int, str, int]:
    """CDR encapsulation + std_msgs/Header: (byte order char, stamp_ns, frame_id, offset after it).

    Offsets returned are relative to the CDR payload (buffer offset minus 4), as alignment is.
    """
    _need(buf, 16, "CDR header")
    kind = buf[1]
    if kind not in (0, 1):
        raise DecodeError(f"unsupported CDR encapsulation kind {kind} (expected plain CDR)", "bad_header")
    e = "<" if kind == 1 else ">"
    sec, nsec, n = struct.unpack_from(f"{e}iII", buf, 4)
    pos = 12
    _need(buf, 4 + pos + n, "header.frame_id")
    frame_id = bytes(buf[4 + pos:4 + pos + n]).rstrip(b"\x00").decode(errors="replace")
    return e, sec * 1_000_000_000 + nsec, frame_id, pos + n


def _alloc(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return np.empty(n, np.uint16), np.empty(n, np.uint16), np.empty(n, np.int64), np.empty(n, np.uint8)


def _fill(ev: np.ndarray, out: tuple[np.ndarray, ...], offset: int) -> None:
    """Copy a structured dvs Event view into ``out`` from ``offset`` (one numba pass, native order)."""
    fields = [ev[f] for f in ("x", "y", "sec", "nsec", "p")]
    if ev.dtype["x"].byteorder == ">":
        fields = [f.astype(f.dtype.newbyteorder("=")) for f in fields]
    _dvs_fields(*fields, *out, offset)


def decode_dvs_raw(rawdata: bytes | memoryview, ros_version: int) -> DvsArray:
    """Decode a serialized dvs EventArray (ROS 1 or CDR) with numpy views."""
    buf = memoryview(rawdata).cast("B")
    if ros_version == 1:
        stamp, frame_id, pos = parse_ros1_header(buf)
        _need(buf, pos + 12, "height/width/length")
        height, width, n = struct.unpack_from("<III", buf, pos)
        pos += 12
        _need(buf, pos + 13 * n, f"{n} events")
        out = _alloc(n)
        _fill(np.frombuffer(buf, ROS1_DVS_EVENT, count=n, offset=pos), out, 0)
        return DvsArray(stamp, frame_id, width, height, *out)
    e, stamp, frame_id, pos = parse_cdr_header(buf)
    pos = align(pos, 4)
    _need(buf, 4 + pos + 12, "height/width/length")
    height, width, n = struct.unpack_from(f"{e}III", buf, 4 + pos)
    pos += 12
    lay = dvs_cdr_layout(pos)
    _need(buf, 4 + lay.end(n), f"{n} events")
    if n == 0:
        z = np.zeros(0)
        return DvsArray(stamp, frame_id, width, height, z.astype(np.uint16), z.astype(np.uint16),
                        z.astype(np.int64), z.astype(np.uint8))
    f = [4 + o for o in lay.first]
    x0, = struct.unpack_from(f"{e}H", buf, f[0])
    y0, = struct.unpack_from(f"{e}H", buf, f[1])
    s0, = struct.unpack_from(f"{e}i", buf, f[2])
    ns0, = struct.unpack_from(f"{e}I", buf, f[3])
    out = _alloc(n)
    x, y, t, p = out
    x[0], y[0], t[0], p[0] = x0, y0, s0 * 1_000_000_000 + ns0, buf[f[4]] != 0
    if n > 1:
        # the last element may lack its trailing padding: view whole strides, then the last one apart
        start = 4 + lay.rest_start
        m_full = min(n - 1, (len(buf) - start) // lay.stride)
        _fill(np.frombuffer(buf, lay.dtype(e == ">"), count=m_full, offset=start), out, 1)
        if m_full < n - 1:
            last = np.zeros(1, lay.dtype(e == ">"))
            tail = bytes(buf[start + m_full * lay.stride:])
            last.view(np.uint8)[: len(tail)] = np.frombuffer(tail, np.uint8)
            _fill(last, out, n - 1)
    return DvsArray(stamp, frame_id, width, height, x, y, t, p)


def decode_dvs_message(msg) -> DvsArray:
    """Decode a deserialized dvs EventArray (rosbags or rclpy object; one Python object per event
    already exists there, so this is the slow path; prefer :func:`decode_dvs_raw`)."""
    events = msg.events
    n = len(events)
    x = np.fromiter((e.x for e in events), np.uint16, n)
    y = np.fromiter((e.y for e in events), np.uint16, n)
    t = np.fromiter((e.ts.sec * 1_000_000_000 + e.ts.nanosec for e in events), np.int64, n)
    p = np.fromiter((bool(e.polarity) for e in events), np.uint8, n)
    st = msg.header.stamp
    return DvsArray(st.sec * 1_000_000_000 + st.nanosec, msg.header.frame_id, int(msg.width), int(msg.height),
                    x, y, t, p)
