"""Tracking (the PTAM split): one frame against the current map snapshot.

Residual blocks of Eq. 4 (photometric RGB and ATS, geometric depth, the motion prior), the
coarse-to-fine Levenberg-Marquardt optimiser over them, the checks that judge its result, and the
motion model that predicts where each frame starts.
"""
from __future__ import annotations

from atsvo_ros.core.tracking.checks import DEGRADED, LOST, OK, Priors, Verdict
from atsvo_ros.core.tracking.motion import MotionModel
from atsvo_ros.core.tracking.tracker import Tracker, TrackResult
from atsvo_ros.core.tracking.tracking import Tracking, TrackingOutcome, rotation_hypotheses

__all__ = ["DEGRADED", "LOST", "OK", "MotionModel", "Priors", "TrackResult", "Tracker", "Tracking", "TrackingOutcome",
           "Verdict", "rotation_hypotheses"]
