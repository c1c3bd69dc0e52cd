"""Private numba kernels of the event decoders.

One call per packet: each kernel counts the events, allocates the output once and fills it, and
drops (and counts) events outside the sensor, so Python only sees finished arrays. Decoder state
that must survive a packet boundary lives in a small int64 array owned by the caller.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# libcaer_cmp codes (top 4 bits of each little-endian 16-bit word)
_CMP_TIME_HIGH, _CMP_TIME_LOW, _CMP_ADDR_X, _CMP_ADDR_Y, _CMP_VECT_BASE_Y, _CMP_VECT_8 = 0, 1, 2, 3, 4, 5

# evt3 codes
_E3_ADDR_Y, _E3_ADDR_X, _E3_VECT_BASE_X, _E3_VECT_12, _E3_VECT_8 = 0, 2, 3, 4, 5
_E3_TIME_LOW, _E3_CONT_4, _E3_TIME_HIGH, _E3_PAD, _E3_EXT_TRIGGER, _E3_OTHERS, _E3_CONT_12 = 6, 7, 8, 9, 10, 14, 15

# evt3 state slots
E3_STATE_SIZE = 7
_S_VALID, _S_TIME_HIGH, _S_TIME_LOW, _S_Y, _S_BASE_X, _S_POL, _S_HAVE_HIGH = 0, 1, 2, 3, 4, 5, 6

# libcaer state slots: last raw microsecond stamp, roll-overs so far
LC_STATE_SIZE = 2
_LC_ROLLOVER_US = 1 << 31


def _event_lut(codes_one: tuple[int, ...], code_v12: int, code_v8: int) -> np.ndarray:
    """Events produced by each possible 16-bit word (an upper bound: validity/range not checked)."""
    w = np.arange(1 << 16, dtype=np.int64)
    code = w >> 12
    bits = np.unpackbits(w.astype(">u2").view(np.uint8).reshape(-1, 2), axis=1)[:, ::-1]  # bit i at column i
    lut = np.zeros(1 << 16, np.uint8)
    for c in codes_one:
        lut[code == c] = 1
    if code_v12 >= 0:
        lut[code == code_v12] = bits[code == code_v12, :12].sum(axis=1)
    lut[code == code_v8] = bits[code == code_v8, :8].sum(axis=1)
    return lut


_CMP_LUT = _event_lut((_CMP_ADDR_Y,), -1, _CMP_VECT_8)
_E3_LUT = _event_lut((_E3_ADDR_X,), _E3_VECT_12, _E3_VECT_8)


@njit(cache=True)
def _count_words(words: np.ndarray, lut: np.ndarray, trigger_code: int) -> tuple[int, int]:
    """(upper bound of the events in the words, number of words with ``trigger_code``)."""
    n = 0
    n_trig = 0
    for i in range(words.shape[0]):
        w = words[i]
        n += lut[w]
        if (w >> 12) == trigger_code:
            n_trig += 1
    return n, n_trig


@njit(cache=True, inline="always")
def _inside(x: int, y: int, width: int, height: int) -> bool:
    return (width <= 0 or height <= 0) or (x < width and y < height)


@njit(cache=True, inline="always")
def _limits(width: int, height: int) -> tuple[int, int]:
    """Exclusive coordinate limits; an unknown size (0) accepts every coordinate."""
    if width <= 0 or height <= 0:
        return 1 << 30, 1 << 30
    return width, height


@njit(cache=True)
def _libcaer_cmp(words: np.ndarray, time_base_ns: int, width: int, height: int):
    """libcaer_cmp packet -> (x, y, t, p, n_out_of_range, n_unknown_words); time words restart per packet."""
    n, _ = _count_words(words, _CMP_LUT, -1)
    unknown = 0
    xs = np.empty(n, np.uint16)
    ys = np.empty(n, np.uint16)
    ts = np.empty(n, np.int64)
    ps = np.empty(n, np.uint8)
    w_lim, h_lim = _limits(width, height)
    k = 0
    oob = 0
    t_high = 0
    t_low = 0
    t = time_base_ns
    ex = 0
    base_y = 0
    vpol = 0
    for i in range(words.shape[0]):
        w = np.int64(words[i])
        code = w >> 12
        if code == _CMP_ADDR_Y:
            ey = w & 0x7FF
            if ex < w_lim and ey < h_lim:
                xs[k] = ex
                ys[k] = ey
                ps[k] = (w >> 11) & 1
                ts[k] = t
                k += 1
            else:
                oob += 1
        elif code == _CMP_ADDR_X:
            ex = w & 0x7FF
        elif code == _CMP_TIME_LOW:
            t_low = w & 0xFFF
            t = time_base_ns + ((t_high << 12) | t_low) * 1000
        elif code == _CMP_TIME_HIGH:
            t_high = w & 0xFFF
            t = time_base_ns + ((t_high << 12) | t_low) * 1000
        elif code == _CMP_VECT_BASE_Y:
            base_y = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _CMP_VECT_8:
            for b in range(8):
                if (w >> b) & 1:
                    ey = base_y + b
                    if ex < w_lim and ey < h_lim:
                        xs[k] = ex
                        ys[k] = ey
                        ps[k] = vpol
                        ts[k] = t
                        k += 1
                    else:
                        oob += 1
            base_y += 8
        else:
            unknown += 1
    return xs[:k], ys[:k], ts[:k], ps[:k], oob, unknown


@njit(cache=True)
def _libcaer(data: np.ndarray, stamp_us: np.ndarray, time_base_ns: int, width: int, height: int,
             state: np.ndarray, use_state: bool):
    """libcaer packet (uint32 address word, int32 us) -> (x, y, t, p, n_out_of_range).

    The 31-bit microsecond counter wraps at 2**31 us; a decrease counts one roll-over. With
    ``use_state`` the last stamp and the roll-overs so far carry over from the previous packet.
    """
    n = data.shape[0]
    xs = np.empty(n, np.uint16)
    ys = np.empty(n, np.uint16)
    ts = np.empty(n, np.int64)
    ps = np.empty(n, np.uint8)
    last = state[0] if use_state else -1
    wraps = state[1] if use_state else 0
    k = 0
    oob = 0
    for i in range(n):
        s = np.int64(stamp_us[i])
        if s < last:
            wraps += 1
        last = s
        d = np.int64(data[i])
        x = (d >> 17) & 0x7FFF
        y = (d >> 2) & 0x7FFF
        if _inside(x, y, width, height):
            xs[k] = x
            ys[k] = y
            ps[k] = (d >> 1) & 1
            ts[k] = time_base_ns + (s + wraps * _LC_ROLLOVER_US) * 1000
            k += 1
        else:
            oob += 1
    if use_state:
        state[0] = last
        state[1] = wraps
    return xs[:k], ys[:k], ts[:k], ps[:k], oob


@njit(cache=True)
def _mono(words: np.ndarray, time_base_ns: int, width: int, height: int):
    """mono packet (uint64 ``p << 63 | y << 48 | x << 32 | dt_ns``) -> (x, y, t, p, n_out_of_range)."""
    n = words.shape[0]
    xs = np.empty(n, np.uint16)
    ys = np.empty(n, np.uint16)
    ts = np.empty(n, np.int64)
    ps = np.empty(n, np.uint8)
    k = 0
    oob = 0
    for i in range(n):
        w = words[i]
        x = np.int64((w >> np.uint64(32)) & np.uint64(0xFFFF))
        y = np.int64((w >> np.uint64(48)) & np.uint64(0x7FFF))
        if _inside(x, y, width, height):
            xs[k] = x
            ys[k] = y
            ps[k] = np.uint8(w >> np.uint64(63))
            ts[k] = time_base_ns + np.int64(w & np.uint64(0xFFFFFFFF))
            k += 1
        else:
            oob += 1
    return xs[:k], ys[:k], ts[:k], ps[:k], oob


@njit(cache=True)
def _evt3_update_high(t: int, time_high: int) -> int:
    """New TIME_HIGH word: keep the roll-over bits (above bit 24), bump them on a real wrap."""
    last = (time_high >> 12) & 0xFFF
    if t < last and last - t > 10:
        time_high += 1 << 24
    return (time_high & ~np.int64((1 << 24) - 1)) | (t << 12)


@njit(cache=True)
def _evt3_pass(words: np.ndarray, state: np.ndarray, width: int, height: int,
               xs: np.ndarray, ys: np.ndarray, ts: np.ndarray, ps: np.ndarray,
               trig_t: np.ndarray, trig_edge: np.ndarray, trig_id: np.ndarray):
    """Fill the outputs from an evt3 packet; returns (n_cd, n_trigger, n_out_of_range, n_unknown).

    Time is sensor time, returned in ns. Events before the first TIME_HIGH + TIME_LOW pair are
    skipped, as the reference decoder does, since their time is unknown. ``state`` is updated.
    """
    valid = state[_S_VALID]
    t_high = state[_S_TIME_HIGH]
    t_low = state[_S_TIME_LOW]
    ey = state[_S_Y]
    base_x = state[_S_BASE_X]
    vpol = state[_S_POL]
    have_high = state[_S_HAVE_HIGH]
    n = 0
    n_trig = 0
    n_oob = 0
    n_unknown = 0
    w_lim, h_lim = _limits(width, height)
    t = (t_high | t_low) * 1000
    for i in range(words.shape[0]):
        w = np.int64(words[i])
        code = w >> 12
        if valid == 0:
            if code == _E3_TIME_LOW:
                t_low = w & 0xFFF
                if have_high:
                    valid = 1
                    t = (t_high | t_low) * 1000
            elif code == _E3_TIME_HIGH:
                t_high = _evt3_update_high(w & 0xFFF, t_high)
                have_high = 1
            continue
        if code == _E3_ADDR_X:
            x = w & 0x7FF
            if x < w_lim and ey < h_lim:
                xs[n] = x
                ys[n] = ey
                ps[n] = (w >> 11) & 1
                ts[n] = t
                n += 1
            else:
                n_oob += 1
        elif code == _E3_ADDR_Y:
            ey = w & 0x7FF
        elif code == _E3_TIME_LOW:
            t_low = w & 0xFFF
            t = (t_high | t_low) * 1000
        elif code == _E3_TIME_HIGH:
            t_high = _evt3_update_high(w & 0xFFF, t_high)
            t = (t_high | t_low) * 1000
        elif code == _E3_VECT_BASE_X:
            base_x = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _E3_VECT_12 or code == _E3_VECT_8:
            nbits = 12 if code == _E3_VECT_12 else 8
            for b in range(nbits):
                if (w >> b) & 1:
                    x = base_x + b
                    if x < w_lim and ey < h_lim:
                        xs[n] = x
                        ys[n] = ey
                        ps[n] = vpol
                        ts[n] = t
                        n += 1
                    else:
                        n_oob += 1
            base_x += nbits
        elif code == _E3_EXT_TRIGGER:
            trig_t[n_trig] = t
            trig_edge[n_trig] = w & 1
            trig_id[n_trig] = (w >> 8) & 0xF
            n_trig += 1
        elif code == _E3_OTHERS or code == _E3_CONT_4 or code == _E3_CONT_12 or code == _E3_PAD:
            pass
        else:
            n_unknown += 1
    state[_S_VALID] = valid
    state[_S_TIME_HIGH] = t_high
    state[_S_TIME_LOW] = t_low
    state[_S_Y] = ey
    state[_S_BASE_X] = base_x
    state[_S_POL] = vpol
    state[_S_HAVE_HIGH] = have_high
    return n, n_trig, n_oob, n_unknown


@njit(cache=True)
def _evt3(words: np.ndarray, state: np.ndarray, width: int, height: int):
    """evt3 packet -> (x, y, t_ns, p, trigger t_ns, edge, id, n_out_of_range, n_unknown); updates ``state``."""
    n, n_trig = _count_words(words, _E3_LUT, _E3_EXT_TRIGGER)
    xs = np.empty(n, np.uint16)
    ys = np.empty(n, np.uint16)
    ts = np.empty(n, np.int64)
    ps = np.empty(n, np.uint8)
    tt = np.empty(n_trig, np.int64)
    te = np.empty(n_trig, np.uint8)
    ti = np.empty(n_trig, np.uint8)
    k, k_trig, n_oob, n_unknown = _evt3_pass(words, state, width, height, xs, ys, ts, ps, tt, te, ti)
    return xs[:k], ys[:k], ts[:k], ps[:k], tt[:k_trig], te[:k_trig], ti[:k_trig], n_oob, n_unknown


@njit(cache=True)
def _dvs_fields(ex: np.ndarray, ey: np.ndarray, esec: np.ndarray, ensec: np.ndarray, ep: np.ndarray,
                xs: np.ndarray, ys: np.ndarray, ts: np.ndarray, ps: np.ndarray, offset: int) -> None:
    """Copy strided dvs Event fields into the output arrays from ``offset`` on, in one pass."""
    for i in range(ex.shape[0]):
        xs[offset + i] = ex[i]
        ys[offset + i] = ey[i]
        ts[offset + i] = np.int64(esec[i]) * 1_000_000_000 + np.int64(ensec[i])
        ps[offset + i] = 1 if ep[i] != 0 else 0


@njit(cache=True)
def _count_backwards(t: np.ndarray, last_t: int) -> int:
    """How many events are older than the newest one before them (``last_t`` included)."""
    n = t.shape[0]
    if n == 0:
        return 0
    ordered = t[0] >= last_t
    for i in range(1, n):  # branch-free and vectorizable: the common, already ordered case
        ordered &= t[i] >= t[i - 1]
    if ordered:
        return 0
    m = last_t
    bad = 0
    for i in range(t.shape[0]):
        if t[i] < m:
            bad += 1
        else:
            m = t[i]
    return bad


@njit(cache=True)
def _keep_forward(t: np.ndarray, last_t: int) -> np.ndarray:
    """Mask of the events not older than the newest one before them."""
    keep = np.empty(t.shape[0], np.bool_)
    m = last_t
    for i in range(t.shape[0]):
        keep[i] = t[i] >= m
        if keep[i]:
            m = t[i]
    return keep
