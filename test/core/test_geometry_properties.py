"""Property-based tests of the SE(3)/SO(3) utilities (hypothesis, derandomized).

exp/log round trips (also near 0 and near pi), inverse, composition, quaternion round trip and
``project_to_so3`` (a rotation, the identity on rotations, the nearest one).
"""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from atsvo_ros.core.geometry import (
    check_pose,
    project_to_so3,
    quat_from_rotmat,
    rotation_angle_rad,
    rotmat_from_quat,
    se3_exp,
    se3_inv,
    se3_log,
    so3_exp,
    so3_log,
)

PROPS = settings(max_examples=150, deadline=None, derandomize=True)
finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)


@st.composite
def rotvecs(draw, max_angle: float = np.pi - 1e-3):
    """Axis-angle vectors with angle in [0, max_angle], including tiny and near-pi angles."""
    axis = draw(arrays(np.float64, 3, elements=st.floats(-1, 1, allow_nan=False)))
    n = np.linalg.norm(axis)
    axis = axis / n if n > 1e-3 else np.array([0.0, 0.0, 1.0])
    angle = draw(st.one_of(st.floats(0, 1e-7), st.floats(0, max_angle), st.floats(max_angle - 1e-3, max_angle)))
    return axis * angle


@st.composite
def twists(draw, max_angle: float = np.pi - 1e-3):
    rho = draw(arrays(np.float64, 3, elements=finite))
    return np.concatenate([rho, draw(rotvecs(max_angle))])


@st.composite
def poses(draw):
    return se3_exp(draw(twists()))


@PROPS
@given(twists())
def test_se3_log_inverts_exp(xi):
    np.testing.assert_allclose(se3_log(se3_exp(xi)), xi, atol=1e-6 * (1 + np.abs(xi).max()))


@PROPS
@given(poses())
def test_se3_exp_inverts_log_and_poses_are_valid(T):
    check_pose(T)
    np.testing.assert_allclose(se3_exp(se3_log(T)), T, atol=1e-8 * (1 + np.abs(T).max()))


@PROPS
@given(rotvecs(np.pi))
def test_so3_log_exp_round_trip_up_to_pi(phi):
    R = so3_exp(phi)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(so3_exp(so3_log(R)), R, atol=1e-7)
    assert abs(rotation_angle_rad(R) - np.linalg.norm(phi)) < 1e-6


@PROPS
@given(poses())
def test_inverse(T):
    Ti = se3_inv(T)
    np.testing.assert_allclose(Ti @ T, np.eye(4), atol=1e-9 * (1 + np.abs(T).max()))
    np.testing.assert_allclose(T @ Ti, np.eye(4), atol=1e-9 * (1 + np.abs(T).max()))
    np.testing.assert_allclose(se3_inv(Ti), T, atol=1e-12 * (1 + np.abs(T).max()))


@PROPS
@given(poses(), poses(), poses())
def test_composition_is_associative_and_inverts_in_reverse_order(A, B, C):
    scale = 1 + max(np.abs(A).max(), np.abs(B).max(), np.abs(C).max()) ** 3
    np.testing.assert_allclose((A @ B) @ C, A @ (B @ C), atol=1e-9 * scale)
    np.testing.assert_allclose(se3_inv(A @ B), se3_inv(B) @ se3_inv(A), atol=1e-9 * scale)
    check_pose(A @ B @ C, tol=1e-9)


@PROPS
@given(rotvecs(np.pi))
def test_quaternion_round_trip(phi):
    R = so3_exp(phi)
    q = quat_from_rotmat(R)
    assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[3] >= 0
    np.testing.assert_allclose(rotmat_from_quat(q), R, atol=1e-9)
    np.testing.assert_allclose(rotmat_from_quat(-3.0 * q), R, atol=1e-9)  # sign and scale do not matter


@PROPS
@given(rotvecs(np.pi), arrays(np.float64, (3, 3), elements=st.floats(-0.2, 0.2, allow_nan=False)), rotvecs(np.pi))
def test_project_to_so3_gives_the_nearest_rotation(phi, noise, other):
    R = so3_exp(phi)
    P = project_to_so3(R)
    np.testing.assert_allclose(P, R, atol=1e-9)  # identity on rotations
    M = R + noise
    Q = project_to_so3(M)
    np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(Q) > 0
    # no other rotation is nearer to M (Frobenius norm)
    assert np.linalg.norm(Q - M) <= np.linalg.norm(so3_exp(other) - M) + 1e-9
    assert np.linalg.norm(Q - M) <= np.linalg.norm(R - M) + 1e-9
