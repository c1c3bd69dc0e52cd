from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core import geometry as g
from atsvo_ros.errors import GeometryError

rng = np.random.default_rng(7)


def random_pose() -> np.ndarray:
    return g.se3_exp(np.concatenate([rng.normal(size=3), rng.uniform(-np.pi, np.pi, 3) / 2]))


def test_so3_exp_log_round_trip_including_small_and_near_pi_angles():
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([rng.uniform(0, np.pi - 1e-3, 190), [0.0, 1e-9, 1e-7, 1e-5, np.pi - 1e-6,
                                                                    np.pi - 1e-5, 3.0, 3.14, 1e-3, 2.0]])
    phis = axes * angles[:, None]
    R = g.so3_exp(phis)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    back = g.so3_log(R)
    assert np.allclose(g.so3_exp(back), R, atol=1e-9)
    far = angles < np.pi - 1e-4
    assert np.allclose(back[far], phis[far], atol=1e-9)


def test_so3_log_exactly_pi():
    R = g.so3_exp(np.array([0.0, 0.0, np.pi]))
    assert np.allclose(np.abs(g.so3_log(R)), [0, 0, np.pi], atol=1e-9)


def test_se3_exp_log_round_trip_and_inverse():
    for _ in range(100):
        xi = np.concatenate([rng.normal(size=3), rng.normal(size=3)])
        xi[3:] *= min(1.0, 3.0 / np.linalg.norm(xi[3:]))
        T = g.se3_exp(xi)
        assert np.allclose(g.se3_log(T), xi, atol=1e-9)
        assert np.allclose(g.se3_inv(T) @ T, np.eye(4), atol=1e-12)


def test_se3_exp_matches_matrix_exponential():
    from scipy.linalg import expm

    xi = np.array([0.3, -0.2, 0.5, 0.4, -0.1, 0.7])
    M = np.zeros((4, 4))
    M[:3, :3] = g.hat(xi[3:])
    M[:3, 3] = xi[:3]
    assert np.allclose(g.se3_exp(xi), expm(M), atol=1e-12)


def test_quaternion_round_trip_and_convention():
    Ts = np.stack([random_pose() for _ in range(50)])
    t, q = g.tq_from_pose(Ts)
    assert np.all(q[:, 3] >= 0)
    assert np.allclose(g.pose_from_tq(t, q), Ts, atol=1e-12)
    # 90 deg about z is (0, 0, sin45, cos45) in (x, y, z, w) order.
    q = g.quat_from_rotmat(g.so3_exp(np.array([0, 0, np.pi / 2])))
    assert np.allclose(q, [0, 0, np.sqrt(0.5), np.sqrt(0.5)])


def test_interpolation_endpoints_midpoint_and_trajectory():
    T0, T1 = random_pose(), random_pose()
    assert np.allclose(g.interpolate_pose(T0, T1, 0.0), T0, atol=1e-12)
    assert np.allclose(g.interpolate_pose(T0, T1, 1.0), T1, atol=1e-9)
    mid = g.interpolate_pose(T0, T1, 0.5)
    a0 = g.rotation_angle_rad(T0[:3, :3].T @ mid[:3, :3])
    a1 = g.rotation_angle_rad(mid[:3, :3].T @ T1[:3, :3])
    assert a0 == pytest.approx(a1, abs=1e-9)
    assert np.allclose(g.se3_interpolate(T0, T1, 1.0), T1, atol=1e-9)
    stamps = np.array([0, 10, 20], dtype=np.int64)
    poses = np.stack([T0, mid, T1])
    out, valid = g.interpolate_trajectory(stamps, poses, np.array([-1, 0, 5, 20, 21]))
    assert valid.tolist() == [False, True, True, True, False]
    assert np.allclose(out[2], g.interpolate_pose(T0, mid, 0.5), atol=1e-12)


def test_check_pose_rejects_bad_input():
    with pytest.raises(GeometryError, match="4x4"):
        g.check_pose(np.eye(3))
    bad = np.eye(4)
    bad[0, 0] = 2
    with pytest.raises(GeometryError, match="rotation"):
        g.check_pose(bad)
    bad = np.eye(4)
    bad[1, 3] = np.nan
    with pytest.raises(GeometryError, match="NaN"):
        g.check_pose(bad)
