"""Procedural albedo textures with natural-image statistics, stored as trilinear mip pyramids.

Real indoor surfaces are neither checkerboards nor white noise: their spectra fall off roughly as
1/f (amplitude), they hold sharp-edged regions (posters, tiles, planks, furniture) and large
nearly uniform areas (painted plaster) where direct methods get little gradient. Each texture here
mixes the three, is periodic (tiles without seams) and comes with a box-filtered mip pyramid so
the renderer can pick the level matching the pixel footprint and avoid aliasing.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.errors import SimulationError

#: Surface styles: (1/f exponent, noise contrast, share of shapes, low-texture share, anisotropy).
STYLES: dict[str, tuple[float, float, float, float, float]] = {
    "plaster": (1.2, 0.04, 0.2, 0.7, 1.0),
    "concrete": (1.0, 0.10, 0.4, 0.3, 1.0),
    "wood": (1.0, 0.12, 0.3, 0.1, 6.0),
    "poster": (1.0, 0.08, 1.0, 0.1, 1.0),
    "carpet": (0.8, 0.12, 0.3, 0.1, 1.0),
    "cardboard": (1.3, 0.06, 0.6, 0.3, 1.0),
}


@dataclass(frozen=True)
class TextureAtlas:
    """All mip levels of all textures in one flat float32 array (what the numba renderer reads).

    ``offsets[i, l]`` is where level ``l`` of texture ``i`` starts, ``sizes[i, l]`` its side
    (power of two, square); levels past the last one repeat the coarsest level.
    """

    data: np.ndarray
    offsets: np.ndarray
    sizes: np.ndarray
    names: tuple[str, ...]

    @property
    def n_levels(self) -> int:
        return int(self.offsets.shape[1])

    def level(self, index: int, level: int = 0) -> np.ndarray:
        """One mip level as a 2-D view (for tests and previews)."""
        s = int(self.sizes[index, level])
        o = int(self.offsets[index, level])
        return self.data[o:o + s * s].reshape(s, s)


def pink_noise(rng: np.random.Generator, size: int, alpha: float, anisotropy: float = 1.0) -> np.ndarray:
    """Periodic zero-mean unit-variance noise with amplitude spectrum ~ 1/f^alpha.

    ``anisotropy`` > 1 stretches the structure along x (wood grain).
    """
    fx = np.fft.fftfreq(size)[None, :] * anisotropy
    fy = np.fft.fftfreq(size)[:, None]
    f = np.sqrt(fx * fx + fy * fy)
    f[0, 0] = 1.0
    amp = f ** (-alpha)
    amp[0, 0] = 0.0
    spec = (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size))) * amp
    out = np.fft.ifft2(spec).real
    out -= out.mean()
    return (out / max(out.std(), 1e-12)).astype(np.float32)


def _blur_wrap(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """Periodic Gaussian blur (in the Fourier domain, so tiles stay seamless)."""
    f = np.fft.fftfreq(img.shape[0])
    g = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (f[:, None] ** 2 + f[None, :] ** 2))
    return np.fft.ifft2(np.fft.fft2(img) * g).real.astype(np.float32)


def _shapes(rng: np.random.Generator, size: int, count: int) -> np.ndarray:
    """Sharp-edged rectangles, ellipses and bars drawn periodically (wrap-around) with random levels."""
    img = np.zeros((size, size), np.float32)
    for _ in range(count):
        kind = rng.integers(3)
        level = float(rng.uniform(-1.0, 1.0))
        cx, cy = (int(v) for v in rng.integers(0, size, 2))
        w, h = (int(v) for v in rng.integers(size // 40 + 1, size // 5 + 2, 2))
        for ox in (0, -size):
            for oy in (0, -size):
                x, y = cx + ox, cy + oy
                if kind == 0:
                    cv2.rectangle(img, (x, y), (x + w, y + h), level, -1, cv2.LINE_AA)
                elif kind == 1:
                    cv2.ellipse(img, (x, y), (w // 2 + 1, h // 2 + 1), float(rng.uniform(0, 180)), 0, 360,
                                level, -1, cv2.LINE_AA)
                else:
                    cv2.line(img, (x, y), (x + 2 * w, y + h // 3), level, max(1, size // 128), cv2.LINE_AA)
    return img


def make_texture(rng: np.random.Generator, size: int, style: str) -> np.ndarray:
    """One albedo texture in [0.03, 0.92] (float32, size x size, periodic) of the given style."""
    if style not in STYLES:
        raise SimulationError(f"unknown texture style {style!r} (known: {', '.join(STYLES)})")
    if size < 8 or size & (size - 1):
        raise SimulationError(f"texture size must be a power of two >= 8, got {size}")
    alpha, contrast, shape_share, flat_share, aniso = STYLES[style]
    base = float(rng.uniform(0.25, 0.7))
    noise = pink_noise(rng, size, alpha + float(rng.uniform(-0.1, 0.1)), aniso)
    shapes = _shapes(rng, size, int(8 + 60 * shape_share))
    # Low-texture regions: a smooth mask from coarse noise; inside it the contrast drops to ~5 %.
    coarse = pink_noise(rng, size, 2.5)
    thresh = np.quantile(coarse, flat_share) if flat_share > 0 else -np.inf
    mask = _blur_wrap((coarse > thresh).astype(np.float32), size / 64.0)
    gain = 0.05 + 0.95 * mask
    tex = base + gain * (contrast * noise + 0.3 * shapes)
    return np.clip(tex, 0.03, 0.92).astype(np.float32)


def build_atlas(textures: list[np.ndarray], names: list[str] | None = None) -> TextureAtlas:
    """Pack square power-of-two textures and their 2x2 box-filtered mip levels into one atlas."""
    if not textures:
        raise SimulationError("a scene needs at least one texture")
    sizes0 = [t.shape[0] for t in textures]
    for t in textures:
        if t.ndim != 2 or t.shape[0] != t.shape[1] or t.shape[0] & (t.shape[0] - 1):
            raise SimulationError(f"textures must be square power-of-two images, got shape {t.shape}")
    n_levels = int(np.log2(max(sizes0))) + 1
    chunks, offsets, sizes = [], np.zeros((len(textures), n_levels), np.int64), np.zeros((len(textures), n_levels),
                                                                                         np.int64)
    pos = 0
    for i, tex in enumerate(textures):
        level = np.asarray(tex, np.float32)
        for lv in range(n_levels):
            if lv > 0 and level.shape[0] > 1:
                s = level.shape[0] // 2
                level = level.reshape(s, 2, s, 2).mean(axis=(1, 3), dtype=np.float32)
                chunks.append(level.ravel())
                offsets[i, lv], sizes[i, lv] = pos, s
                pos += s * s
            elif lv == 0:
                chunks.append(level.ravel())
                offsets[i, lv], sizes[i, lv] = pos, level.shape[0]
                pos += level.size
            else:  # coarsest level reached: repeat it
                offsets[i, lv], sizes[i, lv] = offsets[i, lv - 1], sizes[i, lv - 1]
    data = np.ascontiguousarray(np.concatenate(chunks), dtype=np.float32)
    return TextureAtlas(data, offsets, sizes, tuple(names or (f"tex{i}" for i in range(len(textures)))))
