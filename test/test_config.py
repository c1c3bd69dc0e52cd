from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from atsvo_ros.config import AtsvoConfig, config_dir, config_from_dict, flatten, load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import ConfigError


@pytest.mark.parametrize("name", ["mini_cheetah", "mvsec", "synthetic", "tum_fr1", "tum_fr2", "tum_fr3"])
def test_bundled_presets_load(name):
    cfg = load_config(name)
    assert isinstance(cfg, AtsvoConfig)
    assert CameraModel.from_config(cfg.event_camera).width in (320, 346)


def test_imu_topic_and_extrinsic_defaults_and_presets():
    default = AtsvoConfig()
    assert default.topics.imu == "/camera/camera/imu" and default.rig.T_rgb_imu_matrix().tolist() == np.eye(4).tolist()
    # mini_cheetah and synthetic: one D455's IMU about 6 cm from the colour imager (ORB-SLAM3's calibration).
    for name in ("mini_cheetah", "synthetic"):
        T = load_config(name).rig.T_rgb_imu_matrix()
        assert load_config(name).topics.imu == "/camera/camera/imu"
        assert 0.05 < np.linalg.norm(T[:3, 3]) < 0.06 and np.allclose(T[:3, :3], np.eye(3), atol=0.01)
    assert load_config("mvsec").topics.imu == "/davis/left/imu"
    assert np.linalg.norm(load_config("mvsec").rig.T_rgb_imu_matrix()[:3, 3]) < 0.02


def test_presets_are_the_files_in_config_dir():
    assert sorted(p.stem for p in config_dir().glob("*.yaml")) == ["mini_cheetah", "mvsec", "synthetic", "tum_fr1",
                                                                   "tum_fr2", "tum_fr3"]


def test_dotted_and_nested_keys_agree_and_round_trip():
    a = config_from_dict({"ats.tau_u_s": 0.05, "tracker": {"w_event": 0.5}})
    b = config_from_dict({"ats": {"tau_u_s": 0.05}, "tracker.w_event": 0.5})
    assert a == b and a.ats.tau_u_s == 0.05
    assert config_from_dict(flatten(a)) == a


@pytest.mark.parametrize("params, words", [
    ({"ats.tau_u_s": -0.1}, ["ats.tau_u_s", "-0.1", "(0.0, 10.0]"]),
    ({"ats.n_latest": 40}, ["ats.n_latest", "40", "[1, 16]"]),
    ({"ats.n_latest": 2.5}, ["ats.n_latest", "2.5", "integer"]),
    ({"ats.tau_l_s": 0.5, "ats.tau_u_s": 0.1}, ["ats.tau_l_s", "0.5", "ats.tau_u_s"]),
    ({"ats.median_ksize": 4}, ["ats.median_ksize", "4", "odd"]),
    ({"mode": "turbo"}, ["mode", "turbo", "fused", "rgbd"]),
    ({"rig.depth_min_m": 7.0}, ["rig.depth_min_m", "7.0", "depth_max_m"]),
    ({"rig.T_base_rgb": [1, 2, 3]}, ["rig.T_base_rgb", "16"]),
    ({"rig.T_rgb_event": [2.0] + [0.0] * 15}, ["rig.T_rgb_event", "rigid"]),
    ({"rig.T_rgb_imu": [0.0] * 16}, ["rig.T_rgb_imu", "rigid"]),
    ({"tracker.huber_delta": "big"}, ["tracker.huber_delta", "big", "type"]),
    ({"mapping.min_healthy_regions": 10}, ["mapping.min_healthy_regions", "10", "[1, 9]"]),
    ({"ats.nonsense": 1}, ["ats.nonsense", "unknown"]),
])
def test_bad_values_name_key_value_and_range(params, words):
    with pytest.raises(ConfigError) as info:
        config_from_dict(params)
    for w in words:
        assert w in str(info.value)


def test_ros_parameter_file_node_section_overrides_wildcard(tmp_path: Path):
    doc = {"/**": {"ros__parameters": {"ats": {"tau_u_s": 0.05}, "tracker.w_event": 2.0}},
           "atsvo_tracking": {"ros__parameters": {"ats": {"tau_u_s": 0.08}}}}
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert load_config(path).ats.tau_u_s == 0.05
    cfg = load_config(path, node_name="atsvo_tracking")
    assert cfg.ats.tau_u_s == 0.08 and cfg.tracker.w_event == 2.0
    assert load_config(path, overrides={"ats.tau_u_s": 0.09}).ats.tau_u_s == 0.09


def test_missing_file_and_missing_section(tmp_path: Path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")
    path = tmp_path / "q.yaml"
    path.write_text("foo: 1\n")
    with pytest.raises(ConfigError, match="ros__parameters"):
        load_config(path)
