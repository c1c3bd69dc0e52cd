"""The point-to-plane depth block: normal equations against finite differences, basin, depth pyramid."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp, se3_log
from atsvo_ros.core.image.pyramid import depth_pyramid, pyramid_cameras
from atsvo_ros.core.tracking.residuals.geometric import GeometricBlock
from atsvo_ros.core.tracking.tracker import Tracker
from test.core.render_helpers import BoxRoom

CAM = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)


def _points(depth: np.ndarray, step: int = 8) -> np.ndarray:
    v, u = np.mgrid[4:CAM.height - 4:step, 4:CAM.width - 4:step]
    z = depth[v, u]
    return CAM.backproject(np.column_stack([u.ravel(), v.ravel()]).astype(float), z.ravel().astype(float))


def test_normal_equations_match_finite_differences():
    """With the association and normals fixed (a tiny step moves no point to another pixel), 2g = dE/dxi."""
    room = BoxRoom(seed=2)
    depth = room.render_depth(CAM, np.eye(4))
    blk = GeometricBlock("depth", _points(depth), depth_pyramid(depth, 1), [CAM], huber=1e6, outlier=1e6)
    T0 = se3_exp(np.array([0.004, -0.003, 0.002, 0.002, -0.003, 0.001]))
    bs = blk.linearise(0, T0, (0.0, 0.0))
    assert bs.n_inliers == bs.n_visible > 800
    num = np.zeros(6)
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-7
        num[k] = (blk.linearise(0, se3_exp(d) @ T0, (0, 0)).energy
                  - blk.linearise(0, se3_exp(-d) @ T0, (0, 0)).energy) / 2e-7
    assert np.allclose(2 * bs.g, num, rtol=1e-4, atol=1e-6 * np.abs(num).max()), (2 * bs.g, num)
    assert np.allclose(bs.H, bs.H.T) and np.all(np.linalg.eigvalsh(bs.H) > -1e-9 * np.abs(bs.H).max())


def test_depth_alone_recovers_a_pose_offset_of_several_degrees():
    """The depth term's basin is wide: 5 deg and 5 cm off, from the zero-motion guess, on a box room."""
    room = BoxRoom(seed=2)
    depth0 = room.render_depth(CAM, np.eye(4))
    T_w_c = se3_exp(np.array([0.05, -0.03, 0.04, 0.05, -0.06, 0.03]))
    depth1 = room.render_depth(CAM, T_w_c)
    blk = GeometricBlock("depth", _points(depth0), depth_pyramid(depth1, 5), pyramid_cameras(CAM, 5))
    res = Tracker(TrackerConfig()).track([blk], [np.eye(4)])
    e = se3_log(res.T_rgb_w @ T_w_c)
    assert np.linalg.norm(e[:3]) < 2e-3 and np.degrees(np.linalg.norm(e[3:])) < 0.1, e
    assert res.converged and res.blocks["depth"].inlier_fraction > 0.9


def test_depth_pyramid_never_averages_across_edges_and_keeps_holes():
    d = np.full((8, 8), 2.0, np.float32)
    d[:, 4:] = 4.0  # a step between 2 and 4 m: 2x2 blocks never straddle it here
    d[0:2, 0:2] = 0.0  # a hole
    d[4, 3] = 3.0  # one block with a 50 % jump inside: invalid on the next level
    lv = depth_pyramid(d, 3)
    assert [x.shape for x in lv] == [(8, 8), (4, 4), (2, 2)]
    assert lv[1][0, 0] == 0.0 and lv[1][1, 0] == 2.0 and lv[1][0, 3] == 4.0
    assert lv[1][2, 1] == 0.0  # 2, 2, 2, 3 m: an edge, not 2.25 m
    assert lv[2][0, 1] == 4.0 and lv[2][1, 0] == 2.0  # three valid 2 m pixels next to the invalid one
    nan = np.full((8, 8), np.nan, np.float32)
    assert np.all(depth_pyramid(nan, 2)[0] == 0.0)
