"""event_camera_msgs/EventPacket payload decoders: libcaer_cmp, libcaer, mono and evt3.

Time conventions follow the reference decoders (ros-event-camera/event_camera_codecs), in ns:

* ``libcaer_cmp``: ``t = time_base + ((high << 12) | low) * 1000`` (sensor microseconds relative to
  ``time_base``; the time words restart at 0 in every packet).
* ``libcaer``: 8 bytes per event (uint32 ``valid | p << 1 | y << 2 | x << 17``, int32 microseconds);
  ``t = time_base + ts_us * 1000`` with the 31-bit microsecond counter rolling over at 2**31 us.
  The driver keeps ``time_base`` while the counter wraps, so the number of roll-overs is state
  that must be carried across packets (:class:`LibcaerState`).
* ``mono``: uint64 ``p << 63 | y << 48 | x << 32 | dt_ns``; ``t = time_base + dt_ns``.
* ``evt3``: Prophesee 16-bit words, time is the camera's own microsecond clock (``time_base`` is 0
  in the bags); high/low time, y, vector base and roll-over bits persist across packets
  (:class:`Evt3State`).

Every function returns a :class:`PacketResult` with the CD events plus the counts of what was
dropped (out-of-range coordinates, unknown words, trailing bytes), never raising inside numba.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import _kernels as kern

ENCODINGS = ("libcaer_cmp", "libcaer", "mono", "evt3")
LIBCAER_ROLLOVER_US = 1 << 31
_NO_I64 = np.zeros(0, np.int64)
_NO_U8 = np.zeros(0, np.uint8)
_NO_I64.flags.writeable = False
_NO_U8.flags.writeable = False


@dataclass
class PacketResult:
    """Decoded CD events of one packet plus what was left out (and why)."""

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    n_out_of_range: int = 0
    n_unknown_words: int = 0
    n_trailing_bytes: int = 0
    trigger_t: np.ndarray = field(default_factory=lambda: _NO_I64)
    trigger_edge: np.ndarray = field(default_factory=lambda: _NO_U8)
    trigger_id: np.ndarray = field(default_factory=lambda: _NO_U8)


@dataclass
class LibcaerState:
    """Roll-over tracking of the 31-bit libcaer microsecond counter across packets."""

    time_base: int | None = None
    slots: np.ndarray = field(default_factory=lambda: np.array([-1, 0], np.int64))  # last stamp, roll-overs


@dataclass
class Evt3State:
    """evt3 decoder state carried between packets (see the kernel for the slot meaning)."""

    slots: np.ndarray = field(default_factory=lambda: np.zeros(kern.E3_STATE_SIZE, np.int64))


def as_bytes_array(payload: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
    """A zero-copy uint8 view of a payload."""
    if isinstance(payload, np.ndarray):
        return payload.view(np.uint8).reshape(-1)
    return np.frombuffer(payload, dtype=np.uint8)


def _words(buf: np.ndarray, size: int, big_endian: bool) -> tuple[np.ndarray, int]:
    """Native-order unsigned words of ``size`` bytes and the number of trailing bytes."""
    n = buf.shape[0] // size
    trailing = buf.shape[0] - n * size
    dtype = np.dtype(f"{'>' if big_endian else '<'}u{size}")
    words = buf[: n * size].view(dtype) if n else np.zeros(0, dtype)
    return (words.astype(f"=u{size}") if big_endian else words), trailing


def decode_libcaer_cmp(payload, time_base_ns: int, width: int = 0, height: int = 0,
                       big_endian: bool = False) -> PacketResult:
    """Decode a libcaer_cmp packet (16-bit words; see module docstring)."""
    words, trailing = _words(as_bytes_array(payload), 2, big_endian)
    x, y, t, p, oob, unknown = kern._libcaer_cmp(words, int(time_base_ns), int(width), int(height))
    return PacketResult(x, y, t, p, n_out_of_range=oob, n_unknown_words=unknown, n_trailing_bytes=trailing)


def decode_libcaer(payload, time_base_ns: int, width: int = 0, height: int = 0, big_endian: bool = False,
                   state: LibcaerState | None = None) -> PacketResult:
    """Decode a libcaer packet (8 bytes per event), unwrapping the 2**31 us counter.

    Without ``state`` only roll-overs inside the packet are seen (the reference decoder's
    behaviour); with it, roll-overs between packets with the same ``time_base`` are counted too.
    """
    buf = as_bytes_array(payload)
    n = buf.shape[0] // 8
    trailing = buf.shape[0] - 8 * n
    e = ">" if big_endian else "<"
    rec = buf[: 8 * n].view(np.dtype([("d", f"{e}u4"), ("ts", f"{e}i4")]))
    data, stamp = rec["d"], rec["ts"]
    if big_endian:
        data, stamp = data.astype(np.uint32), stamp.astype(np.int32)
    if state is not None and state.time_base != time_base_ns:
        state.time_base = int(time_base_ns)
        state.slots[:] = (-1, 0)
    slots = state.slots if state is not None else np.array([-1, 0], np.int64)
    x, y, t, p, oob = kern._libcaer(data, stamp, int(time_base_ns), int(width), int(height), slots,
                                    state is not None)
    return PacketResult(x, y, t, p, n_out_of_range=oob, n_trailing_bytes=trailing)


def decode_mono(payload, time_base_ns: int, width: int = 0, height: int = 0, big_endian: bool = False) -> PacketResult:
    """Decode a mono packet (uint64 per event, ns offsets from ``time_base``)."""
    words, trailing = _words(as_bytes_array(payload), 8, big_endian)
    x, y, t, p, oob = kern._mono(words, int(time_base_ns), int(width), int(height))
    return PacketResult(x, y, t, p, n_out_of_range=oob, n_trailing_bytes=trailing)


def decode_evt3(payload, width: int = 0, height: int = 0, big_endian: bool = False,
                state: Evt3State | None = None) -> PacketResult:
    """Decode an evt3 packet; time is the camera clock in ns. Pass ``state`` between packets."""
    words, trailing = _words(as_bytes_array(payload), 2, big_endian)
    st = state if state is not None else Evt3State()
    x, y, t, p, tt, te, ti, oob, unknown = kern._evt3(words, st.slots, int(width), int(height))
    return PacketResult(x, y, t, p, n_out_of_range=oob, n_unknown_words=unknown, n_trailing_bytes=trailing,
                        trigger_t=tt, trigger_edge=te, trigger_id=ti)


def decode_packet(encoding: str, payload, time_base_ns: int = 0, width: int = 0, height: int = 0,
                  big_endian: bool = False, libcaer_state: LibcaerState | None = None,
                  evt3_state: Evt3State | None = None) -> PacketResult:
    """Dispatch on the EventPacket ``encoding`` string; unknown encodings raise :class:`DecodeError`."""
    if encoding == "libcaer_cmp":
        return decode_libcaer_cmp(payload, time_base_ns, width, height, big_endian)
    if encoding == "libcaer":
        return decode_libcaer(payload, time_base_ns, width, height, big_endian, libcaer_state)
    if encoding == "mono":
        return decode_mono(payload, time_base_ns, width, height, big_endian)
    if encoding == "evt3":
        return decode_evt3(payload, width, height, big_endian, evt3_state)
    raise DecodeError(f"unknown event encoding {encoding!r}; supported: {', '.join(ENCODINGS)}")
