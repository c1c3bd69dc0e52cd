"""``atsvo_node``: tracking and mapping nodes in one process (the launch default, the lowest latency).

The two nodes share one executor (``node.executor``: rclpy's C++ events executor by default, or its
multi-threaded one); the odometry runs in the tracking node's worker thread and the mapper in a
thread of its own (:class:`~atsvo_ros.core.mapping.ports.ThreadedMapping`); every new snapshot is
handed over in memory, both to tracking and to the mapping node, which publishes the map. Same parameters, topics
and behaviour as ``tracking_node`` + ``mapping_node``, without serialising keyframes.

    ros2 run atsvo_ros atsvo_node --ros-args --params-file config/mini_cheetah.yaml
"""
from __future__ import annotations

from rclpy.node import Node

from atsvo_ros.nodes._ros import run_nodes
from atsvo_ros.nodes.mapping_node import MappingNode
from atsvo_ros.nodes.tracking_node import TrackingNode


def _make() -> list[Node]:
    mapping = MappingNode(serve=False)
    return [TrackingNode(mapping="memory", on_snapshot=mapping.publish_snapshot), mapping]


def main(args: list[str] | None = None) -> int:
    """Entry point of ``atsvo_node`` / ``ros2 run atsvo_ros atsvo_node``."""
    return run_nodes("atsvo_node", _make, args, threads=3,
                     what="Visual odometry (RGB-D + events) with tracking and mapping in one process.")


if __name__ == "__main__":
    raise SystemExit(main())
