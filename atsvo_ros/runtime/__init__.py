"""The one ROS-free driver of the odometry core, for the replay, the benchmarks and the nodes.

:class:`OdometryRuntime` (:mod:`.runtime`) feeds the core frame by frame; it composes :mod:`.ingest`
(event message decoding), :mod:`.release` (the IMU gate and the frames held for the camera_info) and
:mod:`.problems` (counting and rate-limited logging), with the interface types in :mod:`.types`.
:mod:`.frame_queue` hands frames to a worker thread; :mod:`.mapping_remote` runs mapping behind a
message channel (the split nodes).
"""
from __future__ import annotations

from atsvo_ros.runtime.runtime import OdometryRuntime
from atsvo_ros.runtime.types import FrameInput, Logger, OdometryCore, RuntimeOutput, Sink

__all__ = ["FrameInput", "Logger", "OdometryCore", "OdometryRuntime", "RuntimeOutput", "Sink"]
