"""Coarse-to-fine direct photometric 3D-2D alignment on SE(3) (Eq. 4 of the paper).

The cost is a weighted sum of :class:`ResidualBlock` terms. Each block holds map points (world
frame), their stored pattern intensities on every pyramid level, the image pyramid of its own
camera and the extrinsic from the RGB camera to that camera; it contributes to one joint normal
equation in the RGB camera pose (a left perturbation of ``T_rgb_world``) plus, when it estimates a
brightness model, its own affine gain/offset ``(a, b)`` (``I' = e^a z + b``, as DSO). RGB-only
tracking (``w2 = 0``) is a single RGB block; the fusion issue adds an ATS block with its own
weight, camera, ``T_event_rgb`` and 14-pixel pattern without touching this solver.

The solver is Levenberg-Marquardt with Huber weights, per-point outlier rejection (the RMS
residual of a patch above ``outlier_threshold``), a convergence test on the update norm, and
several initial guesses (constant motion, zero motion) compared at the coarsest level.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from atsvo_ros.config import TrackerConfig
from atsvo_ros.core import _track_kernels as kernels
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import TrackingError


@dataclass
class ResidualBlock:
    """One term of Eq. 4: map points observed in one camera's image pyramid.

    Attributes:
        name: label (``"rgb"``, ``"ats"``) used for per-block results.
        points_w: (N, 3) float64 map points in the world frame.
        patches: (L, N, P) float32 stored intensities per pyramid level (``z_p`` of Eq. 4).
        pattern: (P, 2) float32 pixel offsets of the residual pattern.
        pyramid: per level an (H, W, 3) float32 array ``[I, dI/dx, dI/dy]`` of the current image.
        cameras: pinhole model per level, matching ``pyramid``.
        T_cam_rgb: 4x4 extrinsic from the RGB camera frame to this block's camera frame.
        weight: omega of Eq. 4.
        estimate_affine: whether the block has its own gain/offset parameters.
        border_px: projections closer than this to the image edge are not used (default: pattern
            radius + 1, the least that keeps bilinear reads inside the image).
        coarse_points: on level ``l > 0`` use an evenly strided subset of ``max(coarse_points, N / 4^l)``
            points (0 = all): coarse levels only need to bring the estimate into the basin of the
            next level, and their pixels are 4x fewer per level anyway.
        zero_mean: compare patches after removing their means (only the gain of the brightness
            model remains): robust to vignetting and uneven lighting.
        ref_depth: (N,) depth of each point in its host keyframe, for ``max_scale_change``.
        max_scale_change: skip points now nearer/farther than this factor times their host depth
            (their stored patch shows another scale); 0 = use every point.
    """

    name: str
    points_w: np.ndarray
    patches: np.ndarray
    pattern: np.ndarray
    pyramid: list[np.ndarray]
    cameras: list[CameraModel]
    T_cam_rgb: np.ndarray = field(default_factory=lambda: np.eye(4))
    weight: float = 1.0
    estimate_affine: bool = True
    border_px: float | None = None
    coarse_points: int = 0
    zero_mean: bool = False
    ref_depth: np.ndarray | None = None
    max_scale_change: float = 0.0

    def __post_init__(self) -> None:
        self.points_w = np.ascontiguousarray(self.points_w, dtype=np.float64).reshape(-1, 3)
        self.patches = np.asarray(self.patches, dtype=np.float32)
        self.pattern = np.ascontiguousarray(self.pattern, dtype=np.float64)
        self.T_cam_rgb = np.ascontiguousarray(self.T_cam_rgb, dtype=np.float64)
        n = len(self.points_w)
        if self.patches.ndim != 3 or self.patches.shape[1] != n or self.patches.shape[2] != len(self.pattern):
            raise TrackingError(f"block {self.name}: patches shape {self.patches.shape} does not match "
                                f"{n} points x {len(self.pattern)} pattern pixels")
        if len(self.pyramid) != len(self.cameras):
            raise TrackingError(f"block {self.name}: {len(self.pyramid)} pyramid levels but "
                                f"{len(self.cameras)} cameras")
        self.ref_depth = (np.zeros(n) if self.ref_depth is None
                          else np.ascontiguousarray(self.ref_depth, dtype=np.float64).reshape(-1))
        if len(self.ref_depth) != n:
            raise TrackingError(f"block {self.name}: {len(self.ref_depth)} reference depths for {n} points")
        if self.border_px is None:  # the pattern plus the bilinear neighbour must stay inside
            self.border_px = float(np.abs(self.pattern).max(initial=0.0)) + 1.0
        self.state = np.zeros(n, dtype=np.int8)
        self._subsets: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _level_data(self, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Points, patches, reference depths and state array used on ``level`` (strided subset on coarse levels)."""
        n = len(self.points_w)
        keep = n if level == 0 or self.coarse_points <= 0 else max(self.coarse_points, n >> (2 * level))
        if keep >= n:
            patches = self.patches[level]
            if not patches.flags.c_contiguous:
                patches = np.ascontiguousarray(patches)
            return self.points_w, patches, self.ref_depth, self.state
        if level not in self._subsets:
            stride = n / keep
            idx = np.floor(np.arange(keep) * stride).astype(np.int64)
            self._subsets[level] = (np.ascontiguousarray(self.points_w[idx]),
                                    np.ascontiguousarray(self.patches[level][idx]),
                                    np.ascontiguousarray(self.ref_depth[idx]), np.zeros(keep, np.int8))
        return self._subsets[level]

    @property
    def n_levels(self) -> int:
        return min(len(self.pyramid), self.patches.shape[0])

    def linearise(self, level: int, T_rgb_w: np.ndarray, affine: tuple[float, float], huber: float,
                  outlier_thr: float, grad_c: float = 0.0) -> tuple[np.ndarray, np.ndarray, float, int, int, float]:
        """Normal equations (8x8 ``H``, 8 ``g``), energy, inliers, visible points, inlier SSE at ``level``."""
        cam = self.cameras[level]
        H = np.zeros((8, 8))
        g = np.zeros(8)
        points, patches, zref, state = self._level_data(level)
        e, n_in, n_vis, sse = kernels._linearise(
            points, patches, self.pyramid[level], self.pattern, cam.fx, cam.fy, cam.cx, cam.cy,
            np.ascontiguousarray(T_rgb_w), self.T_cam_rgb, float(np.exp(affine[0])), float(affine[1]),
            float(huber), float(outlier_thr), float(self.border_px), float(grad_c) ** 2, bool(self.zero_mean),
            zref, float(self.max_scale_change), H, g, state)
        return H * self.weight, g * self.weight, e * self.weight, int(n_in), int(n_vis), float(sse)


@dataclass(frozen=True)
class TrackResult:
    """Outcome of :meth:`Tracker.track`.

    ``covariance`` is the 6x6 covariance of a left perturbation of ``T_rgb_w`` (twist, translation
    first), the inverse of the final normal equations scaled by the residual variance.
    """

    T_rgb_w: np.ndarray
    affine: dict[str, tuple[float, float]]
    covariance: np.ndarray
    energy: float
    n_inliers: int
    n_visible: int
    n_points: int
    iterations: int
    converged: bool
    guess_index: int
    states: dict[str, np.ndarray]
    singular: bool = False  # LM met a singular system on some level (degenerate geometry or no texture)

    @property
    def ok(self) -> bool:
        return bool(np.all(np.isfinite(self.T_rgb_w)) and np.all(np.isfinite(self.covariance)))


@dataclass
class _System:
    """Normal equations of all blocks at one level and one estimate (what LM compares and solves)."""

    H: np.ndarray
    g: np.ndarray
    energy: float
    n_inliers: int
    n_visible: int
    n_residuals: int
    sse: float
    affine_blocks: list[ResidualBlock]

    @property
    def energy_per_point(self) -> float:
        return self.energy / max(self.n_visible, 1)


@dataclass
class _LevelResult:
    """Outcome of LM on one pyramid level."""

    T: np.ndarray
    affine: dict[str, tuple[float, float]]
    system: _System
    iterations: int
    converged: bool
    singular: bool
    fresh: bool  # the blocks' point states belong to ``T`` (no rejected step after the last accepted one)
    threshold: float


class Tracker:
    """Coarse-to-fine Levenberg-Marquardt over a list of residual blocks."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config

    def _system(self, blocks: list[ResidualBlock], level: int, T: np.ndarray,
                affine: dict[str, tuple[float, float]], thr: float) -> _System:
        cfg = self.config
        aff_blocks = [b for b in blocks if b.estimate_affine and level < b.n_levels]
        dim = 6 + 2 * len(aff_blocks)
        H = np.zeros((dim, dim))
        g = np.zeros(dim)
        energy = 0.0
        n_in = n_vis = n_res = 0
        sse = 0.0
        for blk in blocks:
            if level >= blk.n_levels or len(blk.points_w) == 0:
                continue
            Hb, gb, e, ni, nv, s = blk.linearise(level, T, affine[blk.name], cfg.huber_delta, thr,
                                                 cfg.gradient_weight)
            H[:6, :6] += Hb[:6, :6]
            g[:6] += gb[:6]
            if blk.estimate_affine:
                k = 6 + 2 * aff_blocks.index(blk)
                H[:6, k:k + 2] += Hb[:6, 6:]
                H[k:k + 2, :6] += Hb[6:, :6]
                H[k:k + 2, k:k + 2] += Hb[6:, 6:]
                g[k:k + 2] += gb[6:]
            energy += e
            n_in += ni
            n_vis += nv
            n_res += ni * len(blk.pattern)
            sse += s
        # Weak prior keeps the brightness parameters well posed when few points are visible.
        for i in range(6, dim):
            H[i, i] += 1e-3 * max(1, n_in)
        return _System(H, g, float(energy), int(n_in), int(n_vis), int(n_res), float(sse), aff_blocks)

    def _optimise_level(self, blocks: list[ResidualBlock], level: int, T: np.ndarray,
                        affine: dict[str, tuple[float, float]], first: _System | None = None) -> _LevelResult:
        """LM at one level. The outlier threshold is relaxed (x2, up to x4) while most visible points
        are outliers (a poor initial guess); convergence is an update below ``convergence_eps``
        scaled by the level's pixel size, or a stalling energy."""
        cfg = self.config
        thr = cfg.outlier_threshold
        cur = first if first is not None else self._system(blocks, level, T, affine, thr)
        for _ in range(2):
            if cur.n_visible == 0 or cur.n_inliers >= 0.5 * cur.n_visible:
                break
            thr *= 2.0
            cur = self._system(blocks, level, T, affine, thr)
        eps = cfg.convergence_eps * (2.0 ** level)
        lam = 1e-4
        iters = rejected = 0
        converged = singular = False
        fresh = True
        for _ in range(cfg.max_iterations):
            iters += 1
            if cur.n_inliers < 6:
                break
            delta, T_new = kernels._lm_step(cur.H, cur.g, float(lam), np.ascontiguousarray(T))
            if not np.all(np.isfinite(delta)):  # singular damped system: reported, never hidden
                singular = True
                break
            aff_new = dict(affine)
            for j, blk in enumerate(cur.affine_blocks):
                a, b = affine[blk.name]
                aff_new[blk.name] = (a + delta[6 + 2 * j], b + delta[7 + 2 * j])
            new = self._system(blocks, level, T_new, aff_new, thr)
            small = float(np.sqrt(delta[:6] @ delta[:6])) < eps
            if new.n_visible > 0 and new.energy_per_point < cur.energy_per_point:
                gain = 1.0 - new.energy_per_point / max(cur.energy_per_point, 1e-12)
                T, affine, cur = T_new, aff_new, new
                fresh = True
                rejected = 0
                lam = max(lam * 0.25, 1e-7)
                if small or gain < 1e-3:  # the update or the energy (per visible point) stalls
                    converged = True
                    break
            else:
                fresh = False
                rejected += 1
                lam *= 8.0
                # Near the minimum, noise and points crossing the border make tiny steps fail: stop.
                if small or rejected >= 3:
                    converged = small or iters > 3
                    break
        return _LevelResult(T, affine, cur, iters, converged, singular, fresh, thr)

    def track(self, blocks: list[ResidualBlock], guesses: list[np.ndarray],
              affine: dict[str, tuple[float, float]] | None = None) -> TrackResult:
        """Estimate ``T_rgb_w`` of the current frame.

        Args:
            blocks: residual blocks (RGB first); their pyramids hold the current images.
            guesses: candidate initial ``T_rgb_w`` (e.g. constant motion, zero motion); each is
                evaluated at the coarsest level and the lowest energy per visible point wins.
            affine: initial ``(a, b)`` per block name (default zeros).
        """
        if not blocks or not guesses:
            raise TrackingError("tracking needs at least one residual block and one initial guess")
        affine = {b.name: (affine or {}).get(b.name, (0.0, 0.0)) for b in blocks}
        top = max(b.n_levels for b in blocks) - 1
        # Evaluate every guess at the coarsest level; energy per visible point (outliers pay a
        # constant) picks the guess that explains the image best, which is then optimised.
        best, best_sys = None, None
        for gi, T0 in enumerate(guesses):
            T0 = np.asarray(T0, dtype=np.float64)
            if not np.all(np.isfinite(T0)):
                continue
            sysm = self._system(blocks, top, T0, affine, self.config.outlier_threshold)
            if sysm.n_visible > 0 and (best_sys is None or sysm.energy_per_point < best_sys.energy_per_point):
                best, best_sys = gi, sysm
        if best is None:
            raise TrackingError("no initial guess sees any map point (or every guess contains NaN)")
        if best != len(guesses) - 1:
            best_sys = None  # the blocks' point states belong to the last guess evaluated
        out = self._optimise_level(blocks, top, np.asarray(guesses[best], dtype=np.float64), dict(affine), best_sys)
        total_iters = out.iterations
        singular = out.singular
        for level in range(top - 1, -1, -1):
            out = self._optimise_level(blocks, level, out.T, out.affine)
            total_iters += out.iterations
            singular |= out.singular
        final = out.system
        if not out.fresh or top == 0 or out.threshold != self.config.outlier_threshold:
            # Point states and H must belong to the final estimate (a rejected step overwrote them), and
            # inliers are judged at the nominal threshold: the relaxed one only helps a poor guess converge.
            final = self._system(blocks, 0, out.T, out.affine, self.config.outlier_threshold)
        cov = self._covariance(final.H, final.n_residuals, final.sse) * self.config.covariance_scale
        states = {b.name: b.state.copy() for b in blocks}
        n_points = sum(len(b.points_w) for b in blocks)
        return TrackResult(out.T, out.affine, cov, final.energy, final.n_inliers, final.n_visible, int(n_points),
                           int(total_iters), bool(out.converged), int(best), states, bool(singular))

    @staticmethod
    def _covariance(H: np.ndarray, n_res: int, sse: float) -> np.ndarray:
        dof = max(1, n_res - H.shape[0])
        # The residual variance, floored at 1 intensity^2 (quantisation and sensor noise never vanish),
        # so a degenerate fit (a blank image explained by the brightness model) is not "certain".
        sigma2 = max(sse / dof, 1.0) if n_res > H.shape[0] else 1e4
        try:
            cov = np.linalg.inv(H + 1e-9 * np.eye(len(H)))[:6, :6] * sigma2
        except np.linalg.LinAlgError:
            cov = np.full((6, 6), np.nan)
        if not np.all(np.isfinite(cov)):
            cov = np.eye(6) * 1e6
        return 0.5 * (cov + cov.T)


def image_pyramid_with_gradients(pyramid: list[np.ndarray]) -> list[np.ndarray]:
    """Stack each level with its central-difference gradients: (H, W, 3) float32 ``[I, Ix, Iy]``."""
    return [kernels._gradient_stack(np.ascontiguousarray(img, dtype=np.float32)) for img in pyramid]


__all__ = ["ResidualBlock", "TrackResult", "Tracker", "image_pyramid_with_gradients"]
