"""Event message decoders: serialized bytes or deserialized messages -> :class:`EventBatch`.

Public API (stable; used by the replay tool and the nodes):

* :func:`decode_raw` -- serialized bytes (ROS 1 or CDR) of an EventPacket / dvs EventArray, parsed
  with numpy (the fast path);
* :func:`decode_message` -- a deserialized message (rosbags or rclpy object, duck typed);
* :class:`EventDecoder` -- per-topic, stateful: carries evt3 and libcaer roll-over state across
  packets, drops (and counts per kind, and logs once per kind, then rate-limited) events outside
  the sensor, events whose time goes backwards, and broken messages instead of crashing.

The one-shot functions decode a single message without history, exactly as the reference decoders
do; streams should go through :class:`EventDecoder`.
"""
from __future__ import annotations

import logging
import sys
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import _kernels as kern
from atsvo_ros.io.decode import _msg_kernels as mkern
from atsvo_ros.io.decode._kernels import _count_backwards, _keep_forward
from atsvo_ros.io.decode.dvs import decode_dvs_message, decode_dvs_raw
from atsvo_ros.io.decode.packet import ENCODINGS, Evt3State, LibcaerState, PacketResult, check_time_base, decode_packet
from atsvo_ros.io.decode.packet_msg import PacketFields, packet_fields_from_message, parse_packet_raw

__all__ = ["ENCODINGS", "PACKET_TYPES", "DVS_TYPES", "DecodeStats", "EventDecoder", "decode_message", "decode_raw",
           "normalize_msgtype"]

_log = logging.getLogger(__name__)
_monotonic = time.monotonic  # the clock of the warning rate limit (replaced in tests)

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
                      f"{', '.join(sorted(PACKET_TYPES | DVS_TYPES))}", "unknown_type")


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
    """Running counts of one :class:`EventDecoder` (what was kept and what was dropped, and why).

    ``dropped_by_kind`` counts dropped messages per problem (``truncated``, ``unknown_encoding``,
    ``time_range``, ``bad_header``, ...); ``time_backsteps`` counts the times the camera clock
    (evt3 TIME_HIGH, libcaer counter) stepped back, whose events ``dropped_backwards`` then counts.
    """

    n_messages: int = 0
    n_events: int = 0
    dropped_out_of_range: int = 0
    dropped_backwards: int = 0
    dropped_messages: int = 0
    dropped_by_kind: dict[str, int] = field(default_factory=dict)
    time_backsteps: int = 0
    n_trigger: int = 0
    n_unknown_words: int = 0
    n_trailing_bytes: int = 0
    encoding: str = ""
    width: int = 0
    height: int = 0

    def as_dict(self) -> dict:
        return asdict(self)


class _Arena:
    """Output arrays that successive packets fill one after the other.

    Each batch handed out is a view of its own slice, never written while a view of it exists: a
    full arena is replaced by a new one (the old one lives as long as batches view it), and an
    arena no batch views any more is rewound and refilled, which keeps the memory that the
    decoder writes small and in cache (fresh large allocations cost a page fault per 4 KiB).
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = (int(capacity) + 7) // 8 * 8
        self.block = np.empty(13 * self.capacity, np.uint8)
        self.x, self.y, self.t, self.p = mkern.arena_views(self.block, self.capacity)
        self.pos = 0
        self._idle_refs = sys.getrefcount(self.block)  # references when no batch views the block

    def rewind_if_idle(self) -> None:
        """Start again at slot 0 when no batch handed out still views the arena."""
        if self.pos and sys.getrefcount(self.block) == self._idle_refs:
            self.pos = 0


_PADS = [b"\x00" * k for k in range(8)]
_ERR_KIND = {kern.ERR_TRUNCATED: "truncated", kern.ERR_UNKNOWN_ENCODING: "unknown_encoding",
             kern.ERR_TIME_RANGE: "time_range", kern.ERR_BAD_HEADER: "bad_header"}


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
        warn_interval_s: each kind of problem is logged at its first occurrence, then at most once
            per this interval with the count since the last report.
        arena_events: events per output arena (batches are views of it; see :class:`_Arena`).
    """

    def __init__(self, msgtype: str, ros_version: int = 2, width: int = 0, height: int = 0,
                 drop_backwards: bool = True, align_to_header: bool = False, strict: bool = False,
                 warn_interval_s: float = 30.0, arena_events: int = 1 << 17) -> None:
        self.kind = _kind(msgtype)
        self.msgtype = normalize_msgtype(msgtype)
        self.ros_version = ros_version
        self.width, self.height = int(width), int(height)
        self.drop_backwards = drop_backwards
        self.align_to_header = align_to_header
        self.strict = strict
        self.warn_interval_s = float(warn_interval_s)
        self.stats = DecodeStats(width=self.width, height=self.height)
        self._st = np.zeros(kern.STATE_SIZE, np.int64)
        self._st[kern.S_DROP] = 1 if drop_backwards else 0
        self._st[[kern.P_ROS, kern.P_WIDTH, kern.P_HEIGHT]] = (ros_version, self.width, self.height)
        self._arena_events = max(1024, int(arena_events))
        self._arena = _Arena(self._arena_events)
        self._have_offset = False
        self._last_t: int | None = None  # dvs path only
        self._warn_state: dict[str, list] = {}  # kind -> [time of last report, count since]

    # ------------------------------------------------------------------ public

    def decode_raw(self, rawdata: bytes | memoryview) -> EventBatch:
        """Decode the serialized bytes of the next message of the topic."""
        try:
            if self.kind == "packet":
                return self._packet_raw(rawdata)
            return self._dvs(decode_dvs_raw(rawdata, self.ros_version))
        except DecodeError as exc:
            return self._broken(exc)

    def decode_raw_many(self, raws: Iterable[bytes | memoryview]) -> EventBatch:
        """Decode consecutive messages of the topic into one batch.

        The same events, state and counts as concatenating :meth:`decode_raw` of each, with one
        kernel call for the whole run of well-formed messages instead of a call and a batch per
        message: for offline reading, where that overhead would dominate packets of a few hundred
        events. The messages are copied once into one buffer (8-byte aligned each).
        """
        raws = list(raws)
        if self.kind != "packet" or (self.align_to_header and not self._have_offset) or not raws:
            parts = [self.decode_raw(r) for r in raws]
            return EventBatch.concatenate(parts) if parts else EventBatch.empty(self.width, self.height)
        sizes = np.fromiter((len(r) for r in raws), np.int64, len(raws))
        padded = (sizes + 7) // 8 * 8
        ends_p = np.cumsum(padded)
        starts = ends_p - padded
        blob = np.frombuffer(b"".join(x for r, pad in zip(raws, (padded - sizes).tolist())
                                      for x in (r, _PADS[pad])), np.uint8)
        ends = starts + sizes
        room = int(ends_p[-1]) // 2 + len(raws) + 1  # one slot per word: enough but for vectors
        self._arena.rewind_if_idle()
        if self._arena.capacity - self._arena.pos < room:
            self._arena = _Arena(max(room, self._arena_events))
        parts: list[EventBatch] = []
        i = 0
        while i < len(raws):
            st, a = self._st, self._arena
            st[kern.P_K0] = k0 = a.pos
            st[kern.P_CAP] = a.capacity
            n_ok = mkern._decode_msgs(blob, starts[i:], ends[i:], st, a.block)
            if n_ok:
                self.stats.n_messages += n_ok - 1  # _emit counts one
                parts.append(self._emit(st, a))
            i += n_ok
            if i < len(raws):
                if st[kern.O_ERR] == kern.ERR_NEED_SPACE and a.pos == k0 and n_ok == 0:
                    self._arena = _Arena(max(self._arena_events, int(st[kern.O_NEED]), room))
                parts.append(self.decode_raw(raws[i]))  # general path, or counted as broken
                i += 1
        parts = [p for p in parts if len(p)]
        if not parts:
            return EventBatch.empty(self.stats.width, self.stats.height)
        return parts[0] if len(parts) == 1 else EventBatch.concatenate(parts)

    def decode_message(self, msg) -> EventBatch:
        """Decode the next deserialized message of the topic."""
        try:
            if self.kind == "packet":
                return self._packet(packet_fields_from_message(msg))
            return self._dvs(decode_dvs_message(msg))
        except DecodeError as exc:
            return self._broken(exc)

    # ------------------------------------------------------------------ warnings

    def _warn(self, kind: str, msg: str, count: int = 1) -> None:
        """Log ``msg`` the first time ``kind`` happens, then at most once per ``warn_interval_s``."""
        now = _monotonic()
        state = self._warn_state.get(kind)
        if state is None:
            self._warn_state[kind] = [now, 0]
            _log.warning("%s (%s; %s problems are counted in EventDecoder.stats, reported again at most every "
                         "%.0f s)", msg, self.msgtype, kind, self.warn_interval_s)
            return
        state[1] += count
        if now - state[0] >= self.warn_interval_s:
            _log.warning("%s: %d more %s since the last report, latest: %s", self.msgtype, state[1], kind, msg)
            state[0], state[1] = now, 0

    # ------------------------------------------------------------------ internals

    def _broken(self, exc: DecodeError) -> EventBatch:
        if self.strict:
            raise exc
        kind = getattr(exc, "kind", "malformed")
        self.stats.dropped_messages += 1
        self.stats.dropped_by_kind[kind] = self.stats.dropped_by_kind.get(kind, 0) + 1
        self._warn(kind, f"dropped a message: {exc}")
        return EventBatch.empty(self.width, self.height)

    def _size(self, width: int, height: int) -> tuple[int, int]:
        w, h = (width, height) if width and height else (self.width, self.height)
        self.stats.width, self.stats.height = w, h
        return w, h

    def _packet_raw(self, rawdata: bytes | memoryview) -> EventBatch:
        """The fast path: one kernel call parses the message and decodes it into the arena."""
        buf = rawdata if isinstance(rawdata, np.ndarray) else np.frombuffer(rawdata, np.uint8)
        st, a = self._st, self._arena
        a.rewind_if_idle()
        st[kern.P_K0] = a.pos
        st[kern.P_CAP] = a.capacity
        err = mkern._decode_msg(buf, st, a.block)
        if err == kern.ERR_NEED_SPACE:
            a = self._arena = _Arena(max(self._arena_events, int(st[kern.O_NEED])))
            st[kern.P_K0] = 0
            st[kern.P_CAP] = a.capacity
            err = mkern._decode_msg(buf, st, a.block)
        if err != kern.OK:
            if err == kern.ERR_SLOW_PATH:  # big-endian data: the general path
                return self._packet(parse_packet_raw(rawdata, self.ros_version))
            raise self._explain(rawdata, err)
        return self._emit(st, a)

    def _explain(self, rawdata: bytes | memoryview, err: int) -> DecodeError:
        """The detailed error for a message the kernel refused (the Python parser mirrors its checks)."""
        f = parse_packet_raw(rawdata, self.ros_version)  # raises for truncated messages and bad headers
        if f.encoding not in ENCODINGS:
            return DecodeError(f"unknown event encoding {f.encoding!r}; supported: {', '.join(ENCODINGS)}",
                               "unknown_encoding")
        check_time_base(f.encoding, f.time_base)
        return DecodeError(f"{f.encoding} packet: event times run past int64 nanoseconds",
                           _ERR_KIND.get(err, "malformed"))

    def _emit(self, st: np.ndarray, a: _Arena, encoding: str | None = None, width: int = 0,
              height: int = 0) -> EventBatch:
        """The batch of the last decode call (arena slots from ``a.pos``); stats and warnings updated.

        Encoding and size come from the message header slots unless given.
        """
        out = st[kern.O_ERR:kern.P_ROS].tolist()  # one conversion instead of a numpy scalar per slot
        if encoding is None:
            o = kern.O_ERR
            encoding, width, height = ENCODINGS[out[kern.O_ENC - o]], out[kern.O_WIDTH - o], out[kern.O_HEIGHT - o]
        k0, n = a.pos, out[kern.O_N - kern.O_ERR]
        a.pos = k0 + n
        w, h = self._size(width, height)
        s = self.stats
        s.encoding = encoding
        s.n_messages += 1
        s.n_events += n
        if out[kern.O_ANY - kern.O_ERR]:
            self._account(out, encoding, w, h)
        if n and self.align_to_header and encoding == "evt3" and not self._have_offset:
            offset = out[kern.O_STAMP - kern.O_ERR] - int(a.t[k0])
            a.t[k0:k0 + n] += offset
            st[kern.S_OFFSET] = offset
            st[kern.S_LAST_T] += offset
            self._have_offset = True
        return EventBatch(a.x[k0:k0 + n], a.y[k0:k0 + n], a.t[k0:k0 + n], a.p[k0:k0 + n], w, h)

    def _account(self, out: list[int], encoding: str, w: int, h: int) -> None:
        """Add the counts of a decode call (``out``: the ``O_*`` slots as ints) to the stats; warn."""
        s = self.stats
        o = kern.O_ERR
        oob, back, steps = out[kern.O_OOB - o], out[kern.O_BACK - o], out[kern.O_BACKSTEPS - o]
        trailing, unknown = out[kern.O_TRAILING - o], out[kern.O_UNKNOWN - o]
        s.n_trigger += out[kern.O_TRIG - o]
        if not (oob or back or steps or trailing or unknown):
            return
        s.n_unknown_words += unknown
        s.n_trailing_bytes += trailing
        s.dropped_out_of_range += oob
        s.dropped_backwards += back
        s.time_backsteps += steps
        if oob:
            self._warn("out_of_range", f"dropped {oob} events outside the {w}x{h} sensor", oob)
        if steps:
            self._warn("time_backstep", f"the {encoding} camera clock stepped back {steps} time(s) in a packet "
                       "(read as a step back, not as a roll-over)", steps)
        if back:
            self._warn("backwards", f"dropped {back} events whose time went backwards", back)
        if trailing:
            self._warn("trailing_bytes", f"{trailing} trailing bytes ignored in a {encoding} packet", trailing)
        if unknown:
            self._warn("unknown_words", f"{unknown} unknown {encoding} words ignored", unknown)

    def _packet(self, f: PacketFields) -> EventBatch:
        """General path (deserialized messages, big-endian data): decode, then copy into the arena."""
        w, h = (f.width, f.height) if f.width and f.height else (self.width, self.height)
        st = self._st
        lc = LibcaerState(time_base=int(st[kern.S_LC_TB]) if st[kern.S_LC_HAVE] else None,
                          slots=st[[kern.S_LC_HAVE, kern.S_LC_LAST]].copy())
        e3 = Evt3State(slots=st[: kern.S_E3_HAVE_HIGH + 1].copy())
        r = decode_packet(f.encoding, f.events, f.time_base, w, h, f.is_bigendian, lc, e3)
        st[: kern.S_E3_HAVE_HIGH + 1] = e3.slots
        if lc.time_base is not None:
            st[kern.S_LC_HAVE], st[kern.S_LC_LAST] = lc.slots
            st[kern.S_LC_TB] = lc.time_base
        t = r.t + st[kern.S_OFFSET] if f.encoding == "evt3" else r.t
        if self.align_to_header and f.encoding == "evt3" and len(t) and not self._have_offset:
            st[kern.S_OFFSET] = f.stamp_ns - int(t[0])
            t = t + st[kern.S_OFFSET]
            self._have_offset = True
        x, y, p = r.x, r.y, r.p
        back = 0
        if self.drop_backwards and len(t):
            last = int(st[kern.S_LAST_T]) if st[kern.S_HAVE_LAST] else kern.INT64_MIN
            back = int(_count_backwards(t, last))
            if back:
                keep = _keep_forward(t, last)
                x, y, t, p = x[keep], y[keep], t[keep], p[keep]
        if len(t):
            newest = int(t.max())
            st[kern.S_LAST_T] = max(int(st[kern.S_LAST_T]), newest) if st[kern.S_HAVE_LAST] else newest
            st[kern.S_HAVE_LAST] = 1
        counts = np.zeros(kern.STATE_SIZE, np.int64)
        counts[[kern.O_OOB, kern.O_UNKNOWN, kern.O_TRAILING, kern.O_BACK, kern.O_BACKSTEPS, kern.O_TRIG]] = (
            r.n_out_of_range, r.n_unknown_words, r.n_trailing_bytes, back, r.n_time_backsteps, len(r.trigger_t))
        counts[kern.O_ANY] = counts.any()
        counts[kern.O_N] = len(t)
        a = self._arena
        a.rewind_if_idle()
        if a.pos + len(t) > a.capacity:
            a = self._arena = _Arena(max(self._arena_events, len(t) + 1))
        sl = slice(a.pos, a.pos + len(t))
        a.x[sl], a.y[sl], a.t[sl], a.p[sl] = x, y, t, p
        return self._emit(counts, a, f.encoding, w, h)

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
            self._warn("out_of_range", f"dropped {n_oob} events outside the {w}x{h} sensor", n_oob)
        if self.drop_backwards and len(t):
            last = self._last_t if self._last_t is not None else np.iinfo(np.int64).min
            n_back = int(_count_backwards(t, last))
            if n_back:
                keep = _keep_forward(t, last)
                self.stats.dropped_backwards += n_back
                self._warn("backwards", f"dropped {n_back} events whose time went backwards", n_back)
                x, y, t, p = x[keep], y[keep], t[keep], p[keep]
        if len(t):
            self._last_t = int(t[-1]) if self._last_t is None else max(self._last_t, int(t[-1]))
        self.stats.n_events += len(t)
        return EventBatch(x, y, t, p, w, h)
