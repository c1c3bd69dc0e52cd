"""Event pixel selection through the ATS (Section II-B, Eq. 3).

1. **Mask** (Fig. 5b): median-blur the ATS (``mask_median_ksize``) and keep the pixels whose
   blurred value is not black and reaches the median of the blurred image. On a sparse surface
   that median is 0 and the mask is "everything but the black areas of the median-blurred ATS"
   (the paper's wording in Section I); on a dense one it tightens to the brighter half.
2. **Candidates**: pixels of the events of the last ``window_fraction`` of the ATS window (a
   quarter in the paper) that fall on the mask.
3. **Eq. 3**: keep candidates with ``I + alpha * |grad I| > h`` on the ATS ``I`` (central
   differences).
4. **Spacing**: greedily, best score first, drop a candidate when an already selected pixel is
   within ``d`` in x *and* within ``d`` in y (so every selected pair differs by more than ``d`` in
   x or in y -- the printed ``|u_i - u_j| > d, |v_i - v_j| > d`` read as a minimum spacing, since
   requiring both for every pair would allow at most one pixel per ``d`` rows); at most
   ``max_points`` pixels, none within ``border_px`` of the border.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.config import EventSelectionConfig
from atsvo_ros.core.events import EventBatch
from atsvo_ros.core.selection._event_kernels import _thin
from atsvo_ros.errors import ImageError


@dataclass(frozen=True)
class EventSelection:
    """Every stage of the selection (for plots like the paper's Fig. 5); ``selected`` is what callers use."""

    mask: np.ndarray          # bool (H, W), step 1
    candidates: np.ndarray    # (N, 2) x, y of the unique event pixels of the window, step 2 before the mask
    on_mask: np.ndarray       # (N,) bool
    score: np.ndarray         # (N,) I + alpha |grad I|
    passed: np.ndarray        # (N,) bool: on the mask, inside the border, and score > h
    selected: np.ndarray      # (M, 2) x, y after the spacing rule, best first


def ats_mask(ats: np.ndarray, median_ksize: int) -> np.ndarray:
    """Step 1: pixels whose median-blurred ATS value is above 0 and at least the blurred image's median."""
    img = np.clip(ats + 0.5, 0, 255).astype(np.uint8)
    blurred = cv2.medianBlur(img, median_ksize) if median_ksize > 1 else img
    return (blurred > 0) & (blurred >= np.median(blurred))


def gradient_magnitude(img: np.ndarray) -> np.ndarray:
    """|grad I| from central differences (one-sided at the border), float32."""
    gy, gx = np.gradient(img.astype(np.float32))
    return np.sqrt(gx * gx + gy * gy)


def select_event_pixels_detailed(ats: np.ndarray, events: EventBatch, t_ns: int, window_ns: int,
                                 cfg: EventSelectionConfig | None = None) -> EventSelection:
    """Run the whole selection and keep every intermediate result."""
    cfg = cfg or EventSelectionConfig()
    if ats.ndim != 2:
        raise ImageError(f"the ATS must be a 2-D image, got shape {ats.shape}")
    h, w = ats.shape
    mask = ats_mask(ats, cfg.mask_median_ksize)
    t0 = int(t_ns) - int(round(cfg.window_fraction * window_ns))
    recent = (events.t > t0) & (events.t <= int(t_ns)) & (events.x < w) & (events.y < h)
    if np.any(recent):
        lin = np.unique(events.y[recent].astype(np.int64) * w + events.x[recent].astype(np.int64))
    else:
        lin = np.zeros(0, np.int64)
    cx, cy = lin % w, lin // w
    on_mask = mask[cy, cx]
    score = ats[cy, cx].astype(np.float32) + np.float32(cfg.alpha) * gradient_magnitude(ats)[cy, cx]
    b = cfg.border_px
    inside = (cx >= b) & (cy >= b) & (cx < w - b) & (cy < h - b)
    passed = on_mask & inside & (score > cfg.h)
    idx = np.flatnonzero(passed)
    order = idx[np.argsort(-score[idx], kind="stable")]
    keep = _thin(cx, cy, order, int(cfg.min_distance_px), w, h, int(cfg.max_points))
    selected = np.stack([cx[keep], cy[keep]], axis=1).astype(np.int64) if len(keep) else np.zeros((0, 2), np.int64)
    return EventSelection(mask, np.stack([cx, cy], axis=1), on_mask, score, passed, selected)


def select_event_pixels(ats: np.ndarray, events: EventBatch, t_ns: int, window_ns: int,
                        cfg: EventSelectionConfig | None = None) -> np.ndarray:
    """Selected pixels ``(N, 2)`` as integer ``(x, y)``, best score first.

    Args:
        ats: the rendered ATS (float 0..255) at ``t_ns``.
        events: recent events (at least the last ``window_fraction * window_ns``; older ones are ignored).
        t_ns: the ATS time.
        window_ns: the ATS window (``TimeSurface.window_ns()``).
        cfg: Eq. 3 parameters.
    """
    return select_event_pixels_detailed(ats, events, t_ns, window_ns, cfg).selected
