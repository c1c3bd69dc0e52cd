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

Roll-overs are unwrapped by the nearest step (see :mod:`._kernels`): a clock stepping back is
counted in ``n_time_backsteps`` and kept as a step back, never read as a roll-over. A ``time_base``
that, with the offsets of its encoding, does not fit int64 nanoseconds raises :class:`DecodeError`
(kind ``time_range``).

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
_ENC_ID = {name: i for i, name in enumerate(ENCODINGS)}
_WORD = {"libcaer_cmp": 2, "libcaer": 4, "mono": 8, "evt3": 2}  # byte-swap unit of big-endian payloads
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
    n_time_backsteps: int = 0


@dataclass
class LibcaerState:
    """Roll-over tracking of the 31-bit libcaer microsecond counter across packets."""

    time_base: int | None = None
    slots: np.ndarray = field(default_factory=lambda: np.array([0, 0], np.int64))  # have a stamp, its unwrapped us


@dataclass
class Evt3State:
    """evt3 decoder state carried between packets (see the kernel for the slot meaning)."""

    slots: np.ndarray = field(default_factory=lambda: np.zeros(kern.S_E3_HAVE_HIGH + 1, np.int64))


def as_bytes_array(payload: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
    """A zero-copy uint8 view of a payload."""
    if isinstance(payload, np.ndarray):
        return payload.view(np.uint8).reshape(-1)
    return np.frombuffer(payload, dtype=np.uint8)


def check_time_base(encoding: str, time_base_ns: int) -> int:
    """``time_base_ns`` as int when it plus the encoding's time offsets fits int64 ns, else DecodeError."""
    tb = int(time_base_ns)
    if encoding == "evt3":
        return 0  # evt3 carries the camera clock and ignores time_base
    top = kern.INT64_MAX - int(kern.MAX_OFFSET_NS[_ENC_ID[encoding]])
    if not 0 <= tb <= top:
        raise DecodeError(f"{encoding} time_base {tb} ns is outside 0..{top} (int64 nanoseconds with the "
                          "encoding's time offsets): corrupt or not nanoseconds", "time_range")
    return tb


def _little_endian(buf: np.ndarray, word: int) -> np.ndarray:
    """A little-endian copy of a big-endian payload (trailing bytes kept, so they are still counted)."""
    n = buf.shape[0] // word * word
    out = buf.copy()
    out[:n] = buf[:n].view(f">u{word}").astype(f"<u{word}").view(np.uint8)
    return out


def _decode(encoding: str, payload, time_base_ns: int, width: int, height: int, big_endian: bool,
            st: np.ndarray, triggers: bool = False) -> PacketResult:
    enc = _ENC_ID[encoding]
    tb = check_time_base(encoding, time_base_ns)
    buf = as_bytes_array(payload)
    if big_endian:
        buf = _little_endian(buf, _WORD[encoding])
    tt = np.empty(kern._trigger_count(buf, 0, buf.shape[0]) if triggers else 0, np.int64)
    te, ti = np.empty(len(tt), np.uint8), np.empty(len(tt), np.uint8)
    cap = buf.shape[0] // _WORD[encoding] // (2 if encoding == "libcaer" else 1) + 1
    while True:
        xs, ys = np.empty(cap, np.uint16), np.empty(cap, np.uint16)
        ts, ps = np.empty(cap, np.int64), np.empty(cap, np.uint8)
        kern._reset_outputs(st)
        err = kern._decode_payload(enc, buf, 0, buf.shape[0], tb, int(width), int(height), st, xs, ys, ts, ps, 0,
                                   tt, te, ti)
        if err != kern.ERR_NEED_SPACE:
            break
        cap = int(st[kern.O_NEED])
    if err == kern.ERR_TIME_RANGE:
        raise DecodeError(f"{encoding} packet: event times run past int64 nanoseconds (time_base {tb})", "time_range")
    n = int(st[kern.O_N])
    return PacketResult(xs[:n], ys[:n], ts[:n], ps[:n], n_out_of_range=int(st[kern.O_OOB]),
                        n_unknown_words=int(st[kern.O_UNKNOWN]), n_trailing_bytes=int(st[kern.O_TRAILING]),
                        trigger_t=tt, trigger_edge=te, trigger_id=ti,
                        n_time_backsteps=int(st[kern.O_BACKSTEPS]))


def decode_libcaer_cmp(payload, time_base_ns: int, width: int = 0, height: int = 0,
                       big_endian: bool = False) -> PacketResult:
    """Decode a libcaer_cmp packet (16-bit words; see module docstring)."""
    return _decode("libcaer_cmp", payload, time_base_ns, width, height, big_endian,
                   np.zeros(kern.STATE_SIZE, np.int64))


def decode_libcaer(payload, time_base_ns: int, width: int = 0, height: int = 0, big_endian: bool = False,
                   state: LibcaerState | None = None) -> PacketResult:
    """Decode a libcaer packet (8 bytes per event), unwrapping the 2**31 us counter.

    Without ``state`` only roll-overs inside the packet are seen (the reference decoder's
    behaviour); with it, roll-overs between packets with the same ``time_base`` are counted too.
    """
    st = np.zeros(kern.STATE_SIZE, np.int64)
    if state is not None and state.time_base is not None:
        st[kern.S_LC_HAVE], st[kern.S_LC_LAST] = state.slots
        st[kern.S_LC_TB] = state.time_base
    else:
        st[kern.S_LC_TB] = int(time_base_ns) if 0 <= int(time_base_ns) <= kern.INT64_MAX else 0
    r = _decode("libcaer", payload, time_base_ns, width, height, big_endian, st)
    if state is not None:
        state.time_base = int(time_base_ns)
        state.slots[:] = (st[kern.S_LC_HAVE], st[kern.S_LC_LAST])
    return r


def decode_mono(payload, time_base_ns: int, width: int = 0, height: int = 0, big_endian: bool = False) -> PacketResult:
    """Decode a mono packet (uint64 per event, ns offsets from ``time_base``)."""
    return _decode("mono", payload, time_base_ns, width, height, big_endian, np.zeros(kern.STATE_SIZE, np.int64))


def decode_evt3(payload, width: int = 0, height: int = 0, big_endian: bool = False,
                state: Evt3State | None = None) -> PacketResult:
    """Decode an evt3 packet; time is the camera clock in ns. Pass ``state`` between packets."""
    st = np.zeros(kern.STATE_SIZE, np.int64)
    n_slots = kern.S_E3_HAVE_HIGH + 1
    if state is not None:
        st[:n_slots] = state.slots
    r = _decode("evt3", payload, 0, width, height, big_endian, st, triggers=True)
    if state is not None:
        state.slots[:] = st[:n_slots]
    return r


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
    raise DecodeError(f"unknown event encoding {encoding!r}; supported: {', '.join(ENCODINGS)}", "unknown_encoding")
