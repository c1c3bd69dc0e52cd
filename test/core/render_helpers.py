"""A tiny ray-cast renderer of a textured box room for the odometry tests (exact depth and poses).

Independent of ``atsvo_ros.sim`` on purpose: the tracker tests need frames whose geometry is
known exactly, rendered for arbitrary camera poses.
"""
from __future__ import annotations

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel

_PX_PER_M = 200.0


def make_texture(seed: int, size: int = 512) -> np.ndarray:
    """Periodic pink-ish noise (FFT-filtered, so it wraps seamlessly) scaled to 20..235, float32."""
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(size)
    fr = np.hypot(f[:, None], f[None, :])
    # 1/f amplitude with a soft cut-off near 1/8 cycles per texel: band-limited, edges ~ 2 cm wide.
    spectrum = np.exp(-(fr / 0.06) ** 2) / np.maximum(fr, 1.0 / size)
    tex = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((size, size))) * spectrum)).astype(np.float32)
    tex -= tex.min()
    return (20.0 + 215.0 * tex / tex.max()).astype(np.float32)


def _rays(camera: CameraModel, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Viewing rays with z = 1 through (raw, possibly distorted) pixels."""
    xy = camera.pixel_to_normalized(np.column_stack([u.ravel(), v.ravel()]))
    return np.concatenate([xy, np.ones((len(xy), 1))], axis=1).reshape(u.shape + (3,))


class BoxRoom:
    """Axis-aligned room around the origin: planes ``n . p = d`` with their own textures."""

    def __init__(self, seed: int = 0, half_width_m: float = 2.5, half_height_m: float = 1.5,
                 front_m: float = 4.0, back_m: float = 3.0) -> None:
        # (normal, offset, in-plane axis u, in-plane axis v); normals point into the room.
        self.planes = [
            (np.array([0.0, 0.0, -1.0]), -front_m, np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
            (np.array([0.0, 0.0, 1.0]), -back_m, np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
            (np.array([1.0, 0.0, 0.0]), -half_width_m, np.array([0, 0, 1.0]), np.array([0, 1.0, 0])),
            (np.array([-1.0, 0.0, 0.0]), -half_width_m, np.array([0, 0, 1.0]), np.array([0, 1.0, 0])),
            (np.array([0.0, 1.0, 0.0]), -half_height_m, np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
            (np.array([0.0, -1.0, 0.0]), -half_height_m, np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
        ]
        self.textures = [make_texture(seed * 10 + i) for i in range(len(self.planes))]

    def render(self, camera: CameraModel, T_w_c: np.ndarray, supersample: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Grey image (float32, 0-255) and z-depth (float32 m) of a camera at ``T_w_c`` (raw pixels)."""
        s = supersample
        w, h = camera.width * s, camera.height * s
        u, v = np.meshgrid((np.arange(w) + 0.5) / s - 0.5, (np.arange(h) + 0.5) / s - 0.5)
        d_c = _rays(camera, u, v)
        R, o = T_w_c[:3, :3], T_w_c[:3, 3]
        d_w = d_c @ R.T
        best_t = np.full(u.shape, np.inf)
        best_i = np.full(u.shape, -1)
        for i, (n, d, _, _) in enumerate(self.planes):
            nd = d_w @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (d - n @ o) / nd
            t = np.where((t > 1e-6) & np.isfinite(t), t, np.inf)
            closer = t < best_t
            best_t = np.where(closer, t, best_t)
            best_i = np.where(closer, i, best_i)
        img = np.zeros(u.shape, np.float32)
        p = o + d_w * best_t[..., None]
        for i, (_, _, ax_u, ax_v) in enumerate(self.planes):
            m = best_i == i
            if not m.any():
                continue
            tu = (p[..., :] @ ax_u * _PX_PER_M).astype(np.float32)
            tv = (p[..., :] @ ax_v * _PX_PER_M).astype(np.float32)
            tex = self.textures[i]
            size = tex.shape[0]
            look = cv2.remap(tex, np.mod(tu, size), np.mod(tv, size), cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            img[m] = look[m]
        if s > 1:
            img = cv2.resize(img, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
        return img, self.render_depth(camera, T_w_c)

    def render_depth(self, camera: CameraModel, T_w_c: np.ndarray) -> np.ndarray:
        """Exact z-depth at pixel centres."""
        u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
        d_c = _rays(camera, u, v)
        R, o = T_w_c[:3, :3], T_w_c[:3, 3]
        d_w = d_c @ R.T
        best_t = np.full(u.shape, np.inf)
        for n, d, _, _ in self.planes:
            nd = d_w @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (d - n @ o) / nd
            t = np.where((t > 1e-6) & np.isfinite(t), t, np.inf)
            best_t = np.minimum(best_t, t)
        return best_t.astype(np.float32)
