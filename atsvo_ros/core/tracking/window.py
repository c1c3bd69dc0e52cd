"""Local mapping that refines: the keyframe poses of the local map optimised jointly against each other's points.

When mapping inserts a keyframe, every keyframe of the map's window is aligned at once: each keyframe's colour
image against the photometric points of every other keyframe (DSO's windowed photometric terms, with the point
depths held as the depth camera gave them). A point hosted by keyframe ``h`` and seen in keyframe ``t`` depends on
both poses. With the left update ``T_c_w <- exp(xi) T_c_w`` of both, moving the host by ``xi_h`` moves the point
in the target as moving the target by ``-Ad(T_t_h) xi_h`` would, so the host's Jacobian is the target's times
``-Ad(T_t_h)``. The pair's 6x6 normal equations from the tracking kernels (target pose, points fixed in the
world) thus fill all four blocks of the joint system, with no per-point Jacobian leaving the kernel. The oldest
keyframe is held fixed (the gauge); Levenberg-Marquardt runs ``mapping.window_iterations`` steps on the finest
level, and each keyframe's points move with it.

The depth term is left out: pairs of depth maps pull the poses towards the depth camera's own systematic errors
(TUM fr1_rpy_300 1.36 -> 3.1 cm with it, 1.2-1.3 without; docs/odometry.md). Tracking is not slowed: this runs
where mapping runs (a thread or a process of its own in the nodes).
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_adjoint, se3_exp, se3_inv, transform_points
from atsvo_ros.core.mapping.map import PointMap
from atsvo_ros.core.mapping.refine import KeyframeView, WindowReport
from atsvo_ros.core.tracking.residuals.photometric import PhotometricBlock
from atsvo_ros.core.tracking.tracking import rgb_block

#: Levenberg-Marquardt's first damping: the window runs on the finest level only, where an undamped first step
#: from 2 px of error overshoots (1 cm and 0.6 deg off in the unit test's room: to 2 cm at 1e-4, 8 mm at 1e-2).
#: Measured on TUM fr1_rpy_300 and its 11 subsamples and four simulated gaits (docs/odometry.md): 1e-2 kept
#: fr1_rpy_300's 1.20 cm and every 4th frame's four offsets under 1.6 cm where 1e-4 lost one of them (10 cm).
FIRST_DAMPING = 1e-2


@dataclass(frozen=True)
class _Pair:
    """The points hosted by one keyframe (``points_h``, host frame) against another keyframe's image (``block``,
    whose world points are set from the host's pose at each linearisation)."""

    target: int
    host: int
    points_h: np.ndarray
    block: PhotometricBlock


class WindowOptimiser:
    """Joint photometric optimisation of a point map's keyframe poses (see the module docstring).

    Args:
        config: ``mapping.window_iterations`` and the RGB term's parameters (``tracker``).
        cameras: the colour camera's pinhole model per pyramid level.
    """

    def __init__(self, config: AtsvoConfig, cameras: list[CameraModel]) -> None:
        self.config = config
        self.cameras = cameras

    def refine(self, point_map: PointMap, views: Mapping[int, KeyframeView]) -> WindowReport:
        """Optimise the keyframes of ``point_map`` that have a view, the oldest held; in place."""
        t_start = time.perf_counter()
        ids = [k for k in sorted(point_map.keyframes) if k in views]
        if len(ids) < 2 or self.config.mapping.window_iterations <= 0:
            return WindowReport(0, 0, 0, 0.0, time.perf_counter() - t_start)
        free = ids[1:]
        T0 = {k: se3_inv(point_map.keyframes[k].T_w_c) for k in ids}  # T_c_w
        pairs = self._pairs(point_map, views, ids, T0)
        T, iterations, accepted = self._optimise(point_map, pairs, free, T0)
        moves = [float(np.linalg.norm(se3_inv(T[k])[:3, 3] - point_map.keyframes[k].T_w_c[:3, 3])) for k in free]
        if accepted:
            for k in free:
                point_map.move_keyframe(k, se3_inv(T[k]))
        return WindowReport(len(free), iterations, accepted, max(moves) if accepted else 0.0,
                            time.perf_counter() - t_start)

    def _pairs(self, point_map: PointMap, views: Mapping[int, KeyframeView], ids: list[int],
               T_c_w: dict[int, np.ndarray]) -> list[_Pair]:
        """Every (target, host) pair of keyframes in ``ids``: the host's photometric points, the target's image."""
        cfg = self.config.tracker
        hosted = {h: point_map.host == h for h in ids}
        pairs = []
        for h in ids:
            if not hosted[h].any():
                continue
            points_h = transform_points(T_c_w[h], point_map.points_w[hosted[h]])
            patches = np.ascontiguousarray(point_map.patches[:, hosted[h]])
            depth_h = point_map.host_depth[hosted[h]]
            for t in ids:
                if t != h:
                    view = views[t]
                    block = rgb_block(cfg, point_map.points_w[hosted[h]], patches, depth_h, view.frame, self.cameras,
                                      view.rolling_shutter)
                    pairs.append(_Pair(t, h, points_h, block))
        return pairs

    def _system(self, point_map: PointMap, pairs: list[_Pair], col: dict[int, int],
                T: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray, float, int]:
        """Joint normal equations over the free poses, total energy and visible points at the poses ``T``."""
        n = 6 * len(col)
        H, g = np.zeros((n, n)), np.zeros(n)
        energy, visible = 0.0, 0
        for p in pairs:
            T_w_h = se3_inv(T[p.host])
            p.block.points_w = np.ascontiguousarray(transform_points(T_w_h, p.points_h))
            bs = p.block.linearise(0, T[p.target], point_map.keyframes[p.target].affine, 1.0)
            energy += bs.energy
            visible += bs.n_visible
            H_t, g_t = bs.H[:6, :6], bs.g[:6]
            A = se3_adjoint(T[p.target] @ T_w_h)
            i, j = col.get(p.target), col.get(p.host)
            if i is not None:
                H[i:i + 6, i:i + 6] += H_t
                g[i:i + 6] += g_t
            if j is not None:
                HA = H_t @ A
                H[j:j + 6, j:j + 6] += A.T @ HA
                g[j:j + 6] -= A.T @ g_t
                if i is not None:
                    H[i:i + 6, j:j + 6] -= HA
                    H[j:j + 6, i:i + 6] -= HA.T
        return H, g, energy, visible

    def _optimise(self, point_map: PointMap, pairs: list[_Pair], free: list[int],
                  T0: dict[int, np.ndarray]) -> tuple[dict[int, np.ndarray], int, int]:
        """Levenberg-Marquardt over the free poses; ``(poses, iterations, accepted steps)``."""
        col = {k: 6 * i for i, k in enumerate(free)}
        T = dict(T0)
        H, g, energy, visible = self._system(point_map, pairs, col, T)
        lam, iterations, accepted = FIRST_DAMPING, 0, 0
        for _ in range(self.config.mapping.window_iterations):
            if visible == 0:
                break
            iterations += 1
            damped = H + lam * np.diag(np.diag(H))
            try:
                delta = np.linalg.solve(damped, -g)
            except np.linalg.LinAlgError:  # a keyframe sees none of the others' points: nothing to align
                break
            if not np.all(np.isfinite(delta)):
                break
            T_new = dict(T)
            for k, c in col.items():
                T_new[k] = se3_exp(delta[c:c + 6]) @ T[k]
            H_new, g_new, e_new, v_new = self._system(point_map, pairs, col, T_new)
            if v_new > 0 and e_new / v_new < energy / visible:
                T, H, g, energy, visible = T_new, H_new, g_new, e_new, v_new
                lam = max(lam * 0.25, 1e-7)
                accepted += 1
            else:
                lam *= 8.0
        return T, iterations, accepted


def window_refiner(config: AtsvoConfig, cameras: list[CameraModel]) -> WindowOptimiser | None:
    """The mapper's window optimiser for ``config`` (None when ``mapping.window_iterations`` is 0)."""
    return WindowOptimiser(config, cameras) if config.mapping.window_iterations > 0 else None


__all__ = ["FIRST_DAMPING", "WindowOptimiser", "window_refiner"]
