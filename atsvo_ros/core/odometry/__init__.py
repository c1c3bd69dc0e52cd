"""The odometry facade: RGB-D frames, events and IMU samples in, ``odom -> base`` poses out.

Composes the front ends, tracking and mapping per frame; the runtime, the replay and the nodes drive it.
"""
from __future__ import annotations

from atsvo_ros.core.frame import OdometryResult, RgbdFrame, TrackingStatus
from atsvo_ros.core.odometry.odometry import Odometry

__all__ = ["Odometry", "OdometryResult", "RgbdFrame", "TrackingStatus"]
