"""Consistency checks: is a tracked pose supported by the data? (ok, degraded or lost, and why)

A direct method always returns *some* optimum; on blur, repetitive or smooth texture it can be a
wrong one that still has many "inliers" and a healthy-looking covariance. These checks judge each
residual term apart and look for what a wrong pose leaves behind:

* lost: no estimate, a singular system, too few photometric inliers, degenerate geometry (a
  position standard deviation above ``max_position_std_m``), a brightness-gain jump no camera makes
  in one frame, a pose jump larger than ``max_step_m`` / ``max_step_rot_deg``, or patches that do not
  correlate with the image at all (mean ZNCC below ``lost_zncc``, judged on the terms that pass their
  inlier counts);
* degraded: tracked, but the inlier patches correlate poorly with the image (mean ZNCC below
  ``min_zncc``: they landed on other texture), the rotation disagrees with the gyro's prediction by
  more than ``max_gyro_disagreement_deg``, the camera centre left the constant-velocity prediction by
  more than the platform can accelerate (``max_acceleration_m_s2``: a wrong optimum that slid along
  a plane or a repeated texture), or the depth term rejects most of its points (the photometric
  optimum disagrees with the scene's geometry).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.geometry import camera_centre, relative_motion, rotation_angle_rad, se3_inv
from atsvo_ros.core.tracking.residuals.prior import MotionPrior
from atsvo_ros.core.tracking.tracker import TrackResult

OK, DEGRADED, LOST = "ok", "degraded", "lost"


@dataclass(frozen=True)
class Priors:
    """What the motion says the pose should be, for the checks.

    ``gyro_T_c_w``: the pose with the gyro's rotation since the last frame. ``centre_w``: the camera
    centre (world) of the constant-velocity prediction, made only from trusted poses, and
    ``centre_tolerance_m`` how far from it the platform's acceleration can take the camera. ``motion``: the
    prior the optimiser adds to the normal equations (None without a trusted velocity).
    """

    gyro_T_c_w: np.ndarray | None = None
    centre_w: np.ndarray | None = None
    centre_tolerance_m: float = float("inf")
    motion: MotionPrior | None = None


@dataclass(frozen=True)
class Verdict:
    """What the checks concluded: ``level`` is ok, degraded or lost; ``reason`` says why (None when ok)."""

    level: str
    reason: str | None = None
    #: degraded because no image term holds: the pose rests on the depth term and the motion prior (mid-flip,
    #: facing a blank floor). The prediction it follows stays usable for the next frames.
    coasting: bool = False

    @classmethod
    def lost(cls, reason: str) -> Verdict:
        return cls(LOST, reason)

    @property
    def ok(self) -> bool:
        return self.level == OK


#: The image terms of Eq. 4 (the depth term is judged by its inlier fraction alone).
IMAGE_TERMS = ("rgb", "ats")


def failing_image_terms(config: AtsvoConfig, res: TrackResult) -> list[str]:
    """The image terms of ``res`` under their own inlier counts (``rgb``: ``tracker.min_inliers`` and
    ``min_inlier_fraction``; ``ats``: ``fusion.min_points`` and ``min_inlier_fraction``)."""
    need = {"rgb": (config.tracker.min_inliers, config.tracker.min_inlier_fraction),
            "ats": (config.fusion.min_points, config.fusion.min_inlier_fraction)}
    return [n for n, b in res.blocks.items()
            if n in need and b.n_inliers < max(need[n][0], need[n][1] * b.n_visible)]


def judge(config: AtsvoConfig, res: TrackResult, T_c_w: np.ndarray, reference: np.ndarray,
          affine_before: tuple[float, float], affine_after: tuple[float, float], zncc: dict[str, float],
          priors: Priors | None = None, coast_reason: str | None = None) -> Verdict:
    """Apply the checks of the module docstring to one tracking result.

    ``zncc`` is the mean ZNCC of each image term's inlier patches (by block name); only the terms that pass
    their own inlier counts are judged by it: a dozen blurred colour patches mid-flip correlate with
    nothing while the ATS term holds the pose. ``priors`` are the motion's predictions (gyro, constant velocity).
    ``coast_reason``: the image terms were left out on purpose (they misled the alignment), judge as coasting.
    """
    cfg = config.tracker
    if not res.ok:
        return Verdict.lost("no estimate (NaN in the pose or its covariance)")
    if res.singular:
        return Verdict.lost("singular normal equations (no texture or depth structure constrains the pose)")
    # The image terms are judged apart: in fused mode a blurred colour image may fail while the ATS term
    # holds the pose; the frame is lost only when no image term constrains it.
    priors = priors or Priors()
    image_terms = {n: b for n, b in res.blocks.items() if n in IMAGE_TERMS}
    failing = {n: image_terms[n] for n in failing_image_terms(config, res)}
    coasting = None
    if coast_reason is not None or (image_terms and len(failing) == len(image_terms)):
        weak = coast_reason or "; ".join(f"{b.n_inliers} {'photometric' if n == 'rgb' else 'ATS'} inliers of "
                                         f"{b.n_visible} visible map points" for n, b in failing.items())
        depth = res.blocks.get("depth")
        if (priors.motion is None or depth is None or depth.n_inliers < cfg.min_inliers
                or depth.inlier_fraction < cfg.min_depth_inlier_fraction):
            return Verdict.lost(weak)
        # No image term holds, but the depth term does and the motion prior fills what it leaves free (a plane
        # fixes 3 DoF): coast on them, reported degraded, rather than start a new map mid-flip.
        coasting = Verdict(DEGRADED, f"{weak}: pose from the depth term and the motion prior", coasting=True)
    std = float(np.sqrt(max(np.linalg.eigvalsh(res.covariance[:3, :3]).max(), 0.0)))
    if std > cfg.max_position_std_m and coasting is None:  # coasting: the data alone is degenerate by definition
        return Verdict.lost(f"degenerate geometry (position std {std:.3f} m)")
    jump = affine_after[0] - affine_before[0]
    if abs(jump) > np.log(cfg.max_gain_ratio):
        return Verdict.lost(f"brightness gain jumped by x{np.exp(jump):.2f}")
    rot, trans = relative_motion(se3_inv(reference), se3_inv(T_c_w))
    if trans > cfg.max_step_m or np.degrees(rot) > cfg.max_step_rot_deg:
        return Verdict.lost(f"jump of {trans:.3f} m / {np.degrees(rot):.1f} deg in one frame")
    carrying = {n: z for n, z in zncc.items() if n not in failing and np.isfinite(z)}
    best = max(carrying.values(), default=float("nan"))
    if np.isfinite(best) and best < cfg.lost_zncc:
        return Verdict.lost(f"patches do not match the image (mean ZNCC {best:.2f})")
    if coasting is not None:
        return coasting
    if np.isfinite(best) and best < cfg.min_zncc:
        return Verdict(DEGRADED, f"patches match the image poorly (mean ZNCC {best:.2f})")
    if priors.gyro_T_c_w is not None:
        off = np.degrees(rotation_angle_rad(T_c_w[:3, :3] @ priors.gyro_T_c_w[:3, :3].T))
        if off > cfg.max_gyro_disagreement_deg:
            return Verdict(DEGRADED, f"the pose disagrees with the gyro by {off:.1f} deg")
    if priors.centre_w is not None:
        off_m = float(np.linalg.norm(camera_centre(T_c_w) - priors.centre_w))
        if off_m > priors.centre_tolerance_m:
            reach_cm = priors.centre_tolerance_m * 100
            return Verdict(DEGRADED, f"the camera centre is {off_m * 100:.1f} cm from the constant-velocity "
                                     f"prediction (the platform's acceleration allows {reach_cm:.1f})")
    depth = res.blocks.get("depth")
    if (depth is not None and depth.n_visible >= cfg.min_inliers
            and depth.inlier_fraction < cfg.min_depth_inlier_fraction):
        return Verdict(DEGRADED, f"the depth term rejects {depth.n_visible - depth.n_inliers} of {depth.n_visible} "
                                 "points (pose disagrees with the scene geometry)")
    return Verdict(OK)


__all__ = ["DEGRADED", "IMAGE_TERMS", "LOST", "OK", "Priors", "Verdict", "failing_image_terms", "judge"]
