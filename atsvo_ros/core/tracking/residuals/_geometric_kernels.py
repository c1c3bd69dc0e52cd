"""numba kernels of the geometric (point-to-plane) residual block; private, see :mod:`.geometric`."""
from __future__ import annotations

import numpy as np
from numba import njit

from atsvo_ros.core.tracking.residuals._photometric_kernels import _at_row_time

INVISIBLE = 0
INLIER = 1
OUTLIER = 2


@njit(cache=True, nogil=True, inline="always")
def _backproject(depth, x, y, fx, fy, cx, cy):  # pragma: no cover - compiled
    z = depth[y, x]
    return (x - cx) / fx * z, (y - cy) / fy * z, z


@njit(cache=True, nogil=True)
def _linearise_geometric(pts_w, depth, fx, fy, cx, cy, T_rw, T_cr, sigma_at_1m, sigma_min, huber, outlier,
                         edge_ratio, vel, rs_t0, rs_line, H, g, state):  # pragma: no cover - compiled
    """Point-to-plane normal equations of map points against the current depth image (one pyramid level).

    Each point ``p`` (world) is moved into this block's camera, ``q = T_cr T_rw p``, and associated
    projectively with the depth pixel it falls on; the residual is the distance of ``q`` to the
    tangent plane of the depth surface at that pixel, ``r = n . (q - s)`` (``s`` the back-projected
    pixel, ``n`` its normal from the four neighbours), divided by the depth noise
    ``max(sigma_min, sigma_at_1m z^2)`` (stereo and structured-light depth noise grows with z^2).
    Pixels on depth edges or next to holes (a neighbour off by more than ``edge_ratio`` of the depth)
    give no residual. Parameters are a left perturbation of ``T_rw`` (twist, translation first);
    ``dr/dxi = [m, p x m]`` with ``m = R_cr^T n`` and ``p`` the point in the RGB frame (the normal is
    held fixed during a step, as in ICP). Huber weights on the normalised residual (``huber``); a
    residual above ``outlier`` is an outlier and adds the constant Huber cost at the threshold, so
    the energy per visible point compares estimates fairly. A rolling shutter (``rs_t0``, ``rs_line``)
    is handled as in the photometric kernel. Fills ``H`` (6x6), ``g`` (6), ``state``;
    returns ``(energy, n_inliers, n_visible, sum of squared normalised inlier residuals)``.
    """
    n = pts_w.shape[0]
    h = depth.shape[0]
    w = depth.shape[1]
    for i in range(6):
        g[i] = 0.0
        for j in range(6):
            H[i, j] = 0.0
    if outlier > huber:
        fixed = 2.0 * huber * outlier - huber * huber
    else:
        fixed = outlier * outlier
    energy = 0.0
    sse = 0.0
    n_in = 0
    n_vis = 0
    R = T_cr[:3, :3]
    J = np.empty(6)
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
        state[i] = INVISIBLE
        if qz < 1e-3:
            continue
        u = fx * qx / qz + cx
        v = fy * qy / qz + cy
        if rs_line != 0.0 or rs_t0 != 0.0:
            qx, qy, qz = _at_row_time(px, py, pz, qx, qy, qz, R, vel, rs_t0 + rs_line * v)
            if qz < 1e-3:
                continue
            u = fx * qx / qz + cx
            v = fy * qy / qz + cy
        if not (u >= 1.0 and v >= 1.0 and u < w - 2.0 and v < h - 2.0):
            continue
        xi = int(u + 0.5)
        yi = int(v + 0.5)
        zc = depth[yi, xi]
        if not zc > 0.0:
            continue
        zl = depth[yi, xi - 1]
        zr = depth[yi, xi + 1]
        zu = depth[yi - 1, xi]
        zd = depth[yi + 1, xi]
        lim = edge_ratio * zc
        if not (zl > 0.0 and zr > 0.0 and zu > 0.0 and zd > 0.0 and abs(zl - zc) <= lim and abs(zr - zc) <= lim
                and abs(zu - zc) <= lim and abs(zd - zc) <= lim):
            continue
        sx, sy, sz = _backproject(depth, xi, yi, fx, fy, cx, cy)
        lx, ly, lz = _backproject(depth, xi - 1, yi, fx, fy, cx, cy)
        rx, ry, rz = _backproject(depth, xi + 1, yi, fx, fy, cx, cy)
        ux, uy, uz = _backproject(depth, xi, yi - 1, fx, fy, cx, cy)
        dx, dy, dz = _backproject(depth, xi, yi + 1, fx, fy, cx, cy)
        ax, ay, az = rx - lx, ry - ly, rz - lz
        bx, by, bz = dx - ux, dy - uy, dz - uz
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
        if nn <= 0.0:
            continue
        nx /= nn
        ny /= nn
        nz /= nn
        n_vis += 1
        sigma = sigma_at_1m * zc * zc
        if sigma < sigma_min:
            sigma = sigma_min
        r = (nx * (qx - sx) + ny * (qy - sy) + nz * (qz - sz)) / sigma
        ar = abs(r)
        if ar > outlier:
            state[i] = OUTLIER
            energy += fixed
            continue
        state[i] = INLIER
        n_in += 1
        sse += r * r
        if ar <= huber:
            wt = 1.0
            energy += r * r
        else:
            wt = huber / ar
            energy += 2.0 * huber * ar - huber * huber
        # m = R^T n / sigma (the normal in the RGB frame, scaled), J = [m, p x m]
        mx = (R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz) / sigma
        my = (R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz) / sigma
        mz = (R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz) / sigma
        J[0] = mx
        J[1] = my
        J[2] = mz
        J[3] = py * mz - pz * my
        J[4] = pz * mx - px * mz
        J[5] = px * my - py * mx
        for a in range(6):
            wa = wt * J[a]
            g[a] += wa * r
            for b in range(a, 6):
                H[a, b] += wa * J[b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return energy, n_in, n_vis, sse
