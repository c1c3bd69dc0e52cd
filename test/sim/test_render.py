"""Ray caster and scenes: depth equals the analytic geometry, textures, determinism."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.render import Renderer, render_view
from atsvo_ros.sim.scene import build_scene, make_scene
from atsvo_ros.sim.textures import STYLES, build_atlas, make_texture, pink_noise

# Optical frame (x right, y down, z forward) looking along world +x, z up.
R_LOOK_X = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _pose(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _flat(value: float = 0.5, size: int = 16) -> np.ndarray:
    return np.full((size, size), value, np.float32)


def test_depth_equals_analytic_plane_and_box_distances():
    box_c, box_h = np.array([5.0, 0.3, -0.2]), np.array([0.5, 1.0, 0.8])
    scene = build_scene((-1, -30, -30), (10, 30, 30), [(box_c, box_h, 0.0)], [_flat()], 0)
    cam = CameraModel(80, 60, 60.0, 60.0, 39.5, 29.5)
    irr, depth = render_view(scene, cam, _pose(R_LOOK_X, (1.0, 0.0, 0.0)))
    assert irr.shape == depth.shape == (60, 80) and irr.dtype == depth.dtype == np.float32
    # Analytic: each ray hits the box front face (x = 4.5) inside its extent, else the far wall (x = 10).
    u, v = np.meshgrid(np.arange(80), np.arange(60))
    xn, yn = (u - 39.5) / 60.0, (v - 29.5) / 60.0
    z_box = box_c[0] - box_h[0] - 1.0
    y_w, z_w = -xn * z_box, -yn * z_box  # world y, z of the hit on the plane x = 4.5
    on_box = (np.abs(y_w - box_c[1]) < box_h[1]) & (np.abs(z_w - box_c[2]) < box_h[2])
    expected = np.where(on_box, z_box, 9.0)
    assert 100 < on_box.sum() < on_box.size - 100
    np.testing.assert_allclose(depth, expected, rtol=1e-5)


def _surface_residual(scene, p: np.ndarray) -> np.ndarray:
    """Distance of world points to the nearest room wall or box surface."""
    d = np.minimum(np.abs(p - scene.room_min), np.abs(p - scene.room_max)).min(axis=1)
    for c, h, yaw in zip(scene.box_center, scene.box_half, scene.box_yaw):
        q = p - c
        cs, sn = np.cos(yaw), np.sin(yaw)
        local = np.column_stack([cs * q[:, 0] + sn * q[:, 1], -sn * q[:, 0] + cs * q[:, 1], q[:, 2]])
        d = np.minimum(d, np.abs((np.abs(local) - h).max(axis=1)))
    return d


def test_every_pixel_of_a_distorted_camera_lands_on_a_surface():
    """Back-projecting the rendered depth through the camera model gives points on the geometry."""
    scene = make_scene(2, texture_size=32)
    cfg = load_config("synthetic")
    cam = CameraModel.from_config(cfg.event_camera)  # plumb_bob: rays are cast through the raw pixels
    x0, x1, y0, y1 = scene.free_xy
    T_world_base = _pose(np.eye(3), (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.35))
    for yaw in (0.0, 2.0, 4.0):
        c, s = np.cos(yaw), np.sin(yaw)
        T_wb = T_world_base.copy()
        T_wb[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
        T_wc = T_wb @ cfg.rig.T_base_rgb_matrix() @ cfg.rig.T_rgb_event_matrix()
        irr, depth = render_view(scene, cam, T_wc)
        u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
        p_c = cam.backproject(np.column_stack([u.ravel(), v.ravel()]), depth.ravel())
        p_w = p_c @ T_wc[:3, :3].T + T_wc[:3, 3]
        assert np.percentile(_surface_residual(scene, p_w), 99.9) < 1e-4
        assert np.all(np.isfinite(irr)) and irr.min() > 0 and irr.max() < 4


def test_box_faces_shade_and_texture_as_specified():
    """Constant albedo and pure ambient light give a flat image; a textured face keeps its contrast."""
    scene = build_scene((-1, -30, -30), (10, 30, 30), [], [_flat(0.4)], 0, ambient=1.0)
    cam = CameraModel(40, 30, 40.0, 40.0, 19.5, 14.5)
    irr, _ = render_view(scene, cam, _pose(R_LOOK_X, (1.0, 0.0, 0.0)))
    np.testing.assert_allclose(irr, 0.8, rtol=1e-5)  # albedo x shade x 2 (the renderer's scale)
    tex = make_texture(np.random.default_rng(0), 64, "poster")
    scene = build_scene((-1, -30, -30), (3, 30, 30), [], [tex], 0, ambient=1.0, face_texel_per_m=64.0)
    irr, _ = render_view(scene, cam, _pose(R_LOOK_X, (1.0, 0.0, 0.0)))
    assert irr.std() > 0.02


def test_far_surfaces_are_filtered_not_aliased():
    """Seen from far away a fine texture averages to its mean (mip-mapping) instead of aliasing."""
    rng = np.random.default_rng(1)
    tex = (rng.random((256, 256)) > 0.5).astype(np.float32) * 0.8 + 0.1  # texel-scale binary noise
    scene = build_scene((-1, -50, -50), (30, 50, 50), [], [tex], 0, ambient=1.0, face_texel_per_m=256.0)
    cam = CameraModel(64, 48, 50.0, 50.0, 31.5, 23.5)
    irr, _ = render_view(scene, cam, _pose(R_LOOK_X, (0.0, 0.0, 0.0)))
    assert abs(irr.mean() / 2.0 - tex.mean()) < 0.01
    assert irr.std() / 2.0 < 0.05  # raw texture std is 0.4


def test_textures_have_natural_statistics():
    rng = np.random.default_rng(0)
    n = pink_noise(rng, 256, 1.0)
    assert abs(n.mean()) < 1e-6 and abs(n.std() - 1.0) < 1e-4
    spec = np.abs(np.fft.fft2(n)) ** 2
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(256), np.fft.fftfreq(256)))
    lo = spec[(f > 0.02) & (f < 0.04)].mean()
    hi = spec[(f > 0.2) & (f < 0.4)].mean()
    assert 30 < lo / hi < 1000  # power ~ 1/f^2: a decade in frequency -> ~100x in power
    for style in STYLES:
        tex = make_texture(rng, 64, style)
        assert tex.dtype == np.float32 and 0.03 <= tex.min() and tex.max() <= 0.92
    with pytest.raises(SimulationError):
        make_texture(rng, 60, "poster")
    atlas = build_atlas([make_texture(rng, 64, "wood"), make_texture(rng, 32, "plaster")])
    np.testing.assert_allclose(atlas.level(0, 1).mean(), atlas.level(0, 0).mean(), rtol=1e-5)
    assert atlas.level(1, atlas.n_levels - 1).shape == (1, 1)


def test_scenes_are_seeded_and_furnished():
    a, b, c = make_scene(3, 32), make_scene(3, 32), make_scene(4, 32)
    np.testing.assert_array_equal(a.box_center, b.box_center)
    np.testing.assert_array_equal(a.atlas.data, b.atlas.data)
    assert a.box_center.shape != c.box_center.shape or np.abs(a.box_center - c.box_center).max() > 0
    assert a.n_boxes >= 8
    x0, x1, y0, y1 = a.free_xy
    centre = np.array([[0.5 * (x0 + x1), 0.5 * (y0 + y1), 1.0]])
    assert a.inside_free_space(centre, a.clearance_m).all()
    assert not a.inside_free_space(a.box_center[:1]).any()


def test_renderer_reuses_rays_and_matches_render_view():
    scene = make_scene(0, 32)
    cam = CameraModel(32, 24, 30.0, 30.0, 15.5, 11.5)
    x0, x1, y0, y1 = scene.free_xy
    T = _pose(R_LOOK_X, (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.4))
    r = Renderer(scene, cam)
    g1, d1, rgb = r.render(T, rgb=True)
    g2, d2 = render_view(scene, cam, T)
    np.testing.assert_array_equal(g1, g2)
    np.testing.assert_array_equal(d1, d2)
    # The colour tint keeps luminance: grey ~ luma(rgb).
    luma = rgb @ np.array([0.299, 0.587, 0.114])
    np.testing.assert_allclose(luma, g1, rtol=1e-4)


def test_an_image_cast_on_several_threads_is_bit_identical_to_one_thread():
    scene = make_scene(3, 64)
    cam = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)
    x0, x1, y0, y1 = scene.free_xy
    T = _pose(R_LOOK_X, (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.4))
    threaded = Renderer(scene, cam, threads=4)
    assert threaded._pool is not None and len(threaded._bands) == 16  # the image really is split
    one = Renderer(scene, cam, threads=1).render(T, rgb=True)
    for a, b in zip(one, threaded.render(T, rgb=True)):
        assert a.tobytes() == b.tobytes()
