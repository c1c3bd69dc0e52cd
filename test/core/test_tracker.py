"""Tracker: Jacobians against finite differences, recovery of known pose offsets, a second block."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import RgbSelectionConfig, TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp, se3_inv, se3_log
from atsvo_ros.core.map import extract_patches
from atsvo_ros.core.photometric import ATS_PATTERN, RGB_PATTERN
from atsvo_ros.core.pyramid import build_pyramid, pyramid_cameras
from atsvo_ros.core.selection.rgb import select_rgb_pixels
from atsvo_ros.core.tracker import ResidualBlock, Tracker, image_pyramid_with_gradients
from atsvo_ros.errors import TrackingError
from test.core.render_helpers import BoxRoom

CAM = CameraModel(640, 480, 382.0, 382.0, 319.5, 239.5)
LEVELS = 4


@pytest.fixture(scope="module")
def room() -> BoxRoom:
    return BoxRoom(seed=3)


@pytest.fixture(scope="module")
def reference(room):
    """Map points of a keyframe at the world origin: points, per-level patches."""
    img, depth = room.render(CAM, np.eye(4), supersample=3)
    pyr = image_pyramid_with_gradients(build_pyramid(img, LEVELS))
    uv = select_rgb_pixels(img, RgbSelectionConfig())
    p_c = CAM.backproject(uv.astype(np.float64), depth[uv[:, 1], uv[:, 0]])
    return p_c, extract_patches(pyr, uv, RGB_PATTERN)


def _block(room, T_w_c, points_w, patches, camera=CAM, T_cam_rgb=None, pattern=RGB_PATTERN, name="rgb"):
    T_cam_rgb = np.eye(4) if T_cam_rgb is None else T_cam_rgb
    img, _ = room.render(camera, T_w_c @ se3_inv(T_cam_rgb), supersample=3)
    pyr = image_pyramid_with_gradients(build_pyramid(img, LEVELS))
    return ResidualBlock(name, points_w, patches, pattern, pyr, pyramid_cameras(camera, LEVELS), T_cam_rgb=T_cam_rgb)


def _errors(T_est_c_w, T_w_c):
    e = se3_log(T_est_c_w @ T_w_c)
    return np.linalg.norm(e[:3]), np.degrees(np.linalg.norm(e[3:]))


@pytest.mark.parametrize("xi", [[0.02, -0.01, 0.03, 0.01, -0.015, 0.008], [-0.03, 0.02, -0.015, -0.02, 0.01, 0.015]])
def test_recovers_known_pose_offset(room, reference, xi):
    p_w, patches = reference
    T_w_c = se3_exp(np.array(xi))
    blk = _block(room, T_w_c, p_w, patches)
    res = Tracker(TrackerConfig()).track([blk], [np.eye(4)])
    dt, dr = _errors(res.T_rgb_w, T_w_c)
    assert dt < 1e-3 and dr < 0.05, (dt, dr)
    assert res.n_inliers > 0.8 * res.n_visible
    assert np.all(np.linalg.eigvalsh(res.covariance) > 0)


def test_best_initial_guess_wins(room, reference):
    """A bad constant-motion guess next to a good zero-motion one: the tracker keeps the good one."""
    p_w, patches = reference
    T_w_c = se3_exp(np.array([0.01, 0.0, 0.01, 0.0, 0.01, 0.0]))
    blk = _block(room, T_w_c, p_w, patches)
    bad = se3_inv(se3_exp(np.array([0.0, 0.0, 0.0, 0.0, 0.35, 0.0])))
    res = Tracker(TrackerConfig()).track([blk], [bad, np.eye(4)])
    assert res.guess_index == 1
    assert _errors(res.T_rgb_w, T_w_c)[0] < 1e-3


def test_normal_equations_match_finite_differences():
    """On a linear-ramp image (bilinear sampling and central differences exact) 2g = dE/dparams."""
    rng = np.random.default_rng(0)
    u, v = np.meshgrid(np.arange(640, dtype=np.float32), np.arange(480, dtype=np.float32))
    img = 0.3 * u - 0.2 * v + 40.0
    pyr = image_pyramid_with_gradients([img])
    uv = np.column_stack([rng.uniform(40, 600, 200), rng.uniform(40, 440, 200)])
    p = CAM.backproject(uv, rng.uniform(1.0, 4.0, 200))
    patches = rng.uniform(0, 200, (1, 200, 9)).astype(np.float32)
    T_cam_rgb = se3_exp(np.array([0.05, -0.02, 0.01, 0.01, 0.03, -0.02]))
    blk = ResidualBlock("rgb", p, patches, RGB_PATTERN, pyr, [CAM], T_cam_rgb=se3_inv(T_cam_rgb))
    T0 = se3_exp(np.array([0.01, 0.02, -0.01, 0.01, 0.02, 0.003]))
    aff = (0.1, 3.0)
    H, g, *_ = blk.linearise(0, T0, aff, huber=1e6, outlier_thr=1e6)
    num = np.zeros(8)
    for k in range(8):
        d = np.zeros(8)
        d[k] = 1e-6
        ep = blk.linearise(0, se3_exp(d[:6]) @ T0, (aff[0] + d[6], aff[1] + d[7]), 1e6, 1e6)[2]
        em = blk.linearise(0, se3_exp(-d[:6]) @ T0, (aff[0] - d[6], aff[1] - d[7]), 1e6, 1e6)[2]
        num[k] = (ep - em) / 2e-6
    assert np.allclose(2 * g, num, rtol=1e-3, atol=1e-6 * np.abs(num).max())
    assert H.shape == (8, 8) and np.allclose(H, H.T)
    assert np.all(np.linalg.eigvalsh(H) > -1e-6 * np.abs(H).max())


def test_second_block_with_its_own_camera_and_extrinsic(room, reference):
    """A block in a second, displaced camera (like the event camera) constrains the RGB pose alone."""
    p_w, _ = reference
    cam2 = CameraModel(320, 240, 200.0, 200.0, 159.5, 119.5)
    T_e_rgb = se3_inv(se3_exp(np.array([0.05, -0.04, 0.01, 0.0, 0.03, 0.02])))  # event from RGB
    img2, _ = room.render(cam2, se3_inv(T_e_rgb), supersample=3)
    pyr2 = image_pyramid_with_gradients(build_pyramid(img2, 3))
    uv2, front = cam2.project((p_w @ T_e_rgb[:3, :3].T) + T_e_rgb[:3, 3])
    keep = front & cam2.in_image(uv2, 4)
    uv2 = np.round(uv2[keep])
    # Re-anchor points at pixel centres of the second camera so its patches are exact.
    depth2 = room.render_depth(cam2, se3_inv(T_e_rgb))
    z = depth2[uv2[:, 1].astype(int), uv2[:, 0].astype(int)]
    p_e = cam2.backproject(uv2, z)
    pts_w = (p_e - T_e_rgb[:3, 3]) @ T_e_rgb[:3, :3]
    patches2 = extract_patches(pyr2, uv2, ATS_PATTERN)
    T_w_c = se3_exp(np.array([0.015, 0.01, -0.02, 0.005, -0.01, 0.0]))
    blk = _block(room, T_w_c, pts_w, patches2, camera=cam2, T_cam_rgb=T_e_rgb, pattern=ATS_PATTERN, name="ats")
    assert blk.n_levels == 3
    res = Tracker(TrackerConfig()).track([blk], [np.eye(4)])
    dt, dr = _errors(res.T_rgb_w, T_w_c)
    assert dt < 3e-3 and dr < 0.1, (dt, dr)
    assert set(res.states) == {"ats"}


def test_rejects_inconsistent_input():
    with pytest.raises(TrackingError):
        ResidualBlock("rgb", np.zeros((3, 3)), np.zeros((2, 4, 9), np.float32), RGB_PATTERN, [], [])
    with pytest.raises(TrackingError):
        Tracker(TrackerConfig()).track([], [np.eye(4)])
