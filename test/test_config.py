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


# ---------------------------------------------------------------- reproductions r07, r08, r09 (../shared/repro)

R07_DUP_KEY = """/**:
  ros__parameters:
    rgb_camera:
      use_camera_info: false
      fx: 382.0
      fy: 382.0
      fx: 38.2
"""
R07_DUP_SECTION = """/**:
  ros__parameters:
    rig:
      depth_max_m: 4.0
    rgb_camera:
      fx: 400.0
    rig:
      sync_tolerance_s: 0.02
"""


def _bomb() -> str:
    """r09 c: the 12-line billion-laughs YAML (9^9 strings once its aliases expand)."""
    lines = ["a: &a [x,x,x,x,x,x,x,x,x]"]
    for i in range(8):
        p, c = chr(97 + i), chr(98 + i)
        lines.append(f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]")
    return "\n".join(lines + ["/**:", "  ros__parameters:", "    topics:", "      rgb: *i"]) + "\n"


def _info_error(capsys, argv: list[str]) -> str:
    """The one line atsvo-info prints for ``argv`` (exit code 1, nothing on stdout)."""
    from atsvo_ros.tools.info import main

    assert main(argv) == 1
    out = capsys.readouterr()
    lines = out.err.strip().splitlines()
    assert out.out == "" and len(lines) == 1, out
    return lines[0]


@pytest.mark.parametrize("name, text, message", [
    ("dup_key.yaml", R07_DUP_KEY,
     "{p}:7: duplicate key rgb_camera.fx (first at line 5; YAML would keep only the last)"),
    ("dup_section.yaml", R07_DUP_SECTION, "{p}:7: duplicate key rig (first at line 3; YAML would keep only the last)"),
    ("bigint.yaml", "/**:\n  ros__parameters:\n    rgb_camera:\n      width: 99999999999999999999999999999999\n",
     "{p}: rgb_camera.width = 99999999999999999999999999999999 is out of range: allowed [1, 10000]"),
], ids=["r07_dup_key", "r07_dup_section", "r09_bigint"])
def test_config_file_errors_are_one_line_naming_key_file_and_line(tmp_path: Path, capsys, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    expected = message.format(p=f"config {path}")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == expected
    assert _info_error(capsys, ["--config", str(path)]) == f"atsvo-info: error: {expected}"


def _limit_memory() -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))


def test_alias_bomb_is_refused_before_it_expands(tmp_path: Path):
    """r09 c; atsvo-info runs in a child with 3 GB and 60 s, as an expanding bomb would hang this process."""
    import subprocess
    import sys
    import time

    path = tmp_path / "bomb.yaml"
    path.write_text(_bomb())
    expected = f"config {path}:2: YAML alias *a is not allowed in a config (write the value out)"
    try:
        child = subprocess.run([sys.executable, "-m", "atsvo_ros.tools.info", "--config", str(path)],
                               capture_output=True, text=True, timeout=60, preexec_fn=_limit_memory)
    except subprocess.TimeoutExpired:
        pytest.fail("atsvo-info still running 60 s after reading a 12-line YAML alias bomb")
    assert (child.returncode, child.stdout, child.stderr) == (1, "", f"atsvo-info: error: {expected}\n")
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert time.perf_counter() - t0 < 0.5 and str(info.value) == expected


@pytest.mark.parametrize("pairs, message", [
    (["rgb_camera={fx: 382.0, fx: 38.2}"], "--set 'rgb_camera={fx: 382.0, fx: 38.2}': duplicate key rgb_camera.fx "
                                           "(first at column 2; YAML would keep only the last)"),
    (["topics.rgb=&a [x]", "topics.depth=*a"], "--set 'topics.depth=*a': YAML alias *a is not allowed in a config "
                                               "(write the value out)"),
])
def test_set_values_refuse_duplicate_keys_and_aliases(pairs, message):
    from atsvo_ros.config import parse_overrides

    with pytest.raises(ConfigError) as info:
        parse_overrides(pairs)
    assert str(info.value) == message


@pytest.mark.parametrize("key, value, message", [
    ("rgb_camera.width", 10**40, "rgb_camera.width = 10000000000000000000000000000000000000000 is out of range: "
                                 "allowed [1, 10000]"),
    ("rgb_camera.width", 1e32, "rgb_camera.width = 1e+32 is out of range: allowed [1, 10000]"),
    ("rgb_camera.fx", 10**400, None),
    ("rgb_camera.D", [0.0, 10**400, 0.0, 0.0, 0.0], None),
])
def test_huge_numbers_are_out_of_range(key, value, message):
    with pytest.raises(ConfigError) as info:
        config_from_dict({key: value})
    text = str(info.value)
    assert text == message if message else (text.startswith(f"{key} = ") and "is out of range" in text)


def test_config_naming_a_directory_says_so(tmp_path: Path, capsys):
    folder = tmp_path / "cfgdir.yaml"
    folder.mkdir()
    expected = f"config file {folder} is a directory, not a ROS-parameter YAML file"
    with pytest.raises(ConfigError) as info:
        load_config(folder)
    assert str(info.value) == expected
    assert _info_error(capsys, ["--config", str(folder)]) == f"atsvo-info: error: {expected}"


def test_nan_distortion_from_set_names_the_coefficient(capsys):
    from atsvo_ros.config import parse_overrides

    pairs = ["rgb_camera.use_camera_info=false", "rgb_camera.D=[.nan,0,0,0,0]", "rgb_camera.width=320",
             "rgb_camera.height=240", "rgb_camera.fx=191", "rgb_camera.fy=191", "rgb_camera.cx=160",
             "rgb_camera.cy=120"]
    expected = "rgb_camera.D[0] is nan (every element must be a finite number)"
    with pytest.raises(ConfigError) as info:
        load_config("mini_cheetah", overrides=parse_overrides(pairs))
    assert str(info.value) == expected
    argv = [a for p in pairs for a in ("--set", p)]
    assert _info_error(capsys, argv) == f"atsvo-info: error: {expected}"
    with pytest.raises(ConfigError, match=r"rgb_camera\.D\[1\] is inf"):
        config_from_dict({"rgb_camera.D": [0.0, float("inf"), 0.0, 0.0, 0.0]})


def test_duplicate_keys_in_different_mappings_still_load(tmp_path: Path):
    """The same key in two sections, and ``/**`` and a node section both holding a section, are not duplicates."""
    path = tmp_path / "ok.yaml"
    path.write_text("/**:\n  ros__parameters:\n    rgb_camera: {fx: 300.0}\n    event_camera: {fx: 300.0}\n"
                    "atsvo_tracking:\n  ros__parameters:\n    rgb_camera: {fx: 310.0}\n")
    cfg = load_config(path, node_name="atsvo_tracking")
    assert (cfg.rgb_camera.fx, cfg.event_camera.fx) == (310.0, 300.0)
