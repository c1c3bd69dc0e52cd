"""Private numba kernels for the stateful word-stream encodings (libcaer_cmp, evt3).

Each kernel runs two passes over the 16-bit words: one to count the events (so the output is
allocated exactly once), one to fill it. Decoder state that must survive a packet boundary lives in
a small int64 array owned by the caller, so the kernels stay pure functions.
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


@njit(cache=True)
def _libcaer_cmp_count(words: np.ndarray) -> tuple[int, int]:
    """Number of events and of unknown words in a libcaer_cmp packet."""
    n = 0
    unknown = 0
    for i in range(words.shape[0]):
        w = words[i]
        code = w >> 12
        if code == _CMP_ADDR_Y:
            n += 1
        elif code == _CMP_VECT_8:
            v = w & 0xFF
            while v:
                v &= v - 1
                n += 1
        elif code > _CMP_VECT_8:
            unknown += 1
    return n, unknown


@njit(cache=True)
def _libcaer_cmp_fill(words: np.ndarray, time_base_ns: int, time_mult: int, xs: np.ndarray, ys: np.ndarray,
                      ts: np.ndarray, ps: np.ndarray) -> int:
    """Decode into preallocated arrays; time = time_base + ((high << 12) | low) * time_mult."""
    k = 0
    t_high = 0
    t_low = 0
    ex = 0
    base_y = 0
    vpol = 0
    for i in range(words.shape[0]):
        w = np.int64(words[i])
        code = w >> 12
        if code == _CMP_ADDR_Y:
            xs[k] = ex
            ys[k] = w & 0x7FF
            ps[k] = (w >> 11) & 1
            ts[k] = time_base_ns + ((t_high << 12) | t_low) * time_mult
            k += 1
        elif code == _CMP_ADDR_X:
            ex = w & 0x7FF
        elif code == _CMP_TIME_LOW:
            t_low = w & 0xFFF
        elif code == _CMP_TIME_HIGH:
            t_high = w & 0xFFF
        elif code == _CMP_VECT_BASE_Y:
            base_y = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _CMP_VECT_8:
            t = time_base_ns + ((t_high << 12) | t_low) * time_mult
            for b in range(8):
                if (w >> b) & 1:
                    xs[k] = ex
                    ys[k] = base_y + b
                    ps[k] = vpol
                    ts[k] = t
                    k += 1
            base_y += 8
    return k


@njit(cache=True)
def _evt3_update_high(t: int, time_high: int) -> int:
    """New TIME_HIGH word: keep the roll-over bits (above bit 24), bump them on a real wrap."""
    last = (time_high >> 12) & 0xFFF
    if t < last and last - t > 10:
        time_high += 1 << 24
    return (time_high & ~np.int64((1 << 24) - 1)) | (t << 12)


@njit(cache=True)
def _evt3_decode(words: np.ndarray, state: np.ndarray, width: int, height: int, count_only: bool,
                 xs: np.ndarray, ys: np.ndarray, ts: np.ndarray, ps: np.ndarray,
                 trig_t: np.ndarray, trig_edge: np.ndarray, trig_id: np.ndarray) -> tuple[int, int, int, int]:
    """One pass over an evt3 packet; returns (n_cd, n_trigger, n_out_of_range, n_unknown).

    ``state`` carries validity, time high/low (incl. roll-over bits), y, vector base x and polarity
    across packets; it is updated in place only when ``count_only`` is False. Time is sensor time in
    microseconds (the caller scales it). Events before the first TIME_HIGH+TIME_LOW pair are skipped,
    as the reference decoder does, since their time is unknown.
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
    check = width > 0 and height > 0
    for i in range(words.shape[0]):
        w = np.int64(words[i])
        code = w >> 12
        if valid == 0:
            if code == _E3_TIME_LOW:
                t_low = w & 0xFFF
                if have_high:
                    valid = 1
            elif code == _E3_TIME_HIGH:
                t_high = _evt3_update_high(w & 0xFFF, t_high)
                have_high = 1
            continue
        if code == _E3_ADDR_X:
            x = w & 0x7FF
            if check and (x >= width or ey >= height):
                n_oob += 1
            else:
                if not count_only:
                    xs[n] = x
                    ys[n] = ey
                    ps[n] = (w >> 11) & 1
                    ts[n] = t_high | t_low
                n += 1
        elif code == _E3_ADDR_Y:
            ey = w & 0x7FF
        elif code == _E3_TIME_LOW:
            t_low = w & 0xFFF
        elif code == _E3_TIME_HIGH:
            t_high = _evt3_update_high(w & 0xFFF, t_high)
        elif code == _E3_VECT_BASE_X:
            base_x = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _E3_VECT_12 or code == _E3_VECT_8:
            nbits = 12 if code == _E3_VECT_12 else 8
            for b in range(nbits):
                if (w >> b) & 1:
                    x = base_x + b
                    if check and (x >= width or ey >= height):
                        n_oob += 1
                    else:
                        if not count_only:
                            xs[n] = x
                            ys[n] = ey
                            ps[n] = vpol
                            ts[n] = t_high | t_low
                        n += 1
            base_x += nbits
        elif code == _E3_EXT_TRIGGER:
            if not count_only:
                trig_t[n_trig] = t_high | t_low
                trig_edge[n_trig] = w & 1
                trig_id[n_trig] = (w >> 8) & 0xF
            n_trig += 1
        elif code == _E3_OTHERS or code == _E3_CONT_4 or code == _E3_CONT_12 or code == _E3_PAD:
            pass
        else:
            n_unknown += 1
    if not count_only:
        state[_S_VALID] = valid
        state[_S_TIME_HIGH] = t_high
        state[_S_TIME_LOW] = t_low
        state[_S_Y] = ey
        state[_S_BASE_X] = base_x
        state[_S_POL] = vpol
        state[_S_HAVE_HIGH] = have_high
    return n, n_trig, n_oob, n_unknown
