"""Private numba kernels of the event decoders.

One call per packet: the kernels write the events straight into output arrays owned by the caller
(from offset ``k0``; a packet needs at most one slot per word, except vector words, which are
checked as they come: too little room returns ``ERR_NEED_SPACE`` with the state untouched, and the
caller retries with more). Out-of-sensor events and, when asked, events older than the newest one
kept are dropped and counted in the same pass. Decoder state that survives a packet boundary, the
flags and the per-call counts live in one int64 array ``st`` (slots ``S_*`` / ``O_*`` below).

Clock roll-overs (evt3's 24-bit microsecond clock, libcaer's 31-bit counter) are unwrapped by the
nearest-step rule: a new stamp is read as the previous one plus the signed difference modulo the
counter period, so a real roll-over (the counter passing its top value) is a small step forward,
and a stamp stepping back stays a step back (counted in ``O_BACKSTEPS``) instead of being taken as
a roll-over. This holds while true forward gaps stay below half a period (8.4 s for evt3, 17.9 min
for libcaer), far beyond the camera's clock words (evt3 sends TIME_HIGH every 4.096 ms). The
reference decoder's "step back by at most 10 TIME_HIGH ticks is no roll-over" is the special case
of small steps.

Whole serialized messages are parsed and decoded in one call by :mod:`._msg_kernels`.
"""
from __future__ import annotations

import numpy as np
from numba import njit

INT64_MAX = (1 << 63) - 1
INT64_MIN = -(1 << 63)

# ---- slots of the state array
S_E3_VALID, S_E3_HIGH, S_E3_LOW, S_E3_Y, S_E3_BASE_X, S_E3_POL, S_E3_HAVE_HIGH = 0, 1, 2, 3, 4, 5, 6
S_LC_HAVE, S_LC_LAST, S_LC_TB = 7, 8, 9       # libcaer: have a previous stamp, its unwrapped us, its time_base
S_LAST_T, S_HAVE_LAST, S_DROP = 10, 11, 12     # newest kept time, whether there is one, drop older events
S_OFFSET = 13                                  # added to evt3 times (header alignment)
O_ERR, O_STAMP, O_WIDTH, O_HEIGHT, O_ENC, O_N = 16, 17, 18, 19, 20, 21
O_OOB, O_UNKNOWN, O_TRAILING, O_BACK, O_BACKSTEPS, O_TRIG, O_NEED, O_TB, O_ANY = 22, 23, 24, 25, 26, 27, 28, 29, 30
P_ROS, P_WIDTH, P_HEIGHT, P_K0, P_CAP = 32, 33, 34, 35, 36  # parameters of _decode_msg
S_SAVED = 40  # copy of the state slots 0..O_ERR-1 while a packet is decoded (restored on ERR_NEED_SPACE)
STATE_SIZE = S_SAVED + O_ERR

# ---- error codes (O_ERR)
OK, ERR_TRUNCATED, ERR_UNKNOWN_ENCODING, ERR_TIME_RANGE, ERR_SLOW_PATH, ERR_NEED_SPACE, ERR_BAD_HEADER = range(7)

# ---- encodings, in the order of packet.ENCODINGS
ENC_LIBCAER_CMP, ENC_LIBCAER, ENC_MONO, ENC_EVT3 = 0, 1, 2, 3
#: largest time offset (ns) each encoding can add to time_base inside one packet (libcaer: checked per packet)
MAX_OFFSET_NS = np.array([((1 << 24) - 1) * 1000, 0, (1 << 32) - 1, 0], np.int64)

# libcaer_cmp: time high/low, address x/y, vector base y, vector of 8; everything above 5 is unknown
_CMP_TIME_HIGH, _CMP_TIME_LOW, _CMP_ADDR_X, _CMP_ADDR_Y, _CMP_VECT_BASE_Y, _CMP_VECT_8 = 0, 1, 2, 3, 4, 5
# evt3 codes; 7 (CONTINUED_4), 9 (padding), 14 (OTHERS) and 15 (CONTINUED_12) carry nothing for us
_E3_ADDR_Y, _E3_ADDR_X, _E3_VECT_BASE_X, _E3_VECT_12, _E3_VECT_8 = 0, 2, 3, 4, 5
_E3_TIME_LOW, _E3_TIME_HIGH, _E3_EXT_TRIGGER = 6, 8, 10
_E3_MAX_HIGH = (INT64_MAX // 1000) >> 12   # TIME_HIGH ticks (4096 us) that still fit int64 ns

_LC_PERIOD = 1 << 31
_LC_HALF = 1 << 30


# ------------------------------------------------------------------ little helpers


@njit(cache=True, nogil=True, inline="always")
def _u16(b, j):
    return np.int64(b[j]) | (np.int64(b[j + 1]) << 8)


@njit(cache=True, nogil=True, inline="always")
def _u32(b, j):
    return np.int64(b[j]) | (np.int64(b[j + 1]) << 8) | (np.int64(b[j + 2]) << 16) | (np.int64(b[j + 3]) << 24)


@njit(cache=True, nogil=True, inline="always")
def _limits(width, height):
    """Exclusive coordinate limits; an unknown size (0) accepts every coordinate."""
    if width <= 0 or height <= 0:
        return np.int64(1) << 40, np.int64(1) << 40
    return np.int64(width), np.int64(height)


@njit(cache=True, nogil=True)
def _reset_outputs(st):
    for i in range(O_ERR, P_ROS):
        st[i] = 0


# ------------------------------------------------------------------ payload words


@njit(cache=True, nogil=True)
def _words16(b, off, size):
    """The payload as little-endian uint16 words: a view when aligned, else an aligned copy."""
    n = size // 2
    if (b.ctypes.data + off) % 2 == 0:
        return b[off:off + 2 * n].view(np.uint16)
    w = np.empty(2 * n, np.uint8)  # an aligned copy (ROS 1 messages put the payload anywhere)
    w[:] = b[off:off + 2 * n]
    return w.view(np.uint16)


@njit(cache=True, nogil=True)
def _words32(b, off, size):
    """The payload as little-endian uint32 words (two per 8-byte record): a view when aligned, else a copy."""
    n = size // 8 * 2
    if (b.ctypes.data + off) % 4 == 0:
        return b[off:off + 4 * n].view(np.uint32)
    w = np.empty(4 * n, np.uint8)
    w[:] = b[off:off + 4 * n]
    return w.view(np.uint32)


# ------------------------------------------------------------------ fill passes
#
# Each returns the write index after the packet, -1 when times leave int64 ns, -2 when the outputs
# are too small for a vector word (the caller restores ``st`` and retries with more room). The
# real streams are regular (ADDR_X, ADDR_Y, TIME_LOW, ... repeating), so plain branches ordered by
# frequency predict well and beat branch-free selects here.


@njit(cache=True, nogil=True)
def _fill_libcaer_cmp(words, tb, width, height, st, xs, ys, ts, ps, k0):
    """libcaer_cmp words -> events from ``k0``; time words restart at 0 in every packet."""
    wl, hl = _limits(width, height)
    drop = st[S_DROP] != 0
    last = st[S_LAST_T] if st[S_HAVE_LAST] != 0 else INT64_MIN
    cap = xs.shape[0]
    k = k0
    oob = 0
    back = 0
    unknown = 0
    t_high = 0
    t_low = 0
    ex = 0
    base_y = 0
    vpol = 0
    t = tb
    tok = (not drop) or t >= last
    for i in range(words.shape[0]):
        w = np.int64(words[i])
        code = w >> 12
        if code == _CMP_ADDR_Y:
            ey = w & 0x7FF
            if ex < wl and ey < hl:
                if tok:
                    xs[k] = ex
                    ys[k] = ey
                    ps[k] = (w >> 11) & 1
                    ts[k] = t
                    k += 1
                    if t > last:
                        last = t
                else:
                    back += 1
            else:
                oob += 1
        elif code == _CMP_ADDR_X:
            ex = w & 0x7FF
        elif code == _CMP_TIME_LOW:
            t_low = w & 0xFFF
            t = tb + ((t_high << 12) | t_low) * 1000
            tok = (not drop) or t >= last
        elif code == _CMP_TIME_HIGH:
            t_high = w & 0xFFF
            t = tb + ((t_high << 12) | t_low) * 1000
            tok = (not drop) or t >= last
        elif code == _CMP_VECT_BASE_Y:
            base_y = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _CMP_VECT_8:
            if k + 8 > cap:
                return -2
            for bit in range(8):
                if (w >> bit) & 1:
                    ey = base_y + bit
                    if ex < wl and ey < hl:
                        if tok:
                            xs[k] = ex
                            ys[k] = ey
                            ps[k] = vpol
                            ts[k] = t
                            k += 1
                            if t > last:
                                last = t
                        else:
                            back += 1
                    else:
                        oob += 1
            base_y += 8
        else:
            unknown += 1
    st[O_OOB] += oob
    st[O_BACK] += back
    st[O_UNKNOWN] += unknown
    if k > k0:
        st[S_LAST_T] = last
        st[S_HAVE_LAST] = 1
    return k


@njit(cache=True, nogil=True)
def _fill_libcaer(words, tb, width, height, st, xs, ys, ts, ps, k0):
    """libcaer records (uint32 address, int32 us), unwrapping the 31-bit counter across packets."""
    wl, hl = _limits(width, height)
    drop = st[S_DROP] != 0
    last = st[S_LAST_T] if st[S_HAVE_LAST] != 0 else INT64_MIN
    if st[S_LC_TB] != tb:  # a new time base restarts the counter
        st[S_LC_HAVE] = 0
    have = st[S_LC_HAVE] != 0
    prev = st[S_LC_LAST]
    k = k0
    oob = 0
    back = 0
    steps = 0
    top = np.int64(0)
    for i in range(words.shape[0] // 2):
        d = np.int64(words[2 * i])
        s = np.int64(words[2 * i + 1]) & (_LC_PERIOD - 1)
        if have:
            delta = ((s - prev + _LC_HALF) & (_LC_PERIOD - 1)) - _LC_HALF
            a = prev + delta
            if delta < 0:
                steps += 1
                if a < 0:
                    a = s
        else:
            a = s
            have = True
        prev = a
        if a > top:
            top = a
        x = (d >> 17) & 0x7FFF
        y = (d >> 2) & 0x7FFF
        t = tb + a * 1000
        if x < wl and y < hl:
            if (not drop) or t >= last:
                xs[k] = x
                ys[k] = y
                ps[k] = (d >> 1) & 1
                ts[k] = t
                k += 1
                if t > last:
                    last = t
            else:
                back += 1
        else:
            oob += 1
    if top > (INT64_MAX - tb) // 1000:
        return -1
    st[S_LC_HAVE] = 1 if have else 0
    st[S_LC_LAST] = prev
    st[S_LC_TB] = tb
    st[O_OOB] += oob
    st[O_BACK] += back
    st[O_BACKSTEPS] += steps
    if k > k0:
        st[S_LAST_T] = last
        st[S_HAVE_LAST] = 1
    return k


@njit(cache=True, nogil=True)
def _fill_mono(words, tb, width, height, st, xs, ys, ts, ps, k0):
    """mono uint64 words ``p << 63 | y << 48 | x << 32 | dt_ns`` (read as low, high uint32)."""
    wl, hl = _limits(width, height)
    drop = st[S_DROP] != 0
    last = st[S_LAST_T] if st[S_HAVE_LAST] != 0 else INT64_MIN
    k = k0
    oob = 0
    back = 0
    for i in range(words.shape[0] // 2):
        lo = np.int64(words[2 * i])
        hi = np.int64(words[2 * i + 1])
        x = hi & 0xFFFF
        y = (hi >> 16) & 0x7FFF
        t = tb + lo
        if x < wl and y < hl:
            if (not drop) or t >= last:
                xs[k] = x
                ys[k] = y
                ps[k] = hi >> 31
                ts[k] = t
                k += 1
                if t > last:
                    last = t
            else:
                back += 1
        else:
            oob += 1
    st[O_OOB] += oob
    st[O_BACK] += back
    if k > k0:
        st[S_LAST_T] = last
        st[S_HAVE_LAST] = 1
    return k


@njit(cache=True, nogil=True, inline="always")
def _unwrap_high(v, high, have_high):
    """New absolute TIME_HIGH (in 4096 us ticks) for the 12-bit value ``v``: nearest step, see module doc.

    Returns (new value, 1 if it is a step back else 0).
    """
    if not have_high:
        return v, 0
    delta = ((v - (high & 0xFFF) + 2048) & 0xFFF) - 2048
    nh = high + delta
    if nh < 0:  # back beyond the first epoch: keep the clock's own value
        nh = v
    return nh, 1 if delta < 0 else 0


@njit(cache=True, nogil=True)
def _fill_evt3(words, width, height, st, xs, ys, ts, ps, k0, tt, te, ti):
    """evt3 words -> events (camera clock in ns, plus ``S_OFFSET``) and triggers; state in ``st``.

    Events before the first TIME_HIGH + TIME_LOW pair of the stream are skipped, as the reference
    decoder does, since their time is unknown. Triggers beyond ``len(tt)`` are only counted.
    """
    wl, hl = _limits(width, height)
    drop = st[S_DROP] != 0
    last = st[S_LAST_T] if st[S_HAVE_LAST] != 0 else INT64_MIN
    valid = st[S_E3_VALID] != 0
    high = st[S_E3_HIGH]
    low = st[S_E3_LOW]
    ey = st[S_E3_Y]
    base_x = st[S_E3_BASE_X]
    vpol = st[S_E3_POL]
    have_high = st[S_E3_HAVE_HIGH] != 0
    offset = st[S_OFFSET]
    nw = words.shape[0]
    cap = xs.shape[0]
    k = k0
    oob = 0
    back = 0
    unknown = 0
    steps = 0
    n_trig = 0
    i = 0
    while not valid and i < nw:  # prologue: find the first complete time
        w = np.int64(words[i])
        code = w >> 12
        i += 1
        if code == _E3_TIME_LOW:
            low = w & 0xFFF
            valid = have_high
        elif code == _E3_TIME_HIGH:
            high, step = _unwrap_high(w & 0xFFF, high, have_high)
            steps += step
            have_high = True
    t = ((high << 12) | low) * 1000 + offset
    tok = (not drop) or t >= last
    for j in range(i, nw):
        w = np.int64(words[j])
        code = w >> 12
        if code == _E3_ADDR_X:
            x = w & 0x7FF
            if x < wl and ey < hl:
                if tok:
                    xs[k] = x
                    ys[k] = ey
                    ps[k] = (w >> 11) & 1
                    ts[k] = t
                    k += 1
                    if t > last:
                        last = t
                else:
                    back += 1
            else:
                oob += 1
        elif code == _E3_ADDR_Y:
            ey = w & 0x7FF
        elif code == _E3_TIME_LOW:
            low = w & 0xFFF
            t = ((high << 12) | low) * 1000 + offset
            tok = (not drop) or t >= last
        elif code == _E3_TIME_HIGH:
            high, step = _unwrap_high(w & 0xFFF, high, True)
            steps += step
            t = ((high << 12) | low) * 1000 + offset
            tok = (not drop) or t >= last
        elif code == 14 or code == 15 or code == 7 or code == 9:
            pass  # OTHERS, CONTINUED_12, CONTINUED_4, padding: nothing for us
        elif code == _E3_VECT_BASE_X:
            base_x = w & 0x7FF
            vpol = (w >> 11) & 1
        elif code == _E3_VECT_12 or code == _E3_VECT_8:
            nbits = 12 if code == _E3_VECT_12 else 8
            if k + nbits > cap:
                return -2
            for bit in range(nbits):
                if (w >> bit) & 1:
                    x = base_x + bit
                    if x < wl and ey < hl:
                        if tok:
                            xs[k] = x
                            ys[k] = ey
                            ps[k] = vpol
                            ts[k] = t
                            k += 1
                            if t > last:
                                last = t
                        else:
                            back += 1
                    else:
                        oob += 1
            base_x += nbits
        elif code == _E3_EXT_TRIGGER:
            if n_trig < tt.shape[0]:
                tt[n_trig] = t
                te[n_trig] = w & 1
                ti[n_trig] = (w >> 8) & 0xF
            n_trig += 1
        else:
            unknown += 1
    if high > _E3_MAX_HIGH:
        return -1
    st[S_E3_VALID] = 1 if valid else 0
    st[S_E3_HIGH] = high
    st[S_E3_LOW] = low
    st[S_E3_Y] = ey
    st[S_E3_BASE_X] = base_x
    st[S_E3_POL] = vpol
    st[S_E3_HAVE_HIGH] = 1 if have_high else 0
    st[O_OOB] += oob
    st[O_BACK] += back
    st[O_UNKNOWN] += unknown
    st[O_BACKSTEPS] += steps
    st[O_TRIG] += n_trig
    if k > k0:
        st[S_LAST_T] = last
        st[S_HAVE_LAST] = 1
    return k


@njit(cache=True, nogil=True)
def _trigger_count(b, off, size):
    """Number of evt3 EXT_TRIGGER words in a payload (to size the trigger outputs)."""
    n = 0
    for i in range(size // 2):
        n += (np.int64(b[off + 2 * i + 1]) >> 4) == _E3_EXT_TRIGGER
    return n


# ------------------------------------------------------------------ payload entry point


@njit(cache=True, nogil=True)
def _decode_payload(enc, b, off, size, tb, width, height, st, xs, ys, ts, ps, k0, tt, te, ti):
    """Decode one payload into the outputs from ``k0``; returns an error code, counts in ``st``.

    The outputs need at least ``k0 + words + 1`` slots; when they are too small (also later, for a
    vector word) nothing is decoded, ``O_NEED`` says how many slots to provide and
    ``ERR_NEED_SPACE`` is returned with the decoder state unchanged.
    """
    word = 2 if enc == ENC_LIBCAER_CMP or enc == ENC_EVT3 else 8
    n_words = size // word
    if k0 + n_words + 1 > xs.shape[0]:
        st[O_NEED] = n_words + 1
        return ERR_NEED_SPACE
    st[S_SAVED:S_SAVED + O_ERR] = st[:O_ERR]
    st[O_TRAILING] = size % word
    if enc == ENC_LIBCAER_CMP:
        k = _fill_libcaer_cmp(_words16(b, off, size), tb, width, height, st, xs, ys, ts, ps, k0)
    elif enc == ENC_LIBCAER:
        k = _fill_libcaer(_words32(b, off, size), tb, width, height, st, xs, ys, ts, ps, k0)
    elif enc == ENC_MONO:
        k = _fill_mono(_words32(b, off, size), tb, width, height, st, xs, ys, ts, ps, k0)
    else:
        k = _fill_evt3(_words16(b, off, size), width, height, st, xs, ys, ts, ps, k0, tt, te, ti)
    if k == -2:
        st[:O_ERR] = st[S_SAVED:S_SAVED + O_ERR]
        for i in range(O_ERR, P_ROS):
            st[i] = 0
        st[O_NEED] = 12 * n_words + 1
        return ERR_NEED_SPACE
    if k < 0:
        return ERR_TIME_RANGE
    st[O_N] = k - k0
    st[O_ANY] = st[O_OOB] | st[O_UNKNOWN] | st[O_TRAILING] | st[O_BACK] | st[O_BACKSTEPS] | st[O_TRIG]
    return OK


# ------------------------------------------------------------------ dvs arrays and ordering helpers


@njit(cache=True, nogil=True)
def _dvs_fields(ex: np.ndarray, ey: np.ndarray, esec: np.ndarray, ensec: np.ndarray, ep: np.ndarray,
                xs: np.ndarray, ys: np.ndarray, ts: np.ndarray, ps: np.ndarray, offset: int) -> None:
    """Copy strided dvs Event fields into the output arrays from ``offset`` on, in one pass."""
    for i in range(ex.shape[0]):
        xs[offset + i] = ex[i]
        ys[offset + i] = ey[i]
        ts[offset + i] = np.int64(esec[i]) * 1_000_000_000 + np.int64(ensec[i])
        ps[offset + i] = 1 if ep[i] != 0 else 0


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _keep_forward(t: np.ndarray, last_t: int) -> np.ndarray:
    """Mask of the events not older than the newest one before them."""
    keep = np.empty(t.shape[0], np.bool_)
    m = last_t
    for i in range(t.shape[0]):
        keep[i] = t[i] >= m
        if keep[i]:
            m = t[i]
    return keep
