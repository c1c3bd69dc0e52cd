"""atsvo_ros: event + RGB-D direct visual odometry for agile legged robots.

Implements Zhu et al., "Event Camera-based Visual Odometry for Dynamic Motion Tracking of a
Legged Robot Using Adaptive Time Surface". Everything outside ``atsvo_ros.nodes`` runs without ROS.
"""
from __future__ import annotations

from atsvo_ros.errors import AtsvoError

__version__ = "0.1.0"
__all__ = ["AtsvoError", "__version__"]
