"""Event + RGB-D fusion: depth into the event camera, the ATS term alone, the joint alignment of Eq. 4."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.event_map import build_event_map, depth_in_camera
from atsvo_ros.core.events.frontend import EventFrontEnd
from atsvo_ros.core.geometry import se3_exp, se3_inv, se3_log, transform_points
from atsvo_ros.core.image.photometric import ATS_PATTERN
from atsvo_ros.core.tracking.residuals.photometric import PhotometricBlock
from atsvo_ros.core.tracking.tracker import Tracker
from test.core.event_helpers import simulate_events
from test.core.render_helpers import BoxRoom

RGB = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)
EV = CameraModel(160, 120, 120.0, 120.0, 79.5, 59.5)
T_RGB_EVENT = se3_exp(np.array([0.0, -0.04, 0.005, 0.01, 0.02, -0.01]))  # event camera in the colour frame
XI = np.array([0.2, 0.1, 0.3, 1.2, 2.4, 0.6])  # camera twist per second: ~160 deg/s, a bounding robot
MS = 1_000_000


def _T_w_rgb(t_ns: int) -> np.ndarray:
    return se3_exp(XI * t_ns * 1e-9)


def _T_w_ev(t_ns: int) -> np.ndarray:
    return _T_w_rgb(t_ns) @ T_RGB_EVENT


def test_depth_reprojected_into_the_event_camera_round_trips_a_scene_point():
    room = BoxRoom(seed=4)
    depth_rgb = room.render_depth(RGB, np.eye(4))
    z_ev = depth_in_camera(depth_rgb, RGB, EV, se3_inv(T_RGB_EVENT))
    truth = room.render_depth(EV, T_RGB_EVENT)
    both = (z_ev > 0) & np.isfinite(truth)
    assert both.mean() > 0.9  # the colour image covers the event camera's view
    assert np.median(np.abs(z_ev[both] - truth[both]) / truth[both]) < 0.01
    # one point: colour pixel -> 3-D -> event pixel -> 3-D with the reprojected depth -> the same point
    p_rgb = RGB.backproject(np.array([[200.0, 90.0]]), depth_rgb[90, 200])
    p_ev = transform_points(se3_inv(T_RGB_EVENT), p_rgb)
    uv, _ = EV.project(p_ev)
    u, v = np.rint(uv[0]).astype(int)
    back = transform_points(T_RGB_EVENT, EV.backproject(np.array([[u, v]], float), z_ev[v, u]))
    assert np.linalg.norm(back - p_rgb) < 0.02  # within the pixel rounding of the event camera


def _frames(room, dt_ns: int):
    cfg = load_config("synthetic", overrides={"mode": "fused"})
    fe = EventFrontEnd(EV, cfg, 4)
    fe.add_events(simulate_events(room, EV, _T_w_ev, -40 * MS, 0))
    f0 = fe.select(fe.render(0))
    fe.add_events(simulate_events(room, EV, _T_w_ev, 0, dt_ns))
    f1 = fe.render(dt_ns)
    depth_rgb = room.render_depth(RGB, _T_w_rgb(0))
    return f0, f1, build_event_map(f0, depth_rgb, RGB, EV, _T_w_rgb(0), T_RGB_EVENT), fe.cameras


def test_an_event_map_from_depth_exposed_earlier_places_its_points_at_their_depth():
    """A D455 exposes depth up to 16 ms off the colour: given where the depth was exposed (``T_depth_rgb``), the
    event map's points land at the event camera's true depth (measured 0.007 % median error, as from depth at the
    colour's time); read as if exposed with the colour, 1.3-1.7 % off and 29-42 % of them more than 2 %."""
    room = BoxRoom(seed=4)
    f0, _, _, _ = _frames(room, 33 * MS)
    truth = room.render_depth(EV, _T_w_ev(0))

    def rel_err(event_map):
        p = transform_points(se3_inv(_T_w_ev(0)), event_map.points_w)
        u, v = np.rint(EV.project(p)[0]).astype(int).T
        return np.abs(p[:, 2] - truth[v, u]) / truth[v, u]

    t_d = -12 * MS
    depth_d = room.render_depth(RGB, _T_w_rgb(t_d))
    T_depth_rgb = se3_inv(_T_w_rgb(t_d)) @ _T_w_rgb(0)
    placed = rel_err(build_event_map(f0, depth_d, RGB, EV, _T_w_rgb(0), T_RGB_EVENT, T_depth_rgb))
    stale = rel_err(build_event_map(f0, depth_d, RGB, EV, _T_w_rgb(0), T_RGB_EVENT))
    assert len(placed) > 300 and np.median(placed) < 1e-3 and (placed > 0.02).mean() < 0.01
    assert np.median(stale) > 0.01 and (stale > 0.02).mean() > 0.2  # the scene this test runs on shows it


@pytest.fixture(scope="module")
def event_frames():
    """ATS of the event camera at 0 and 33 ms of a fast turn, and the event map of the first."""
    room = BoxRoom(seed=4)
    return (room, *_frames(room, 33 * MS))


def _ats_block(emap, f1, cameras):
    return PhotometricBlock("ats", emap.points_w, emap.patches, ATS_PATTERN, f1.pyramid, cameras,
                            T_cam_rgb=se3_inv(T_RGB_EVENT), sigma=12.0, huber=15.0, outlier=40.0,
                            estimate_affine=False, zero_mean=True)


def test_event_map_points_carry_depth_and_ats_patches(event_frames):
    _, f0, _, emap, cams = event_frames
    assert len(f0.selected) > 100 and len(emap) > 0.8 * len(f0.selected)
    assert emap.patches.shape == (len(cams), len(emap), len(ATS_PATTERN))
    # the points project back onto the pixels they were selected at
    uv, _ = EV.project(transform_points(se3_inv(_T_w_ev(0)), emap.points_w))
    d = np.abs(uv[:, None, :] - np.asarray(f0.selected, float)[None]).max(axis=2).min(axis=1)
    assert np.all(d < 1e-6)


def test_the_event_block_alone_converges_on_a_pure_event_case():
    """No colour, no depth term: the ATS term from the zero-motion start the paper prescribes for it.

    16 ms of the turn (2.6 deg, 0.5 cm): measured 0.10 deg, 0.7 cm off at the end (the test's event model has
    no sub-frame timing; the 33 ms / 5 deg case is beyond the ATS term's basin on this 160x120 sensor, where
    the joint alignment below takes over).
    """
    from atsvo_ros.config import TrackerConfig

    room = BoxRoom(seed=4)
    _, f1, emap, cams = _frames(room, 16 * MS)
    res = Tracker(TrackerConfig()).track([_ats_block(emap, f1, cams)], [se3_inv(_T_w_rgb(0))])
    e = se3_log(res.T_rgb_w @ _T_w_rgb(16 * MS))
    assert res.converged and res.iterations > 3 and res.blocks["ats"].inlier_fraction > 0.8
    assert np.degrees(np.linalg.norm(e[3:])) < 0.3 and np.linalg.norm(e[:3]) < 0.015, e


def test_joint_alignment_recovers_a_known_pose_offset(event_frames):
    """Eq. 4: the RGB term (keyframe at 0) and the ATS term together, one pose."""
    from atsvo_ros.config import RgbSelectionConfig, TrackerConfig
    from atsvo_ros.core.image.photometric import RGB_PATTERN, extract_patches
    from atsvo_ros.core.image.pyramid import build_pyramid, image_pyramid_with_gradients, pyramid_cameras
    from atsvo_ros.core.mapping.rgb_selection import select_rgb_pixels

    room, _, f1, emap, cams = event_frames
    img0, depth0 = room.render(RGB, _T_w_rgb(0), supersample=2)
    pyr0 = image_pyramid_with_gradients(build_pyramid(img0, 4))
    uv = select_rgb_pixels(img0, RgbSelectionConfig(target_points=600))
    p_w = transform_points(_T_w_rgb(0), RGB.backproject(uv.astype(float), depth0[uv[:, 1], uv[:, 0]]))
    img1, _ = room.render(RGB, _T_w_rgb(33 * MS), supersample=2)
    rgb = PhotometricBlock("rgb", p_w, extract_patches(pyr0, uv, RGB_PATTERN), RGB_PATTERN,
                           image_pyramid_with_gradients(build_pyramid(img1, 4)), pyramid_cameras(RGB, 4),
                           sigma=8.0, zero_mean=True, estimate_affine=False)
    res = Tracker(TrackerConfig()).track([rgb, _ats_block(emap, f1, cams)], [se3_inv(_T_w_rgb(0))])
    e = se3_log(res.T_rgb_w @ _T_w_rgb(33 * MS))
    assert set(res.blocks) == {"rgb", "ats"} and res.converged
    assert np.degrees(np.linalg.norm(e[3:])) < 0.2 and np.linalg.norm(e[:3]) < 0.005, e
