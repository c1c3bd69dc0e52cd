"""numba kernels of the Levenberg-Marquardt step; private, see :mod:`atsvo_ros.core.tracking.tracker`.

Both carry explicit signatures, so numba compiles them (or loads them from its cache) when this module
is imported: a broken numba install fails at import, with numba's message, never per frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit("float64[::1](float64[:, ::1], float64[::1], float64[:, ::1])", cache=True, nogil=True)
def _solve_spd(A, b, L):  # pragma: no cover - compiled
    """Solve ``A x = b`` for a small symmetric positive-definite ``A`` by Cholesky (``L`` is scratch).

    Hand-written rather than ``np.linalg.solve``: numba's LAPACK bindings need SciPy at run time, and
    for the 6x6-10x10 systems of the tracker this is faster anyway (~2.5 us vs ~3.9 us per call, same
    result to 1e-17). Returns NaN in every entry when ``A`` is not numerically positive definite (a
    pivot below 1e-12 of the largest diagonal entry): the caller sees a singular system explicitly.
    """
    n = A.shape[0]
    x = np.empty(n)
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(A[i, i]))
    tiny = 1e-12 * scale if scale > 0.0 else 1e-300
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > tiny:  # also catches NaN
            x[:] = np.nan
            return x
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x


@njit("Tuple((float64[::1], float64[:, ::1]))(float64[:, ::1], float64[::1], float64, float64[:, ::1])",
      cache=True, nogil=True)
def _lm_step(H, g, lam, T):  # pragma: no cover - compiled
    """Damped Gauss-Newton step ``(H + lam diag H) delta = -g`` and ``exp(delta[:6]) @ T``.

    Returns ``(delta, T_new)``; every entry of ``delta`` is NaN when the damped system is singular
    (then ``T_new`` is ``T``).
    """
    n = H.shape[0]
    A = H.copy()
    for i in range(n):
        A[i, i] += lam * H[i, i]  # no absolute regularisation: a direction without information is singular
    delta = _solve_spd(A, -g, np.zeros((n, n)))
    if not np.isfinite(delta[0]):
        return delta, T.copy()
    rho = delta[:3]
    wx, wy, wz = delta[3], delta[4], delta[5]
    th2 = wx * wx + wy * wy + wz * wz
    if th2 < 1e-12:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
        c = 1.0 / 6.0 - th2 / 120.0
    else:
        th = np.sqrt(th2)
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / th2
        c = (th - np.sin(th)) / (th2 * th)
    # exp of the twist: R = I + a W + b W^2, t = (I + b W + c W^2) rho; written out, because numba's
    # matrix product (np.dot / @) also needs SciPy's BLAS.
    W = np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])
    E = np.eye(4)
    for i in range(3):
        for j in range(3):
            w2 = W[i, 0] * W[0, j] + W[i, 1] * W[1, j] + W[i, 2] * W[2, j]
            E[i, j] += a * W[i, j] + b * w2
            v = (1.0 if i == j else 0.0) + b * W[i, j] + c * w2
            E[i, 3] += v * rho[j]
    out = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            out[i, j] = E[i, 0] * T[0, j] + E[i, 1] * T[1, j] + E[i, 2] * T[2, j] + E[i, 3] * T[3, j]
    return delta, out
