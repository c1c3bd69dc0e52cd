"""numba kernels of the tracker: residuals, Jacobians and normal equations of one residual block.

Private: call them through :class:`atsvo_ros.core.tracker.ResidualBlock`.
"""
from __future__ import annotations

import numpy as np
from numba import njit

# Point states written by _linearise.
INVISIBLE = 0
INLIER = 1
OUTLIER = 2


@njit(cache=True)
def _linearise(pts_w, patches, img, pattern, fx, fy, cx, cy, T_rw, T_cr, gain, offset, huber, outlier_thr,
               border, grad_c2, zero_mean, zref, max_scale, H, g, state):  # pragma: no cover - compiled
    """Gauss-Newton system of the patch residuals ``r = I(pi(T_cr T_rw p) + o) - (gain z + offset)``.

    Parameters are ``(xi, a, b)``: a left perturbation ``xi`` of ``T_rw`` (twist, translation first),
    the log-gain ``a`` (gain = e^a) and offset ``b``. Fills ``H`` (8x8), ``g`` (8) with the
    Huber-weighted ``J^T W J`` and ``J^T W r``, and ``state`` per point. Pixels are further weighted
    by ``c^2 / (c^2 + |grad I|^2)`` (``grad_c2`` = c^2, 0 = off), DSO's guard against edges whose
    sub-pixel blur and occlusions make them unreliable. With ``zero_mean`` each patch's mean is
    removed from the residuals (and Jacobians): brightness that varies slowly over the image
    (vignetting, uneven light), which one global gain cannot model, then cancels. With
    ``max_scale > 1`` a point whose depth differs from its depth in the host keyframe (``zref``)
    by more than that factor is skipped: its stored patch shows the scene at another scale. Returns
    ``(energy, n_inliers, n_visible, sum of inlier squared residuals)``. Outliers add a constant
    energy (the Huber cost of a patch at the threshold) and invisible points none, so the energy
    per visible point compares estimates fairly (as DSO's coarse tracker does).
    """
    n = pts_w.shape[0]
    npat = pattern.shape[0]
    h = img.shape[0]
    w = img.shape[1]
    for i in range(8):
        g[i] = 0.0
        for j in range(8):
            H[i, j] = 0.0
    if outlier_thr > huber:
        fixed = npat * (2.0 * huber * outlier_thr - huber * huber)
    else:
        fixed = npat * outlier_thr * outlier_thr
    max_sse = npat * outlier_thr * outlier_thr
    energy = 0.0
    sse_in = 0.0
    n_in = 0
    n_vis = 0
    res = np.empty(npat)
    gxs = np.empty(npat)
    gys = np.empty(npat)
    zs = np.empty(npat)
    Jg = np.empty((2, 6))
    M = np.empty((2, 6))
    # Rotation from the RGB camera to this block's camera.
    R = T_cr[:3, :3]
    for i in range(n):
        X = pts_w[i, 0]
        Y = pts_w[i, 1]
        Z = pts_w[i, 2]
        px = T_rw[0, 0] * X + T_rw[0, 1] * Y + T_rw[0, 2] * Z + T_rw[0, 3]
        py = T_rw[1, 0] * X + T_rw[1, 1] * Y + T_rw[1, 2] * Z + T_rw[1, 3]
        pz = T_rw[2, 0] * X + T_rw[2, 1] * Y + T_rw[2, 2] * Z + T_rw[2, 3]
        qx = R[0, 0] * px + R[0, 1] * py + R[0, 2] * pz + T_cr[0, 3]
        qy = R[1, 0] * px + R[1, 1] * py + R[1, 2] * pz + T_cr[1, 3]
        qz = R[2, 0] * px + R[2, 1] * py + R[2, 2] * pz + T_cr[2, 3]
        if qz < 1e-3 or (max_scale > 1.0 and (qz > max_scale * zref[i] or qz * max_scale < zref[i])):
            state[i] = INVISIBLE
            continue
        iz = 1.0 / qz
        u = fx * qx * iz + cx
        v = fy * qy * iz + cy
        if not (u >= border and v >= border and u <= w - 1 - border and v <= h - 1 - border):
            state[i] = INVISIBLE
            continue
        n_vis += 1
        sse = 0.0
        for k in range(npat):
            x = u + pattern[k, 0]
            y = v + pattern[k, 1]
            x0 = int(x)
            y0 = int(y)
            ax = x - x0
            ay = y - y0
            w00 = (1.0 - ax) * (1.0 - ay)
            w01 = ax * (1.0 - ay)
            w10 = (1.0 - ax) * ay
            w11 = ax * ay
            iv = (w00 * img[y0, x0, 0] + w01 * img[y0, x0 + 1, 0]
                  + w10 * img[y0 + 1, x0, 0] + w11 * img[y0 + 1, x0 + 1, 0])
            gxs[k] = (w00 * img[y0, x0, 1] + w01 * img[y0, x0 + 1, 1]
                      + w10 * img[y0 + 1, x0, 1] + w11 * img[y0 + 1, x0 + 1, 1])
            gys[k] = (w00 * img[y0, x0, 2] + w01 * img[y0, x0 + 1, 2]
                      + w10 * img[y0 + 1, x0, 2] + w11 * img[y0 + 1, x0 + 1, 2])
            zs[k] = patches[i, k]
            r = iv - (gain * zs[k] + offset)
            res[k] = r
            sse += r * r
        if zero_mean:
            mr = 0.0
            mgx = 0.0
            mgy = 0.0
            mz = 0.0
            for k in range(npat):
                mr += res[k]
                mgx += gxs[k]
                mgy += gys[k]
                mz += zs[k]
            mr /= npat
            mgx /= npat
            mgy /= npat
            mz /= npat
            sse = 0.0
            for k in range(npat):
                res[k] -= mr
                gxs[k] -= mgx
                gys[k] -= mgy
                zs[k] -= mz
                sse += res[k] * res[k]
        if not (sse <= max_sse):
            state[i] = OUTLIER
            energy += fixed
            continue
        state[i] = INLIER
        n_in += 1
        sse_in += sse
        # d(pixel)/d(q) (2x3) times R, then times [I, -hat(p)] for the left perturbation of T_rw.
        a0 = fx * iz
        a2 = -fx * qx * iz * iz
        b1 = fy * iz
        b2 = -fy * qy * iz * iz
        B00 = a0 * R[0, 0] + a2 * R[2, 0]
        B01 = a0 * R[0, 1] + a2 * R[2, 1]
        B02 = a0 * R[0, 2] + a2 * R[2, 2]
        B10 = b1 * R[1, 0] + b2 * R[2, 0]
        B11 = b1 * R[1, 1] + b2 * R[2, 1]
        B12 = b1 * R[1, 2] + b2 * R[2, 2]
        Jg[0, 0] = B00
        Jg[0, 1] = B01
        Jg[0, 2] = B02
        Jg[1, 0] = B10
        Jg[1, 1] = B11
        Jg[1, 2] = B12
        # -hat(p) = [[0, pz, -py], [-pz, 0, px], [py, -px, 0]]
        Jg[0, 3] = -B01 * pz + B02 * py
        Jg[0, 4] = B00 * pz - B02 * px
        Jg[0, 5] = -B00 * py + B01 * px
        Jg[1, 3] = -B11 * pz + B12 * py
        Jg[1, 4] = B10 * pz - B12 * px
        Jg[1, 5] = -B10 * py + B11 * px
        sxx = 0.0
        sxy = 0.0
        syy = 0.0
        sxa = 0.0
        sya = 0.0
        sxb = 0.0
        syb = 0.0
        saa = 0.0
        sab = 0.0
        sbb = 0.0
        sxr = 0.0
        syr = 0.0
        sar = 0.0
        sbr = 0.0
        for k in range(npat):
            r = res[k]
            ar = abs(r)
            if ar <= huber:
                wt = 1.0
                energy += r * r
            else:
                wt = huber / ar
                energy += 2.0 * huber * ar - huber * huber
            gx = gxs[k]
            gy = gys[k]
            if grad_c2 > 0.0:
                wt *= grad_c2 / (grad_c2 + gx * gx + gy * gy)
            ja = -gain * zs[k]
            sxx += wt * gx * gx
            sxy += wt * gx * gy
            syy += wt * gy * gy
            sxa += wt * gx * ja
            sya += wt * gy * ja
            saa += wt * ja * ja
            sxr += wt * gx * r
            syr += wt * gy * r
            sar += wt * ja * r
            if not zero_mean:  # the offset cancels in zero-mean residuals
                sxb -= wt * gx
                syb -= wt * gy
                sab -= wt * ja
                sbb += wt
                sbr -= wt * r
        for c in range(6):
            M[0, c] = sxx * Jg[0, c] + sxy * Jg[1, c]
            M[1, c] = sxy * Jg[0, c] + syy * Jg[1, c]
        for r6 in range(6):
            j0 = Jg[0, r6]
            j1 = Jg[1, r6]
            for c in range(r6, 6):
                H[r6, c] += j0 * M[0, c] + j1 * M[1, c]
            H[r6, 6] += j0 * sxa + j1 * sya
            H[r6, 7] += j0 * sxb + j1 * syb
            g[r6] += j0 * sxr + j1 * syr
        H[6, 6] += saa
        H[6, 7] += sab
        H[7, 7] += sbb
        g[6] += sar
        g[7] += sbr
    for r8 in range(8):
        for c in range(r8):
            H[r8, c] = H[c, r8]
    return energy, n_in, n_vis, sse_in


@njit(cache=True)
def _gradient_stack(img):  # pragma: no cover - compiled
    """(H, W, 3) float32 ``[I, dI/dx, dI/dy]`` with central differences (0 on the border)."""
    h, w = img.shape
    out = np.empty((h, w, 3), dtype=np.float32)
    for y in range(h):
        ym = y - 1 if y > 0 else y
        yp = y + 1 if y < h - 1 else y
        inner_y = 0 < y < h - 1
        for x in range(w):
            out[y, x, 0] = img[y, x]
            if 0 < x < w - 1:
                out[y, x, 1] = 0.5 * (img[y, x + 1] - img[y, x - 1])
            else:
                out[y, x, 1] = 0.0
            out[y, x, 2] = 0.5 * (img[yp, x] - img[ym, x]) if inner_y else 0.0
    return out


@njit("float64[::1](float64[:, ::1], float64[::1], float64[:, ::1])", cache=True)
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
      cache=True)
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
