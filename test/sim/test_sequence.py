"""In-memory sequences: ordering, determinism, and the ground truth / extrinsics / intrinsics
being consistent with what is rendered (project known scene points and find them in the data)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import interpolate_trajectory, se3_inv
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.events import EventModel
from atsvo_ros.sim.rgbd import DepthModel
from atsvo_ros.sim.scene import build_scene
from atsvo_ros.sim.sequence import (
    GroundTruth,
    RgbdFrame,
    SequenceSpec,
    Simulation,
    iter_sequence,
    sequence_rig,
    with_sensors,
)

TINY = {"width": 64, "event_scale": 0.25, "texture_size": 32, "gt_rate_hz": 200.0}


def _collect(spec: SequenceSpec, scene=None, imu: list | None = None):
    frames, events, poses, order = [], [], [], []
    for item in iter_sequence(spec, scene):
        if isinstance(item, ImuBatch):
            assert len(item) == 1
            order.append(item.t_first_ns)
            if imu is not None:
                imu.append(item)
        elif isinstance(item, RgbdFrame):
            frames.append(item)
            order.append(item.stamp_ns)
        elif isinstance(item, GroundTruth):
            poses.append(item)
            order.append(item.stamp_ns)
        else:
            assert isinstance(item, EventBatch) and len(item) > 0
            events.append(item)
            order.append(int(item.t[0]))
    return frames, events, poses, order


def test_stream_is_time_ordered_with_expected_rates():
    spec = SequenceSpec(scenario="trot", duration_s=0.5, seed=1, **TINY)
    imu: list[ImuBatch] = []
    frames, events, poses, order = _collect(spec, imu=imu)
    assert len(frames) == 16 and len(poses) == 101
    # IMU samples at ~200 Hz (the gyro's clock is a few percent off), inside the sequence.
    imu_t = np.array([b.t_first_ns for b in imu])
    assert 90 <= len(imu) <= 106 and np.all(np.diff(imu_t) > 0)
    assert imu_t[0] >= spec.start_ns and imu_t[-1] <= spec.start_ns + 500_000_000
    assert np.all(np.diff(order) >= -1_000_000)  # event packets are keyed by their end (<= 1 ms)
    t = np.concatenate([b.t for b in events])
    assert np.all(np.diff(t) >= 0)
    assert t[0] >= spec.start_ns and t[-1] <= spec.start_ns + 500_000_000
    spans = np.array([b.t[-1] - b.t[0] for b in events])
    assert spans.max() < 1_000_000  # ~1 ms packets
    assert frames[0].rgb.shape == (48, 64, 3) and frames[0].rgb.dtype == np.uint8
    assert frames[0].depth_mm.shape == (48, 64) and frames[0].depth_mm.dtype == np.uint16
    assert events[0].width == 80 and events[0].height == 60


def test_sequences_are_deterministic_for_a_seed():
    spec = SequenceSpec(scenario="pronk", duration_s=0.3, seed=7, **TINY)
    imu_a: list[ImuBatch] = []
    imu_b: list[ImuBatch] = []
    a, b = _collect(spec, imu=imu_a), _collect(spec, imu=imu_b)
    assert len(imu_a) > 50
    np.testing.assert_array_equal(ImuBatch.concatenate(imu_a).accel_m_s2, ImuBatch.concatenate(imu_b).accel_m_s2)
    for fa, fb in zip(a[0], b[0]):
        np.testing.assert_array_equal(fa.rgb, fb.rgb)
        np.testing.assert_array_equal(fa.depth_mm, fb.depth_mm)
    np.testing.assert_array_equal(np.concatenate([e.t for e in a[1]]), np.concatenate([e.t for e in b[1]]))
    np.testing.assert_array_equal(np.concatenate([e.x for e in a[1]]), np.concatenate([e.x for e in b[1]]))
    c = _collect(dataclasses.replace(spec, seed=8))
    assert not np.array_equal(a[0][0].rgb, c[0][0].rgb)


def _marker_scene():
    """Uniform grey room lit by ambient light only, with dark boxes: edges are the only contrast."""
    grey = np.full((16, 16), 0.6, np.float32)
    dark = np.full((16, 16), 0.12, np.float32)
    boxes = [((1.0, 1.2, 0.4), (0.3, 0.3, 0.4), 0.2), ((7.0, 1.0, 0.5), (0.4, 0.3, 0.5), -0.3),
             ((4.0, 0.6, 0.3), (0.5, 0.25, 0.3), 0.0), ((1.0, 5.0, 0.35), (0.3, 0.4, 0.35), 0.5),
             ((7.2, 5.2, 0.6), (0.3, 0.3, 0.6), 0.1), ((4.2, 5.5, 0.25), (0.6, 0.2, 0.25), 0.0),
             ((0.5, 3.0, 0.5), (0.25, 0.5, 0.5), 0.0), ((7.6, 3.2, 0.45), (0.2, 0.5, 0.45), 0.0)]
    face_tex = [0] * 6 + [1] * (6 * len(boxes))
    return build_scene((0, 0, 0), (8, 6.2, 2.8), boxes, [grey, dark], face_tex, ambient=1.0,
                       free_xy=(2.2, 5.8, 2.0, 4.2))


def _edge_points(scene, n: int = 60) -> np.ndarray:
    pts = []
    s = np.linspace(0.0, 1.0, n)[:, None]
    for c, h, yaw in zip(scene.box_center, scene.box_half, scene.box_yaw):
        cs, sn = np.cos(yaw), np.sin(yaw)
        R = np.array([[cs, -sn, 0], [sn, cs, 0], [0, 0, 1]])
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        for i in range(8):
            for j in range(i + 1, 8):
                if np.count_nonzero(corners[i] != corners[j]) == 1:
                    seg = corners[i] + s * (corners[j] - corners[i])
                    pts.append(seg @ R.T + c)
    return np.concatenate(pts)


def _face_points(scene) -> np.ndarray:
    """A 3x3 grid of points well inside every box face (world frame)."""
    pts = []
    g = np.array([-0.5, 0.0, 0.5])
    for c, h, yaw in zip(scene.box_center, scene.box_half, scene.box_yaw):
        cs, sn = np.cos(yaw), np.sin(yaw)
        R = np.array([[cs, -sn, 0], [sn, cs, 0], [0, 0, 1]])
        for axis in range(3):
            a, b = [k for k in range(3) if k != axis]
            for side in (-1.0, 1.0):
                for u in g:
                    for v in g:
                        q = np.zeros(3)
                        q[axis], q[a], q[b] = side * h[axis], u * h[a], v * h[b]
                        pts.append(R @ q + c)
    return np.array(pts)


def _event_edge_fraction(events, poses, rig, T_rgb_event, edge_w, tol_px: float) -> float:
    stamps = np.array([g.stamp_ns for g in poses])
    T_wb = np.array([g.T_world_base for g in poses])
    cam = rig.event_camera
    near = total = 0
    for b in events:
        t_mid = int(b.t[len(b) // 2])
        T, _ = interpolate_trajectory(stamps, T_wb, np.array([t_mid]))
        T_w_ev = T[0] @ rig.T_base_rgb @ T_rgb_event
        p_c = (edge_w - T_w_ev[:3, 3]) @ T_w_ev[:3, :3]
        uv, ok = cam.project(p_c[p_c[:, 2] > 0.05])
        ev = np.column_stack([b.x, b.y]).astype(float)
        d = np.abs(ev[:, None, :] - uv[None, :, :]).max(axis=2).min(axis=1)
        near += int(np.count_nonzero(d <= tol_px))
        total += len(b)
    return near / max(total, 1)


def test_ground_truth_extrinsics_and_intrinsics_put_scene_points_where_they_are_rendered():
    scene = _marker_scene()
    # sharp depth: the check is of the rig's geometry (the D455 model's timing and matching errors are scored
    # against the truth in test_stereo.py)
    spec = SequenceSpec(scenario="flying", duration_s=0.4, seed=3, width=160, event_scale=0.5, texture_size=16,
                        event_model=EventModel(noise_rate_hz=0.0),
                        depth_model=DepthModel(dropout_fraction=0.0), depth="sharp")
    rig = sequence_rig(spec)
    frames, events, poses, _ = _collect(spec, scene)
    edge_w = _edge_points(scene)
    # Events: every event lies on a box edge projected with GT pose, T_base_rgb, T_rgb_event and the
    # event camera's distorted intrinsics (camera_info) - and a wrong extrinsic breaks that.
    n_events = sum(len(b) for b in events)
    assert n_events > 500
    good = _event_edge_fraction(events, poses, rig, rig.T_rgb_event, edge_w, 1.5)
    assert good > 0.97
    bad = _event_edge_fraction(events, poses, rig, np.eye(4), edge_w, 1.5)
    assert bad < good - 0.15
    # Depth: points on box faces projected into the colour camera read back their own depth.
    good = _depth_agreement(frames, poses, rig, rig.T_base_rgb, _face_points(scene))
    assert good["in_view"] > 50
    assert good["matched"] > 0.3 * good["in_view"]  # the rest lie on back faces or behind other boxes
    assert good["seen_through"] == 0  # never a surface behind a point that should be in front
    shifted = rig.T_base_rgb.copy()
    shifted[:3, 3] += [0.0, 0.0, 0.05]
    bad = _depth_agreement(frames, poses, rig, shifted, _face_points(scene))
    assert bad["matched"] < 0.7 * good["matched"] or bad["seen_through"] > 5


def _depth_agreement(frames, poses, rig, T_base_rgb, pts) -> dict[str, int]:
    stamps = np.array([g.stamp_ns for g in poses])
    T_wb = np.array([g.T_world_base for g in poses])
    out = {"matched": 0, "seen_through": 0, "in_view": 0}
    for f in frames:
        T, _ = interpolate_trajectory(stamps, T_wb, np.array([f.stamp_ns]))
        T_c_w = se3_inv(T[0] @ T_base_rgb)
        p_c = pts @ T_c_w[:3, :3].T + T_c_w[:3, 3]
        uv, front = rig.rgb_camera.project(p_c)
        inside = front & rig.rgb_camera.in_image(uv, 1.0)
        iu = np.round(uv[inside]).astype(int)
        z_meas = f.depth_mm[iu[:, 1], iu[:, 0]] * 1e-3
        z_true = p_c[inside, 2]
        valid = z_meas > 0
        tol = 0.004 + 4 * 0.002 * z_true**2 + 0.03 * z_true  # noise + half a pixel of slope on a face
        out["in_view"] += int(valid.sum())
        out["matched"] += int(np.count_nonzero(valid & (np.abs(z_meas - z_true) < tol)))
        out["seen_through"] += int(np.count_nonzero(valid & (z_meas > z_true + tol)))
    return out


def test_rig_follows_config_and_size_overrides():
    rig = sequence_rig(SequenceSpec(width=320))
    assert (rig.rgb_camera.width, rig.rgb_camera.height) == (320, 240)
    assert rig.rgb_camera.fx == pytest.approx(382.0 / 2)
    assert rig.rgb_camera.cx == pytest.approx((319.5 + 0.5) / 2 - 0.5)
    assert rig.event_camera.width == 320 and rig.event_camera.distortion_model == "plumb_bob"
    mv = sequence_rig(SequenceSpec(layout="mvsec"))
    assert mv.rgb_camera.distortion_model == "equidistant" and mv.depth_camera == mv.rgb_camera  # depth_image_raw
    np.testing.assert_allclose(mv.T_base_rgb, np.eye(4))


def test_mvsec_ground_truth_is_the_camera_pose():
    spec = SequenceSpec(scenario="flying", duration_s=0.2, seed=0, layout="mvsec", **TINY)
    robot = dataclasses.replace(spec, layout="robot")
    _, _, p_mv, _ = _collect(spec)
    _, _, p_rb, _ = _collect(robot)
    rig_rb = sequence_rig(robot)
    # Same body motion: the MVSEC "base" is the colour camera of the robot rig.
    for a, b in zip(p_mv[::10], p_rb[::10]):
        np.testing.assert_allclose(a.T_world_base, b.T_world_base @ rig_rb.T_base_rgb, atol=1e-9)


def test_invalid_specs_raise():
    with pytest.raises(SimulationError, match="scenario"):
        SequenceSpec(scenario="walk")
    with pytest.raises(SimulationError, match="layout"):
        SequenceSpec(layout="tum")
    with pytest.raises(SimulationError, match="exposure"):
        SequenceSpec(exposure_s=0.05)


def test_event_renders_never_let_the_scene_move_more_than_half_a_pixel():
    """Check the adaptive render rate independently: dense flow of every pixel between renders."""
    spec = SequenceSpec(scenario="backflip", duration_s=2.2, seed=0, event_scale=0.2, texture_size=16)
    from atsvo_ros.sim.render import Renderer
    from atsvo_ros.sim.sequence import Simulation

    sim = Simulation(spec)
    stats = {"log_render_stamps": True}
    for _ in sim.events(stats):
        pass
    stamps = np.array(stats["event_render_stamps"])
    assert len(stamps) == stats["event_renders"] and np.all(np.diff(stamps) > 0)
    assert stamps[-1] == sim.t_end_ns
    assert np.diff(stamps).max() <= spec.event_model.max_render_interval_s * 1e9
    cam = sim.rig.event_camera
    r = Renderer(sim.scene, cam)
    u, v = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
    uv = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    poses = sim.T_world_event(stamps)
    worst = []
    for k in range(0, len(stamps) - 1, 3):
        _, depth = r.render(poses[k])
        p0 = r.rays * depth.reshape(-1, 1)
        T = se3_inv(poses[k + 1]) @ poses[k]
        uv1, ok = cam.project(p0 @ T[:3, :3].T + T[:3, 3])
        worst.append(np.abs(uv1 - uv).max(axis=1).max())
    worst = np.array(worst)
    assert np.percentile(worst, 99) <= spec.event_model.max_step_px * 1.1
    assert worst.max() <= spec.event_model.max_step_px * 1.5
    # ... and the rate really adapts: renders are dense during the flip, sparse when standing.
    gaps = np.diff(stamps)
    assert np.percentile(gaps, 95) > 10 * np.percentile(gaps, 5)


def test_host_stamp_jitter_and_latency_delay_the_stamps_not_the_images():
    """``RgbModel.stamp_jitter_s`` / ``stamp_latency_s``: the images stay on the frame clock, the stamps come
    later by half-normal delays plus the latency (the draws the tracking benchmark applies to cached frames
    with ``--stamp-jitter`` / ``--stamp-latency``)."""
    from atsvo_ros.sim.sequence import make_simulation

    spec = SequenceSpec(scenario="trot", duration_s=0.5, seed=2, **TINY)
    jittered = dataclasses.replace(spec, rgb_model=dataclasses.replace(spec.rgb_model, stamp_jitter_s=0.002))
    clean, late = list(make_simulation(spec).frames()), list(make_simulation(jittered).frames())
    delays = np.array([b.stamp_ns - a.stamp_ns for a, b in zip(clean, late)])
    assert len(delays) == 16 and np.all(delays >= 0) and 0.3e6 < delays.std() < 3e6
    np.testing.assert_array_equal(delays, make_simulation(spec).stamp_delays_ns(16, 0.002))
    for a, b in zip(clean, late):
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth_mm, b.depth_mm)
    with pytest.raises(SimulationError):
        dataclasses.replace(spec.rgb_model, stamp_jitter_s=0.02)
    latent = dataclasses.replace(jittered, rgb_model=dataclasses.replace(jittered.rgb_model, stamp_latency_s=0.01))
    np.testing.assert_array_equal(make_simulation(latent).stamp_delays_ns(16), delays + 10_000_000)
    np.testing.assert_array_equal(make_simulation(spec).stamp_delays_ns(4, 0.0, 0.01), np.full(4, 10_000_000))
    with pytest.raises(SimulationError):
        dataclasses.replace(spec.rgb_model, stamp_latency_s=-0.01)


def test_the_robot_layout_gets_the_d455_depth_and_mvsec_the_sharp_one():
    assert SequenceSpec().depth_sensor == "d455" and SequenceSpec(layout="mvsec").depth_sensor == "sharp"
    stats: dict = {}
    spec = SequenceSpec(scenario="bound", duration_s=0.3, seed=4, **TINY)
    frames = [f for f in iter_sequence(spec, stats=stats) if isinstance(f, RgbdFrame)]
    sim = Simulation(spec)
    assert abs(stats["depth_phase_s"]) <= 0.5 / spec.rate_hz and stats["depth_phase_s"] == sim.depth_phase_s
    reports = stats["frames"]
    assert [r.stamp_ns for r in reports] == [f.stamp_ns for f in frames]
    for r, f in zip(reports, frames):
        assert r.depth_valid == pytest.approx(np.mean(f.depth_mm > 0)) and 0.0 < r.ir_exposure_s <= 0.033
    with pytest.raises(SimulationError, match="depth model"):
        SequenceSpec(depth="kinect")
    with pytest.raises(SimulationError, match="robot layout"):
        SequenceSpec(layout="mvsec", depth="d455")


def test_with_sensors_sets_the_harder_settings_and_keeps_the_rest():
    """The settings a harder held-out run changes (exposure, contrast, noise, the room's IR light), each checked
    by its model; None keeps the spec's."""
    spec = SequenceSpec(scenario="bound", duration_s=1.0, seed=4)
    assert with_sensors(spec) == spec
    hard = with_sensors(spec, exposure_s=0.015, contrast=0.3, noise_rate_hz=1.0, ambient_ir=0.1)
    assert (hard.exposure_s, hard.event_model.contrast_pos, hard.event_model.contrast_neg) == (0.015, 0.3, 0.3)
    assert hard.event_model.noise_rate_hz == 1.0 and hard.stereo_model.ambient_ir == 0.1
    assert dataclasses.replace(hard, exposure_s=spec.exposure_s, event_model=spec.event_model,
                               stereo_model=spec.stereo_model) == spec
    with pytest.raises(SimulationError):
        with_sensors(spec, exposure_s=0.05)  # longer than a 30 Hz frame period
    with pytest.raises(SimulationError):
        with_sensors(spec, contrast=float("nan"))
