"""SE(3)/SO(3) maths on 4x4 / 3x3 float64 matrices.

Conventions: a pose ``T_a_b`` maps points in frame b to frame a (``p_a = T_a_b @ p_b``).
A twist ``xi = (rho, phi)`` puts translation first and rotation second, and perturbations are
left-multiplied: ``T' = exp(xi) @ T``. Quaternions are ``(x, y, z, w)`` like ROS and TUM files.
Functions accept single elements or stacks (leading batch dimensions) where noted.
"""
from __future__ import annotations

import numpy as np

from atsvo_ros.errors import GeometryError

_EPS = 1e-10


def hat(w: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of a 3-vector (or a stack of them), so that ``hat(w) @ v = w x v``."""
    w = np.asarray(w, dtype=np.float64)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def vee(W: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat`."""
    W = np.asarray(W, dtype=np.float64)
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix from an axis-angle vector (Rodrigues), vectorised over leading axes."""
    phi = np.asarray(phi, dtype=np.float64)
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = hat(phi)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(th) / th)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(th)) / th**2)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + a * K + b * (K @ K)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Axis-angle vector of a rotation matrix, robust near 0 and pi; vectorised."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise GeometryError(f"so3_log needs 3x3 matrices, got shape {R.shape}")
    tr = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) * 0.5, -1.0, 1.0)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    # sin(theta) from the antisymmetric part, not sin(arccos(...)): near pi that loses ~1e-8 relative
    sin_t = 0.5 * np.linalg.norm(v, axis=-1)
    theta = np.arctan2(sin_t, tr)
    small = theta < 1e-6
    scale = np.where(small, 0.5 + theta**2 / 12.0, theta / (2.0 * np.where(small, 1.0, sin_t)))
    out = v * scale[..., None]
    near_pi = theta > np.pi - 1e-4
    if np.any(near_pi):
        Rp = R[near_pi] if R.ndim > 2 else R[None]
        th = theta[near_pi] if R.ndim > 2 else np.atleast_1d(theta)
        # R = I + 2 hat(n)^2 at pi => n n^T = (R + I) / 2; pick the best-conditioned column. Only the
        # symmetric part: the antisymmetric one, sin(theta) hat(n), would put an O(pi - theta) error in n.
        B = (Rp + np.swapaxes(Rp, -1, -2)) * 0.25 + np.eye(3) * 0.5
        idx = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        cols = B[np.arange(len(B)), :, idx]
        n = cols / np.sqrt(np.maximum(cols[np.arange(len(B)), idx], _EPS))[:, None]
        # Fix the sign using the antisymmetric part (zero exactly at pi, where both signs are valid).
        vs = v[near_pi] if R.ndim > 2 else v[None]
        sign = np.where(np.sum(n * vs, axis=-1) < 0, -1.0, 1.0)
        res = n * (th * sign)[:, None]
        if R.ndim > 2:
            out[near_pi] = res
        else:
            out = res[0]
    return out


def _left_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-6:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return (np.eye(3) + (1 - np.cos(theta)) / theta**2 * K
            + (theta - np.sin(theta)) / theta**3 * (K @ K))


def _left_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 12.0
    half = 0.5 * theta
    coef = (1.0 - half * np.cos(half) / np.sin(half)) / theta**2
    return np.eye(3) - 0.5 * K + coef * (K @ K)


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """4x4 pose from a twist ``(rho, phi)``."""
    xi = np.asarray(xi, dtype=np.float64).reshape(6)
    T = np.eye(4)
    T[:3, :3] = so3_exp(xi[3:])
    T[:3, 3] = _left_jacobian(xi[3:]) @ xi[:3]
    return T


def se3_log(T: np.ndarray) -> np.ndarray:
    """Twist ``(rho, phi)`` of a 4x4 pose."""
    T = check_pose(T)
    phi = so3_log(T[:3, :3])
    rho = _left_jacobian_inv(phi) @ T[:3, 3]
    return np.concatenate([rho, phi])


def se3_adjoint(T: np.ndarray) -> np.ndarray:
    """``Ad(T)`` (6x6) for twists with the translation first: ``exp(Ad(T) xi) = T exp(xi) T^-1``."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[:3, 3:] = hat(t) @ R
    A[3:, 3:] = R
    return A


def se3_inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a pose (or a stack of poses) without a general matrix inverse."""
    T = np.asarray(T, dtype=np.float64)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def check_pose(T: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Return ``T`` as float64 4x4 after checking its shape, finiteness and rotation block."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise GeometryError(f"expected a 4x4 pose, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise GeometryError("pose contains NaN or inf")
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > tol or np.linalg.det(R) < 0:
        raise GeometryError("pose rotation block is not a proper rotation")
    if np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])).max() > tol:
        raise GeometryError("pose last row must be [0, 0, 0, 1]")
    return T


def camera_centre(T_c_w: np.ndarray) -> np.ndarray:
    """The camera centre in the world frame (``-R^T t`` of ``T_c_w``)."""
    return -T_c_w[:3, :3].T @ T_c_w[:3, 3]


def project_to_so3(R: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (SVD), used to clean up accumulated round-off."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ D @ Vt


def transform_points(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Map an (N, 3) array of points from frame b to frame a."""
    p_b = np.asarray(p_b, dtype=np.float64)
    return p_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def rotation_angle_rad(R: np.ndarray) -> np.ndarray:
    """Rotation angle of a rotation matrix (or stack), in radians, in [0, pi]."""
    R = np.asarray(R, dtype=np.float64)
    return np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) * 0.5, -1.0, 1.0))


def quat_from_rotmat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` from rotation matrices (vectorised)."""
    R = np.asarray(R, dtype=np.float64)
    batch = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    q = np.empty((len(R), 4))
    tr = np.trace(R, axis1=1, axis2=2)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    cases = np.argmax(np.stack([tr, m00, m11, m22], 1), axis=1)
    for c in range(4):
        sel = cases == c
        if not np.any(sel):
            continue
        r = R[sel]
        if c == 0:
            s = np.sqrt(1.0 + tr[sel]) * 2
            q[sel] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                               (r[:, 1, 0] - r[:, 0, 1]) / s, 0.25 * s], 1)
        elif c == 1:
            s = np.sqrt(1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2]) * 2
            q[sel] = np.stack([0.25 * s, (r[:, 0, 1] + r[:, 1, 0]) / s,
                               (r[:, 0, 2] + r[:, 2, 0]) / s, (r[:, 2, 1] - r[:, 1, 2]) / s], 1)
        elif c == 2:
            s = np.sqrt(1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2]) * 2
            q[sel] = np.stack([(r[:, 0, 1] + r[:, 1, 0]) / s, 0.25 * s,
                               (r[:, 1, 2] + r[:, 2, 1]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s], 1)
        else:
            s = np.sqrt(1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1]) * 2
            q[sel] = np.stack([(r[:, 0, 2] + r[:, 2, 0]) / s, (r[:, 1, 2] + r[:, 2, 1]) / s,
                               0.25 * s, (r[:, 1, 0] - r[:, 0, 1]) / s], 1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    return q.reshape(batch + (4,))


def rotmat_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices from quaternions ``(x, y, z, w)`` (normalised here), vectorised."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < _EPS) or not np.all(np.isfinite(q)):
        raise GeometryError("quaternion has zero norm or is not finite")
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    R = np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ], axis=-1)
    return R.reshape(q.shape[:-1] + (3, 3))


def pose_from_tq(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """4x4 pose(s) from translation(s) and quaternion(s) ``(x, y, z, w)``."""
    t = np.asarray(t, dtype=np.float64)
    R = rotmat_from_quat(q)
    T = np.zeros(t.shape[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def tq_from_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation(s) and quaternion(s) ``(x, y, z, w)`` of 4x4 pose(s)."""
    T = np.asarray(T, dtype=np.float64)
    return T[..., :3, 3].copy(), quat_from_rotmat(T[..., :3, :3])


def slerp_rotation(R0: np.ndarray, R1: np.ndarray, alpha: float | np.ndarray) -> np.ndarray:
    """Geodesic interpolation between rotations: ``R0 exp(alpha log(R0^T R1))``."""
    alpha = np.asarray(alpha, dtype=np.float64)
    dphi = so3_log(np.swapaxes(R0, -1, -2) @ R1)
    return R0 @ so3_exp(dphi * alpha[..., None])


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, alpha: float | np.ndarray) -> np.ndarray:
    """Pose between T0 (alpha=0) and T1 (alpha=1): slerp on rotation, linear on translation.

    This decoupled scheme is what trajectory tools (evo, TUM) use for ground truth.
    """
    alpha = np.asarray(alpha, dtype=np.float64)
    T = np.zeros(np.broadcast_shapes(np.shape(T0), alpha.shape + (4, 4)))
    T[..., :3, :3] = slerp_rotation(T0[..., :3, :3], T1[..., :3, :3], alpha)
    T[..., :3, 3] = (1 - alpha[..., None]) * T0[..., :3, 3] + alpha[..., None] * T1[..., :3, 3]
    T[..., 3, 3] = 1.0
    return T


def se3_interpolate(T0: np.ndarray, T1: np.ndarray, alpha: float) -> np.ndarray:
    """Geodesic interpolation on SE(3): ``T0 exp(alpha log(T0^-1 T1))`` (screw motion)."""
    return T0 @ se3_exp(alpha * se3_log(se3_inv(T0) @ T1))


def interpolate_trajectory(stamps_ns: np.ndarray, T_w_b: np.ndarray,
                           query_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses at query stamps by :func:`interpolate_pose` between the bracketing samples.

    Returns ``(poses, valid)``; queries outside ``[stamps[0], stamps[-1]]`` are marked invalid
    and get the nearest end pose.
    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    query_ns = np.asarray(query_ns, dtype=np.int64)
    if len(stamps_ns) == 0:
        raise GeometryError("cannot interpolate an empty trajectory")
    if np.any(np.diff(stamps_ns) <= 0):
        raise GeometryError("trajectory stamps must be strictly increasing")
    valid = (query_ns >= stamps_ns[0]) & (query_ns <= stamps_ns[-1])
    i1 = np.clip(np.searchsorted(stamps_ns, query_ns, side="left"), 1, max(len(stamps_ns) - 1, 1))
    if len(stamps_ns) == 1:
        return np.repeat(T_w_b[:1], len(query_ns), 0), valid
    i0 = i1 - 1
    span = (stamps_ns[i1] - stamps_ns[i0]).astype(np.float64)
    alpha = np.clip((query_ns - stamps_ns[i0]).astype(np.float64) / span, 0.0, 1.0)
    return interpolate_pose(T_w_b[i0], T_w_b[i1], alpha), valid


def relative_motion(T_w_a: np.ndarray, T_w_b: np.ndarray) -> tuple[float, float]:
    """Rotation angle (rad) and translation norm (m) of ``T_a_b = T_w_a^-1 T_w_b``."""
    T_ab = se3_inv(T_w_a) @ T_w_b
    return float(rotation_angle_rad(T_ab[:3, :3])), float(np.linalg.norm(T_ab[:3, 3]))
