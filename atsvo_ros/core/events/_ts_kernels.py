"""Private numba kernels of the time surfaces (see :mod:`atsvo_ros.core.events.time_surface`)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

NEVER = np.iinfo(np.int64).min  # t_last of a pixel that never fired


@njit(cache=True, nogil=True)
def _set_last(t_last: np.ndarray, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> int:
    """Per-pixel latest timestamp; skips (and counts) events outside or older than their pixel's last."""
    h, w = t_last.shape
    skipped = 0
    for i in range(t.shape[0]):
        xi = np.int64(x[i])
        yi = np.int64(y[i])
        if xi >= w or yi >= h:
            skipped += 1
            continue
        if t[i] >= t_last[yi, xi]:
            t_last[yi, xi] = t[i]
        else:
            skipped += 1
    return skipped


@njit(cache=True, nogil=True)
def _set_last_padded(t_last: np.ndarray, x: np.ndarray, y: np.ndarray, t: np.ndarray, w: int, h: int, wp: int,
                     pad: int) -> int:
    """:func:`_set_last` on the flat surface padded by ``pad`` pixels (row length ``wp``): the whole per-event
    work of the ``fire_age`` ATS, whose decay is computed from these times at render time."""
    skipped = 0
    for i in range(t.shape[0]):
        qx = np.int64(x[i])
        qy = np.int64(y[i])
        if qx >= w or qy >= h:
            skipped += 1
            continue
        qi = np.uint64((qy + pad) * wp + qx + pad)
        te = t[i]
        if te >= t_last[qi]:
            t_last[qi] = te
        else:
            skipped += 1
    return skipped


# Per-pixel ATS state: a recency list of n distinct ring indices packed as 4-bit nibbles in an int64, nibble 0
# = the neighbour that fired last. It starts as 0, 1, .., n-1 (placeholders: their pixels have not fired, so
# t_last tells them apart from members); the first neighbour to fire takes the front and pushes one of them out.
_ONES = np.int64(0x1111111111111111)  # 1 in every nibble
_NIB_HIGH = np.array([sum(8 << (4 * k) for k in range(c)) for c in range(17)], np.uint64).view(np.int64)
# _NIB_HIGH[c]: the top bit of each of the first c nibbles


def _ring_list_init(n: int) -> np.int64:
    """The initial recency list: ring indices 0 .. n-1 as placeholders (as int64 bits)."""
    return np.array([sum(k << (4 * k) for k in range(n))], np.uint64).view(np.int64)[0]


@njit(cache=True, nogil=True, inline="always")
def _ring_touch(rec: np.ndarray, p: np.uint64, j: int, high: int, tail_bit: int) -> None:
    """Ring neighbour ``j`` of pixel ``p`` fired: move ``j`` to the front of p's recency list.

    Branch-free: a zero-nibble search (SWAR) of ``list ^ j`` gives, as the lowest set bit, the top bit of j's
    nibble if j is listed; ``| tail_bit`` makes it nibble n-1 (the least recent member, or a placeholder)
    otherwise. That nibble leaves, the ones before it move back by one and j enters at the front. Relies on
    int64 arithmetic wrapping around (as numba's does): at n = 16 the tail bit is the sign bit.
    """
    lst = rec[p]
    d = lst ^ (j * _ONES)
    z = ((d - _ONES) & ~d & high) | tail_bit
    upto = ((z & -z) << 1) - 1  # nibbles 0 .. position of the leaving one
    rec[p] = (lst ^ ((lst ^ (lst << 4)) & upto)) | j  # those take their predecessor's value, nibble 0 then j


@njit(cache=True, nogil=True)
def _ats_update(t_last: np.ndarray, rec: np.ndarray, x: np.ndarray, y: np.ndarray, t: np.ndarray,
                off: np.ndarray, n: int, w: int, h: int, wp: int, pad: int) -> int:
    """Per-pixel last time plus, for every pixel, which ring neighbours are its n most recent (active) ones.

    The arrays are flat over the surface padded by ``pad`` (>= ring radius) pixels on each side, row length
    ``wp``, so that ring neighbours need no bounds checks (padding pixels keep state nobody reads); ``off[j]``
    is ring offset j as a flat index step. Events come in time order, so the event at q is the newest value
    for every pixel p = q - off[j] whose ring contains q: j moves to the front of p's recency list
    (:func:`_ring_touch`), whose active entries are then p's n latest distinct active neighbours -- O(1) per
    neighbour; their times are read from ``t_last`` at render time. Events older than their pixel's last one,
    or outside the surface, are skipped (returned count).
    """
    m = off.shape[0]
    skipped = 0
    high = _NIB_HIGH[n]
    tail_bit = np.int64(1) << (4 * n - 1)
    for i in range(t.shape[0]):
        qx = np.int64(x[i])
        qy = np.int64(y[i])
        te = t[i]
        if qx >= w or qy >= h:
            skipped += 1
            continue
        qi = (qy + pad) * wp + qx + pad
        if te < t_last[np.uint64(qi)]:
            skipped += 1
            continue
        t_last[np.uint64(qi)] = te
        for j in range(m):
            _ring_touch(rec, np.uint64(qi - off[j]), j, high, tail_bit)
    return skipped


@njit(cache=True, nogil=True)
def _ring_sums(t_last: np.ndarray, rec: np.ndarray, off: np.ndarray, n: int, row: int, w: int, t_ns: int,
               t_min: int, buf: np.ndarray) -> int:
    """For the pixels of row .. row + w - 1 that fired at or after ``t_min`` (their count returned), in order:
    ``buf[0]`` their x, ``buf[1]`` their age (ns, clamped at 0), ``buf[2]`` the sum of the ages (clamped at 0)
    of their n latest active ring neighbours (exact in int64; equals a float sum of the ages while they stay
    below 2**53 ns) and ``buf[3]`` how many there are. A pass of its own, so that the scattered loads of many
    pixels overlap and Eq. 1 runs over these only, vectorised (:func:`_eq1`)."""
    m = off.shape[0]
    c = np.uint64(0)
    for xx in range(w):
        p = np.uint64(row + xx)
        tl = t_last[p]
        if tl < t_min:
            continue
        k = 0
        s = np.int64(0)
        if n == m:  # every active ring neighbour counts: no need for the list
            for j in range(m):
                v = t_last[p + np.uint64(off[j])]
                if v != NEVER:
                    k += 1
                    s += max(t_ns - v, 0)
        else:
            lst = rec[p]
            while k < n:  # members first, then placeholders (never fired)
                v = t_last[p + np.uint64(off[lst & 15])]
                if v == NEVER:
                    break
                s += max(t_ns - v, 0)
                lst >>= 4
                k += 1
        buf[0, c] = xx
        buf[1, c] = max(t_ns - tl, 0)
        buf[2, c] = s
        buf[3, c] = k
        c += np.uint64(1)
    return int(c)


@njit(cache=True, nogil=True)
def _upwind_sums(t_last: np.ndarray, off: np.ndarray, row: int, w: int, t_ns: int, t_min: int, clip_ns: int,
                 buf: np.ndarray) -> int:
    """``fire_age`` counterpart of :func:`_ring_sums`: for the pixels of the row that fired at or after ``t_min``,
    ``buf[2]`` is the sum of ``min(t_last(p) - t_last(q), clip_ns)`` over the ring neighbours ``q`` that fired
    at or before ``p`` (how long before ``p`` they had fired, as they still show it) and ``buf[3]`` their count.
    Branch-free over the ring, so the 16 loads of a pixel overlap."""
    m = off.shape[0]
    c = np.uint64(0)
    for xx in range(w):
        p = np.uint64(row + xx)
        tl = t_last[p]
        if tl < t_min:
            continue
        k = np.int64(0)
        s = np.int64(0)
        for j in range(m):
            v = t_last[p + np.uint64(off[j])]
            d = tl - v
            up = (v != NEVER) & (d >= 0)
            s += min(d, clip_ns) if up else 0
            k += 1 if up else 0
        buf[0, c] = xx
        buf[1, c] = max(t_ns - tl, 0)
        buf[2, c] = s
        buf[3, c] = k
        c += np.uint64(1)
    return int(c)


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93145751953125e-1  # ln 2 split in two (Cody-Waite): q * _LN2_HI is exact for |q| < 2**11
_LN2_LO = 1.42860682030941723212e-6
_X_MAX = 87.0  # exp(-87) * 255 is still a normal float32; beyond, Eq. 1 gives 0


@njit(cache=True, nogil=True, error_model="numpy")
def _eq1(c: int, buf: np.ndarray, tau_l_s: float, tau_u_s: float, mode: int, gain: float, cutoff_age_s: float,
         keep_old: bool, val: np.ndarray, tau_row: np.ndarray, scale_bits: np.ndarray) -> None:
    """Eq. 1-2 for the ``c`` pixels listed in ``buf`` (see :func:`_ring_sums`, :func:`_upwind_sums`): ``tau_row``
    gets tau and the value is ``val * scale`` with ``scale`` the float64 whose bits are ``scale_bits`` (a power
    of two). tau is ``clip(gain * mean, tau_l, tau_u)`` of the listed neighbour statistic (modes 0 mean_age with
    gain 1, 2 fire_age) or ``max(tau_u - mean, tau_l)`` (mode 1, eq2_printed); ``tau_u`` without neighbours.

    Branch-free, so that it vectorises: ``exp(-x) = 2**-q exp(-r)`` with ``q = round(x / ln 2)``,
    ``|r| <= ln(2) / 2`` and a degree-10 Taylor polynomial for ``exp(-r)`` (relative error < 1e-12, far
    below float32 resolution); ``2**-q`` is assembled in the exponent bits. ``error_model="numpy"``: no
    ZeroDivisionError checks (tau > 0, k clamped to >= 1). Pixels older than ``cutoff_age_s`` give 0
    unless ``keep_old``.
    """
    for i in range(c):
        k = buf[3, i]
        mean_age = float(buf[2, i]) * 1e-9 / max(k, 1)
        if mode == 1:
            tau = max(tau_u_s - mean_age, tau_l_s)
        else:
            tau = min(max(gain * mean_age, tau_l_s), tau_u_s)
        tau = tau if k > 0 else tau_u_s
        tau_row[i] = tau
        age_s = float(buf[1, i]) * 1e-9
        x = age_s / tau
        keep = x <= _X_MAX and (keep_old or age_s <= cutoff_age_s)
        x = min(x, _X_MAX)
        q = math.floor(x * _LOG2E + 0.5)
        r = (q * _LN2_HI - x) + q * _LN2_LO  # = -(x - q ln 2)
        e = 1.0 + r * (1.0 + r * (1 / 2 + r * (1 / 6 + r * (1 / 24 + r * (1 / 120 + r * (
            1 / 720 + r * (1 / 5040 + r * (1 / 40320 + r * (1 / 362880 + r * (1 / 3628800))))))))))
        scale_bits[i] = (1023 - np.int64(q)) << 52
        val[i] = 255.0 * e if keep else 0.0


@njit(cache=True, nogil=True)
def _ats_render(t_last: np.ndarray, rec: np.ndarray, off: np.ndarray, n: int, w: int, h: int, wp: int, pad: int,
                t_ns: int, tau_l_s: float, tau_u_s: float, mode: int, gain: float, cutoff_age_s: float,
                out: np.ndarray, tau_out: np.ndarray, want_tau: bool) -> None:
    """Eq. 1 with the per-pixel tau of Eq. 2 (mode 0: clip(mean age); mode 1: printed max(tau_u - age, tau_l);
    mode 2: clip(gain x mean age of the ring at the pixel's own firing, see :func:`_upwind_sums`)).

    Modes 0/1: the mean age runs over the active entries of p's recency list (see :func:`_ats_update`), read
    from the padded flat ``t_last`` one row at a time (:func:`_ring_sums`). Mode 2 reads every ring neighbour
    (``rec`` unused). Then Eq. 1 over the listed pixels at once (:func:`_eq1`). Pixels that never fired are 0
    (tau NaN); pixels older than ``cutoff_age_s`` (where even tau_u leaves < 0.5 grey levels) are 0 without
    evaluating tau unless ``want_tau``.
    """
    buf = np.empty((4, w), np.int64)
    val = np.empty(w, np.float64)
    tau_row = np.empty(w, np.float64)
    scale_bits = np.empty(w, np.int64)
    scale = scale_bits.view(np.float64)
    # every pixel that fired if want_tau, else those within the cutoff (with 1 ms to spare for rounding)
    t_min = NEVER + 1 if want_tau else t_ns - int(math.ceil(cutoff_age_s * 1e9)) - 1_000_000
    clip_ns = int(round(tau_u_s * 1e9))
    for yy in range(h):
        if mode == 2:
            c = _upwind_sums(t_last, off, (yy + pad) * wp + pad, w, t_ns, t_min, clip_ns, buf)
        else:
            c = _ring_sums(t_last, rec, off, n, (yy + pad) * wp + pad, w, t_ns, t_min, buf)
        _eq1(c, buf, tau_l_s, tau_u_s, mode, gain, cutoff_age_s, want_tau, val, tau_row, scale_bits)
        o = out[yy]
        if c == w:  # every pixel listed, in order
            for i in range(w):
                o[i] = val[i] * scale[i]
        else:
            o[:] = 0.0
            for i in range(c):
                o[buf[0, i]] = val[i] * scale[i]
        if want_tau:
            to = tau_out[yy]
            if c == w:
                to[:] = tau_row
            else:
                to[:] = np.nan
                for i in range(c):
                    to[buf[0, i]] = tau_row[i]


# ---------------------------------------------------------------------------- fire_age, fast render path

_LN2_HI32 = 0.693359375  # ln 2 split for float32 (Cody-Waite): q * _LN2_HI32 is exact for q < 2**15
_LN2_LO32 = -2.12194440e-4


@njit(cache=True, nogil=True, error_model="numpy")
def _ages_f32(t_last: np.ndarray, t_ns: int, sat_s: float, age: np.ndarray) -> None:
    """``t_ns - t_last`` in seconds as float32 over the (padded, flat) surface, saturated at ``sat_s``; NaN where
    a pixel never fired (every comparison with it is false, so it never counts as a neighbour)."""
    sat = np.float32(sat_s)
    for i in range(t_last.shape[0]):
        v = t_last[i]
        a = np.float32(min(float(t_ns - v) * 1e-9, sat))
        age[i] = a if v != NEVER else np.float32(np.nan)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"}, inline="always")
def _fire_age_block(age: np.ndarray, off: np.ndarray, p0: int, n: int, clip_s: float, tau_l_s: float, tau_u_s: float,
                    gain: float, cutoff_s: float, val: np.ndarray, bits: np.ndarray) -> None:
    """``fire_age`` Eq. 1-2 for ``n`` consecutive pixels from flat index ``p0`` with a 16-point ring, in float32.

    Written out over the 16 ring offsets so that the loop runs across pixels: every neighbour load is then
    contiguous and the whole body vectorises (16 float32 lanes). A neighbour counts when its age is at least the
    pixel's (it fired at or before it; NaN never does); its gap ``age_q - age_p = t_p - t_q`` is clipped at
    ``clip_s``. ``tau = clip(gain * mean gap, tau_l, tau_u)`` is formed as ``1 / tau = clip(k / (gain * sum))``
    (one division), ``tau_u`` without a neighbour. Eq. 1 as in :func:`_eq1` in float32 (Cody-Waite reduction,
    degree-7 Taylor polynomial: relative error < 1e-8); ``val * 2**-q`` is the value, ``2**-q`` built in
    ``bits``. Pixels older than ``cutoff_s`` (or never fired) give 0. ``reassoc`` only reorders the 16 sums.
    """
    o0 = np.uint64(off[0])
    o1 = np.uint64(off[1])
    o2 = np.uint64(off[2])
    o3 = np.uint64(off[3])
    o4 = np.uint64(off[4])
    o5 = np.uint64(off[5])
    o6 = np.uint64(off[6])
    o7 = np.uint64(off[7])
    o8 = np.uint64(off[8])
    o9 = np.uint64(off[9])
    o10 = np.uint64(off[10])
    o11 = np.uint64(off[11])
    o12 = np.uint64(off[12])
    o13 = np.uint64(off[13])
    o14 = np.uint64(off[14])
    o15 = np.uint64(off[15])
    zero = np.float32(0.0)
    one = np.float32(1.0)
    clip = np.float32(clip_s)
    g = np.float32(gain)
    inv_l = np.float32(1.0 / tau_l_s)
    inv_u = np.float32(1.0 / tau_u_s)
    cut = np.float32(cutoff_s)
    for i in range(n):
        p = np.uint64(p0 + i)
        a = age[p]
        s = zero
        k = zero
        d = age[p + o0] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o1] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o2] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o3] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o4] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o5] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o6] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o7] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o8] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o9] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o10] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o11] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o12] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o13] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o14] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        d = age[p + o15] - a
        up = d >= zero
        s += min(d if up else zero, clip)
        k += one if up else zero
        inv = min(max(k / (g * s), inv_u), inv_l) if k > zero else inv_u
        x = max(a, zero) * inv
        keep = (a <= cut) & (x <= np.float32(_X_MAX))
        x = min(x, np.float32(_X_MAX))
        q = np.floor(x * np.float32(_LOG2E) + np.float32(0.5))
        r = (q * np.float32(_LN2_HI32) - x) + q * np.float32(_LN2_LO32)  # = -(x - q ln 2)
        e = one + r * (one + r * (np.float32(1 / 2) + r * (np.float32(1 / 6) + r * (np.float32(1 / 24) + r * (
            np.float32(1 / 120) + r * (np.float32(1 / 720) + r * np.float32(1 / 5040)))))))
        bits[np.uint64(i)] = (np.int32(127) - np.int32(q)) << 23
        val[np.uint64(i)] = np.float32(255.0) * e if keep else zero


_FA_BLOCK = 16  # pixels per block of the fire_age render (one 512-bit vector of float32)


@njit(cache=True, nogil=True, error_model="numpy")
def _fire_age_render(t_last: np.ndarray, off: np.ndarray, w: int, h: int, wp: int, pad: int, t_ns: int,
                     tau_l_s: float, tau_u_s: float, gain: float, cutoff_s: float, age: np.ndarray,
                     out: np.ndarray) -> None:
    """Render of the ``fire_age`` ATS with a 16-point ring (the FAST circle): float32 ages once
    (:func:`_ages_f32`, saturated where every gap is clipped anyway), then per row blocks of 16 pixels, skipped
    (zero) when none is within the cutoff, through :func:`_fire_age_block`. Same result as the int64 path of
    :func:`_ats_render` up to float32 rounding of the ages (relative ~1e-7 of the age, ~1e-5 of tau)."""
    # a pixel within the cutoff sees every neighbour older than cutoff + clip as clipped: saturate there
    _ages_f32(t_last, t_ns, cutoff_s + 2.0 * tau_u_s, age)
    block = _FA_BLOCK
    val = np.empty(w + block, np.float32)
    bits = np.empty(w + block, np.int32)
    scale = bits.view(np.float32)
    cut = np.float32(cutoff_s)
    for yy in range(h):
        row = (yy + pad) * wp + pad
        o = out[yy]
        x0 = 0
        while x0 < w:
            n = min(block, w - x0)
            active = False
            for i in range(n):
                active |= age[np.uint64(row + x0 + i)] <= cut
            if active:  # extend over the following active blocks: one longer vector loop
                x1 = x0 + n
                while x1 < w:
                    n1 = min(block, w - x1)
                    more = False
                    for i in range(n1):
                        more |= age[np.uint64(row + x1 + i)] <= cut
                    if not more:
                        break
                    x1 += n1
                _fire_age_block(age, off, row + x0, x1 - x0, tau_u_s, tau_l_s, tau_u_s, gain, cutoff_s, val, bits)
                for i in range(x1 - x0):
                    o[np.uint64(x0 + i)] = val[np.uint64(i)] * scale[np.uint64(i)]
                x0 = x1
            else:
                for i in range(n):
                    o[np.uint64(x0 + i)] = 0.0
                x0 += n


@njit(cache=True, nogil=True)
def _constant_render(t_last: np.ndarray, t_ns: int, tau_s: float, out: np.ndarray) -> None:
    """Eq. 1 with one tau for every pixel."""
    h, w = t_last.shape
    inv = 1.0 / tau_s
    for yy in range(h):
        for xx in range(w):
            tl = t_last[yy, xx]
            if tl == NEVER:
                out[yy, xx] = 0.0
            else:
                out[yy, xx] = 255.0 * np.exp(-max(t_ns - tl, 0) * 1e-9 * inv)


@njit(cache=True, nogil=True)
def _sits_update(surface: np.ndarray, x: np.ndarray, y: np.ndarray, radius: int, w: int, h: int, wp: int) -> int:
    """Speed-invariant time surface (Manderscheid et al. 2019, Alg. 1), polarities merged.

    For each event at p: every neighbour q in the (2r+1)^2 patch with S(q) >= S(p) and S(q) > 0 loses 1, then
    S(p) = (2r+1)^2. ``surface`` is flat (row length ``wp``, int16: values never exceed 21^2) and padded by
    ``radius`` on every side; padding cells stay 0, so the test ``S(q) >= max(S(p), 1)`` (the two conditions in
    one, on integers) leaves them alone and no bounds checks are needed. Returns the number of events outside
    the surface.
    """
    full = np.int16((2 * radius + 1) * (2 * radius + 1))
    n = 2 * radius + 1
    skipped = 0
    for i in range(x.shape[0]):
        px = np.int64(x[i])
        py = np.int64(y[i])
        if px >= w or py >= h:
            skipped += 1
            continue
        c = np.uint64((py + radius) * wp + px + radius)
        sp = max(surface[c], np.int16(1))
        for dy in range(n):
            b = np.uint64((py + dy) * wp + px)
            for k in range(n):
                v = surface[b + np.uint64(k)]
                surface[b + np.uint64(k)] = v - np.int16(v >= sp)
        surface[c] = full
    return skipped
