"""numba kernels of the photometric residual block; private, see :mod:`.photometric`."""
from __future__ import annotations

import numpy as np
from numba import njit

# Point states written by _linearise.
INVISIBLE = 0
INLIER = 1
OUTLIER = 2


@njit(cache=True, nogil=True, inline="always")
def _at_row_time(px, py, pz, qx, qy, qz, R, vel, dt):  # pragma: no cover - compiled
    """Rolling shutter: where a point is in the block camera ``dt`` seconds after the frame's reference time.

    ``vel`` = (rho, omega) is the camera's twist per second (``T_rw(t + dt) = exp(dt vel) T_rw(t)``), so the
    point, ``p`` in the RGB frame, moves by ``dt (rho + omega x p)``, rotated into the block camera by ``R``.
    """
    vx = vel[0] + vel[4] * pz - vel[5] * py
    vy = vel[1] + vel[5] * px - vel[3] * pz
    vz = vel[2] + vel[3] * py - vel[4] * px
    return (qx + dt * (R[0, 0] * vx + R[0, 1] * vy + R[0, 2] * vz),
            qy + dt * (R[1, 0] * vx + R[1, 1] * vy + R[1, 2] * vz),
            qz + dt * (R[2, 0] * vx + R[2, 1] * vy + R[2, 2] * vz))


@njit(cache=True, nogil=True, inline="always")
def _zncc(a, b):  # pragma: no cover - compiled
    """Zero-mean normalised cross-correlation of two patches (NaN when one has no contrast)."""
    n = a.shape[0]
    ma = 0.0
    mb = 0.0
    for k in range(n):
        ma += a[k]
        mb += b[k]
    ma /= n
    mb /= n
    sab = 0.0
    saa = 0.0
    sbb = 0.0
    for k in range(n):
        da = a[k] - ma
        db = b[k] - mb
        sab += da * db
        saa += da * da
        sbb += db * db
    den = np.sqrt(saa * sbb)
    return sab / den if den > 1e-9 else np.nan


@njit(cache=True, nogil=True)
def _linearise(pts_w, patches, img, pattern, fx, fy, cx, cy, T_rw, T_cr, gain, offset, huber, outlier_thr,
               border, grad_c2, zero_mean, zref, max_scale, vel, rs_t0, rs_line, H, g, state,
               zncc, want_zncc):  # pragma: no cover - compiled
    """Gauss-Newton system of the patch residuals ``r = I(pi(T_cr T_rw p) + o) - (gain z + offset)``.

    Parameters are ``(xi, a, b)``: a left perturbation ``xi`` of ``T_rw`` (twist, translation first),
    the log-gain ``a`` (gain = e^a) and offset ``b``. Fills ``H`` (8x8), ``g`` (8) with the
    Huber-weighted ``J^T W J`` and ``J^T W r``, and ``state`` per point. Pixels are further weighted
    by ``c^2 / (c^2 + |grad I|^2)`` (``grad_c2`` = c^2, 0 = off), DSO's guard against edges whose
    sub-pixel blur and occlusions make them unreliable; ``grad I`` is the image gradient itself, not
    the mean-removed one (which is small on an edge and would hardly down-weight it). With ``zero_mean``
    each patch's mean is
    removed from the residuals (and Jacobians): brightness that varies slowly over the image
    (vignetting, uneven light), which one global gain cannot model, then cancels. With
    ``max_scale > 1`` a point whose depth differs from its depth in the host keyframe (``zref``)
    by more than that factor is skipped: its stored patch shows the scene at another scale. With a rolling
    shutter (``rs_t0``, ``rs_line`` not 0) each point is moved to the time its row was exposed,
    ``rs_t0 + rs_line v`` seconds from the frame's stamp, with the camera twist ``vel`` (per second); the
    Jacobian ignores how that time depends on the pose. With ``want_zncc``, ``zncc`` receives each visible
    point's zero-mean normalised cross-correlation of stored and current patch (NaN otherwise), for the
    consistency checks. Returns
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
    g2s = np.empty(npat)
    ivs = np.empty(npat)
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
        zncc[i] = np.nan
        if qz < 1e-3 or (max_scale > 1.0 and (qz > max_scale * zref[i] or qz * max_scale < zref[i])):
            state[i] = INVISIBLE
            continue
        iz = 1.0 / qz
        u = fx * qx * iz + cx
        v = fy * qy * iz + cy
        if rs_line != 0.0 or rs_t0 != 0.0:
            qx, qy, qz = _at_row_time(px, py, pz, qx, qy, qz, R, vel, rs_t0 + rs_line * v)
            if qz < 1e-3:
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
            g2s[k] = gxs[k] * gxs[k] + gys[k] * gys[k]  # before any mean removal: the edge weight
            ivs[k] = iv
            zs[k] = patches[i, k]
            r = iv - (gain * zs[k] + offset)
            res[k] = r
            sse += r * r
        if want_zncc:
            zncc[i] = _zncc(ivs, zs)
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
                wt *= grad_c2 / (grad_c2 + g2s[k])
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
