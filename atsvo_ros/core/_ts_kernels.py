"""Private numba kernels of the time surfaces (see :mod:`atsvo_ros.core.time_surface`)."""
from __future__ import annotations

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


@njit(cache=True)
def _ats_update(t_last: np.ndarray, top: np.ndarray, x: np.ndarray, y: np.ndarray, t: np.ndarray,
                ring_dx: np.ndarray, ring_dy: np.ndarray) -> int:
    """Per-pixel last time plus, for every pixel, the n latest timestamps of its ring neighbours.

    ``top[y, x, :]`` holds (unordered) the n newest ring-neighbour timestamps, ``NEVER`` in unused
    slots. Events come in time order, so an event at q with time t is the newest value for every
    pixel p whose ring contains q (p = q - d): it replaces q's previous time if that is in p's list
    (equal values are interchangeable), otherwise the oldest entry. That keeps the exact multiset
    of the n latest in O(16 n) per event. Events older than their pixel's last one, or outside the
    surface, are skipped (returned count).
    """
    h, w = t_last.shape
    n = top.shape[2]
    m = ring_dx.shape[0]
    skipped = 0
    for i in range(t.shape[0]):
        qx = np.int64(x[i])
        qy = np.int64(y[i])
        te = t[i]
        if qx >= w or qy >= h:
            skipped += 1
            continue
        old = t_last[qy, qx]
        if te < old:
            skipped += 1
            continue
        t_last[qy, qx] = te
        for j in range(m):
            px = qx - ring_dx[j]
            py = qy - ring_dy[j]
            if px < 0 or py < 0 or px >= w or py >= h:
                continue
            row = top[py, px]
            i_min = 0
            v_min = row[0]
            i_old = -1
            for s in range(n):
                v = row[s]
                if v == old:
                    i_old = s
                if v < v_min:
                    v_min = v
                    i_min = s
            row[i_old if i_old >= 0 else i_min] = te
    return skipped


@njit(cache=True)
def _ats_render(t_last: np.ndarray, top: np.ndarray, t_ns: int, tau_l_s: float, tau_u_s: float,
                mode: int, cutoff_age_s: float, out: np.ndarray, tau_out: np.ndarray, want_tau: bool) -> None:
    """Eq. 1 with the per-pixel tau of Eq. 2 (mode 0: clip(mean age); mode 1: printed max(tau_u - age, tau_l)).

    Pixels that never fired are 0 (tau NaN); pixels older than ``cutoff_age_s`` (where even tau_u
    leaves < 0.5 grey levels) are 0 without evaluating tau unless ``want_tau``.
    """
    h, w = t_last.shape
    n = top.shape[2]
    for yy in range(h):
        for xx in range(w):
            tl = t_last[yy, xx]
            if tl == NEVER:
                out[yy, xx] = 0.0
                if want_tau:
                    tau_out[yy, xx] = np.nan
                continue
            age_s = max(t_ns - tl, 0) * 1e-9
            if age_s > cutoff_age_s and not want_tau:
                out[yy, xx] = 0.0
                continue
            k = 0
            s = 0.0
            for j in range(n):
                v = top[yy, xx, j]
                if v != NEVER:
                    k += 1
                    s += max(t_ns - v, 0)
            if k == 0:
                tau = tau_u_s
            else:
                mean_age = s * 1e-9 / k
                if mode == 0:
                    tau = min(max(mean_age, tau_l_s), tau_u_s)
                else:
                    tau = max(tau_u_s - mean_age, tau_l_s)
            if want_tau:
                tau_out[yy, xx] = tau
            out[yy, xx] = 255.0 * np.exp(-age_s / tau)


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
