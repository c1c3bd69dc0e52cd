"""What mapping hands a local window optimisation of its keyframes, and what it hears back.

The mapper keeps, for each keyframe of its local map, the image tracking prepared (colour pyramid, depth) and its
row timing; after inserting a keyframe it may ask a :class:`WindowRefiner` to move the keyframe poses, and their
points with them, so that each keyframe's image agrees with the other keyframes' points. The optimiser itself works
on residual blocks and lives with tracking (:mod:`atsvo_ros.core.tracking.window`); it is handed to the mapper.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.mapping.map import PointMap
from atsvo_ros.core.rolling_shutter import RollingShutter


@dataclass(frozen=True)
class KeyframeView:
    """A keyframe's image as tracking prepared it, and its row timing frozen at the pose it was inserted at.

    Attributes:
        frame: the keyframe's colour pyramid and depth (on the pinhole grid).
        rolling_shutter: the colour image's row timing with its velocity frozen
            (:meth:`~atsvo_ros.core.rolling_shutter.RollingShutter.frozen`), or None for a global shutter.
    """

    frame: PreparedFrame
    rolling_shutter: RollingShutter | None


@dataclass(frozen=True)
class WindowReport:
    """One window optimisation: how much it did and how long it took (mapping time, not tracking time).

    Attributes:
        keyframes: keyframe poses optimised (the oldest of the window is held fixed: the gauge).
        iterations: Levenberg-Marquardt iterations run.
        accepted: iterations whose step lowered the energy.
        max_move_m: the largest move of a keyframe's camera centre.
        time_s: wall time of the optimisation.
    """

    keyframes: int
    iterations: int
    accepted: int
    max_move_m: float
    time_s: float


class WindowRefiner(Protocol):
    """Moves the keyframe poses of a point map (and the points they host) to agree with each other's images."""

    def refine(self, point_map: PointMap, views: Mapping[int, KeyframeView]) -> WindowReport:
        """Optimise ``point_map``'s keyframes that have a view in ``views``, in place."""
        ...


__all__ = ["KeyframeView", "WindowRefiner", "WindowReport"]
