"""Residual patterns, bilinear sampling and robust weights for the photometric error of Eq. 4.

A map point stores the intensities of a small pattern of pixels around it (``z_p`` in Eq. 4).
The RGB term uses :data:`RGB_PATTERN` (p = 0..8: the pixel and its 8 neighbours, "the new pixel
and adjacent pixels" of Section II-C); the ATS term of the fusion issue uses :data:`ATS_PATTERN`
(q = 0..13). The paper does not draw either pattern; offsets are in pixels of the pyramid level
the pattern is sampled on, so a pattern covers the same share of the scene on every level.
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.image._sampling_kernels import _bilinear
from atsvo_ros.errors import ImageError

#: 9-pixel RGB residual pattern (dx, dy): the 3x3 neighbourhood, centre first.
RGB_PATTERN = np.array([(0, 0), (-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)],
                       dtype=np.float32)

#: 14-pixel ATS residual pattern (dx, dy): centre, 8 neighbours, the 4 axial pixels at distance 2
#: and one diagonal at distance 2. ATS images are smooth, so a wider footprint widens the basin of
#: convergence; 14 pixels (odd count impossible to make point-symmetric with the centre) as stated.
ATS_PATTERN = np.array([(0, 0), (-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1),
                        (0, -2), (-2, 0), (2, 0), (0, 2), (2, 2)], dtype=np.float32)

#: Pixels a pattern reaches from its centre (the tracker keeps projections this far inside).
RGB_PATTERN_RADIUS_PX = 1
ATS_PATTERN_RADIUS_PX = 2


def bilinear(image: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample a single-channel image at sub-pixel positions (N, 2) (x, y).

    Returns ``(values float32, valid)``; positions whose 2x2 support leaves the image are invalid
    and read 0.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2:
        raise ImageError(f"bilinear samples a single-channel image, got shape {img.shape}")
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.empty(len(uv), np.float32)
    valid = np.empty(len(uv), np.bool_)
    _bilinear(img, uv, out, valid)
    return out, valid


def sample_patches(image: np.ndarray, uv: np.ndarray, pattern: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intensities of ``pattern`` around each position: ``(N, P)`` float32 and a per-point validity mask."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    pat = np.asarray(pattern, dtype=np.float64).reshape(-1, 2)
    pos = uv[:, None, :] + pat[None, :, :]
    vals, valid = bilinear(image, pos.reshape(-1, 2))
    return vals.reshape(len(uv), len(pat)), valid.reshape(len(uv), len(pat)).all(axis=1)


def level_position(uv0: np.ndarray, level: int) -> np.ndarray:
    """Pixel position on pyramid ``level`` of level-0 positions (pixel-centre convention of build_pyramid)."""
    s = 0.5 ** level
    return (np.asarray(uv0, dtype=np.float64) + 0.5) * s - 0.5


def huber_weight(r: np.ndarray, delta: float) -> np.ndarray:
    """IRLS weight of the Huber loss: 1 inside ``delta``, ``delta / |r|`` outside."""
    a = np.abs(np.asarray(r, dtype=np.float64))
    return np.where(a <= delta, 1.0, delta / np.maximum(a, 1e-12))


def huber_energy(r: np.ndarray, delta: float) -> np.ndarray:
    """Huber loss scaled like a squared error: ``r^2`` inside ``delta``, ``2 delta |r| - delta^2`` outside."""
    a = np.abs(np.asarray(r, dtype=np.float64))
    return np.where(a <= delta, a * a, 2.0 * delta * a - delta * delta)


def extract_patches(pyramid: list[np.ndarray], uv0: np.ndarray, pattern: np.ndarray,
                    affine: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Pattern intensities of level-0 pixels on every level, ``(L, N, P)`` float32.

    Positions are clamped into each level so a point near the border still gets a patch (the
    tracker never reads it there). Intensities are mapped to the reference brightness scale
    ``z = (I - b) / e^a`` with the host frame's ``affine = (a, b)``.
    """
    uv0 = np.asarray(uv0, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(pyramid), len(uv0), len(pattern)), dtype=np.float32)
    a, b = affine
    for lvl, img in enumerate(pyramid):
        img = img[..., 0] if img.ndim == 3 else img
        h, w = img.shape
        pos = level_position(uv0, lvl)[:, None, :] + np.asarray(pattern, dtype=np.float64)[None]
        pos[..., 0] = np.clip(pos[..., 0], 0, w - 1)
        pos[..., 1] = np.clip(pos[..., 1], 0, h - 1)
        vals, _ = sample_patches(img, pos.reshape(-1, 2), np.zeros((1, 2)))
        out[lvl] = ((vals.reshape(len(uv0), len(pattern)) - b) / np.exp(a)).astype(np.float32)
    return out


__all__ = ["ATS_PATTERN", "ATS_PATTERN_RADIUS_PX", "RGB_PATTERN", "RGB_PATTERN_RADIUS_PX", "bilinear",
           "extract_patches", "huber_energy", "huber_weight", "level_position", "sample_patches"]
