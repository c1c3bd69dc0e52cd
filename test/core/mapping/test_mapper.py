"""Mapping: keyframe requests in, snapshots out; culling of repeated outliers and of old keyframes."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.geometry import se3_exp, se3_inv
from atsvo_ros.core.image.frontend import RgbdFrontEnd
from atsvo_ros.core.mapping.mapper import KeyframeRequest, Mapper
from test.core.render_helpers import BoxRoom

CAM = CameraModel(320, 240, 191.0, 191.0, 159.5, 119.5)


def _prepared(room, T_w_c, stamp):
    cfg = load_config("synthetic")
    fe = RgbdFrontEnd(CAM, 4, cfg.rig.depth_min_m, cfg.rig.depth_max_m, cfg.mapping.depth_edge_ratio)
    img, depth = room.render(CAM, T_w_c, 1)
    return fe, fe.prepare(RgbdFrame(stamp, img, depth))


def _first_keyframe(cfg):
    """A mapper with a new map from a frame at the origin of a box room: ``(room, frame, mapper, snapshot)``."""
    room = BoxRoom(seed=1)
    fe, f0 = _prepared(room, np.eye(4), 0)
    mapper = Mapper(cfg, fe.cameras)
    s0 = mapper.insert(KeyframeRequest(-1, f0, np.eye(4), (0.0, 0.0), np.zeros((0, 2)), np.zeros(0, np.int32),
                                       reset=True))
    return room, f0, mapper, s0


def test_requests_become_snapshots_and_outliers_are_culled():
    cfg = load_config("synthetic", overrides={"mapping.max_outlier_frames": 3, "mapping.max_keyframes": 2})
    room = BoxRoom(seed=1)
    fe, f0 = _prepared(room, np.eye(4), 0)
    mapper = Mapper(cfg, fe.cameras)
    s0 = mapper.insert(KeyframeRequest(-1, f0, np.eye(4), (0.0, 0.0), np.zeros((0, 2)), np.zeros(0, np.int32),
                                       reset=True))
    assert s0.snapshot_id == 1 and len(s0) > 300 and len(s0.geo_points_w) > 300 and len(s0.keyframes) == 1
    # Tracking reports three points as outliers for 3 frames: the next keyframe removes them.
    runs = np.zeros(len(s0), np.int32)
    runs[:3] = 3
    _, f1 = _prepared(room, se3_exp(np.array([0.02, 0, 0, 0, 0.01, 0])), 33_000_000)
    s1 = mapper.insert(KeyframeRequest(s0.snapshot_id, f1, np.eye(4), (0.0, 0.0), np.zeros((0, 2)), runs))
    assert s1.snapshot_id == 2 and len(s1.keyframes) == 2
    kf0 = s0.keyframes[0].kf_id
    assert np.count_nonzero(s1.host == kf0) == len(s0) - 3
    # Outlier runs of another snapshot are ignored (they index other points); the window drops keyframe 0.
    s2 = mapper.insert(KeyframeRequest(s0.snapshot_id, f1, np.eye(4), (0.0, 0.0), np.zeros((0, 2)),
                                       np.full(len(s1), 9, np.int32)))
    assert len(s2.keyframes) == 2 and kf0 not in s2.host and len(s2) > 300
    assert len(s0) == len(s0.points_w)  # old snapshots are untouched


def test_no_new_points_still_renews_the_reference_health():
    cfg = load_config("synthetic")
    room, f0, mapper, s0 = _first_keyframe(cfg)
    # Every candidate cell already covered by a tracked point: nothing to add, yet a fresh reference.
    h, w = f0.grey.shape
    ys, xs = np.mgrid[0:h:2, 0:w:2]
    tracked = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    s1 = mapper.insert(KeyframeRequest(s0.snapshot_id, f0, np.eye(4), (0.0, 0.0), tracked, np.zeros(len(s0), np.int32)))
    assert len(s1) == len(s0) and mapper.n_keyframes == 1
    assert s1.snapshot_id == s0.snapshot_id + 1 and s1.n_reference == len(tracked)


def test_a_geometry_only_keyframe_adds_depth_points_and_no_patches():
    cfg = load_config("synthetic")
    room, f0, mapper, s0 = _first_keyframe(cfg)
    T_w_c1 = se3_exp(np.array([0.05, 0, 0, 0, 0.2, 0]))  # turned 11 deg: new depth in view
    _, f1 = _prepared(room, T_w_c1, 33_000_000)
    s1 = mapper.insert(KeyframeRequest(s0.snapshot_id, f1, np.linalg.inv(T_w_c1), (0.0, 0.0), np.zeros((0, 2)),
                                       np.zeros(len(s0), np.int32), geometry_only=True))
    assert len(s1) == len(s0) and len(s1.keyframes) == 2  # no photometric point from a frame that did not hold
    assert len(s1.geo_points_w) - len(s0.geo_points_w) > 0.5 * cfg.mapping.depth_points


def _look_around_and_back(culling: str):
    """Keyframes looking round the box room (0, 90, 180, 270 deg of yaw) and then back at its first wall."""
    cfg = load_config("synthetic", overrides={"mapping.max_keyframes": 2, "mapping.recent_keyframes": 1,
                                              "mapping.keyframe_culling": culling})
    room, f0, mapper, snap = _first_keyframe(cfg)
    for k, yaw in enumerate((np.pi / 2, np.pi, 1.5 * np.pi, 2 * np.pi - 0.05), start=1):
        T_w_c = se3_exp(np.array([0.0, 0.0, 0.0, 0.0, yaw, 0.0]))
        _, f = _prepared(room, T_w_c, k * 33_000_000)
        snap = mapper.insert(KeyframeRequest(snap.snapshot_id, f, se3_inv(T_w_c), (0.0, 0.0), np.zeros((0, 2)),
                                             np.zeros(len(snap), np.int32)))
    return snap


def test_a_camera_back_over_mapped_ground_gets_the_keyframe_that_mapped_it():
    """``mapping.keyframe_culling`` covisible: the first keyframe, retired while the camera looked round the room,
    is back in the local map once the camera faces its wall again (the newest keyframe,
    ``mapping.recent_keyframes``, stays); with ``oldest`` the map holds only the two newest."""
    snap = _look_around_and_back("covisible")
    assert [kf.kf_id for kf in snap.keyframes] == [0, 4] and np.count_nonzero(snap.host == 0) > 300
    assert [kf.kf_id for kf in _look_around_and_back("oldest").keyframes] == [3, 4]


def _lost_and_back(keep_memory: bool):
    """The first keyframe faces a wall; the camera turns away and loses the map (a new map from a frame facing the
    opposite wall), then turns back: the keyframe after the turn back, and the map it leaves."""
    cfg = load_config("synthetic", overrides={"mapping.max_keyframes": 2, "mapping.recent_keyframes": 1})
    room, _, mapper, _ = _first_keyframe(cfg)
    T_away = se3_exp(np.array([0.0, 0.0, 0.0, 0.0, np.pi, 0.0]))
    _, f1 = _prepared(room, T_away, 33_000_000)
    snap = mapper.insert(KeyframeRequest(-1, f1, se3_inv(T_away), (0.0, 0.0), np.zeros((0, 2)),
                                         np.zeros(0, np.int32), reset=True, keep_memory=keep_memory))
    T_back = se3_exp(np.array([0.0, 0.0, 0.0, 0.0, 0.05, 0.0]))
    _, f2 = _prepared(room, T_back, 66_000_000)
    return mapper.insert(KeyframeRequest(snap.snapshot_id, f2, se3_inv(T_back), (0.0, 0.0), np.zeros((0, 2)),
                                         np.zeros(len(snap), np.int32)))


def test_a_reinitialisation_keeps_the_old_map_aside_and_takes_it_back():
    """After a loss the world goes on (the new map starts at the predicted pose): the old map's keyframes are kept
    aside and the first keyframe comes back once the camera faces its wall again. A first map or its rebuild
    (``keep_memory`` false) forgets them."""
    kept = _lost_and_back(True)
    assert [kf.stamp_ns for kf in kept.keyframes] == [0, 66_000_000]
    assert np.count_nonzero(kept.host == kept.keyframes[0].kf_id) > 300
    assert [kf.stamp_ns for kf in _lost_and_back(False).keyframes] == [33_000_000, 66_000_000]
