"""The motion prior: a robust Gaussian on the RGB pose around the motion model's prediction.

The image and depth terms leave some directions of the pose unconstrained: mid-flip the camera
faces a blank, blurred floor, the depth image is one plane (it fixes the distance and the tilt, not
the slide along the floor or the turn about its normal) and a few dozen ATS patches are all that
is left. Without a prior the optimum drifts along those directions (backflip seed 4: 6.4 deg off
in the roll no turn had, lost the next frame). In flight a body keeps its angular momentum, so the
constant-velocity prediction is good to a fraction of a degree. The prior's information
(1/sigma^2) is tiny next to what textured images or a non-planar depth image contribute, so it
decides only the directions the data leaves free; a Huber kernel caps its pull where the
prediction is wrong (a landing's impact).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core._se3_kernels import _twist_per_s


@dataclass(frozen=True)
class PriorSystem:
    """The prior's normal equations in the pose twist (translation first) and its robust energy."""

    H: np.ndarray
    g: np.ndarray
    energy: float


@dataclass(frozen=True)
class MotionPrior:
    """Robust Gaussian prior on ``T_rgb_w`` around ``T_pred_rgb_w``.

    The residual is the left-perturbation twist ``log(T T_pred^-1)``: its translation is the camera
    centre's offset from the predicted one (in the camera frame), its rotation the turn between the
    two orientations. Each part is whitened by its sigma and Huber-weighted on its norm (``huber`` in
    sigma units), in the blocks' energy convention (squared residual, ``2 k |z| - k^2`` beyond ``k``).
    """

    T_pred_rgb_w: np.ndarray
    sigma_m: float
    sigma_rad: float
    huber: float = 2.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_pred_rgb_w", np.ascontiguousarray(self.T_pred_rgb_w, dtype=np.float64))

    def linearise(self, T_rgb_w: np.ndarray) -> PriorSystem:
        """Contribution to the normal equations ``H delta = -g`` at the estimate ``T_rgb_w`` (Jacobian ~ identity)."""
        r = _twist_per_s(np.ascontiguousarray(T_rgb_w, dtype=np.float64), self.T_pred_rgb_w, 1.0)
        w = np.empty(6)
        energy = 0.0
        k = self.huber
        for i, sigma in ((0, self.sigma_m), (3, self.sigma_rad)):
            z = math.sqrt(r[i] ** 2 + r[i + 1] ** 2 + r[i + 2] ** 2) / sigma
            energy += z * z if z <= k else 2.0 * k * z - k * k
            w[i:i + 3] = (1.0 if z <= k else k / z) / sigma ** 2
        return PriorSystem(np.diag(w), w * r, float(energy))


__all__ = ["MotionPrior", "PriorSystem"]
