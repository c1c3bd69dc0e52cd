"""Event message decoders: serialized bytes or deserialized messages -> :class:`EventBatch`.

Public API (stable; used by the replay tool and the nodes):

* :func:`decode_raw` -- serialized bytes (ROS 1 or CDR) of an EventPacket / dvs EventArray, parsed
  with numpy (the fast path);
* :func:`decode_message` -- a deserialized message (rosbags or rclpy object, duck typed);
* :class:`EventDecoder` -- per-topic, stateful: carries evt3 and libcaer roll-over state across
  packets, drops (and counts, and logs once) events outside the sensor, events whose time goes
  backwards, and broken messages instead of crashing.

The one-shot functions decode a single message without history, exactly as the reference decoders
do; streams should go through :class:`EventDecoder`.
"""
from __future__ import annotations

import logging
from dataclasses import asdict, dataclass

import numpy as np

from atsvo_ros.core.events import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode._kernels import _count_backwards, _keep_forward
from atsvo_ros.io.decode.dvs import decode_dvs_message, decode_dvs_raw
from atsvo_ros.io.decode.packet import ENCODINGS, Evt3State, LibcaerState, PacketResult, decode_packet
from atsvo_ros.io.decode.packet_msg import PacketFields, packet_fields_from_message, parse_packet_raw

__all__ = ["ENCODINGS", "PACKET_TYPES", "DVS_TYPES", "DecodeStats", "EventDecoder", "decode_message", "decode_raw",
           "normalize_msgtype"]

_log = logging.getLogger(__name__)

PACKET_TYPES = frozenset({"event_camera_msgs/msg/EventPacket", "event_array_msgs/msg/EventArray"})
DVS_TYPES = frozenset({"dvs_msgs/msg/EventArray", "dv_ros_msgs/msg/EventArray", "dv_ros2_msgs/msg/EventArray"})


def normalize_msgtype(msgtype: str) -> str:
    """``dvs_msgs/EventArray`` (ROS 1 style) -> ``dvs_msgs/msg/EventArray``."""
    parts = msgtype.strip("/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    return "/".join(parts)


def _kind(msgtype: str) -> str:
    name = normalize_msgtype(msgtype)
    if name in PACKET_TYPES:
        return "packet"
    if name in DVS_TYPES:
        return "dvs"
    raise DecodeError(f"not an event message type: {msgtype!r}; supported: "
                      f"{', '.join(sorted(PACKET_TYPES | DVS_TYPES))}")


def _packet_batch(f: PacketFields, libcaer_state: LibcaerState | None = None,
                  evt3_state: Evt3State | None = None) -> tuple[EventBatch, PacketResult]:
    r = decode_packet(f.encoding, f.events, f.time_base, f.width, f.height, f.is_bigendian, libcaer_state, evt3_state)
    return EventBatch(r.x, r.y, r.t, r.p, f.width, f.height), r


def decode_raw(rawdata: bytes | memoryview, msgtype: str, ros_version: int = 2) -> EventBatch:
    """Decode the serialized bytes of one event message (no state carried between calls)."""
    if _kind(msgtype) == "packet":
        return _packet_batch(parse_packet_raw(rawdata, ros_version))[0]
    a = decode_dvs_raw(rawdata, ros_version)
    return EventBatch(a.x, a.y, a.t, a.p, a.width, a.height)


def decode_message(msg, msgtype: str) -> EventBatch:
    """Decode one deserialized event message (rosbags or rclpy object; no state carried)."""
    if _kind(msgtype) == "packet":
        return _packet_batch(packet_fields_from_message(msg))[0]
    a = decode_dvs_message(msg)
    return EventBatch(a.x, a.y, a.t, a.p, a.width, a.height)


@dataclass
class DecodeStats:
    """Running counts of one :class:`EventDecoder` (what was kept and what was dropped, and why)."""

    n_messages: int = 0
    n_events: int = 0
    dropped_out_of_range: int = 0
    dropped_backwards: int = 0
    dropped_messages: int = 0
    n_trigger: int = 0
    n_unknown_words: int = 0
    n_trailing_bytes: int = 0
    encoding: str = ""
    width: int = 0
    height: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


class EventDecoder:
    """Stateful decoder for one event topic.

    Args:
        msgtype: message type of the topic (``event_camera_msgs/msg/EventPacket``, dvs types, ...).
        ros_version: serialization of raw data (1 or 2).
        width, height: sensor size used to drop out-of-range events when the messages do not carry it.
        drop_backwards: drop events older than the newest one already emitted, so the stream is
            time-ordered for the time surface.
        align_to_header: evt3 carries camera-clock time; when True its events are shifted onto the
            header stamp clock (offset fixed at the first packet) so they line up with images.
        strict: raise :class:`DecodeError` on a broken message (truncated, unknown encoding) instead of
            counting it in ``stats.dropped_messages``.
    """

    def __init__(self, msgtype: str, ros_version: int = 2, width: int = 0, height: int = 0,
                 drop_backwards: bool = True, align_to_header: bool = False, strict: bool = False) -> None:
        self.kind = _kind(msgtype)
        self.msgtype = normalize_msgtype(msgtype)
        self.ros_version = ros_version
        self.width, self.height = int(width), int(height)
        self.drop_backwards = drop_backwards
        self.align_to_header = align_to_header
        self.strict = strict
        self.stats = DecodeStats(width=self.width, height=self.height)
        self._libcaer = LibcaerState()
        self._evt3 = Evt3State()
        self._last_t: int | None = None
        self._offset_ns: int | None = None
        self._warned: set[str] = set()

    def _warn(self, kind: str, msg: str) -> None:
        if kind not in self._warned:
            self._warned.add(kind)
            _log.warning("%s (%s; further drops are only counted in EventDecoder.stats)", msg, self.msgtype)

    def decode_raw(self, rawdata: bytes | memoryview) -> EventBatch:
        """Decode the serialized bytes of the next message of the topic."""
        try:
            if self.kind == "packet":
                return self._packet(parse_packet_raw(rawdata, self.ros_version))
            return self._dvs(decode_dvs_raw(rawdata, self.ros_version))
        except DecodeError as exc:
            return self._broken(exc)

    def decode_message(self, msg) -> EventBatch:
        """Decode the next deserialized message of the topic."""
        try:
            if self.kind == "packet":
                return self._packet(packet_fields_from_message(msg))
            return self._dvs(decode_dvs_message(msg))
        except DecodeError as exc:
            return self._broken(exc)

    # ------------------------------------------------------------------ internals

    def _broken(self, exc: DecodeError) -> EventBatch:
        if self.strict:
            raise exc
        self.stats.dropped_messages += 1
        self._warn(f"msg:{exc}", f"dropped a message: {exc}")
        return EventBatch.empty(self.width, self.height)

    def _size(self, width: int, height: int) -> tuple[int, int]:
        w, h = (width, height) if width and height else (self.width, self.height)
        self.stats.width, self.stats.height = w, h
        return w, h

    def _packet(self, f: PacketFields) -> EventBatch:
        w, h = self._size(f.width, f.height)
        self.stats.encoding = f.encoding
        r = decode_packet(f.encoding, f.events, f.time_base, w, h, f.is_bigendian, self._libcaer, self._evt3)
        self.stats.n_trigger += len(r.trigger_t)
        self.stats.n_unknown_words += r.n_unknown_words
        self.stats.n_trailing_bytes += r.n_trailing_bytes
        if r.n_trailing_bytes:
            self._warn("trailing", f"{r.n_trailing_bytes} trailing bytes ignored in a {f.encoding} packet")
        t = r.t
        if self.align_to_header and f.encoding == "evt3" and len(t):
            if self._offset_ns is None:
                self._offset_ns = f.stamp_ns - int(t[0])
            t = t + self._offset_ns
        return self._finish(r.x, r.y, t, r.p, w, h, r.n_out_of_range)

    def _dvs(self, a) -> EventBatch:
        self.stats.encoding = "dvs"
        w, h = self._size(a.width, a.height)
        x, y, t, p = a.x, a.y, a.t, a.p
        n_oob = 0
        if w and h and len(x):
            ok = (x < w) & (y < h)
            if not ok.all():
                n_oob = int(len(ok) - np.count_nonzero(ok))
                x, y, t, p = x[ok], y[ok], t[ok], p[ok]
        return self._finish(x, y, t, p, w, h, n_oob)

    def _finish(self, x, y, t, p, w: int, h: int, n_oob: int) -> EventBatch:
        self.stats.n_messages += 1
        if n_oob:
            self.stats.dropped_out_of_range += n_oob
            self._warn("oob", f"dropped {n_oob} events outside the {w}x{h} sensor")
        if self.drop_backwards and len(t):
            last = self._last_t if self._last_t is not None else np.iinfo(np.int64).min
            n_back = int(_count_backwards(t, last))
            if n_back:
                keep = _keep_forward(t, last)
                self.stats.dropped_backwards += n_back
                self._warn("back", f"dropped {n_back} events whose time went backwards")
                x, y, t, p = x[keep], y[keep], t[keep], p[keep]
        if len(t):
            self._last_t = int(t[-1]) if self._last_t is None else max(self._last_t, int(t[-1]))
        self.stats.n_events += len(t)
        return EventBatch(x, y, t, p, w, h)
