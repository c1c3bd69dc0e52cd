"""Residual blocks of Eq. 4: each adds its normal equations in the RGB pose to one joint system.

A block is anything with the :class:`ResidualBlock` interface: the photometric block (RGB image or
ATS, :mod:`.photometric`) and the geometric block (point-to-plane on the depth image,
:mod:`.geometric`). The optimiser (:mod:`atsvo_ros.core.tracking.tracker`) knows only this interface, so the
event term of the fusion is another photometric block with its own camera, pattern and weights.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class BlockSystem:
    """One block's contribution at one level and one estimate.

    ``H`` is 8x8 (pose twist, then the block's log-gain and offset) for a block that estimates a
    brightness model, 6x6 otherwise; ``energy`` is the robust cost (outliers at a constant),
    ``sse`` the sum of squared inlier residuals in the block's noise units, ``n_residuals`` how
    many scalar residuals the inliers contributed.
    """

    H: np.ndarray
    g: np.ndarray
    energy: float
    n_inliers: int
    n_visible: int
    n_residuals: int
    sse: float


NO_MOTION = np.zeros(6)


class ResidualBlock(Protocol):
    """What the tracker needs from a term of Eq. 4."""

    name: str
    estimate_affine: bool
    state: np.ndarray  # per point: 0 invisible, 1 inlier, 2 outlier (after the last ``linearise`` at level 0)

    @property
    def n_levels(self) -> int: ...

    def __len__(self) -> int: ...

    def linearise(self, level: int, T_rgb_w: np.ndarray, affine: tuple[float, float],
                  relax: float = 1.0) -> BlockSystem:
        """Normal equations at ``level`` for the RGB pose ``T_rgb_w``; ``relax`` scales the outlier threshold."""
        ...


INVISIBLE, INLIER, OUTLIER = 0, 1, 2

__all__ = ["INLIER", "INVISIBLE", "NO_MOTION", "OUTLIER", "BlockSystem", "ResidualBlock"]
