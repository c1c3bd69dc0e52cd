"""Numba ray caster for :class:`~atsvo_ros.sim.scene.Scene`: irradiance, depth and colour per pixel.

One ray per pixel, cast from the *raw* pixel through the camera's distortion model
(:meth:`CameraModel.pixel_to_normalized`), so distorted cameras are rendered as the sensor sees
them. Textures are sampled trilinearly between the two mip levels that bracket the pixel
footprint, which keeps textures free of aliasing and of level popping (that would fire events).
Shading: albedo x (ambient + Lambertian ceiling light with inverse-square falloff), linear units
(1.0 ~ a mid-grey surface under the light at a couple of metres).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.sim.scene import Scene

_TILE = 8
#: pixels per band below which one thread casts the whole image (a hand-off costs ~0.05 ms)
_MIN_CHUNK_PX = 8_192
#: bands per thread: the floor, walls and boxes cost differently, so small bands balance the threads
_BANDS_PER_THREAD = 4


@njit(cache=True, fastmath=True)
def _sample(tex_data, offset, size, u, v):
    """Bilinear, wrap-around sample of one square power-of-two level at texel coordinates."""
    fu = u - 0.5
    fv = v - 0.5
    iu = int(np.floor(fu))
    iv = int(np.floor(fv))
    au = fu - iu
    av = fv - iv
    m = size - 1
    u0 = iu & m
    v0 = iv & m
    u1 = (iu + 1) & m
    v1 = (iv + 1) & m
    a = tex_data[offset + v0 * size + u0]
    b = tex_data[offset + v0 * size + u1]
    c = tex_data[offset + v1 * size + u0]
    d = tex_data[offset + v1 * size + u1]
    return (a * (1 - au) + b * au) * (1 - av) + (c * (1 - au) + d * au) * av


@njit(cache=True, fastmath=True)
def _room_exit(o, d_lo, d_hi, room_lo, room_hi):
    """Ray parameter and face where a ray from inside leaves the room along one axis."""
    if d_hi > 1e-12:
        return (room_hi - o) / d_hi, 1
    if d_hi < -1e-12:
        return (room_lo - o) / d_hi, 0
    return 1e30, 0


@njit(cache=True, fastmath=True, nogil=True)
def _cast(rays, pix_angle, pix_tile, R, t, room_min, room_max, box_c, box_h, box_cs, tile_boxes, tile_count,
          box_cam, box_rot, box_lo, face_tex,
          face_tpm, face_off, face_tint, tex_data, tex_off, tex_size, light, ambient, light_ref2, out_grey,
          out_depth, out_rgb, want_rgb):
    n_pix = rays.shape[0]
    n_lv = tex_off.shape[1]
    ox, oy, oz = t[0], t[1], t[2]
    for i in range(n_pix):
        cx, cy, cz = rays[i, 0], rays[i, 1], rays[i, 2]
        dx = R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
        dy = R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
        dz = R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz
        # Room: exit through the nearest inner face.
        best, side = _room_exit(ox, dx, dx, room_min[0], room_max[0])
        face = side
        tk, side = _room_exit(oy, dy, dy, room_min[1], room_max[1])
        if tk < best:
            best = tk
            face = 2 + side
        tk, side = _room_exit(oz, dz, dz, room_min[2], room_max[2])
        if tk < best:
            best = tk
            face = 4 + side
        # Boxes: bounding-sphere rejection in the camera frame, then a slab test in the box frame.
        rr = cx * cx + cy * cy + cz * cz
        inv_rr = 1.0 / rr
        inv_r = np.sqrt(inv_rr)
        tile = pix_tile[i]
        for j in range(tile_count[tile]):
            b = tile_boxes[tile, j]
            proj = (box_cam[b, 0] * cx + box_cam[b, 1] * cy + box_cam[b, 2] * cz) * inv_rr
            qx = box_cam[b, 0] - proj * cx
            qy = box_cam[b, 1] - proj * cy
            qz = box_cam[b, 2] - proj * cz
            rad = box_cam[b, 3]
            if qx * qx + qy * qy + qz * qz > rad * rad:
                continue
            if proj - rad * inv_r >= best:
                continue
            lx = box_rot[b, 0, 0] * cx + box_rot[b, 0, 1] * cy + box_rot[b, 0, 2] * cz
            ly = box_rot[b, 1, 0] * cx + box_rot[b, 1, 1] * cy + box_rot[b, 1, 2] * cz
            lz = box_rot[b, 2, 0] * cx + box_rot[b, 2, 1] * cy + box_rot[b, 2, 2] * cz
            tmin = -1e30
            tmax = 1e30
            axis = -1
            miss = False
            for k in range(3):
                h = box_h[b, k]
                lo = box_lo[b, k]
                ld = lx if k == 0 else (ly if k == 1 else lz)
                if abs(ld) < 1e-12:
                    if abs(lo) > h:
                        miss = True
                        break
                    continue
                t1 = (-h - lo) / ld
                t2 = (h - lo) / ld
                if t1 > t2:
                    t1, t2 = t2, t1
                if t1 > tmin:
                    tmin = t1
                    axis = k
                if t2 < tmax:
                    tmax = t2
                if tmin > tmax:
                    miss = True
                    break
            if miss or axis < 0 or tmin <= 1e-6 or tmin >= best:
                continue
            best = tmin
            ld = lx if axis == 0 else (ly if axis == 1 else lz)
            face = 6 + 6 * b + 2 * axis + (0 if ld > 0 else 1)
        # Hit point, face frame (texture axes in metres) and normal.
        hx = ox + best * dx
        hy = oy + best * dy
        hz = oz + best * dz
        nx = 0.0
        ny = 0.0
        nz = 0.0
        if face < 6:
            k = face // 2
            sgn = 1.0 if face % 2 == 0 else -1.0
            if k == 0:
                su, sv = hy, hz
                nx = sgn
            elif k == 1:
                su, sv = hx, hz
                ny = sgn
            else:
                su, sv = hx, hy
                nz = sgn
        else:
            b = (face - 6) // 6
            k = ((face - 6) % 6) // 2
            cs = box_cs[b, 0]
            sn = box_cs[b, 1]
            px = hx - box_c[b, 0]
            py = hy - box_c[b, 1]
            lx = cs * px + sn * py + box_h[b, 0]
            ly = -sn * px + cs * py + box_h[b, 1]
            lz = hz - box_c[b, 2] + box_h[b, 2]
            sgn = 1.0 if face % 2 == 1 else -1.0
            if k == 0:
                su, sv = ly, lz
                nx = sgn * cs
                ny = sgn * sn
            elif k == 1:
                su, sv = lx, lz
                nx = -sgn * sn
                ny = sgn * cs
            else:
                su, sv = lx, ly
                nz = sgn
        # Pixel footprint -> mip level (trilinear).
        dn = np.sqrt(dx * dx + dy * dy + dz * dz)
        cos_i = abs(nx * dx + ny * dy + nz * dz) / dn
        if cos_i < 0.05:
            cos_i = 0.05
        tpm = face_tpm[face]
        foot = best * dn * pix_angle[i] / np.sqrt(cos_i) * tpm
        # Level l0 with footprint in [2^l0, 2^(l0+1)); blend weight linear in the footprint
        # (continuous across levels, cheaper than log2).
        l0 = 0
        while foot >= 2.0 and l0 < n_lv - 1:
            foot *= 0.5
            l0 += 1
        w1 = foot - 1.0 if foot > 1.0 else 0.0
        if w1 > 1.0:
            w1 = 1.0
        l1 = l0 + 1 if l0 + 1 < n_lv else l0
        tid = face_tex[face]
        u = (su + face_off[face, 0]) * tpm
        v = (sv + face_off[face, 1]) * tpm
        s0 = 1.0 / (1 << l0)
        albedo = _sample(tex_data, tex_off[tid, l0], tex_size[tid, l0], u * s0, v * s0)
        if w1 > 0.0:
            a1 = _sample(tex_data, tex_off[tid, l1], tex_size[tid, l1], u * s0 * 0.5, v * s0 * 0.5)
            albedo = albedo * (1.0 - w1) + a1 * w1
        albedo *= 1.0 / 65535.0
        # Shading: ambient + Lambertian point light, inverse-square falloff normalised at light_ref.
        lx = light[0] - hx
        ly = light[1] - hy
        lz = light[2] - hz
        r2 = lx * lx + ly * ly + lz * lz
        cos_l = (nx * lx + ny * ly + nz * lz) / np.sqrt(r2)
        if cos_l < 0.0:
            cos_l = 0.0
        shade = ambient + (1.0 - ambient) * cos_l * light_ref2 / (r2 + 0.25 * light_ref2)
        g = albedo * shade * 2.0
        out_grey[i] = g
        out_depth[i] = best * cz
        if want_rgb:
            out_rgb[i, 0] = g * face_tint[face, 0]
            out_rgb[i, 1] = g * face_tint[face, 1]
            out_rgb[i, 2] = g * face_tint[face, 2]


@njit(cache=True, fastmath=True, nogil=True)
def _cull_tiles(tile_axis, tile_cone, vis, box_cam, tile_boxes, tile_count):
    """Per pixel tile, the boxes whose bounding sphere meets the tile's cone of rays."""
    for k in range(tile_axis.shape[0]):
        n = 0
        for j in range(vis.shape[0]):
            b = vis[j]
            cx, cy, cz, rad = box_cam[b, 0], box_cam[b, 1], box_cam[b, 2], box_cam[b, 3]
            dist = np.sqrt(cx * cx + cy * cy + cz * cz)
            hit = dist <= rad
            if not hit:
                cos_a = (cx * tile_axis[k, 0] + cy * tile_axis[k, 1] + cz * tile_axis[k, 2]) / dist
                ang = np.arccos(min(max(cos_a, -1.0), 1.0))
                hit = ang <= tile_cone[k] + np.arcsin(rad / dist)
            if hit:
                tile_boxes[k, n] = b
                n += 1
        tile_count[k] = n


class Renderer:
    """Renders one camera in one scene; the per-pixel rays are computed once here.

    Rays go through raw pixel centres (integer coordinates), ``z = 1`` in the camera frame, so the
    ray parameter of a hit is its z-depth. The caster releases the GIL, so an image is cast in row
    bands on ``threads`` threads (default: the CPUs this process may use); every pixel is cast on its
    own, so the image is bit-identical for any number of threads.
    """

    def __init__(self, scene: Scene, camera: CameraModel, threads: int | None = None) -> None:
        self.scene = scene
        self.camera = camera
        n_pix = camera.width * camera.height
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        n_threads = max(1, min(threads or cpus, n_pix // _MIN_CHUNK_PX))
        n_bands = 1 if n_threads == 1 else n_threads * _BANDS_PER_THREAD
        edges = np.linspace(0, n_pix, n_bands + 1).astype(int)
        self._bands = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
        self._pool = ThreadPoolExecutor(n_threads, thread_name_prefix="atsvo-render") if n_threads > 1 else None
        u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
        uv = np.column_stack([u.ravel(), v.ravel()])
        xy = camera.pixel_to_normalized(uv)
        self.rays = np.ascontiguousarray(np.column_stack([xy, np.ones(len(xy))]))
        # Angular size of a pixel along each ray (from the neighbour one pixel to the right/down).
        xy_r = camera.pixel_to_normalized(uv + [0.5, 0.5])
        step = np.linalg.norm(xy_r - camera.pixel_to_normalized(uv - [0.5, 0.5]), axis=1) / np.sqrt(2.0)
        self.pix_angle = np.ascontiguousarray(step / (1.0 + np.sum(xy * xy, axis=1)))
        s = scene
        self._light_ref2 = float((s.room_max[2] - s.room_min[2] - 0.5) ** 2)
        # Half-angle of the cone holding every ray (for culling boxes outside the view).
        self._cone_half_angle = float(np.max(np.arctan(np.hypot(xy[:, 0], xy[:, 1])))) + 0.02
        # 8x8 pixel tiles: unit axis and half-angle of each tile's cone of rays (box culling per tile).
        tv, tu = np.divmod(np.arange(camera.width * camera.height), camera.width)
        tiles_x = (camera.width + _TILE - 1) // _TILE
        self.pix_tile = np.ascontiguousarray((tv // _TILE) * tiles_x + tu // _TILE, dtype=np.int64)
        n_tiles = int(self.pix_tile.max()) + 1
        unit = self.rays / np.linalg.norm(self.rays, axis=1, keepdims=True)
        axis = np.zeros((n_tiles, 3))
        np.add.at(axis, self.pix_tile, unit)
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        cone = np.zeros(n_tiles)
        np.maximum.at(cone, self.pix_tile, np.arccos(np.clip(np.sum(unit * axis[self.pix_tile], axis=1), -1, 1)))
        self._tile_axis = np.ascontiguousarray(axis)
        self._tile_cone = cone + 0.01
        self._tile_boxes = np.zeros((n_tiles, max(scene.n_boxes, 1)), np.int64)
        self._tile_count = np.zeros(n_tiles, np.int64)
        edges = np.linspace(0, n_tiles, n_threads + 1).astype(int)
        self._tile_bands = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
        tex16 = np.round(np.clip(s.atlas.data, 0.0, 1.0) * 65535.0).astype(np.uint16)
        self._scene_args = (s.room_min, s.room_max, s.box_center, s.box_half, np.ascontiguousarray(s.box_cos_sin),
                            s.face_tex, s.face_texel_per_m, s.face_offset_m, s.face_tint, tex16,
                            s.atlas.offsets, s.atlas.sizes, s.light_pos, float(s.ambient), self._light_ref2)
        self._empty_rgb = np.zeros((0, 3), np.float32)

    def render(self, T_world_cam: np.ndarray, rgb: bool = False,
               then: Callable[[slice, np.ndarray, np.ndarray], None] | None = None):
        """``(irradiance HxW float32, depth_m HxW float32[, rgb HxWx3 float32])`` at one pose.

        ``then(band, grey, depth)``, if given, runs in each band's thread once that band is cast (``grey`` and
        ``depth`` flat): per-pixel work on the image shares the threads instead of a pass of its own after them.
        """
        cam = self.camera
        n = cam.width * cam.height
        grey = np.empty(n, np.float32)
        depth = np.empty(n, np.float32)
        col = np.empty((n, 3), np.float32) if rgb else self._empty_rgb
        T = np.asarray(T_world_cam, np.float64)
        R, t = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])
        s = self.scene
        # Per-view box data: bounding spheres in the camera frame, camera->box rotations, origins.
        rel = s.box_center - t
        box_cam = np.ascontiguousarray(np.column_stack([rel @ R, np.linalg.norm(s.box_half, axis=1)]))
        dist = np.linalg.norm(box_cam[:, :3], axis=1)
        ang = np.arccos(np.clip(box_cam[:, 2] / np.maximum(dist, 1e-9), -1.0, 1.0))
        slack = np.arcsin(np.clip(box_cam[:, 3] / np.maximum(dist, 1e-9), 0.0, 1.0))
        vis = np.flatnonzero((dist <= box_cam[:, 3]) | (ang <= self._cone_half_angle + slack))
        cs, sn = s.box_cos_sin[:, 0], s.box_cos_sin[:, 1]
        Rz_inv = np.zeros((s.n_boxes, 3, 3))
        Rz_inv[:, 0, 0], Rz_inv[:, 0, 1], Rz_inv[:, 1, 0], Rz_inv[:, 1, 1] = cs, sn, -sn, cs
        Rz_inv[:, 2, 2] = 1.0
        box_rot = np.ascontiguousarray(Rz_inv @ R)
        box_lo = np.ascontiguousarray((Rz_inv @ -rel[:, :, None])[:, :, 0])

        def cull(tiles: slice) -> None:
            _cull_tiles(self._tile_axis[tiles], self._tile_cone[tiles], vis, box_cam, self._tile_boxes[tiles],
                        self._tile_count[tiles])

        self._run(cull, self._tile_bands)
        a = self._scene_args

        def cast(band: slice) -> None:
            _cast(self.rays[band], self.pix_angle[band], self.pix_tile[band], R, t, *a[:5], self._tile_boxes,
                  self._tile_count, box_cam, box_rot, box_lo, *a[5:], grey[band], depth[band],
                  col[band] if rgb else col, rgb)
            if then is not None:
                then(band, grey, depth)

        self._run(cast, self._bands)
        shape = (cam.height, cam.width)
        if rgb:
            return grey.reshape(shape), depth.reshape(shape), col.reshape(shape + (3,))
        return grey.reshape(shape), depth.reshape(shape)

    def _run(self, job: Callable[[slice], None], bands: list[slice]) -> None:
        """``job`` on every band, on the pool's threads when there is one."""
        if self._pool is None:
            for band in bands:
                job(band)
            return
        for done in [self._pool.submit(job, band) for band in bands]:
            done.result()  # re-raises a failure of that band


class MotionProbe:
    """Largest apparent motion (px) of the scene between two camera poses, from a grid of 3-D points."""

    def __init__(self, camera: CameraModel, rays: np.ndarray, step_px: int = 8) -> None:
        self.camera = camera
        h, w = camera.height, camera.width
        step = max(1, min(step_px, w // 8, h // 8))
        vv, uu = np.meshgrid(np.arange(0, h, step), np.arange(0, w, step), indexing="ij")
        uu = np.concatenate([uu.ravel(), [w - 1, 0, w - 1, 0]])
        vv = np.concatenate([vv.ravel(), [h - 1, h - 1, 0, 0]])
        self.index = vv * w + uu
        self.uv = np.column_stack([uu, vv]).astype(np.float64)
        self.rays = rays

    def max_motion_px(self, depth: np.ndarray, T_w_c0: np.ndarray, T_w_c1: np.ndarray) -> np.ndarray | float:
        """Max pixel motion from pose ``T_w_c0`` to ``T_w_c1`` (one pose, or a stack -> one value each)."""
        d = depth.ravel()
        imin = int(np.argmin(d))
        idx = np.append(self.index, imin)
        uv0 = np.vstack([self.uv, [imin % self.camera.width, imin // self.camera.width]])
        p0 = self.rays[idx] * d[idx, None]
        single = np.ndim(T_w_c1) == 2
        T = se3_inv(np.asarray(T_w_c1).reshape(-1, 4, 4)) @ T_w_c0
        p1 = np.matmul(p0[None], np.swapaxes(T[:, :3, :3], 1, 2)) + T[:, None, :3, 3]
        uv1, _ = self.camera.project(p1.reshape(-1, 3))
        err = np.abs(uv1.reshape(len(T), -1, 2) - uv0).max(axis=2).max(axis=1)
        err[np.any(p1[:, :, 2] < 0.02, axis=1)] = np.inf
        return float(err[0]) if single else err


def render_view(scene: Scene, camera: CameraModel, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear irradiance (float32 HxW) and z-depth in metres (float32 HxW) of ``camera`` at a pose.

    ``T_world_cam`` maps camera-frame (optical: x right, y down, z forward) points to the world.
    Build a :class:`Renderer` instead when rendering many views of the same camera.
    """
    return Renderer(scene, camera).render(T_world_cam)
