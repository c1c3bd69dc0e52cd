"""Map points, per-level patches, depth validity, culling and the temporary event map."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import RigConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.event_map import TemporaryEventMap
from atsvo_ros.core.geometry import se3_exp, transform_points
from atsvo_ros.core.image.photometric import ATS_PATTERN, RGB_PATTERN, bilinear, extract_patches, level_position
from atsvo_ros.core.image.pyramid import build_pyramid
from atsvo_ros.core.mapping.map import PointMap, smoothed_depth, valid_depth_mask
from atsvo_ros.errors import TrackingError


def test_valid_depth_mask_rejects_invalid_out_of_range_and_edges():
    rig = RigConfig(depth_min_m=0.3, depth_max_m=6.0)
    d = np.full((20, 20), 2.0, np.float32)
    d[1, 1] = 0.0
    d[2, 2] = np.nan
    d[3, 3] = 0.2
    d[4, 4] = 7.0
    d[10:, 10:] = 4.0  # a depth step: pixels along it are edges
    ok = valid_depth_mask(d, rig)
    assert not ok[1, 1] and not ok[2, 2] and not ok[3, 3] and not ok[4, 4] and ok[15, 15] and ok[9, 12]
    ok_e = valid_depth_mask(d, rig, edge_ratio=0.05)
    assert not ok_e[9, 12] and not ok_e[10, 12] and ok_e[15, 15] and ok_e[6, 15]
    assert not ok_e[0, 1]  # next to the invalid pixel


def test_smoothed_depth_averages_noise_on_planes_and_ignores_invalid():
    rng = np.random.default_rng(2)
    u, v = np.meshgrid(np.arange(60), np.arange(40))
    plane = (2.0 + 0.01 * u + 0.005 * v).astype(np.float32)  # a slanted plane
    noisy = plane + rng.normal(0, 0.03, plane.shape).astype(np.float32)
    valid = np.ones(plane.shape, bool)
    valid[10:14, 20:24] = False
    noisy[~valid] = 0.0
    sm = smoothed_depth(noisy, valid, 5)
    inner = (slice(5, 35), slice(5, 55))
    err_raw = np.abs(noisy - plane)[inner][valid[inner]]
    err_sm = np.abs(sm - plane)[inner][valid[inner]]
    assert err_sm.std() < 0.35 * err_raw.std()  # ~5x less noise, no bias on a linear surface
    assert abs(err_sm.mean() - 0.0) < 0.01 and np.all(sm[valid] > 1.5)
    assert np.array_equal(smoothed_depth(noisy, valid, 1), np.where(valid, noisy, 0))
    assert not valid_depth_mask(noisy, RigConfig(), edge_ratio=0.2, window_px=5)[8, 20]  # near the hole


def test_patches_hold_pattern_intensities_on_every_level():
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 255, (64, 80)).astype(np.float32)
    pyr = build_pyramid(img, 3)
    uv = np.array([[20, 30], [41, 17], [60, 40]])
    patches = extract_patches(pyr, uv, RGB_PATTERN)
    assert patches.shape == (3, 3, 9) and patches.dtype == np.float32
    assert np.allclose(patches[0, :, 0], img[uv[:, 1], uv[:, 0]])
    assert np.allclose(patches[0, 1, 2], img[16, 41])  # offset (0, -1)
    for lvl in (1, 2):
        pos = level_position(uv, lvl)
        assert np.allclose(patches[lvl, :, 0], bilinear(pyr[lvl], pos)[0], atol=1e-4)
    # Brightness normalisation: z = (I - b) / e^a
    pa = extract_patches(pyr, uv, ATS_PATTERN, affine=(np.log(2.0), 10.0))
    assert pa.shape == (3, 3, 14)
    assert np.allclose(pa[0, :, 0], (img[uv[:, 1], uv[:, 0]] - 10.0) / 2.0, atol=1e-4)


def _add(m: PointMap, n: int, T=None):
    p = np.column_stack([np.zeros(n), np.zeros(n), np.full(n, 2.0)])
    T = np.eye(4) if T is None else T
    return m.add_keyframe(len(m.keyframes), T, (0.0, 0.0), p, np.zeros((2, n, 9), np.float32), p[: n // 2])


def test_point_map_stores_world_points_and_hosts():
    m = PointMap(2, 9)
    T = se3_exp(np.array([1.0, 0.0, 0.0, 0.0, 0.3, 0.0]))
    kf = _add(m, 6, T)
    assert len(m) == 6 and len(m.geo_points_w) == 3 and np.all(m.host == kf.kf_id)
    assert np.allclose(m.points_w, transform_points(T, np.array([[0.0, 0.0, 2.0]])))
    assert np.allclose(m.geo_points_w, m.points_w[:3])
    with pytest.raises(TrackingError):
        m.add_keyframe(1, np.eye(4), (0, 0), np.ones((2, 3)), np.zeros((2, 3, 9), np.float32))
    with pytest.raises(TrackingError):
        m.add_keyframe(1, np.eye(4), (0, 0), -np.ones((1, 3)), np.zeros((2, 1, 9), np.float32))
    with pytest.raises(TrackingError):  # geometric points behind the camera
        m.add_keyframe(1, np.eye(4), (0, 0), np.ones((1, 3)), np.zeros((2, 1, 9), np.float32), -np.ones((1, 3)))


def test_culling_bounds_memory_over_many_keyframes():
    m = PointMap(2, 9)
    for _ in range(50):
        _add(m, 400)
        m.cull(max_keyframes=4, max_points=1000)
        assert len(m) <= 1000 and len(m.keyframes) <= 4 and len(m.geo_points_w) <= 4 * 200
        assert m.patches.shape[1] == len(m) == len(m.host) == len(m.host_depth)
    assert m.host.min() >= 47  # only the newest keyframes survive


def test_snapshots_are_immutable_copies():
    m = PointMap(2, 9)
    _add(m, 4)
    snap = m.snapshot(3, 4, 9)
    assert snap.snapshot_id == 3 and len(snap) == 4 and len(snap.keyframes) == 1
    with pytest.raises(ValueError):
        snap.points_w[0, 0] = 1.0
    _add(m, 4)
    assert len(snap) == 4 and len(m) == 8  # mapping goes on; the snapshot tracking holds does not change


def test_temporary_event_map_container():
    ev = TemporaryEventMap.empty(3, 14)
    assert len(ev) == 0 and ev.patches.shape == (3, 0, 14)


def test_retired_keyframes_come_back_with_their_points():
    m = PointMap(2, 9)
    kf0 = _add(m, 6, se3_exp(np.array([0.5, 0.0, 0.0, 0.0, 0.2, 0.0])))
    points, patches, geo = m.points_w.copy(), m.patches.copy(), m.geo_points_w.copy()
    for _ in range(3):
        _add(m, 4)
    m.cull(max_keyframes=2, max_points=1000, memory=1)  # kf 0 and 1 leave; only the newest of them is kept aside
    assert sorted(m.keyframes) == [2, 3] and list(m.retired) == [1]
    m.cull(max_keyframes=2, max_points=1000, order=[2, 3, 0, 1], memory=0)  # nothing to drop; the memory empties
    assert not m.retired
    m = PointMap(2, 9)
    kf0 = _add(m, 6, se3_exp(np.array([0.5, 0.0, 0.0, 0.0, 0.2, 0.0])))
    _add(m, 4)
    m.cull(max_keyframes=1, max_points=1000, memory=5)
    assert list(m.keyframes) == [1] and len(m) == 4 and len(m.geo_points_w) == 2
    m.restore(kf0.kf_id)
    mine = m.host == kf0.kf_id
    assert sorted(m.keyframes) == [0, 1] and not m.retired and len(m) == 10
    assert np.array_equal(m.points_w[mine], points) and np.array_equal(m.patches[:, mine], patches)
    assert np.array_equal(m.geo_points_w[m.geo_host == kf0.kf_id], geo) and m.keyframes[0] == kf0


def test_visible_shares_count_points_in_view_at_a_similar_distance():
    cam = CameraModel(320, 240, 200.0, 200.0, 159.5, 119.5)
    m = PointMap(2, 9)
    _add(m, 4)  # every point 2 m ahead of the origin
    for k in range(3):
        m.add_keyframe(1 + k, np.eye(4), (0.0, 0.0), np.array([[0.0, 0.0, 2.0], [5.0, 0.0, 2.0]]),
                       np.zeros((2, 2, 9), np.float32))  # one point in view, one far outside
    shares = m.visible_shares(np.eye(4), cam, max_scale_change=1.3)
    assert shares == {0: 1.0, 1: 0.5, 2: 0.5, 3: 0.5}
    back = np.eye(4)
    back[2, 3] = 1.0  # T_c_w of a camera 1 m behind the origin: the points are 1.5x further
    assert m.visible_shares(back, cam, max_scale_change=1.3)[0] == 0.0
    assert m.visible_shares(back, cam, max_scale_change=2.0)[0] == 1.0
    turned = se3_exp(np.array([0.0, 0.0, 0.0, 0.0, np.pi, 0.0]))  # looking the other way
    assert set(m.visible_shares(turned, cam, max_scale_change=1.3).values()) == {0.0}
