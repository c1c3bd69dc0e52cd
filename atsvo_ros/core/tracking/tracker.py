"""Coarse-to-fine Levenberg-Marquardt on SE(3) over residual blocks (the optimiser of Eq. 4).

The cost is a weighted sum of :class:`~atsvo_ros.core.tracking.residuals.ResidualBlock` terms (photometric
RGB, geometric point-to-plane depth, the ATS term of Eq. 4); each contributes to one joint
normal equation in the RGB camera pose (a left perturbation of ``T_rgb_world``) plus, when it
estimates a brightness model, its own affine gain/offset ``(a, b)``. This module knows nothing of
images or depth: only of blocks.

Per level, LM with a relaxed outlier threshold (x2, up to x4) while most visible points are
outliers (a poor initial guess), and a convergence test on the update and on the energy. Several
initial guesses (constant motion, zero motion, gyro prediction, rotated hypotheses) are compared by
their energy per visible point at the coarsest level; the best ones are refined there and the
winner goes down the pyramid. Inliers, the covariance and the per-block statistics are taken at
the nominal threshold on the finest level.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import TrackerConfig
from atsvo_ros.core.tracking import _lm_kernels as lm
from atsvo_ros.core.tracking.residuals import BlockSystem, ResidualBlock
from atsvo_ros.core.tracking.residuals.prior import MotionPrior
from atsvo_ros.errors import TrackingError


@dataclass(frozen=True)
class BlockStats:
    """Per-block figures of the final estimate, so the loss checks can judge each term apart."""

    n_points: int
    n_visible: int
    n_inliers: int
    energy: float
    sse: float
    n_residuals: int

    @property
    def inlier_fraction(self) -> float:
        return self.n_inliers / self.n_visible if self.n_visible else 0.0


@dataclass(frozen=True)
class TrackResult:
    """Outcome of :meth:`Tracker.track`.

    ``covariance`` is the 6x6 covariance of a left perturbation of ``T_rgb_w`` (twist, translation
    first): the inverse of the final normal equations times the residual variance (in the blocks'
    noise units) times ``covariance_scale``.
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
    blocks: dict[str, BlockStats]
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
    per_block: dict[str, BlockSystem]
    prior_H: np.ndarray | None = None  # the motion prior's part of H (left out of the covariance)

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
    relax: float  # the factor on the outlier thresholds this level ended with


class Tracker:
    """Coarse-to-fine Levenberg-Marquardt over a list of residual blocks."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config

    @staticmethod
    def _system(blocks: list[ResidualBlock], level: int, T: np.ndarray,
                affine: dict[str, tuple[float, float]], relax: float,
                prior: MotionPrior | None = None) -> _System:
        aff_blocks = [b for b in blocks if b.estimate_affine and level < b.n_levels and len(b)]
        dim = 6 + 2 * len(aff_blocks)
        H = np.zeros((dim, dim))
        g = np.zeros(dim)
        energy = sse = 0.0
        n_in = n_vis = n_res = 0
        per_block: dict[str, BlockSystem] = {}
        for blk in blocks:
            if level >= blk.n_levels or len(blk) == 0:
                continue
            bs = blk.linearise(level, T, affine[blk.name], relax)
            per_block[blk.name] = bs
            H[:6, :6] += bs.H[:6, :6]
            g[:6] += bs.g[:6]
            if blk in aff_blocks:
                k = 6 + 2 * aff_blocks.index(blk)
                H[:6, k:k + 2] += bs.H[:6, 6:]
                H[k:k + 2, :6] += bs.H[6:, :6]
                H[k:k + 2, k:k + 2] += bs.H[6:, 6:]
                g[k:k + 2] += bs.g[6:]
            energy += bs.energy
            n_in += bs.n_inliers
            n_vis += bs.n_visible
            n_res += bs.n_residuals
            sse += bs.sse
        # Weak prior keeps the brightness parameters well posed when few points are visible.
        for i in range(6, dim):
            H[i, i] += 1e-3 * max(1, n_in)
        prior_H = None
        if prior is not None:
            ps = prior.linearise(T)
            H[:6, :6] += ps.H
            g[:6] += ps.g
            energy += ps.energy
            prior_H = ps.H
        return _System(H, g, float(energy), int(n_in), int(n_vis), int(n_res), float(sse), aff_blocks, per_block,
                       prior_H)

    def _optimise_level(self, blocks: list[ResidualBlock], level: int, T: np.ndarray,
                        affine: dict[str, tuple[float, float]], prior: MotionPrior | None = None) -> _LevelResult:
        """LM at one level (see the module docstring)."""
        cfg = self.config
        relax = 1.0
        cur = self._system(blocks, level, T, affine, relax, prior)
        for _ in range(2):
            if cur.n_visible == 0 or cur.n_inliers >= 0.5 * cur.n_visible:
                break
            relax *= 2.0
            cur = self._system(blocks, level, T, affine, relax, prior)
        eps = cfg.convergence_eps * (2.0 ** level)
        lam = 1e-4
        iters = rejected = 0
        converged = singular = False
        fresh = True
        for _ in range(cfg.max_iterations):
            iters += 1
            if cur.n_inliers < 6:
                break
            delta, T_new = lm._lm_step(cur.H, cur.g, float(lam), np.ascontiguousarray(T))
            if not np.all(np.isfinite(delta)):  # singular damped system: reported, never hidden
                singular = True
                break
            aff_new = dict(affine)
            for j, blk in enumerate(cur.affine_blocks):
                a, b = affine[blk.name]
                aff_new[blk.name] = (a + delta[6 + 2 * j], b + delta[7 + 2 * j])
            new = self._system(blocks, level, T_new, aff_new, relax, prior)
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
        return _LevelResult(T, affine, cur, iters, converged, singular, fresh, relax)

    def track(self, blocks: list[ResidualBlock], guesses: list[np.ndarray],
              affine: dict[str, tuple[float, float]] | None = None, refine_best: int = 1,
              prior: MotionPrior | None = None) -> TrackResult:
        """Estimate ``T_rgb_w`` of the current frame.

        Args:
            blocks: residual blocks (RGB first); their pyramids hold the current images.
            guesses: candidate initial ``T_rgb_w``; each is evaluated at the coarsest level.
            affine: initial ``(a, b)`` per block name (default zeros).
            refine_best: how many of the best-scoring guesses are optimised on the coarsest level
                before the lowest final energy per visible point wins (1 = only the best one).
            prior: the motion prior (its energy joins every comparison; None = data alone).
        """
        if not blocks or not guesses:
            raise TrackingError("tracking needs at least one residual block and one initial guess")
        affine = {b.name: (affine or {}).get(b.name, (0.0, 0.0)) for b in blocks}
        # Start on the coarsest level where some guess sees points: blocks have their own pyramid depths
        # (the 320x240 ATS one level fewer than 640x480 RGB), and mid-flip the ATS term may be all that sees any.
        scored: list[tuple[float, int]] = []
        top = max(b.n_levels for b in blocks)
        while not scored and top > 0:
            top -= 1
            for gi, T0 in enumerate(guesses):
                T0 = np.asarray(T0, dtype=np.float64)
                if not np.all(np.isfinite(T0)):
                    continue
                sysm = self._system(blocks, top, T0, affine, 1.0, prior)
                if sysm.n_visible > 0:
                    scored.append((sysm.energy_per_point, gi))
        if not scored:
            raise TrackingError("no initial guess sees any map point (or every guess contains NaN)")
        scored.sort()
        best: _LevelResult | None = None
        best_gi = scored[0][1]
        for _, gi in scored[:max(1, refine_best)]:
            out = self._optimise_level(blocks, top, np.asarray(guesses[gi], dtype=np.float64), dict(affine), prior)
            if best is None or out.system.energy_per_point < best.system.energy_per_point:
                best, best_gi = out, gi
        assert best is not None
        out = best
        total_iters = out.iterations
        singular = out.singular
        for level in range(top - 1, -1, -1):
            out = self._optimise_level(blocks, level, out.T, out.affine, prior)
            total_iters += out.iterations
            singular |= out.singular
        # Point states, H and the statistics must belong to the final estimate at the nominal threshold
        # (a rejected step, another guess or the relaxed threshold may have overwritten them).
        final = out.system
        if not out.fresh or top == 0 or out.relax != 1.0:
            final = self._system(blocks, 0, out.T, out.affine, 1.0, prior)
        # The covariance says what the data supports: the prior's information is left out of it.
        H_data = final.H if final.prior_H is None else final.H - np.pad(final.prior_H, (0, len(final.H) - 6))
        cov = self._covariance(H_data, final.n_residuals, final.sse) * self.config.covariance_scale
        states = {b.name: b.state.copy() for b in blocks}
        stats = {b.name: BlockStats(len(b), bs.n_visible, bs.n_inliers, bs.energy, bs.sse, bs.n_residuals)
                 for b in blocks if (bs := final.per_block.get(b.name)) is not None}
        n_points = sum(len(b) for b in blocks)
        return TrackResult(out.T, out.affine, cov, final.energy, final.n_inliers, final.n_visible, int(n_points),
                           int(total_iters), bool(out.converged), int(best_gi), states, stats, bool(singular))

    @staticmethod
    def _covariance(H: np.ndarray, n_res: int, sse: float) -> np.ndarray:
        """Inverse normal equations (pose part) times the residual variance in noise units.

        The variance is floored at 0.1 (residuals never fit better than a third of their noise
        scale), so a degenerate fit, e.g. a blank image explained by the brightness model, is not
        "certain".
        """
        dof = max(1, n_res - H.shape[0])
        sigma2 = max(sse / dof, 0.1) if n_res > H.shape[0] else 1e4
        try:
            cov = np.linalg.inv(H)[:6, :6] * sigma2
        except np.linalg.LinAlgError:
            return np.eye(6) * 1e6
        if not np.all(np.isfinite(cov)):
            return np.eye(6) * 1e6
        return 0.5 * (cov + cov.T)


__all__ = ["BlockStats", "TrackResult", "Tracker"]
