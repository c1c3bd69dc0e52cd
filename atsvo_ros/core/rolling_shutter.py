"""Row timing of a rolling-shutter camera, shared by mapping (keyframe requests) and tracking (residuals).

A rolling shutter exposes each image row at its own time; the residuals move each point to its row's
exposure time with one constant camera twist per frame.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core._se3_kernels import _twist_per_s


@dataclass(frozen=True)
class RollingShutter:
    """Row timing of a rolling-shutter image, for residuals that move each point to its row's exposure time.

    Row ``v`` (level 0) is exposed ``t0_s + line_s v`` seconds after the frame's stamp; the camera
    velocity over the frame is that of the current estimate relative to the previous frame's pose
    ``T_prev_c_w``, ``dt_s`` earlier (a continuous-time model with one constant twist per frame).
    """

    t0_s: float
    line_s: float
    T_prev_c_w: np.ndarray
    dt_s: float
    #: the twist per second fixed whatever the estimate (:meth:`frozen`), or None: from the estimate
    velocity_per_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "_T_prev", np.ascontiguousarray(self.T_prev_c_w, dtype=np.float64))

    @classmethod
    def centred(cls, readout_s: float, height_px: int, T_prev_c_w: np.ndarray, dt_s: float,
                offset_s: float = 0.0) -> RollingShutter:
        """Readout over ``readout_s`` with the stamp at the middle row plus ``offset_s``."""
        return cls(offset_s - 0.5 * readout_s, readout_s / max(1, height_px), T_prev_c_w, dt_s)

    def frozen(self, T_c_w: np.ndarray) -> RollingShutter:
        """This timing with the velocity it has at ``T_c_w`` kept for any later estimate: a keyframe whose pose a
        window optimisation moves keeps the motion it was seen with (its previous frame is not moved along)."""
        vel = _twist_per_s(np.ascontiguousarray(T_c_w, dtype=np.float64), self._T_prev, float(self.dt_s))
        return dataclasses.replace(self, velocity_per_s=np.ascontiguousarray(vel))

    def params(self, level: int, T_c_w: np.ndarray) -> tuple[np.ndarray, float, float]:
        """``(twist per second, t0, line time)`` for pixel rows of pyramid ``level`` at the estimate ``T_c_w``."""
        vel = self.velocity_per_s
        if vel is None:
            vel = _twist_per_s(np.ascontiguousarray(T_c_w, dtype=np.float64), self._T_prev, float(self.dt_s))
        s = float(2 ** level)
        return np.ascontiguousarray(vel), self.t0_s + self.line_s * (0.5 * s - 0.5), self.line_s * s


    def to_stamp(self, points_c: np.ndarray, rows_px: np.ndarray, T_c_w: np.ndarray) -> np.ndarray:
        """Points seen at level-0 ``rows_px`` (camera frame at their row's time) in the camera frame at the stamp."""
        vel, t0, line = self.params(0, T_c_w)
        dt = (t0 + line * np.asarray(rows_px, dtype=np.float64))[:, None]
        p = np.asarray(points_c, dtype=np.float64).reshape(-1, 3)
        return p - dt * (vel[:3] + np.cross(vel[3:], p))


__all__ = ["RollingShutter"]
