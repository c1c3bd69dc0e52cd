"""Feature matches between two frames (ORB + PnP-RANSAC): the motion of a fast turn, or no answer."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp, se3_log
from atsvo_ros.core.tracking.features import FeatureMatcher
from test.core.render_helpers import BoxRoom

CAM = CameraModel(640, 480, 382.0, 382.0, 319.5, 239.5)


@pytest.fixture(scope="module")
def room() -> BoxRoom:
    return BoxRoom(seed=3)


@pytest.mark.parametrize("xi", [
    [0.02, -0.01, 0.01, 0.0, np.radians(12.0), 0.0],   # 12 deg pan: outside direct alignment's basin
    [0.0, 0.03, 0.0, np.radians(8.0), 0.0, np.radians(6.0)],
])
def test_relative_pose_of_a_fast_turn(room, xi):
    T_w_c0 = np.eye(4)
    T_w_c1 = se3_exp(np.asarray(xi, float))
    img0, depth0 = room.render(CAM, T_w_c0, supersample=2)
    img1, depth1 = room.render(CAM, T_w_c1, supersample=2)
    m = FeatureMatcher(CAM, n_features=500)
    f0, f1 = m.describe(img0, depth0), m.describe(img1, depth1)
    assert len(f0) > 200 and np.isfinite(f0.points_c[:, 2]).mean() > 0.9
    rel = m.relative_pose(f0, f1)
    assert rel is not None and rel.n_inliers >= 30
    err = se3_log(T_w_c1 @ rel.T_cur_prev)  # T_cur_prev = T_c1_c0 = inv(T_w_c1) when c0 is the world
    # walls 2.4-4 m away: 0.2 deg of rotation trades against ~1 cm of translation there
    assert np.degrees(np.linalg.norm(err[3:])) < 0.5 and np.linalg.norm(err[:3]) < 0.02, err


def test_no_answer_without_support(room):
    img, depth = room.render(CAM, np.eye(4), supersample=1)
    m = FeatureMatcher(CAM, n_features=500)
    f = m.describe(img, depth)
    blank = m.describe(np.full_like(img, 128.0), depth)
    assert len(blank) == 0 and m.relative_pose(f, blank) is None
    no_depth = m.describe(img, np.zeros_like(depth))
    assert not np.isfinite(no_depth.points_c[:, 2]).any() and m.relative_pose(no_depth, f) is None
