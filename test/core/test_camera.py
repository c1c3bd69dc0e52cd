from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import CalibrationError


def dvxlite() -> CameraModel:
    return CameraModel.from_config(load_config("mini_cheetah").event_camera)


def mvsec() -> CameraModel:
    return CameraModel.from_config(load_config("mvsec").event_camera)


def pixel_grid(cam: CameraModel, step: float = 1.0) -> np.ndarray:
    u, v = np.meshgrid(np.arange(0, cam.width, step), np.arange(0, cam.height, step))
    return np.column_stack([u.ravel(), v.ravel()]).astype(np.float64)


@pytest.mark.parametrize("make", [dvxlite, mvsec], ids=["dvxplorer_lite_plumb_bob", "mvsec_equidistant"])
def test_distort_undistort_round_trip_below_1e6_px(make):
    cam = make()
    assert cam.is_distorted
    uv = pixel_grid(cam)
    xy = cam.pixel_to_normalized(uv)
    uv_back, valid = cam.project(np.column_stack([xy, np.ones(len(xy))]))
    assert valid.all()
    assert np.abs(uv_back - uv).max() < 1e-6


@pytest.mark.parametrize("make", [dvxlite, mvsec], ids=["plumb_bob", "equidistant"])
def test_projection_agrees_with_opencv(make):
    cam = make()
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-0.4, 0.4, (300, 2)), rng.uniform(0.8, 4.0, 300)])
    p[:, :2] *= p[:, 2:]
    ours, _ = cam.project(p)
    if cam.distortion_model == "equidistant":
        ref, _ = cv2.fisheye.projectPoints(p[None], np.zeros(3), np.zeros(3), cam.K, np.array(cam.D))
        ref = ref[0]
    else:
        ref, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), cam.K, np.array(cam.D))
        ref = ref[:, 0]
    assert np.abs(ours - ref).max() < 1e-6


def test_project_backproject_round_trip_with_depth():
    cam = dvxlite()
    rng = np.random.default_rng(2)
    uv = np.column_stack([rng.uniform(0, cam.width - 1, 500), rng.uniform(0, cam.height - 1, 500)])
    z = rng.uniform(0.3, 6.0, 500)
    p = cam.backproject(uv, z)
    assert np.allclose(p[:, 2], z)
    uv2, valid = cam.project(p)
    assert valid.all() and np.abs(uv2 - uv).max() < 1e-6


def test_points_behind_camera_are_invalid():
    _, valid = dvxlite().project(np.array([[0.0, 0.0, -1.0], [0.1, 0.0, 1.0]]))
    assert valid.tolist() == [False, True]


def test_rectify_maps_agree_with_projection():
    cam = dvxlite()
    map_x, map_y = cam.rectify_maps()
    pin = cam.pinhole()
    u, v = 200, 50
    p = pin.backproject(np.array([[u, v]], dtype=float), 2.0)
    uv_raw, _ = cam.project(p)
    assert abs(map_x[v, u] - uv_raw[0, 0]) < 1e-3 and abs(map_y[v, u] - uv_raw[0, 1]) < 1e-3


def test_from_camera_info_ros2_and_ros1_field_names():
    ros2 = SimpleNamespace(width=320, height=240, k=[270.0, 0, 142.0, 0, 268.0, 116.0, 0, 0, 1],
                           d=[-0.39, 0.17, 0.0, 0.0, 0.0], distortion_model="plumb_bob")
    ros1 = SimpleNamespace(width=320, height=240, K=ros2.k, D=ros2.d, distortion_model="plumb_bob")
    a, b = CameraModel.from_camera_info(ros2), CameraModel.from_camera_info(ros1)
    assert a == b and a.fx == 270.0 and a.D[0] == -0.39


def test_from_rosbags_camera_info_message():
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    CameraInfo = ts.types["sensor_msgs/msg/CameraInfo"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    RoI = ts.types["sensor_msgs/msg/RegionOfInterest"]
    msg = CameraInfo(Header(Time(0, 0), "cam"), 480, 640, "plumb_bob", np.zeros(5),
                     np.array([382.0, 0, 320, 0, 382, 240, 0, 0, 1]), np.eye(3).ravel(),
                     np.zeros(12), 0, 0, RoI(0, 0, 0, 0, False))
    cam = CameraModel.from_camera_info(msg)
    assert (cam.width, cam.fx, cam.cy, cam.distortion_model) == (640, 382.0, 240.0, "none")


def test_calibration_files_from_realdata(realdata):
    cam = CameraModel.from_yaml(realdata / "mvsec_calib_gt/esvo_calib/esvo_upenn_left.yaml")
    assert cam.distortion_model == "equidistant" and cam.width == 346
    assert cam.fx == pytest.approx(226.38018519795807)
    lite = CameraModel.from_yaml(realdata / "cear_dvxlite_d455_calib/cear_dvxplorer_lite_calib.yaml")
    assert lite == dvxlite()


def test_bad_calibrations_raise_calibration_error():
    with pytest.raises(CalibrationError, match="distortion_model"):
        CameraModel(320, 240, 100, 100, 160, 120, "ocam", (0.1,))
    with pytest.raises(CalibrationError, match="focal"):
        CameraModel(320, 240, -1, 100, 160, 120)
    with pytest.raises(CalibrationError, match="K matrix"):
        CameraModel.from_camera_info(SimpleNamespace(width=1, height=1, k=[0] * 9, d=[], distortion_model=""))


def test_scaled_model_follows_pixel_centre_convention():
    cam = CameraModel(640, 480, 400.0, 400.0, 319.5, 239.5)
    half = cam.scaled(0.5)
    assert (half.width, half.height, half.fx, half.cx) == (320, 240, 200.0, 159.5)


def _sim_camera_info(k2: float = 160.0, d0: float = 0.0):
    """The simulator's colour camera_info (320x240, f = 191 px) as rosbags decodes it, as r08 mutates it."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types
    return T["sensor_msgs/msg/CameraInfo"](
        T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](0, 0), "cam"), 240, 320, "plumb_bob",
        np.array([d0, 0, 0, 0, 0], np.float64), np.array([191.0, 0, k2, 0, 191.0, 120.0, 0, 0, 1]),
        np.eye(3).ravel(), np.zeros(12), 0, 0, T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False))


@pytest.mark.parametrize("kwargs, message", [
    ({"k2": np.nan}, "K has non-finite values (cx=nan)"),
    ({"d0": np.nan}, "D has non-finite values (D[0]=nan)"),
    ({"k2": np.inf, "d0": -np.inf}, "K has non-finite values (cx=inf)"),
], ids=["r08_nan_cx", "r08_nan_d", "inf"])
def test_non_finite_camera_info_names_the_entry(kwargs, message):
    with pytest.raises(CalibrationError) as info:
        CameraModel.from_camera_info(_sim_camera_info(**kwargs))
    assert str(info.value) == message
    assert CameraModel.from_camera_info(_sim_camera_info()).cx == 160.0


@pytest.mark.parametrize("args, message", [
    ((320, 240, 191.0, 191.0, np.nan, 120.0), "intrinsics and distortion must be finite, got cx=nan"),
    ((320, 240, np.nan, 191.0, 160.0, 120.0), "intrinsics and distortion must be finite, got fx=nan"),
    ((320, 240, 191.0, 191.0, 160.0, 120.0, "plumb_bob", (0.0, np.nan, 0.0, 0.0, 0.0)),
     "intrinsics and distortion must be finite, got D[1]=nan"),
])
def test_non_finite_intrinsics_are_named_not_blamed_on_the_focal_length(args, message):
    with pytest.raises(CalibrationError) as info:
        CameraModel(*args)
    assert str(info.value) == message
