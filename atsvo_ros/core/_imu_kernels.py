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
