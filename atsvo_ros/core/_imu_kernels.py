"""numba kernel of IMU preintegration; private, see :func:`atsvo_ros.core.imu.preintegrate`.

Explicit signature: compiled (or loaded from numba's cache) at import, never per frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit("float64[::1](float64[::1], float64[:, ::1], float64[:, ::1])", cache=True, nogil=True)
def _preintegrate(t_s, gyro, accel):  # pragma: no cover - compiled
    """Rotation, velocity and position change in the frame of the first edge, gravity left out.

    ``t_s`` (n,) are the interval edges (seconds from the first), ``gyro`` and ``accel`` (n, 3) the rates and
    specific forces at the edges; each interval takes the mean of its two edges, its specific force rotated
    by the rotation at the interval's middle. Returns ``[R (9, row-major), dv (3), dp (3)]``.
    """
    R = np.eye(3)
    v = np.zeros(3)
    p = np.zeros(3)
    half = np.empty((3, 3))
    step = np.empty((3, 3))
    for k in range(t_s.shape[0] - 1):
        dt = t_s[k + 1] - t_s[k]
        if dt <= 0.0:
            continue
        w = 0.5 * (gyro[k] + gyro[k + 1])
        f = 0.5 * (accel[k] + accel[k + 1])
        for j, scale in ((0, 0.5), (1, 1.0)):
            phi = w * (dt * scale)
            th = np.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
            if th < 1e-12:
                a, b = 1.0, 0.5
            else:
                a, b = np.sin(th) / th, (1.0 - np.cos(th)) / (th * th)
            K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
            E = np.eye(3) + a * K + b * (K @ K)
            if j == 0:
                half[:] = R @ E
            else:
                step[:] = E
        a0 = half @ f
        p += v * dt + 0.5 * a0 * dt * dt
        v += a0 * dt
        R = R @ step
    out = np.empty(15)
    out[:9] = R.ravel()
    out[9:12] = v
    out[12:] = p
    return out
