"""numba kernel of IMU preintegration; private, see :func:`atsvo_ros.core.imu.preintegrate`.

Explicit signature: compiled (or loaded from numba's cache) at import, never per frame. Matrix products are
written out: numba's ``@`` needs SciPy's BLAS, which ``pip install .`` does not bring.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit("void(float64[:, ::1], float64, float64, float64)", cache=True, nogil=True)
def _exp_so3(out, x, y, z):  # pragma: no cover - compiled
    """``out = exp([x, y, z]^)`` (Rodrigues)."""
    th = np.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        a, b = 1.0, 0.5
    else:
        a, b = np.sin(th) / th, (1.0 - np.cos(th)) / (th * th)
    out[0, 0] = 1.0 - b * (y * y + z * z)
    out[1, 1] = 1.0 - b * (x * x + z * z)
    out[2, 2] = 1.0 - b * (x * x + y * y)
    out[0, 1] = -a * z + b * x * y
    out[1, 0] = a * z + b * x * y
    out[0, 2] = a * y + b * x * z
    out[2, 0] = -a * y + b * x * z
    out[1, 2] = -a * x + b * y * z
    out[2, 1] = a * x + b * y * z


@njit("void(float64[:, ::1], float64[:, ::1], float64[:, ::1])", cache=True, nogil=True)
def _matmul3(out, A, B):  # pragma: no cover - compiled
    """``out = A B`` for 3x3 matrices (``out`` must not alias ``A`` or ``B``)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit("float64[::1](float64[::1], float64[:, ::1], float64[:, ::1])", cache=True, nogil=True)
def _preintegrate(t_s, gyro, accel):  # pragma: no cover - compiled
    """Rotation, velocity and position change in the frame of the first edge, gravity left out.

    ``t_s`` (n,) are the interval edges (seconds from the first), ``gyro`` and ``accel`` (n, 3) the rates and
    specific forces at the edges; each interval takes the mean of its two edges, its specific force rotated
    by the rotation at the interval's middle. Returns ``[R (9, row-major), dv (3), dp (3)]``.
    """
    R = np.eye(3)
    nxt = np.empty((3, 3))
    half = np.empty((3, 3))
    E = np.empty((3, 3))
    v = np.zeros(3)
    p = np.zeros(3)
    for k in range(t_s.shape[0] - 1):
        dt = t_s[k + 1] - t_s[k]
        if dt <= 0.0:
            continue
        wx = 0.5 * (gyro[k, 0] + gyro[k + 1, 0])
        wy = 0.5 * (gyro[k, 1] + gyro[k + 1, 1])
        wz = 0.5 * (gyro[k, 2] + gyro[k + 1, 2])
        _exp_so3(E, 0.5 * dt * wx, 0.5 * dt * wy, 0.5 * dt * wz)
        _matmul3(half, R, E)
        for i in range(3):
            a0 = 0.0
            for j in range(3):
                a0 += half[i, j] * 0.5 * (accel[k, j] + accel[k + 1, j])
            p[i] += v[i] * dt + 0.5 * a0 * dt * dt
            v[i] += a0 * dt
        _exp_so3(E, dt * wx, dt * wy, dt * wz)
        _matmul3(nxt, R, E)
        R[:, :] = nxt
    out = np.empty(15)
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = R[i, j]
        out[9 + i] = v[i]
        out[12 + i] = p[i]
    return out


@njit("float64(float64[::1], float64[::1], float64)", cache=True, nogil=True)
def _interp(x, y, xq):  # pragma: no cover - compiled
    """``np.interp(xq, x, y)`` for one query: linear between samples, the end values beyond them."""
    n = x.shape[0]
    if xq <= x[0]:
        return y[0]
    if xq >= x[n - 1]:
        return y[n - 1]
    j = np.searchsorted(x, xq, side="right") - 1
    return y[j] + (y[j + 1] - y[j]) / (x[j + 1] - x[j]) * (xq - x[j])


@njit("float64[:, ::1](int64[::1], float64[:, ::1], int64, int64, float64[::1])", cache=True, nogil=True)
def _integrate_gyro(stamps, gyro, t0, t1, bias):  # pragma: no cover - compiled
    """``R_i0_i1`` from ``t0`` to ``t1`` (``t0 < t1``, ns), not re-orthonormalised.

    The rate (minus ``bias``) is linear between samples and held beyond the first and last; each interval
    between ``t0``, the samples strictly inside and ``t1`` adds ``(w_a + w_b) / 2 dt + (w_a x w_b) dt^2 / 12``.
    """
    i0 = np.searchsorted(stamps, t0, side="right")
    i1 = np.searchsorted(stamps, t1, side="left")
    m = i1 - i0 + 2  # edges
    x = (stamps - stamps[0]).astype(np.float64)
    edges = np.empty(m, np.int64)
    edges[0], edges[m - 1] = t0, t1
    edges[1:m - 1] = stamps[i0:i1]
    w = np.empty((m, 3))
    cols = np.ascontiguousarray(gyro.T)
    for k in range(3):
        for e in range(m):
            w[e, k] = _interp(x, cols[k], float(edges[e] - stamps[0])) - bias[k]
    R = np.eye(3)
    E = np.empty((3, 3))
    nxt = np.empty((3, 3))
    for e in range(m - 1):
        dt = (edges[e + 1] - edges[e]) * 1e-9
        if dt <= 0.0:
            continue
        ax, ay, az = w[e, 0], w[e, 1], w[e, 2]
        bx, by, bz = w[e + 1, 0], w[e + 1, 1], w[e + 1, 2]
        c = dt * dt / 12.0
        _exp_so3(E, 0.5 * (ax + bx) * dt + (ay * bz - az * by) * c, 0.5 * (ay + by) * dt + (az * bx - ax * bz) * c,
                 0.5 * (az + bz) * dt + (ax * by - ay * bx) * c)
        _matmul3(nxt, R, E)
        R[:, :] = nxt
    return R


@njit("float64[::1](int64[::1], float64[:, ::1], float64[:, ::1], int64, int64)", cache=True, nogil=True)
def _preintegrate_span(stamps, gyro, accel, t0, t1):  # pragma: no cover - compiled
    """:func:`_preintegrate` from ``t0`` to ``t1`` (ns) over the samples: edges at ``t0``, the samples strictly
    inside and ``t1``, rates and specific forces linear between samples and held beyond them."""
    i0 = np.searchsorted(stamps, t0, side="right")
    i1 = np.searchsorted(stamps, t1, side="left")
    m = max(i1 - i0, 0) + 2
    x = (stamps - t0).astype(np.float64)
    t_s = np.empty(m)
    g = np.empty((m, 3))
    a = np.empty((m, 3))
    g_cols, a_cols = np.ascontiguousarray(gyro.T), np.ascontiguousarray(accel.T)
    for e in range(m):
        te = t0 if e == 0 else (t1 if e == m - 1 else stamps[i0 + e - 1])
        xq = float(te - t0)
        t_s[e] = xq * 1e-9
        for k in range(3):
            g[e, k] = _interp(x, g_cols[k], xq)
            a[e, k] = _interp(x, a_cols[k], xq)
    return _preintegrate(t_s, g, a)
