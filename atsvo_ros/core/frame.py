"""Frame and result types of the odometry: what goes in (an RGB-D pair) and what comes out (a pose).

Status values and their transitions (what a controller subscribing to the odometry should do):

============== ======================================================================================
status         meaning
============== ======================================================================================
initialising   no map yet (first frame, or no valid depth so far): the pose is the identity
ok             tracked against the map, every consistency check passed
degraded       tracked, but a check doubts the pose (poor photometric agreement, disagreement with
               the depth term, with the motion or gyro prediction): the pose is published with an
               inflated covariance and never becomes a keyframe, so the map is not poisoned
relocalised    tracking had failed; the frame was tracked again against the recent keyframes from
               wider starting points and passed the checks
reinitialised  tracking failed and relocalisation too: a fresh map was built from this frame at the
               motion-model pose (the trajectory stays continuous but may jump relative to the scene)
lost           nothing to track and nothing to map (e.g. no valid depth): the pose is the motion
               model's prediction with a large covariance
============== ======================================================================================
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


@dataclass(frozen=True)
class RgbdFrame:
    """One synchronised colour + depth pair.

    ``rgb``: HxWx3 uint8 RGB or HxW uint8/float32 grey, *raw* (still distorted) colour image;
    ``depth_m``: HxW float32 metres aligned to the colour image (0 or NaN = invalid).
    ``depth_rectified``: the depth already lies on the undistorted pinhole grid with the colour
    camera's own K (``CameraModel.pinhole()``) instead of the raw colour grid (only matters for a
    distorted colour camera). MVSEC's ``depth_image_rect`` is *not* such a grid (stereo rectified:
    other K and a rotation); use its ``depth_image_raw``, which lies on the raw grid.
    """

    stamp_ns: int
    rgb: np.ndarray
    depth_m: np.ndarray
    depth_rectified: bool = False


class TrackingStatus(str, Enum):
    """Per-frame status (see the module docstring for the meaning and transitions)."""

    INITIALISING = "initialising"
    OK = "ok"
    DEGRADED = "degraded"
    RELOCALISED = "relocalised"
    REINITIALISED = "reinitialised"
    LOST = "lost"

    @property
    def tracked(self) -> bool:
        """The pose comes from an alignment against the map (ok, degraded, relocalised)."""
        return self in (TrackingStatus.OK, TrackingStatus.DEGRADED, TrackingStatus.RELOCALISED)


@dataclass(frozen=True)
class OdometryResult:
    """Pose estimate of one frame.

    ``covariance`` is 6x6 over a body-frame perturbation of ``T_odom_base`` (``T exp(eps)``), ROS
    order x y z rot_x rot_y rot_z. ``tracking_time_s`` covers preprocessing and tracking (what a
    new frame waits for), not keyframe insertion. ``mode`` is ``rgbd`` or ``fused`` (the event term
    took part in this frame). ``reason`` says why the status is not ``ok`` (None when it is).
    ``inliers`` holds the inlier count of each residual block (``rgb``, ``depth``, ``ats``);
    ``events_dropped`` the events the rate cap (``fusion.max_event_rate_ev_s``) left out since the last frame.
    ``event_map_time_s``: for a fused frame, what building its temporary event map took on mapping's side
    (built while tracking waited for this frame, so not in ``tracking_time_s``).
    """

    stamp_ns: int
    T_odom_base: np.ndarray
    T_odom_camera: np.ndarray
    covariance: np.ndarray
    status: TrackingStatus
    mode: str
    tracking_time_s: float
    n_points: int
    n_inliers: int
    keyframe_inserted: bool
    reason: str | None = None
    inliers: dict[str, int] = field(default_factory=dict)
    events_dropped: int = 0
    event_map_time_s: float = 0.0


__all__ = ["OdometryResult", "RgbdFrame", "TrackingStatus"]
