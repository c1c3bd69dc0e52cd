"""Parameters: every config field is a described, read-only parameter with its range; files load like offline."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy is not installed (pip install -e '.[ros]'; docs/ros_env.md)")

from atsvo_ros.config import AtsvoConfig, flatten, load_config  # noqa: E402
from atsvo_ros.nodes._params import config_fields, range_text  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def ros_args(request):
    """rclpy initialised with the given --ros-args (default context), shut down afterwards."""
    def init(*args: str) -> None:
        rclpy.init(args=["test", "--ros-args", *args])
    yield init
    rclpy.try_shutdown()


def _node(kind: str):
    if kind == "tracking":
        from atsvo_ros.nodes.tracking_node import TrackingNode

        return TrackingNode(mapping="topics")
    from atsvo_ros.nodes.mapping_node import MappingNode

    return MappingNode(serve=True)


@pytest.mark.parametrize("kind", ["tracking", "mapping"])
def test_every_config_field_is_a_described_read_only_parameter(ros_args, kind):
    ros_args("--params-file", str(ROOT / "config" / "mini_cheetah.yaml"))
    node = _node(kind)
    try:
        keys = flatten(AtsvoConfig())
        assert all(node.has_parameter(k) for k in keys)
        d = node.describe_parameter("ats.tau_u_s")
        assert d.read_only and "decay" in d.description and d.additional_constraints == "(0.0, 10.0]"
        assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == (0.0, 10.0)
        d = node.describe_parameter("ats.n_latest")
        assert (d.integer_range[0].from_value, d.integer_range[0].to_value) == (1, 16)
        assert node.describe_parameter("mode").additional_constraints == "one of: fused, rgbd"
        assert "waits for each keyframe" in node.describe_parameter("mapping.synchronous").description
        assert node.describe_parameter("rig.T_base_rgb").additional_constraints.startswith("row-major 4x4")
        assert node.config == load_config(ROOT / "config" / "mini_cheetah.yaml")
        assert not node.set_parameters([rclpy.parameter.Parameter("ats.tau_u_s", value=0.05)])[0].successful
    finally:
        close = getattr(node, "close", None)
        if close:
            close()
        node.destroy_node()


def test_integers_for_doubles_and_empty_lists_read_like_the_offline_loader(ros_args, tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("/**:\n  ros__parameters:\n    ats:\n      tau_u_s: 1\n    rgb_camera:\n      D: []\n"
                 "    rig:\n      T_rgb_event: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n")
    ros_args("--params-file", str(f))
    node = _node("mapping")
    try:
        assert node.config == load_config(f)
        assert node.config.ats.tau_u_s == 1.0 and node.config.rgb_camera.D == ()
    finally:
        node.destroy_node()


@pytest.mark.parametrize("args, words", [
    (["-p", "ats.tau_u_s:=-1.0"], ["ats.tau_u_s = -1.0", "(0.0, 10.0]"]),
    (["-p", "ats.tau_u_s:=0.0"], ["ats.tau_u_s = 0.0", "(0.0, 10.0]"]),  # the open end ROS ranges cannot say
    (["-p", "mode:=turbo"], ["mode", "turbo", "fused, rgbd"]),
    (["-p", "ats.tau_uu_s:=0.1"], ["unknown parameter ats.tau_uu_s", "tau_u_s"]),
    (["-p", "tracker.max_iterations:=2.5"], ["tracker.max_iterations", "2.5", "integer"]),
])
def test_bad_values_raise_config_errors_naming_key_value_and_range(ros_args, args, words):
    from atsvo_ros.errors import ConfigError

    ros_args(*args)
    with pytest.raises(ConfigError) as err:
        _node("mapping")
    assert all(w in str(err.value) for w in words), str(err.value)


def test_range_texts():
    fields = {f.key: f for f in config_fields()}
    assert range_text(fields["tracker.max_iterations"].meta) == "[1, 200]"
    assert range_text(fields["topics.rgb"].meta) == ""


def test_launch_file_starts_the_installed_executables():
    tree = ast.parse((ROOT / "launch" / "atsvo.launch.py").read_text())
    executables = {node.value.value for node in ast.walk(tree)
                   if isinstance(node, ast.keyword) and node.arg == "executable" and isinstance(node.value,
                                                                                                ast.Constant)}
    setup = (ROOT / "setup.py").read_text()
    assert executables == {"atsvo_node", "tracking_node", "mapping_node"}
    for exe in executables:
        assert f'"{exe} = atsvo_ros.nodes.' in setup


@pytest.mark.parametrize("prog", ["atsvo_node", "tracking_node", "mapping_node"])
def test_help_prints_usage_and_does_not_start_the_node(prog, capsys):
    import importlib

    main = importlib.import_module(f"atsvo_ros.nodes.{prog}").main
    assert main([prog, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: {prog} [--ros-args") and "/atsvo/odometry" in out and "docs/nodes.md" in out
    assert not rclpy.ok()  # never initialised: the node did not start


def test_missing_or_broken_params_file_is_one_line(tmp_path, capsys):
    from atsvo_ros.nodes.atsvo_node import main

    missing = tmp_path / "missing.yaml"
    assert main(["atsvo_node", "--ros-args", "--params-file", str(missing)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"atsvo_node: error: --params-file {missing}: no such file"]
    broken = tmp_path / "broken.yaml"
    broken.write_text("/**:\n  ros__parameters:\n    a: [1, 2\n")
    assert main(["atsvo_node", "--ros-args", "--params-file", str(broken)]) == 1
    err = capsys.readouterr().err
    assert "atsvo_node: error: failed to initialize rcl: Couldn't parse params file" in err and "Traceback" not in err
