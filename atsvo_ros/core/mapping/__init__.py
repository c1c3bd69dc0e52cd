"""Mapping (the PTAM split): map points, keyframe health, the mapper and the ports tracking reaches it by.

The mapper owns the mutable map; tracking only ever reads an immutable :class:`MapSnapshot` that mapping
replaces (DSO's coarse-tracking reference), in line, in a thread of its own or in another process.
"""
from __future__ import annotations

from atsvo_ros.core.mapping.depth_selection import select_depth_pixels
from atsvo_ros.core.mapping.keyframes import MapHealth, assess_health
from atsvo_ros.core.mapping.map import Keyframe, MapSnapshot, PointMap
from atsvo_ros.core.mapping.mapper import EventMapRequest, KeyframeRequest, Mapper
from atsvo_ros.core.mapping.ports import InlineMapping, MappingPort, ThreadedMapping
from atsvo_ros.core.mapping.rgb_selection import select_rgb_pixels

__all__ = ["EventMapRequest", "InlineMapping", "Keyframe", "KeyframeRequest", "MapHealth", "MapSnapshot", "Mapper",
           "MappingPort", "PointMap", "ThreadedMapping", "assess_health", "select_depth_pixels", "select_rgb_pixels"]
