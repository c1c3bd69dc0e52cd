"""Tracker: Jacobians against finite differences, recovery of known pose offsets, a second block."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import RgbSelectionConfig, TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp, se3_inv, se3_log
from atsvo_ros.core.image.photometric import ATS_PATTERN, RGB_PATTERN, extract_patches
from atsvo_ros.core.image.pyramid import build_pyramid, image_pyramid_with_gradients, pyramid_cameras
from atsvo_ros.core.mapping.rgb_selection import select_rgb_pixels
from atsvo_ros.core.tracking import _lm_kernels as kernels
from atsvo_ros.core.tracking.residuals.photometric import PhotometricBlock
from atsvo_ros.core.tracking.tracker import Tracker
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
    return PhotometricBlock(name, points_w, patches, pattern, pyr, pyramid_cameras(camera, LEVELS), T_cam_rgb=T_cam_rgb)


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
    # it got there by optimising, not by luck: several LM steps, converged, no singular system
    assert res.converged and res.iterations > 4 and not res.singular, res
    assert res.n_inliers > 0.8 * res.n_visible
    assert np.all(np.linalg.eigvalsh(res.covariance) > 0)


def test_best_initial_guess_wins(room, reference):
    """A bad constant-motion guess next to a good zero-motion one: the tracker keeps the good one."""
    p_w, patches = reference
    T_w_c = se3_exp(np.array([0.01, 0.0, 0.01, 0.0, 0.01, 0.0]))
    blk = _block(room, T_w_c, p_w, patches)
    bad = se3_inv(se3_exp(np.array([0.0, 0.0, 0.0, 0.0, 0.35, 0.0])))
    res = Tracker(TrackerConfig()).track([blk], [bad, np.eye(4)])
    assert res.guess_index == 1 and res.converged and res.iterations > 1
    assert _errors(res.T_rgb_w, T_w_c)[0] < 1e-3


def _quadratic_pyramid_level(dtype) -> np.ndarray:
    """``[I, Ix, Iy]`` of a quadratic image; central differences are exact for it."""
    u, v = np.meshgrid(np.arange(640, dtype=np.float64), np.arange(480, dtype=np.float64))
    img = 2e-3 * (u - 300) ** 2 + 1e-3 * (v - 200) ** 2 + 1.5e-3 * (u - 300) * (v - 200) + 0.3 * u - 0.2 * v + 40.0
    out = np.zeros((480, 640, 3), dtype)
    out[..., 0] = img
    out[:, 1:-1, 1] = 0.5 * (img[:, 2:] - img[:, :-2])
    out[1:-1, :, 2] = 0.5 * (img[2:] - img[:-2])
    return out


@pytest.mark.parametrize("zero_mean", [False, True])
def test_normal_equations_match_finite_differences(zero_mean):
    """``2 g = dE/dparams`` (pose twist, log-gain, offset) and H is symmetric PSD, with and without zero-mean patches.

    The image is quadratic and stored in float64. In float32 (what the tracker uses) the zero-mean
    case differs from finite differences by up to ~14 % on single components of the sum: removing a
    patch's mean leaves only its second-difference signal (~0.004 grey levels per pixel here), of
    the order of float32's rounding of the stored pixels (~1e-5 at 100 grey levels), so each point's
    finite difference is ~0.3 % off, and the per-point terms cancel in the sum (+-400 each, -40
    total), which amplifies that. The kernel is exact; in float64 both agree to 1e-6 (see the tolerance below
    for raw patches).
    """
    rng = np.random.default_rng(0)
    pyr = [_quadratic_pyramid_level(np.float64)]
    uv = np.column_stack([rng.uniform(40, 600, 200), rng.uniform(40, 440, 200)])
    p = CAM.backproject(uv, rng.uniform(1.0, 4.0, 200))
    patches = rng.uniform(0, 200, (1, 200, 9)).astype(np.float32)
    T_cam_rgb = se3_exp(np.array([0.05, -0.02, 0.01, 0.01, 0.03, -0.02]))
    blk = PhotometricBlock("rgb", p, patches, RGB_PATTERN, pyr, [CAM], T_cam_rgb=se3_inv(T_cam_rgb),
                           zero_mean=zero_mean, huber=1e6, outlier=1e6)
    T0 = se3_exp(np.array([0.01, 0.02, -0.01, 0.01, 0.02, 0.003]))
    aff = (0.1, 3.0)
    bs = blk.linearise(0, T0, aff)
    H, g, n_in, n_vis = bs.H, bs.g, bs.n_inliers, bs.n_visible
    assert n_in == n_vis > 150
    num = np.zeros(8)
    for k in range(8):
        d = np.zeros(8)
        d[k] = 1e-6
        ep = blk.linearise(0, se3_exp(d[:6]) @ T0, (aff[0] + d[6], aff[1] + d[7])).energy
        em = blk.linearise(0, se3_exp(-d[:6]) @ T0, (aff[0] - d[6], aff[1] - d[7])).energy
        num[k] = (ep - em) / 2e-6
    # Raw patches: the Jacobian's interpolated central-difference gradient and the slope of the bilinear
    # interpolant differ by (1 - 2 frac) x the curvature (exact only on a linear ramp), ~3e-5 relative here;
    # removing the patch mean cancels that common term, so the zero-mean case is exact.
    rtol = 1e-6 if zero_mean else 1e-4
    assert np.allclose(2 * g, num, rtol=rtol, atol=rtol * np.abs(num).max()), (2 * g, num)
    if zero_mean:  # the offset cancels in zero-mean residuals
        assert g[7] == 0.0 and np.all(H[7] == 0.0)
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
        PhotometricBlock("rgb", np.zeros((3, 3)), np.zeros((2, 4, 9), np.float32), RGB_PATTERN, [], [])
    with pytest.raises(TrackingError):
        Tracker(TrackerConfig()).track([], [np.eye(4)])


def test_covariance_matches_the_spread_of_errors(room):
    """Over several known offsets with sensor noise, the errors are as large as the covariance says.

    Normalised estimation error squared (NEES, eps^T C^-1 eps, 6 on average for a consistent
    estimate): measured ~6 at noise sigma 2 and ~3.5 at sigma 6 with ``covariance_scale`` 4 (24 and
    14 without it). Bounds at a factor of 4 around 6, and each axis's RMS error within 3x of its
    predicted standard deviation (which also checks the ordering x y z rx ry rz).
    """
    cam = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)
    img, depth = room.render(cam, np.eye(4), supersample=3)
    pyr = image_pyramid_with_gradients(build_pyramid(img, LEVELS))
    uv = select_rgb_pixels(img, RgbSelectionConfig(target_points=600))
    p_c = cam.backproject(uv.astype(np.float64), depth[uv[:, 1], uv[:, 0]])
    patches = extract_patches(pyr, uv, RGB_PATTERN)
    rng = np.random.default_rng(1)
    eps, sds, nees = [], [], []
    for _ in range(10):
        T_w_c = se3_exp(rng.normal(0.0, [0.01, 0.01, 0.01, 0.005, 0.005, 0.005]))
        cur, _ = room.render(cam, T_w_c, supersample=3)
        cur = cur + rng.normal(0.0, 3.0, cur.shape).astype(np.float32)
        pyr = image_pyramid_with_gradients(build_pyramid(cur, LEVELS))
        blk = PhotometricBlock("rgb", p_c, patches, RGB_PATTERN, pyr, pyramid_cameras(cam, LEVELS), zero_mean=True)
        res = Tracker(TrackerConfig()).track([blk], [np.eye(4)])
        e = se3_log(res.T_rgb_w @ T_w_c)  # left perturbation of T_rgb_w, like the covariance
        eps.append(e)
        sds.append(np.sqrt(np.diag(res.covariance)))
        nees.append(e @ np.linalg.solve(res.covariance, e))
    ratio = np.sqrt(np.mean(np.square(eps), axis=0)) / np.mean(sds, axis=0)
    assert 1.5 < np.mean(nees) < 24.0, nees
    assert np.all((ratio > 1 / 3) & (ratio < 3.0)), ratio


def test_singular_system_is_reported_not_hidden():
    """No texture: the pose part of the normal equations is zero; LM says so instead of failing silently."""
    H = np.zeros((8, 8))
    H[6, 6] = H[7, 7] = 1.0
    delta, T_new = kernels._lm_step(H, np.ones(8), 1e-4, np.eye(4))
    assert np.all(np.isnan(delta)) and np.array_equal(T_new, np.eye(4))
    flat = [np.dstack([np.full((480 >> k, 640 >> k), 100.0, np.float32),
                       np.zeros((480 >> k, 640 >> k, 2), np.float32)]) for k in range(LEVELS)]
    rng = np.random.default_rng(0)
    p = CAM.backproject(np.column_stack([rng.uniform(50, 590, 100), rng.uniform(50, 430, 100)]), 2.0)
    patches = rng.uniform(50, 150, (LEVELS, 100, 9)).astype(np.float32)
    blk = PhotometricBlock("rgb", p, patches, RGB_PATTERN, flat, pyramid_cameras(CAM, LEVELS), zero_mean=True)
    res = Tracker(TrackerConfig()).track([blk], [np.eye(4)])
    assert res.singular and not res.converged
    assert np.allclose(res.T_rgb_w, np.eye(4))


def test_cholesky_solver_matches_numpy():
    rng = np.random.default_rng(2)
    for n in (6, 8, 10):
        J = rng.standard_normal((50, n))
        A = J.T @ J
        b = rng.standard_normal(n)
        x = kernels._solve_spd(A, b, np.zeros((n, n)))
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
    assert np.all(np.isnan(kernels._solve_spd(np.diag([1.0, 0.0, 1.0]), np.ones(3), np.zeros((3, 3)))))
