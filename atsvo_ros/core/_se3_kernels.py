"""numba kernel of the relative twist of two poses; private, see :mod:`atsvo_ros.core.rolling_shutter`.

It carries an explicit signature, so numba compiles it (or loads it from its cache) when this module is
imported: a broken numba install fails at import, with numba's message, never per frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit("float64[::1](float64[:, ::1], float64[:, ::1], float64)", cache=True, nogil=True)
def _twist_per_s(T1, T0, dt_s):  # pragma: no cover - compiled
    """Twist ``xi`` (translation first) with ``T1 = exp(dt_s xi) T0``, divided by ``dt_s``; zeros if ``dt_s <= 0``.

    The rolling-shutter model evaluates it at every linearisation, so it is a kernel rather than
    :func:`atsvo_ros.core.geometry.se3_log` (which validates its input and costs ~50x more).
    """
    out = np.zeros(6)
    if not dt_s > 0.0:
        return out
    # D = T1 T0^-1 = [R1 R0^T, t1 - R1 R0^T t0]
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = T1[i, 0] * T0[j, 0] + T1[i, 1] * T0[j, 1] + T1[i, 2] * T0[j, 2]
    t = np.empty(3)
    for i in range(3):
        t[i] = T1[i, 3] - (R[i, 0] * T0[0, 3] + R[i, 1] * T0[1, 3] + R[i, 2] * T0[2, 3])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    c = min(1.0, max(-1.0, c))
    th = np.arccos(c)
    wx = R[2, 1] - R[1, 2]
    wy = R[0, 2] - R[2, 0]
    wz = R[1, 0] - R[0, 1]
    if th < 1e-6:
        f = 0.5
    else:
        f = 0.5 * th / np.sin(th)  # valid for the inter-frame rotations this is used for (well below pi)
    wx *= f
    wy *= f
    wz *= f
    # rho = V^-1 t, V^-1 = I - W/2 + (1/th^2)(1 - (th sin th) / (2 (1 - cos th))) W^2
    th2 = wx * wx + wy * wy + wz * wz
    if th2 < 1e-12:
        k = 1.0 / 12.0
    else:
        k = (1.0 - (th * np.sin(th)) / (2.0 * (1.0 - np.cos(th)))) / th2
    # W t and W (W t)
    a0 = wy * t[2] - wz * t[1]
    a1 = wz * t[0] - wx * t[2]
    a2 = wx * t[1] - wy * t[0]
    b0 = wy * a2 - wz * a1
    b1 = wz * a0 - wx * a2
    b2 = wx * a1 - wy * a0
    out[0] = (t[0] - 0.5 * a0 + k * b0) / dt_s
    out[1] = (t[1] - 0.5 * a1 + k * b1) / dt_s
    out[2] = (t[2] - 0.5 * a2 + k * b2) / dt_s
    out[3] = wx / dt_s
    out[4] = wy / dt_s
    out[5] = wz / dt_s
    return out
