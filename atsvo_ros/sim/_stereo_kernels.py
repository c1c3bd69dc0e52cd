"""numba kernels of the active-stereo depth model; private, see :mod:`atsvo_ros.sim.stereo`."""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _ir_irradiance(rays, depth, albedo, dots, fx, fy, cx, cy, proj_dx, proj_power, ambient, weight, out):
    """Add ``weight`` x the IR irradiance of one sub-frame to ``out`` (flat, one value per pixel).

    A pixel sees its surface's albedo lit by the room's IR (``ambient``) and by the projector's dot
    pattern ``dots`` (projector image, same intrinsics as the imager) with inverse-square falloff; the
    projector sits at ``-proj_dx`` along the imager's x axis (a point ``P`` of the imager frame is
    ``P + (proj_dx, 0, 0)`` in the projector frame).
    """
    h, w = dots.shape
    for i in range(rays.shape[0]):
        z = depth[i]
        lit = ambient
        if z > 0.0:
            x = rays[i, 0] * z + proj_dx
            y = rays[i, 1] * z
            u = fx * x / z + cx
            v = fy * y / z + cy
            if u >= 0.0 and v >= 0.0 and u < w - 1 and v < h - 1:
                iu = int(u)
                iv = int(v)
                au = u - iu
                av = v - iv
                d = ((dots[iv, iu] * (1.0 - au) + dots[iv, iu + 1] * au) * (1.0 - av)
                     + (dots[iv + 1, iu] * (1.0 - au) + dots[iv + 1, iu + 1] * au) * av)
                lit += proj_power * d / (x * x + y * y + z * z)
        out[i] += weight * albedo[i] * lit


@njit(cache=True, nogil=True)
def _align_to_colour(z_ir, fx_ir, fy_ir, cx_ir, cy_ir, R, t, fx, fy, cx, cy, out):
    """Register a depth image of the left imager to the colour camera, as librealsense's ``align`` does.

    Each valid depth pixel is deprojected at its two opposite corners, moved into the colour frame
    (``R``, ``t``: left imager -> colour) and reprojected; the colour pixels between the two projections
    take its depth, the nearest surface winning (``out`` starts at +inf and is left there where nothing lands).
    """
    h_ir, w_ir = z_ir.shape
    h, w = out.shape
    for v in range(h_ir):
        for u in range(w_ir):
            z = z_ir[v, u]
            if not z > 0.0:
                continue
            lo_u = 1e9
            lo_v = 1e9
            hi_u = -1e9
            hi_v = -1e9
            zc = 0.0
            for k in range(2):
                du = -0.5 if k == 0 else 0.5
                x = (u + du - cx_ir) / fx_ir * z
                y = (v + du - cy_ir) / fy_ir * z
                X = R[0, 0] * x + R[0, 1] * y + R[0, 2] * z + t[0]
                Y = R[1, 0] * x + R[1, 1] * y + R[1, 2] * z + t[1]
                Z = R[2, 0] * x + R[2, 1] * y + R[2, 2] * z + t[2]
                if Z <= 0.0:
                    zc = -1.0
                    break
                pu = fx * X / Z + cx
                pv = fy * Y / Z + cy
                lo_u = min(lo_u, pu)
                hi_u = max(hi_u, pu)
                lo_v = min(lo_v, pv)
                hi_v = max(hi_v, pv)
                zc += 0.5 * Z
            if zc <= 0.0:
                continue
            u0 = max(int(np.floor(lo_u + 0.5)), 0)
            u1 = min(int(np.floor(hi_u + 0.5)), w - 1)
            v0 = max(int(np.floor(lo_v + 0.5)), 0)
            v1 = min(int(np.floor(hi_v + 0.5)), h - 1)
            for yy in range(v0, v1 + 1):
                for xx in range(u0, u1 + 1):
                    if zc < out[yy, xx]:
                        out[yy, xx] = zc
