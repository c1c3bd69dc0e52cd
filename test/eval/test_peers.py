"""Peer odometry (OpenCV, Open3D) on rendered frames with exact poses; the preprocessing is our odometry's."""
from __future__ import annotations

import sys

import cv2
import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_inv, se3_log
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.peers import OPEN3D_METHODS, OPENCV_METHODS, import_open3d, run_opencv, undistorted_frames
from test.core.render_helpers import BoxRoom
from test.io.tum_helpers import render_frames

FR1 = CameraModel.from_config(load_config("tum_fr1").rgb_camera)


@pytest.fixture(scope="module")
def frames():
    # a narrow room: walls, floor and ceiling in view, so point-to-plane ICP is constrained in every direction
    return render_frames(FR1, n=6, room=BoxRoom(seed=5, half_width_m=1.0, half_height_m=0.8, front_m=2.5))


def test_undistortion_is_the_odometrys(frames):
    stamp, rgb, depth, _ = frames[0]
    depth = depth.copy()
    depth[100:140, 200:260] = 0.0
    (s, img, d, t), = undistorted_frames([(stamp, rgb, depth)], FR1)
    mx, my = FR1.rectify_maps()
    grey = cv2.remap(rgb[..., 0].astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    assert s == stamp and t >= 0 and img.dtype == np.float32 and img.shape == (480, 640, 3)
    assert np.allclose(img[..., 1] * 255.0, grey, atol=1e-3)
    ref = cv2.remap(depth, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    assert np.array_equal(d, ref)  # nearest neighbour: no depth mixed across edges or holes
    assert set(np.unique(d[d > 0])) <= set(np.unique(depth))
    with pytest.raises(EvaluationError, match="640x480"):
        next(undistorted_frames([(stamp, rgb[:-1], depth[:-1])], FR1))


def test_missing_open3d_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # makes "import open3d" raise ImportError
    with pytest.raises(EvaluationError, match=r"atsvo_ros\[peers\]"):
        import_open3d()


def test_open3d_trajectories_follow_the_rendered_motion(frames):
    pytest.importorskip("open3d", reason="open3d is not installed (pip install 'atsvo_ros[peers]')")
    from atsvo_ros.eval.peers import run_open3d

    runs = run_open3d(((s, rgb, d) for s, rgb, d, _ in frames), FR1, depth_max_m=5.0)
    assert set(runs) == set(OPEN3D_METHODS)
    T_gt = np.stack([f[3] for f in frames])
    for name, run in runs.items():
        assert run.name == f"open3d_{name}" and run.stamps_ns.tolist() == [f[0] for f in frames]
        assert run.ok.all() and run.time_s[0] == 0.0 and np.all(run.time_s[1:] > 0)
        assert np.allclose(run.T_world_cam[0], np.eye(4))
        # chained T_world_cam: this frame into the previous one, not the inverse (an inverted chain
        # would be off by twice the motion, ~5 cm and ~1.5 deg per frame here)
        e = se3_log(se3_inv(T_gt[-1]) @ run.T_world_cam[-1])
        assert np.linalg.norm(e[:3]) < 0.02 and np.degrees(np.linalg.norm(e[3:])) < 0.5, (name, e)
        assert run.info["method"] == OPEN3D_METHODS[name] and run.info["undistorted"]
    with pytest.raises(EvaluationError, match="unknown Open3D method"):
        run_open3d(iter(()), FR1, methods=("icp",))


def test_opencv_trajectories_follow_the_rendered_motion(frames):
    runs = run_opencv(((s, rgb, d) for s, rgb, d, _ in frames), FR1, depth_max_m=5.0)
    assert set(runs) == set(OPENCV_METHODS)
    T_gt = np.stack([f[3] for f in frames])
    for name, run in runs.items():
        assert run.name == f"opencv_{name}" and run.stamps_ns.tolist() == [f[0] for f in frames]
        assert run.ok.all() and run.time_s[0] == 0.0 and np.all(run.time_s[1:] > 0)
        assert np.allclose(run.T_world_cam[0], np.eye(4))
        # chained the right way round: OpenCV's Rt maps this frame into the previous one
        e = se3_log(se3_inv(T_gt[-1]) @ run.T_world_cam[-1])
        assert np.linalg.norm(e[:3]) < 0.02 and np.degrees(np.linalg.norm(e[3:])) < 0.5, (name, e)
        assert run.info["method"] == OPENCV_METHODS[name] and run.info["undistorted"]
    with pytest.raises(EvaluationError, match="unknown OpenCV method"):
        run_opencv(iter(()), FR1, methods=("icp",))
    with pytest.raises(EvaluationError, match="no frames"):
        run_opencv(iter(()), FR1)
