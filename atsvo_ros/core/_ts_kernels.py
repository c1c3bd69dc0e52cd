"""Private numba kernels of the time surfaces (see :mod:`atsvo_ros.core.time_surface`)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

NEVER = np.iinfo(np.int64).min  # t_last of a pixel that never fired


@njit(cache=True)
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


# Per-pixel ATS state: a recency list of n distinct ring indices packed as 4-bit nibbles in an int64, nibble 0
# = the neighbour that fired last. It starts as 0, 1, .., n-1 (placeholders: their pixels have not fired, so
# t_last tells them apart from members); the first neighbour to fire takes the front and pushes one of them out.
_ONES = np.int64(0x1111111111111111)  # 1 in every nibble
_NIB_HIGH = np.array([sum(8 << (4 * k) for k in range(c)) for c in range(17)], np.uint64).view(np.int64)
# _NIB_HIGH[c]: the top bit of each of the first c nibbles


def _ring_list_init(n: int) -> np.int64:
    """The initial recency list: ring indices 0 .. n-1 as placeholders (as int64 bits)."""
    return np.array([sum(k << (4 * k) for k in range(n))], np.uint64).view(np.int64)[0]


@njit(cache=True, inline="always")
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


@njit(cache=True)
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


@njit(cache=True)
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


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93145751953125e-1  # ln 2 split in two (Cody-Waite): q * _LN2_HI is exact for |q| < 2**11
_LN2_LO = 1.42860682030941723212e-6
_X_MAX = 87.0  # exp(-87) * 255 is still a normal float32; beyond, Eq. 1 gives 0


@njit(cache=True, error_model="numpy")
def _eq1(c: int, buf: np.ndarray, tau_l_s: float, tau_u_s: float, mode: int, cutoff_age_s: float, keep_old: bool,
         val: np.ndarray, tau_row: np.ndarray, scale_bits: np.ndarray) -> None:
    """Eq. 1-2 for the ``c`` pixels listed in ``buf`` (see :func:`_ring_sums`): ``tau_row`` gets tau and the
    value is ``val * scale`` with ``scale`` the float64 whose bits are ``scale_bits`` (a power of two).

    Branch-free, so that it vectorises: ``exp(-x) = 2**-q exp(-r)`` with ``q = round(x / ln 2)``,
    ``|r| <= ln(2) / 2`` and a degree-10 Taylor polynomial for ``exp(-r)`` (relative error < 1e-12, far
    below float32 resolution); ``2**-q`` is assembled in the exponent bits. ``error_model="numpy"``: no
    ZeroDivisionError checks (tau > 0, k clamped to >= 1). Pixels older than ``cutoff_age_s`` give 0
    unless ``keep_old``.
    """
    for i in range(c):
        k = buf[3, i]
        mean_age = float(buf[2, i]) * 1e-9 / max(k, 1)
        if mode == 0:
            tau = min(max(mean_age, tau_l_s), tau_u_s)
        else:
            tau = max(tau_u_s - mean_age, tau_l_s)
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


@njit(cache=True)
def _ats_render(t_last: np.ndarray, rec: np.ndarray, off: np.ndarray, n: int, w: int, h: int, wp: int, pad: int,
                t_ns: int, tau_l_s: float, tau_u_s: float, mode: int, cutoff_age_s: float, out: np.ndarray,
                tau_out: np.ndarray, want_tau: bool) -> None:
    """Eq. 1 with the per-pixel tau of Eq. 2 (mode 0: clip(mean age); mode 1: printed max(tau_u - age, tau_l)).

    The mean age runs over the active entries of p's recency list (see :func:`_ats_update`), read from the
    padded flat ``t_last`` one row at a time (:func:`_ring_sums`), then Eq. 1 over the listed pixels at once
    (:func:`_eq1`). Pixels that never fired are 0 (tau NaN); pixels older than ``cutoff_age_s`` (where even
    tau_u leaves < 0.5 grey levels) are 0 without evaluating tau unless ``want_tau``.
    """
    buf = np.empty((4, w), np.int64)
    val = np.empty(w, np.float64)
    tau_row = np.empty(w, np.float64)
    scale_bits = np.empty(w, np.int64)
    scale = scale_bits.view(np.float64)
    # every pixel that fired if want_tau, else those within the cutoff (with 1 ms to spare for rounding)
    t_min = NEVER + 1 if want_tau else t_ns - int(math.ceil(cutoff_age_s * 1e9)) - 1_000_000
    for yy in range(h):
        c = _ring_sums(t_last, rec, off, n, (yy + pad) * wp + pad, w, t_ns, t_min, buf)
        _eq1(c, buf, tau_l_s, tau_u_s, mode, cutoff_age_s, want_tau, val, tau_row, scale_bits)
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


@njit(cache=True)
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


@njit(cache=True)
def _sits_update(surface: np.ndarray, x: np.ndarray, y: np.ndarray, radius: int) -> int:
    """Speed-invariant time surface (Manderscheid et al. 2019, Alg. 1), polarities merged.

    For each event at p: every neighbour q in the (2r+1)^2 patch with S(q) >= S(p) loses 1, then
    S(p) = (2r+1)^2. Returns the number of events outside the surface.
    """
    h, w = surface.shape
    full = (2 * radius + 1) * (2 * radius + 1)
    skipped = 0
    for i in range(x.shape[0]):
        px = np.int64(x[i])
        py = np.int64(y[i])
        if px >= w or py >= h:
            skipped += 1
            continue
        sp = surface[py, px]
        for yy in range(max(py - radius, 0), min(py + radius + 1, h)):
            for xx in range(max(px - radius, 0), min(px + radius + 1, w)):
                if surface[yy, xx] >= sp and surface[yy, xx] > 0:
                    surface[yy, xx] -= 1
        surface[py, px] = full
    return skipped
