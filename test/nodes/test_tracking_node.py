"""ROS-dependent checks of the node module; the logic itself is tested in test/test_pipeline.py."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_launch_file_starts_installed_executables():
    tree = ast.parse((ROOT / "launch" / "atsvo.launch.py").read_text())
    executables = {node.value.value for node in ast.walk(tree)
                   if isinstance(node, ast.keyword) and node.arg == "executable"}
    setup = (ROOT / "setup.py").read_text()
    assert executables == {"tracking_node"}
    for exe in executables:
        assert f'"{exe} = atsvo_ros.nodes.' in setup


def test_node_declares_every_config_parameter():
    rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (no ROS 2 on this machine)")
    from atsvo_ros.config import AtsvoConfig, flatten
    from atsvo_ros.nodes.tracking_node import TrackingNode

    rclpy.init()
    try:
        node = TrackingNode()
        for key in flatten(AtsvoConfig()):
            assert node.has_parameter(key)
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
