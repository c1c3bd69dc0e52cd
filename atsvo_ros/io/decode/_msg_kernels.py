"""Private numba kernels: a whole serialized EventPacket parsed and decoded in one call.

A well-formed message (ROS 1 or little-endian CDR) costs one numba call with three arguments:
the header is parsed here, the payload decoded by :func:`._kernels._decode_payload` into an arena
(one byte block holding the x, y, t, p arrays). A message the kernel does not take (truncated,
unknown encoding, time base out of range, big-endian data) returns an error code, and the Python
parser (``packet_msg.parse_packet_raw``), which mirrors these checks, builds the detailed error or
decodes it on the general path. :func:`_decode_msgs` runs many messages in one call.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from atsvo_ros.io.decode._kernels import (
    ENC_EVT3,
    ERR_BAD_HEADER,
    ERR_SLOW_PATH,
    ERR_TIME_RANGE,
    ERR_TRUNCATED,
    ERR_UNKNOWN_ENCODING,
    INT64_MAX,
    MAX_OFFSET_NS,
    O_ANY,
    O_BACK,
    O_BACKSTEPS,
    O_ENC,
    O_ERR,
    O_HEIGHT,
    O_N,
    O_NEED,
    O_OOB,
    O_STAMP,
    O_TB,
    O_TRAILING,
    O_TRIG,
    O_UNKNOWN,
    O_WIDTH,
    OK,
    P_CAP,
    P_HEIGHT,
    P_K0,
    P_ROS,
    P_WIDTH,
    _decode_payload,
    _reset_outputs,
    _u32,
)


@njit(cache=True, nogil=True, inline="always")
def _align(pos, size):
    return (pos + size - 1) // size * size


#: the encoding names, in the order of the ENC_* codes, as bytes the header is compared with
_ENC_BYTES = np.frombuffer(b"libcaer_cmplibcaermonoevt3", np.uint8).copy()
_ENC_START = np.array([0, 11, 18, 22], np.int64)
_ENC_LEN = np.array([11, 7, 4, 4], np.int64)


def arena_views(block: np.ndarray, capacity: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, t, p) views of an arena byte block of ``13 * capacity`` bytes (t first, 8-aligned)."""
    c = int(capacity)
    return (block[8 * c:10 * c].view(np.uint16), block[10 * c:12 * c].view(np.uint16),
            block[:8 * c].view(np.int64), block[12 * c:13 * c])


@njit(cache=True, nogil=True)
def _arena(block, c):
    return (block[8 * c:10 * c].view(np.uint16), block[10 * c:12 * c].view(np.uint16),
            block[:8 * c].view(np.int64), block[12 * c:13 * c])


@njit(cache=True, nogil=True)
def _time_base_ok(enc, tb_lo, tb_top):
    """Whether the uint64 time base (low 56 bits, top byte) plus the encoding's offsets fits int64 ns."""
    if enc == ENC_EVT3:
        return True  # evt3 carries the camera clock; time_base is not used
    if tb_top >= 0x80:
        return False
    tb = (tb_top << 56) | tb_lo
    return tb <= INT64_MAX - MAX_OFFSET_NS[enc]


@njit(cache=True, nogil=True)
def _match_encoding(b, start, n):
    """Index of the encoding named by ``b[start:start+n]`` (trailing NULs ignored), or -1."""
    while n > 0 and b[start + n - 1] == 0:
        n -= 1
    for e in range(_ENC_LEN.shape[0]):
        if _ENC_LEN[e] != n:
            continue
        same = True
        for i in range(n):
            if b[start + i] != _ENC_BYTES[_ENC_START[e] + i]:
                same = False
                break
        if same:
            return e
    return -1


@njit(cache=True, nogil=True)
def _parse_packet(b, ros_version, st):
    """EventPacket header -> (error, payload offset, payload size); header fields into ``st``.

    Mirrors ``packet_msg.parse_packet_raw``: the same fields, the same truncation checks.
    """
    nb = b.shape[0]
    if ros_version == 1:
        if nb < 16:
            return ERR_TRUNCATED, 0, 0
        stamp = _u32(b, 4) * 1_000_000_000 + _u32(b, 8)
        pos = 16 + _u32(b, 12)
        if pos > nb or pos + 28 > nb:
            return ERR_TRUNCATED, 0, 0
        height = _u32(b, pos)
        width = _u32(b, pos + 4)
        tb_lo = _u32(b, pos + 16) | ((_u32(b, pos + 20) & 0xFFFFFF) << 32)
        tb_top = np.int64(b[pos + 23])
        n = _u32(b, pos + 24)
        pos += 28
        if pos + n + 5 > nb:
            return ERR_TRUNCATED, 0, 0
        enc = _match_encoding(b, pos, n)
        if n > 0 and b[pos + n - 1] == 0:
            enc = -1  # ROS 1 strings carry no NUL: let the Python parser name it
        pos += n
        big = b[pos]
        size = _u32(b, pos + 1)
        pos += 5
        if pos + size > nb:
            return ERR_TRUNCATED, 0, 0
    else:
        if nb < 16:
            return ERR_TRUNCATED, 0, 0
        kind = b[1]
        if kind != 1:
            return (ERR_SLOW_PATH if kind == 0 else ERR_BAD_HEADER), 0, 0
        sec = _u32(b, 4)
        sec = sec - (np.int64(1) << 32) if sec >= (np.int64(1) << 31) else sec
        stamp = sec * 1_000_000_000 + _u32(b, 8)
        pos = 12 + _u32(b, 12)
        if 4 + pos > nb:
            return ERR_TRUNCATED, 0, 0
        pos = _align(pos, 4)
        if 4 + pos + 8 > nb:
            return ERR_TRUNCATED, 0, 0
        height = _u32(b, 4 + pos)
        width = _u32(b, 4 + pos + 4)
        pos = _align(pos + 8, 8)
        if 4 + pos + 20 > nb:
            return ERR_TRUNCATED, 0, 0
        tb_lo = _u32(b, 4 + pos + 8) | ((_u32(b, 4 + pos + 12) & 0xFFFFFF) << 32)
        tb_top = np.int64(b[4 + pos + 15])
        n = _u32(b, 4 + pos + 16)
        pos += 20
        if 4 + pos + n + 1 > nb:
            return ERR_TRUNCATED, 0, 0
        enc = _match_encoding(b, 4 + pos, n)
        pos += n
        big = b[4 + pos]
        pos = _align(pos + 1, 4)
        if 4 + pos + 4 > nb:
            return ERR_TRUNCATED, 0, 0
        size = _u32(b, 4 + pos)
        pos += 4
        if 4 + pos + size > nb:
            return ERR_TRUNCATED, 0, 0
        pos += 4
    st[O_STAMP] = stamp
    st[O_HEIGHT] = height
    st[O_WIDTH] = width
    st[O_ENC] = enc
    if enc < 0:
        return ERR_UNKNOWN_ENCODING, 0, 0
    if not _time_base_ok(enc, tb_lo, tb_top):
        return ERR_TIME_RANGE, 0, 0
    st[O_TB] = (tb_top << 56) | tb_lo
    if big != 0:
        return ERR_SLOW_PATH, 0, 0
    return OK, pos, size


@njit(cache=True, nogil=True)
def _decode_msg(b, st, block):
    """One serialized EventPacket into the arena (see :func:`_decode_msg_into`)."""
    return _decode_msg_into(b, st, block, np.empty(0, np.int64), np.empty(0, np.uint8))


@njit(cache=True, nogil=True)
def _decode_msg_into(b, st, block, no_i64, no_u8):
    """Serialized EventPacket -> events into the arena ``block`` from ``st[P_K0]``; returns an error code.

    ``no_i64``/``no_u8`` are empty trigger outputs (triggers are only counted here).

    Parameters in ``st``: ``P_ROS`` (1 or 2), ``P_WIDTH``/``P_HEIGHT`` (used when the message carries
    no size), ``P_K0`` and ``P_CAP`` (arena capacity in events, see :func:`arena_views`). Few
    arguments keep the call cheap: a packet of a few hundred events costs about as much to call
    as to decode. Triggers are only counted.
    """
    _reset_outputs(st)
    err, off, size = _parse_packet(b, st[P_ROS], st)
    if err != OK:
        st[O_ERR] = err
        return err
    xs, ys, ts, ps = _arena(block, st[P_CAP])
    k0 = st[P_K0]
    w = st[O_WIDTH] if st[O_WIDTH] > 0 and st[O_HEIGHT] > 0 else st[P_WIDTH]
    h = st[O_HEIGHT] if st[O_WIDTH] > 0 and st[O_HEIGHT] > 0 else st[P_HEIGHT]
    err = _decode_payload(st[O_ENC], b, off, size, st[O_TB], w, h, st, xs, ys, ts, ps, k0, no_i64, no_u8, no_u8)
    st[O_ERR] = err
    return err


@njit(cache=True, nogil=True)
def _decode_msgs(blob, starts, ends, st, block):
    """:func:`_decode_msg` over consecutive messages ``blob[starts[i]:ends[i]]``, counts summed.

    Stops at the first message that does not decode (its error in ``O_ERR``, the sums of the ones
    before it in the ``O_*`` slots) and returns its index, or the number of messages.
    """
    acc = np.zeros(P_ROS, np.int64)
    k = st[P_K0]
    n_ok = 0
    last_enc, last_w, last_h = 0, 0, 0
    no_i64 = np.empty(0, np.int64)
    no_u8 = np.empty(0, np.uint8)
    for i in range(starts.shape[0]):
        st[P_K0] = k
        err = _decode_msg_into(blob[starts[i]:ends[i]], st, block, no_i64, no_u8)
        if err != OK:
            break
        for j in (O_OOB, O_UNKNOWN, O_TRAILING, O_BACK, O_BACKSTEPS, O_TRIG, O_N):
            acc[j] += st[j]
        last_enc, last_w, last_h = st[O_ENC], st[O_WIDTH], st[O_HEIGHT]
        k += st[O_N]
        n_ok += 1
    err = st[O_ERR] if n_ok < starts.shape[0] else OK
    need = st[O_NEED]
    for j in (O_OOB, O_UNKNOWN, O_TRAILING, O_BACK, O_BACKSTEPS, O_TRIG, O_N):
        st[j] = acc[j]
    st[O_ERR] = err
    st[O_NEED] = need
    st[O_ENC], st[O_WIDTH], st[O_HEIGHT] = last_enc, last_w, last_h
    st[O_ANY] = acc[O_OOB] | acc[O_UNKNOWN] | acc[O_TRAILING] | acc[O_BACK] | acc[O_BACKSTEPS] | acc[O_TRIG]
    st[P_K0] = k
    return n_ok
