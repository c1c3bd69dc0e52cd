"""Event encoders: EventBatch -> EventPacket payloads (libcaer_cmp, libcaer, mono, evt3) and
serialized messages (EventPacket, dvs_msgs/EventArray) built with numpy, never per event in Python.

Used by the simulator to write bags the robot's drivers would have written, and by the tests to
round-trip the decoders. Encodings carry microsecond time except mono (ns): timestamps are
truncated to whole microseconds relative to ``time_base`` (choose ``time_base_ns`` and event times
on the microsecond grid for an exact round trip).
"""
from __future__ import annotations

import struct

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode.layout import ROS1_DVS_EVENT, align, dvs_cdr_layout

ENCODINGS = ("libcaer_cmp", "libcaer", "mono", "evt3")
_CDR_LE = b"\x00\x01\x00\x00"


def _changed(a: np.ndarray) -> np.ndarray:
    out = np.ones(len(a), dtype=bool)
    if len(a) > 1:
        np.not_equal(a[1:], a[:-1], out=out[1:])
    return out


def _check(batch: EventBatch, max_coord: int, encoding: str) -> None:
    if len(batch) and (int(batch.x.max()) > max_coord or int(batch.y.max()) > max_coord):
        raise DecodeError(f"cannot encode {encoding}: coordinates above {max_coord}")
    if not batch.is_sorted():
        raise DecodeError(f"cannot encode {encoding}: events are not sorted by time")


def _interleave(parts: list[tuple[np.ndarray, np.ndarray]], n_events: int) -> np.ndarray:
    """Scatter per-event optional words (mask, value) in the given order into one word stream."""
    counts = np.zeros(n_events, np.int64)
    for mask, _ in parts:
        counts += mask
    ends = np.cumsum(counts)
    starts = ends - counts
    out = np.empty(int(ends[-1]) if n_events else 0, np.uint16)
    pos = starts.copy()
    for mask, value in parts:
        out[pos[mask]] = value[mask]
        pos += mask
    return out


def _encode_libcaer_cmp(b: EventBatch, tb: int) -> np.ndarray:
    _check(b, 0x7FF, "libcaer_cmp")
    d_us = (b.t - tb) // 1000
    if len(b) and (d_us[0] < 0 or d_us[-1] >= 1 << 24):
        raise DecodeError("cannot encode libcaer_cmp: events must lie within 2**24 us (16.7 s) after time_base")
    high, low = d_us >> 12, d_us & 0xFFF
    new_high = _changed(high)
    new_low = new_high | _changed(low)
    x = b.x.astype(np.int64)
    parts = [(new_high, high),
             (new_low, (1 << 12) | low),
             (_changed(x) | new_low, (2 << 12) | x),  # ADDR_X again after a time word keeps packets splittable
             (np.ones(len(b), bool), (3 << 12) | (b.p.astype(np.int64) << 11) | b.y.astype(np.int64))]
    return _interleave(parts, len(b)).view(np.uint8)


def _encode_evt3(b: EventBatch, tb: int) -> np.ndarray:
    _check(b, 0x7FF, "evt3")
    t_us = b.t // 1000
    if len(b) and t_us[0] < 0:
        raise DecodeError("cannot encode evt3: negative sensor time")
    high, low = (t_us >> 12) & 0xFFF, t_us & 0xFFF
    new_high = _changed(t_us >> 12)
    new_low = new_high | _changed(low)
    y = b.y.astype(np.int64)
    parts = [(new_high, (8 << 12) | high),
             (new_low, (6 << 12) | low),
             (_changed(y) | new_low, y),
             (np.ones(len(b), bool), (2 << 12) | (b.p.astype(np.int64) << 11) | b.x.astype(np.int64))]
    return _interleave(parts, len(b)).view(np.uint8)


def _encode_libcaer(b: EventBatch, tb: int) -> np.ndarray:
    _check(b, 0x7FFF, "libcaer")
    d_us = (b.t - tb) // 1000
    if len(b) and (d_us[0] < 0 or d_us[-1] - d_us[0] >= 1 << 31):
        raise DecodeError("cannot encode libcaer: a packet must span less than 2**31 us")
    rec = np.empty(len(b), np.dtype([("d", "<u4"), ("ts", "<i4")]))
    rec["d"] = (b.x.astype(np.uint32) << 17) | (b.y.astype(np.uint32) << 2) | (b.p.astype(np.uint32) << 1) | 1
    rec["ts"] = (d_us & 0x7FFFFFFF).astype(np.int32)
    return rec.view(np.uint8)


def _encode_mono(b: EventBatch, tb: int) -> np.ndarray:
    _check(b, 0x7FFF, "mono")
    dt = b.t - tb
    if len(b) and (dt[0] < 0 or dt[-1] >= 1 << 32):
        raise DecodeError("cannot encode mono: events must lie within 2**32 ns (4.29 s) after time_base")
    w = ((b.p.astype(np.uint64) << np.uint64(63)) | (b.y.astype(np.uint64) << np.uint64(48))
         | (b.x.astype(np.uint64) << np.uint64(32)) | dt.astype(np.uint64))
    return w.astype("<u8").view(np.uint8)


_ENCODERS = {"libcaer_cmp": _encode_libcaer_cmp, "libcaer": _encode_libcaer, "mono": _encode_mono,
             "evt3": _encode_evt3}


def encode_events(batch: EventBatch, encoding: str, time_base_ns: int | None = None) -> tuple[int, np.ndarray]:
    """Encode a time-sorted batch as an EventPacket payload: ``(time_base_ns, uint8 payload)``.

    ``time_base_ns`` defaults to the first event's time (0 for evt3, whose time is the sensor clock,
    i.e. ``batch.t`` itself). Raises :class:`DecodeError` when the events do not fit the encoding.
    """
    if encoding not in _ENCODERS:
        raise DecodeError(f"unknown event encoding {encoding!r}; supported: {', '.join(ENCODINGS)}")
    if encoding == "evt3":
        tb = 0
    else:
        tb = int(time_base_ns) if time_base_ns is not None else (batch.t_first_ns if len(batch) else 0)
    return tb, np.ascontiguousarray(_ENCODERS[encoding](batch, tb))


# ------------------------------------------------------------------------ serialized messages


def _split_ns(stamp_ns: int) -> tuple[int, int]:
    return int(stamp_ns) // 1_000_000_000, int(stamp_ns) % 1_000_000_000


def _cdr_header(stamp_ns: int, frame_id: str) -> bytearray:
    """CDR bytes of std_msgs/Header (after the encapsulation header), unpadded at the end."""
    sec, nsec = _split_ns(stamp_ns)
    fid = frame_id.encode() + b"\x00"
    return bytearray(struct.pack("<iII", sec, nsec, len(fid)) + fid)


def _pad(buf: bytearray, size: int) -> None:
    buf.extend(b"\x00" * (align(len(buf), size) - len(buf)))


def serialize_event_packet(batch: EventBatch, encoding: str, stamp_ns: int | None = None, frame_id: str = "camera",
                           seq: int = 0, ros_version: int = 2, time_base_ns: int | None = None) -> bytes:
    """Serialized event_camera_msgs/EventPacket (CDR for ROS 2, packed for ROS 1) holding ``batch``.

    ``stamp_ns`` (header stamp) defaults to the first event's time, as the drivers do.
    """
    tb, payload = encode_events(batch, encoding, time_base_ns)
    stamp = batch.t_first_ns if stamp_ns is None else int(stamp_ns)
    enc = encoding.encode()
    if ros_version == 1:
        sec, nsec = _split_ns(stamp)
        fid = frame_id.encode()
        head = struct.pack(f"<IIII{len(fid)}s", seq & 0xFFFFFFFF, sec, nsec, len(fid), fid)
        body = struct.pack(f"<IIQQI{len(enc)}s?I", batch.height, batch.width, seq, tb, len(enc), enc, False,
                           len(payload))
        return head + body + payload.tobytes()
    buf = _cdr_header(stamp, frame_id)
    _pad(buf, 4)
    buf += struct.pack("<II", batch.height, batch.width)
    _pad(buf, 8)
    buf += struct.pack("<QQI", seq, tb, len(enc) + 1) + enc + b"\x00"
    buf += b"\x00"  # is_bigendian
    _pad(buf, 4)
    buf += struct.pack("<I", len(payload))
    return _CDR_LE + bytes(buf) + payload.tobytes()


def serialize_dvs_event_array(batch: EventBatch, stamp_ns: int | None = None, frame_id: str = "camera",
                              ros_version: int = 2, seq: int = 0) -> bytes:
    """Serialized dvs_msgs/EventArray (also dv_ros2_msgs/EventArray: same layout) built with numpy."""
    n = len(batch)
    stamp = batch.t_first_ns if stamp_ns is None else int(stamp_ns)
    if ros_version == 1:
        sec, nsec = _split_ns(stamp)
        fid = frame_id.encode()
        head = struct.pack(f"<IIII{len(fid)}sIII", seq & 0xFFFFFFFF, sec, nsec, len(fid), fid,
                           batch.height, batch.width, n)
        ev = np.zeros(n, ROS1_DVS_EVENT)
        ev["x"], ev["y"], ev["p"] = batch.x, batch.y, batch.p
        ev["sec"], ev["nsec"] = batch.t // 1_000_000_000, batch.t % 1_000_000_000
        return head + ev.tobytes()
    buf = _cdr_header(stamp, frame_id)
    _pad(buf, 4)
    buf += struct.pack("<III", batch.height, batch.width, n)
    lay = dvs_cdr_layout(len(buf))
    out = np.zeros(lay.end(n), np.uint8)
    out[: len(buf)] = np.frombuffer(bytes(buf), np.uint8)
    if n:
        sec, nsec = batch.t // 1_000_000_000, batch.t % 1_000_000_000
        f = lay.first
        out[f[0]:f[0] + 2] = np.frombuffer(np.uint16(batch.x[0]).tobytes(), np.uint8)
        out[f[1]:f[1] + 2] = np.frombuffer(np.uint16(batch.y[0]).tobytes(), np.uint8)
        out[f[2]:f[2] + 4] = np.frombuffer(np.int32(sec[0]).tobytes(), np.uint8)
        out[f[3]:f[3] + 4] = np.frombuffer(np.uint32(nsec[0]).tobytes(), np.uint8)
        out[f[4]] = batch.p[0]
    if n > 1:
        rest = np.zeros(n - 1, lay.dtype())
        rest["x"], rest["y"], rest["p"] = batch.x[1:], batch.y[1:], batch.p[1:]
        rest["sec"], rest["nsec"] = sec[1:], nsec[1:]
        raw = rest.view(np.uint8).reshape(-1)
        out[lay.rest_start:] = raw[: len(out) - lay.rest_start]
    return _CDR_LE + out.tobytes()
