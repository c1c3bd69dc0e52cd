"""I/O: event decoders, image conversion, bag reading, trajectory files. No ROS install needed.

Messages are duck-typed: an rclpy message and a rosbags message have the same field names, so one
converter serves the nodes and the replay. The faces below are what the tools use; the modules hold more.
"""
from __future__ import annotations

from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.event_files import EventSource, open_events
from atsvo_ros.io.sources import ReplaySource, open_source
from atsvo_ros.io.trajectory import Trajectory, read_tum, write_tum

__all__ = ["EventDecoder", "EventSource", "ReplaySource", "Trajectory", "open_events", "open_source", "read_tum",
           "write_tum"]
