"""The odometry facade: frames, extrinsics, distortion, loss and re-initialisation, outputs."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import se3_exp, se3_inv, se3_log
from atsvo_ros.core.mapping.refine import WindowReport
from atsvo_ros.core.odometry.odometry import Odometry, OdometryResult, RgbdFrame, TrackingStatus
from atsvo_ros.errors import ImageError
from test.core.render_helpers import BoxRoom

CAM = CameraModel(640, 480, 382.0, 382.0, 319.5, 239.5)
MS = 1_000_000


@pytest.fixture(scope="module")
def room() -> BoxRoom:
    return BoxRoom(seed=7)


@pytest.fixture(scope="module")
def config():
    return load_config("synthetic")  # non-trivial T_base_rgb


def _frame(room, cam, T_w_c, stamp_ns, ss=3):
    img, depth = room.render(cam, T_w_c, supersample=ss)
    rgb = np.repeat(np.clip(img + 0.5, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
    return RgbdFrame(stamp_ns, rgb, depth)


def _err(T_est, T_gt):
    e = se3_log(se3_inv(T_gt) @ T_est)
    return np.linalg.norm(e[:3]), np.degrees(np.linalg.norm(e[3:]))


def test_first_frame_defines_odom_and_offsets_come_out_in_base_frame(room, config):
    odo = Odometry(config, CAM)
    assert odo.events is None  # no event camera given: RGB-D only
    T_b_c = config.rig.T_base_rgb_matrix()
    r0 = odo.process_frame(_frame(room, CAM, np.eye(4), 0))
    assert isinstance(r0, OdometryResult)
    assert r0.status is TrackingStatus.INITIALISING and r0.keyframe_inserted and r0.n_points > 500
    assert np.allclose(r0.T_odom_base, np.eye(4)) and np.allclose(r0.T_odom_camera, T_b_c)
    T_c0_c1 = se3_exp(np.array([0.02, -0.01, 0.03, 0.01, -0.015, 0.008]))
    r1 = odo.process_frame(_frame(room, CAM, T_c0_c1, 33 * MS))
    assert r1.status is TrackingStatus.OK and r1.mode == "rgbd"
    gt = T_b_c @ T_c0_c1 @ se3_inv(T_b_c)
    dt, dr = _err(r1.T_odom_base, gt)
    assert dt < 3e-3 and dr < 0.05, (dt, dr)  # measured 1.2 mm, 0.018 deg
    assert np.allclose(r1.T_odom_camera, r1.T_odom_base @ T_b_c)
    cov = r1.covariance
    assert cov.shape == (6, 6) and np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
    assert np.all(np.sqrt(np.diag(cov))[:3] < 0.01)
    assert r1.n_inliers > 0.5 * r1.n_points and r1.tracking_time_s > 0


def test_covariance_is_expressed_in_the_base_frame(room, config):
    """The camera looks along base x: depth (camera z) is the best-constrained translation."""
    odo = Odometry(config, CAM)
    odo.process_frame(_frame(room, CAM, np.eye(4), 0, ss=1))
    r = odo.process_frame(_frame(room, CAM, se3_exp(np.array([0.01, 0, 0, 0, 0, 0])), 33 * MS, ss=1))
    sd = np.sqrt(np.diag(r.covariance))
    assert sd[0] < sd[1] and sd[0] < sd[2]  # base x = camera z


def test_distorted_camera_is_rectified(room, config):
    raw = CameraModel(640, 480, 300.0, 300.0, 322.0, 236.0, "equidistant", (-0.02, 0.01, -0.004, 0.0005))
    odo = Odometry(config, raw)
    odo.process_frame(_frame(room, raw, np.eye(4), 0))
    T_c0_c1 = se3_exp(np.array([-0.02, 0.01, 0.02, 0.0, 0.01, -0.01]))
    r = odo.process_frame(_frame(room, raw, T_c0_c1, 33 * MS))
    T_b_c = config.rig.T_base_rgb_matrix()
    dt, dr = _err(r.T_odom_base, T_b_c @ T_c0_c1 @ se3_inv(T_b_c))
    assert r.status is TrackingStatus.OK and dt < 2e-3 and dr < 0.1, (dt, dr)


def test_depth_already_on_the_rectified_grid(room, config):
    """Depth already on the pinhole grid of the colour camera (depth_rectified=True), colour raw."""
    raw = CameraModel(640, 480, 300.0, 300.0, 322.0, 236.0, "equidistant", (-0.02, 0.01, -0.004, 0.0005))
    odo = Odometry(config, raw)
    T_c0_c1 = se3_exp(np.array([0.01, 0.02, -0.01, 0.01, 0.0, 0.005]))
    for k, T in enumerate([np.eye(4), T_c0_c1]):
        rgb = _frame(room, raw, T, 0).rgb
        depth = room.render_depth(raw.pinhole(), T)
        r = odo.process_frame(RgbdFrame(k * 33 * MS, rgb, depth, depth_rectified=True))
    T_b_c = config.rig.T_base_rgb_matrix()
    dt, dr = _err(r.T_odom_base, T_b_c @ T_c0_c1 @ se3_inv(T_b_c))
    assert r.status is TrackingStatus.OK and dt < 2e-3 and dr < 0.1, (dt, dr)


def test_a_blank_frame_is_lost_and_the_map_kept_for_the_next(room, config):
    odo = Odometry(config, CAM)
    step = se3_exp(np.array([0.0, 0.0, 0.01, 0.0, 0.0, 0.0]))
    poses = [np.linalg.matrix_power(step, k) for k in range(3)]
    res = [odo.process_frame(_frame(room, CAM, T, k * 33 * MS, ss=1)) for k, T in enumerate(poses)]
    assert res[-1].status is TrackingStatus.OK
    # A frame without texture and without depth: nothing to track, nothing to map.
    blank = RgbdFrame(3 * 33 * MS, np.full((480, 640, 3), 90, np.uint8), np.zeros((480, 640), np.float32))
    lost = odo.process_frame(blank)
    assert lost.status is TrackingStatus.LOST and np.all(np.isfinite(lost.T_odom_base))
    # Published pose keeps moving with the motion model, never back to the origin.
    assert np.linalg.norm(lost.T_odom_base[:3, 3] - res[-1].T_odom_base[:3, 3]) < 0.02
    assert np.linalg.norm(lost.T_odom_base[:3, 3]) > 0.015
    assert "cannot anchor a map" in lost.reason and "no valid depth" in lost.reason
    # The blank frame could not anchor a new map, so the old one is still there: the next frame is
    # tracked against it, at the right pose (no re-initialisation, no offset).
    back = odo.process_frame(_frame(room, CAM, np.linalg.matrix_power(step, 4), 4 * 33 * MS, ss=1))
    assert back.status is TrackingStatus.OK and np.all(np.isfinite(back.covariance))
    T_b_c = config.rig.T_base_rgb_matrix()
    dt, dr = _err(back.T_odom_base, T_b_c @ np.linalg.matrix_power(step, 4) @ se3_inv(T_b_c))
    assert dt < 8e-3 and dr < 0.15, (dt, dr)  # measured 3.1 mm, 0.04 deg (aliased ss=1 renders)


def _second_frame_loss(room, overrides, second):
    """Track a keyframe at the origin, then ``second(T_w_c1)``'s frame; return (result, odometry)."""
    odo = Odometry(load_config("synthetic"), CAM)
    odo.process_frame(_frame(room, CAM, np.eye(4), 0, ss=1))
    # the rule under test judges tracking only: a frame still anchors a new map under the defaults
    odo.tracking.config = load_config("synthetic", overrides=overrides)
    T_w_c1 = se3_exp(np.array([0.01, 0.0, 0.01, 0.0, 0.005, 0.0]))
    return odo.process_frame(second(T_w_c1)), odo


@pytest.mark.parametrize("case, overrides, reason", [
    ("other_scene", {}, "inliers"),
    ("degenerate", {"tracker.max_position_std_m": 1e-7}, "degenerate geometry"),
    ("darker", {}, "brightness gain jumped"),
    ("jump", {"tracker.max_step_m": 0.004}, "jump of"),
])
def test_each_loss_rule_fires_on_its_own(room, case, overrides, reason):
    """Inliers, degenerate geometry, gain jump, step jump: each rule alone makes a frame lost (then re-initialised)."""
    def second(T):
        fr = _frame(room, CAM, T, 33 * MS, ss=1)
        if case == "other_scene":  # same geometry, pixel noise instead of the texture: nothing matches
            noise = np.random.default_rng(0).integers(0, 256, fr.rgb.shape[:2], dtype=np.uint8)
            return RgbdFrame(fr.stamp_ns, np.repeat(noise[..., None], 3, axis=2), fr.depth_m)
        if case == "darker":  # auto-exposure cannot change the gain by 3x in one frame
            return RgbdFrame(fr.stamp_ns, (fr.rgb * 0.33).astype(np.uint8), fr.depth_m)
        return fr

    res, odo = _second_frame_loss(room, overrides, second)
    assert odo.last_loss_reason is not None and reason in odo.last_loss_reason, odo.last_loss_reason
    assert res.status is TrackingStatus.REINITIALISED and res.keyframe_inserted
    # the published pose is the motion-model prediction (the first frame's, here): no jump, no NaN
    assert np.allclose(res.T_odom_base, np.eye(4)) and np.all(res.covariance == np.eye(6) * 1e3)


def test_no_loss_rule_fires_on_a_good_frame(room):
    res, odo = _second_frame_loss(room, {}, lambda T: _frame(room, CAM, T, 33 * MS, ss=1))
    assert res.status is TrackingStatus.OK and odo.last_loss_reason is None


def test_initialising_until_depth_arrives(room, config):
    odo = Odometry(config, CAM)
    img, depth = room.render(CAM, np.eye(4), supersample=1)
    none = np.full_like(depth, np.nan)
    for k in range(2):
        r = odo.process_frame(RgbdFrame(k * 33 * MS, img, none))
        assert r.status is TrackingStatus.INITIALISING and r.n_points == 0 and np.allclose(r.T_odom_base, np.eye(4))
    r = odo.process_frame(RgbdFrame(2 * 33 * MS, img, depth))
    assert r.status is TrackingStatus.INITIALISING and r.keyframe_inserted
    assert odo.process_frame(RgbdFrame(3 * 33 * MS, img, depth)).status is TrackingStatus.OK


@pytest.mark.parametrize("rgb", [
    np.zeros((240, 320, 3), np.uint8),  # wrong size
    np.zeros((480, 640, 3), np.float64), np.zeros((480, 640, 3), np.int64), np.zeros((480, 640, 3), bool),
    np.zeros((480, 640, 3), np.uint16),  # 16-bit colour: not silently accepted
    np.zeros((0, 0, 3), np.uint8), np.zeros((480, 640, 4), np.uint8), np.zeros((480, 640), np.int32),
    np.full((480, 640), np.nan, np.float32),
])
def test_bad_colour_images_raise_image_errors_not_opencv_errors(config, rgb):
    odo = Odometry(config, CAM)
    with pytest.raises(ImageError):
        odo.process_frame(RgbdFrame(0, rgb, np.zeros((480, 640), np.float32)))


def test_bad_depth_images_raise_image_errors(config):
    odo = Odometry(config, CAM)
    with pytest.raises(ImageError):  # not aligned to colour
        odo.process_frame(RgbdFrame(0, np.zeros((480, 640), np.uint8), np.zeros((240, 320), np.float32)))
    with pytest.raises(ImageError):  # raw millimetres, not metres
        odo.process_frame(RgbdFrame(0, np.zeros((480, 640), np.uint8), np.zeros((480, 640), np.uint16)))


def test_clock_jumps_reset_the_motion_model_instead_of_stopping(room, config):
    """A future-stamped frame (1 s, 3600 s, 1.033 s, ...) must not stop the odometry for good."""
    odo = Odometry(config, CAM)
    step = se3_exp(np.array([0.0, 0.0, 0.005, 0.0, 0.0, 0.0]))
    stamps_s = [1.0, 3600.0, 1.033, 1.066, 1.066, 1.1]
    results = [odo.process_frame(_frame(room, CAM, np.linalg.matrix_power(step, k), int(t * 1e9), ss=1))
               for k, t in enumerate(stamps_s)]
    assert [r.status for r in results[1:]] == [TrackingStatus.OK] * 5
    assert "s since the previous frame" in results[1].reason
    assert "clock jumped back" in results[2].reason and "clock jumped back" in results[4].reason
    assert results[3].reason is None and results[5].reason is None
    T_b_c = config.rig.T_base_rgb_matrix()
    dt, dr = _err(results[-1].T_odom_base, T_b_c @ np.linalg.matrix_power(step, 5) @ se3_inv(T_b_c))
    assert dt < 6e-3 and dr < 0.1, (dt, dr)  # still tracking the scene (measured 2.6 mm, 0.02 deg)


def test_events_feed_the_surface_and_their_buffer_stays_bounded(config):
    ev_cam = CameraModel.from_config(config.event_camera)
    odo = Odometry(config, CAM, event_camera=ev_cam)
    for k in range(30):
        t = np.arange(100, dtype=np.int64) * 1000 + k * 100_000_000
        odo.add_events(EventBatch(np.full(100, 10), np.full(100, 20), t, np.ones(100)))
    odo.add_events(EventBatch.empty())
    assert odo.events.surface.n_events == 3000 and odo.events.surface.active_mask()[20, 10]
    assert sum(len(b) for b in odo.events._recent) <= 3 * 100  # only the selection window and a margin
    rgbd_only = Odometry(load_config("synthetic", overrides={"mode": "rgbd"}), CAM, event_camera=ev_cam)
    rgbd_only.add_events(EventBatch(np.zeros(3), np.zeros(3), np.arange(3), np.ones(3)))
    assert rgbd_only.events is None


def _track_trot(depth: str) -> tuple[np.ndarray, list, object]:
    from atsvo_ros.sim.sequence import SequenceSpec, make_simulation

    sim = make_simulation(SequenceSpec(scenario="trot", duration_s=3.0, seed=4, width=320, height=240, depth=depth))
    odo = Odometry(load_config("synthetic"), sim.rig.rgb_camera)
    results = [odo.process_frame(RgbdFrame(f.stamp_ns, f.rgb, f.depth_m)) for f in sim.frames()]
    stamps = np.array([r.stamp_ns for r in results], dtype=np.int64)
    assert results[0].status is TrackingStatus.INITIALISING
    assert all(r.status is TrackingStatus.OK for r in results[1:])
    # The odom frame is the base at the first frame: no alignment needed to compare.
    gt_odom = se3_inv(sim.T_world_base(stamps[0])) @ sim.T_world_base(stamps)
    err = np.linalg.norm(np.stack([r.T_odom_base for r in results])[:, :3, 3] - gt_odom[:, :3, 3], axis=1)
    return err, results, sim


def test_short_synthetic_trot_is_accurate_with_an_ideal_depth_camera():
    """A few seconds of the simulator's trot (noise, blur, auto-exposure, vignetting) with the sharp depth model:
    depth at the colour image's instant, 2 mm x z^2 noise. What the tracker does when depth is not the problem."""
    from atsvo_ros.eval.metrics import evaluate
    from atsvo_ros.io.trajectory import Trajectory

    err, results, sim = _track_trot("sharp")
    stamps = np.array([r.stamp_ns for r in results], dtype=np.int64)
    assert err.max() < 0.02  # measured: max error 0.70 cm, ATE 0.33 cm, RPE 0.025 deg/f; limits at ~3x
    m = evaluate(Trajectory(stamps, sim.T_world_base(stamps)),
                 Trajectory(stamps, np.stack([r.T_odom_base for r in results]))).metrics
    assert m["ate_rmse_m"] < 0.01 and m["rpe_rot_deg_per_frame"] < 0.075 and not m["diverged"], m


def test_short_synthetic_trot_with_the_d455_depth_drifts_a_few_centimetres():
    """The same trot with the D455 model's depth (active stereo exposed 9.6 ms before the colour image on this
    seed, registered to it as realsense2_camera does). Measured 4.3 cm at worst over the 3 s (1.8-4.3 cm on
    seeds 0-4; 0.7-2.4 cm with the exposures in sync): the depth term follows the depth of another instant.
    A regression guard on that figure, not a goal: the goal is the sharp-depth test's."""
    err, _, _ = _track_trot("d455")
    assert err.max() < 0.06


def _imu_for(omega_cam: np.ndarray, R_rgb_imu: np.ndarray, t0_ns: int, t1_ns: int):
    """Gyro samples at 200 Hz of a constant camera angular velocity (rad/s, camera frame), in the IMU frame."""
    from atsvo_ros.core.imu import ImuBatch

    stamps = np.arange(t0_ns - 20_000_000, t1_ns + 20_000_000, 5_000_000, dtype=np.int64)
    w_imu = R_rgb_imu.T @ omega_cam
    return ImuBatch(stamps, np.tile(w_imu, (len(stamps), 1)), np.tile([0.0, 0.0, 9.81], (len(stamps), 1)))


@pytest.mark.parametrize("imu_rotated", [False, True])
def test_gyro_prior_brings_a_fast_turn_into_the_basin(room, imu_rotated):
    """A 9 deg turn in one frame (270 deg/s, a bounding robot) from a standstill: constant- and zero-motion
    guesses are both 9 deg off; the gyro's rotation (through T_rgb_imu) puts the start inside the basin."""
    R_rgb_imu = se3_exp(np.array([0, 0, 0, 0.3, -1.2, 0.5]))[:3, :3] if imu_rotated else np.eye(3)
    T_rgb_imu = np.eye(4)
    T_rgb_imu[:3, :3] = R_rgb_imu
    # the feature matches would rescue the frame without the gyro too (test_feature_matches_rescue_a_fast_turn):
    # off here, to see the gyro prior alone
    cfg = load_config("synthetic", overrides={"rig.T_rgb_imu": T_rgb_imu.reshape(-1).tolist(),
                                              "rig.T_base_rgb": np.eye(4).reshape(-1).tolist(),
                                              "tracker.feature_check_deg": 0.0})
    omega = np.radians(np.array([60.0, 250.0, 80.0]))  # rad/s, camera frame
    dt_ns = 33_000_000
    T_w_c1 = se3_exp(np.r_[0.0, 0.0, 0.0, omega * dt_ns * 1e-9])  # T(t) = exp(t xi) with the body rate
    statuses = {}
    for with_imu in (True, False):
        odo = Odometry(cfg, CAM)
        if with_imu:
            odo.add_imu(_imu_for(omega, R_rgb_imu, 0, dt_ns))
        odo.process_frame(_frame(room, CAM, np.eye(4), 0, ss=1))
        r = odo.process_frame(_frame(room, CAM, T_w_c1, dt_ns, ss=1))
        statuses[with_imu] = r.status
        if with_imu:  # measured 5.1 mm, 0.08 deg (a coarse render of a 9 deg turn)
            dt, dr = _err(r.T_odom_camera, T_w_c1)
            assert dt < 0.01 and dr < 0.2, (dt, dr)
    # with the gyro the first attempt converges; without it tracking fails and only relocalisation helps
    assert statuses == {True: TrackingStatus.OK, False: TrackingStatus.RELOCALISED}, statuses


@pytest.mark.parametrize("angle_deg", [10.0, 12.0])
def test_relocalisation_searches_wider_without_a_trusted_velocity(room, angle_deg):
    """Tracking starts mid-bound: the second frame has turned 10-12 deg and there is no velocity yet. The
    +-4 deg hypotheses alone end in a wrong optimum (measured 6.9 / 10.0 deg off, degraded); the rings at
    8 and 12 deg bring it back (measured 0.06 / 0.02 deg)."""
    T_w_c1 = se3_exp(np.r_[0.01, 0.0, 0.0, np.radians(angle_deg), 0.0, 0.0])
    out = {}
    for rings in (1, 3):
        cfg = load_config("synthetic", overrides={"rig.T_base_rgb": np.eye(4).reshape(-1).tolist(),
                                                  "tracker.relocalisation_rings": rings,
                                                  "tracker.feature_check_deg": 0.0})  # the rings alone
        odo = Odometry(cfg, CAM)
        odo.process_frame(_frame(room, CAM, np.eye(4), 0, ss=1))
        r = odo.process_frame(_frame(room, CAM, T_w_c1, 33 * MS, ss=1))
        out[rings] = (r.status, _err(r.T_odom_camera, T_w_c1)[1])
    assert out[1][0] is not TrackingStatus.OK and out[1][1] > 3.0, out
    assert out[3][0] is TrackingStatus.RELOCALISED and out[3][1] < 0.3, out


@pytest.mark.parametrize("angle_deg", [9.0, 12.0])
def test_feature_matches_rescue_a_fast_turn(room, angle_deg):
    """No gyro, no velocity yet, a 9-12 deg turn: the predictions end in a wrong optimum; ORB matches to the first
    frame (PnP on its depth) start the alignment inside the basin, and the frame is ok and right."""
    T_w_c1 = se3_exp(np.r_[0.01, 0.0, 0.0, np.radians(angle_deg * 0.3), np.radians(angle_deg), 0.0])
    out = {}
    for deg in (0.0, 4.0):
        cfg = load_config("synthetic", overrides={"rig.T_base_rgb": np.eye(4).reshape(-1).tolist(),
                                                  "tracker.relocalisation_rings": 1, "tracker.feature_check_deg": deg})
        odo = Odometry(cfg, CAM)
        odo.process_frame(_frame(room, CAM, np.eye(4), 0, ss=1))
        r = odo.process_frame(_frame(room, CAM, T_w_c1, 33 * MS, ss=1))
        out[deg] = (r.status, _err(r.T_odom_camera, T_w_c1)[1])
    assert out[4.0][0] is TrackingStatus.OK and out[4.0][1] < 0.3, out
    assert out[0.0][0] is not TrackingStatus.OK or out[0.0][1] > 3.0, out  # without them: not ok, or wrong


def test_host_stamped_frames_are_tracked_on_the_frame_clock(room):
    """A camera turning 90 deg/s, its frames stamped on arrival (half-normal delays of 2 ms scale, as TUM's
    Kinect): with the frame clock each pose is published at its stamp and the frame-to-frame rotation is
    right; without it the stamps' jitter goes straight into the relative poses (0.14 vs 0.02 deg measured)."""
    cfg_on = load_config("synthetic", overrides={"rig.T_base_rgb": np.eye(4).reshape(-1).tolist()})
    cfg_off = load_config("synthetic", overrides={"rig.T_base_rgb": np.eye(4).reshape(-1).tolist(),
                                                  "rgb_camera.frame_clock_frames": 0})
    xi = np.r_[0.06, 0.0, 0.02, 0.0, np.radians(90.0), 0.0]  # per second: T_w_c(t) = exp(t xi)
    period_ns = 33_333_333
    n = 36
    t_ns = np.arange(n, dtype=np.int64) * period_ns
    delays = np.round(np.abs(np.random.default_rng(3).standard_normal(n)) * 2e6).astype(np.int64)
    stamps = t_ns + delays
    frames = [_frame(room, CAM, se3_exp(xi * (t * 1e-9)), int(s), ss=1) for t, s in zip(t_ns, stamps)]
    rel = {}
    for name, cfg in (("on", cfg_on), ("off", cfg_off)):
        odo = Odometry(cfg, CAM)
        res = [odo.process_frame(f) for f in frames]
        assert [r.stamp_ns for r in res] == stamps.tolist()  # published at the stamps
        assert all(r.status is TrackingStatus.OK for r in res[1:]), [r.status for r in res]
        errs = []
        for k in range(12, n):  # once the clock's fit is in use
            est = se3_inv(res[k - 1].T_odom_camera) @ res[k].T_odom_camera
            true = se3_exp(xi * ((stamps[k] - stamps[k - 1]) * 1e-9))
            errs.append(_err(est, true)[1])
        rel[name] = float(np.sqrt(np.mean(np.square(errs))))
    assert rel["off"] > 0.08 and rel["on"] < 0.5 * rel["off"], rel


def test_stamp_latency_is_removed_and_the_pose_published_at_the_exposure_time(room):
    """A driver that stamps frames 10 ms after their exposure (plus jitter), the camera swinging +-20 deg at
    1 Hz (up to 125 deg/s): with ``time_offset_s`` = -10 ms each pose is stamped at its exposure and matches
    the motion there; without it every relative pose is the motion of 10 ms later (0.19 vs 0.05 deg per
    frame measured)."""
    period_ns, n, latency_ns = 33_333_333, 36, 10 * MS
    t_ns = np.arange(n, dtype=np.int64) * period_ns
    stamps = t_ns + latency_ns + np.round(np.abs(np.random.default_rng(5).standard_normal(n)) * 1e6).astype(np.int64)

    def T_w_c(t_ns):
        t_s = np.asarray(t_ns) * 1e-9
        return se3_exp(np.r_[0.05 * t_s, 0.0, 0.0, 0.0, np.radians(20.0) * np.sin(2 * np.pi * t_s), 0.0])

    frames = [_frame(room, CAM, T_w_c(t), int(s), ss=1) for t, s in zip(t_ns, stamps)]
    rel = {}
    for name, offset_s in (("on", -0.010), ("off", 0.0)):
        cfg = load_config("synthetic", overrides={"rig.T_base_rgb": np.eye(4).reshape(-1).tolist(),
                                                  "rgb_camera.time_offset_s": offset_s})
        odo = Odometry(cfg, CAM)
        res = [odo.process_frame(f) for f in frames]
        assert [r.stamp_ns for r in res] == (stamps + int(round(offset_s * 1e9))).tolist()
        assert all(r.status is TrackingStatus.OK for r in res[1:]), [r.status for r in res]
        errs = []
        for k in range(12, n):  # once the frame clock's fit is in use
            est = se3_inv(res[k - 1].T_odom_camera) @ res[k].T_odom_camera
            true = se3_inv(T_w_c(res[k - 1].stamp_ns)) @ T_w_c(res[k].stamp_ns)
            errs.append(_err(est, true)[1])
        rel[name] = float(np.sqrt(np.mean(np.square(errs))))
    assert rel["off"] > 0.1 and rel["on"] < 0.4 * rel["off"], rel


def test_the_first_depth_is_turned_once_the_gyro_covers_it(room):
    """Streams that start together: the first frame (depth exposed 12 ms before its colour) comes before the
    IMU's first sample, so its depth goes into the map unturned; mid-flip (500 deg/s: 6 deg over the offset) the
    map is rebuilt from it, turned, as soon as the gyro covers it, before the next frame is tracked."""
    from atsvo_ros.core.imu import ImuBatch

    offset_s, rate = -0.012, np.radians(500.0)
    cfg = load_config("synthetic", overrides={"rig.depth_time_offset_s": offset_s})
    w_c = np.array([0.0, rate, 0.0])  # yaw about the camera's y axis

    def T_w_c(t_s):
        return se3_exp(np.r_[0.0, 0.0, 0.0, w_c * t_s])

    def frame(k):
        t = k * 0.033
        img, _ = room.render(CAM, T_w_c(t), supersample=1)
        _, depth = room.render(CAM, T_w_c(t + offset_s), supersample=1)
        rgb = np.repeat(np.clip(img + 0.5, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
        return RgbdFrame(int(round(t * 1e9)), rgb, depth)

    R_imu_rgb = cfg.rig.T_rgb_imu_matrix()[:3, :3].T
    stamps = np.arange(2 * MS, 70 * MS, 5 * MS, dtype=np.int64)  # 200 Hz from 2 ms after the first frame
    imu = ImuBatch(stamps, np.tile(R_imu_rgb @ w_c, (len(stamps), 1)), np.zeros((len(stamps), 3)))
    odo = Odometry(cfg, CAM)
    odo.process_frame(frame(0))  # no IMU yet: the map's depth as it came
    odo.add_imu(imu.select(stamps <= 33 * MS))
    second = odo.process_frame(frame(1))
    T_b_c = cfg.rig.T_base_rgb_matrix()
    dt, dr = _err(second.T_odom_base, T_b_c @ se3_inv(T_w_c(0.0)) @ T_w_c(0.033) @ se3_inv(T_b_c))
    # measured 3.6 mm, 0.054 deg; the map left unturned (no rebuild): 6.9 mm, 0.10 deg
    assert second.status is TrackingStatus.OK and dt < 5e-3 and dr < 0.08, (dt, dr)



class _MoveTheMap:
    """A window refiner that moves every keyframe (and its points) by one rigid ``T_wnew_wold``: a map that stays
    consistent in a moved world, as the window's correction of the newest keyframe is for the frames after it."""

    def __init__(self, T_wnew_wold: np.ndarray) -> None:
        self.T_wnew_wold = T_wnew_wold

    def refine(self, point_map, views) -> WindowReport:
        if len(point_map.keyframes) < 2:  # as the window: a new map's keyframe has nothing to agree with
            return WindowReport(0, 0, 0, 0.0, 0.0)
        for k in sorted(point_map.keyframes):
            point_map.move_keyframe(k, self.T_wnew_wold @ point_map.keyframes[k].T_w_c)
        return WindowReport(len(point_map.keyframes), 1, 1, 0.03, 0.0)


@pytest.mark.parametrize("turn_deg, calm_s, refined", [(1.5, 0.0, True), (1.5, 0.5, False), (5.0, 0.0, False)])
def test_the_window_runs_only_while_the_camera_is_calm(room, turn_deg, calm_s, refined):
    """A keyframe asks for the window only when no frame of the last ``tracker.calm_s`` turned more than
    ``tracker.calm_turn_deg`` (4) and that span of frames was seen: not in the first 0.5 s of a run, not at 5 deg per
    frame."""
    config = load_config("synthetic", overrides={"tracker.calm_s": calm_s, "mapping.window_iterations": 2})
    odo = Odometry(config, CAM)
    odo.mapper.refiner = _MoveTheMap(np.eye(4))
    step = se3_exp(np.array([0.03, 0.0, 0.01, 0.0, np.radians(turn_deg), 0.0]))
    asked = []
    for k in range(10):
        res = odo.process_frame(_frame(room, CAM, np.linalg.matrix_power(step, k), k * 33 * MS, ss=1))
        if k and res.keyframe_inserted:
            asked.append(odo.mapper.n_windows)
    assert asked, "no keyframe"
    assert (odo.mapper.n_windows > 1) == refined, (asked, odo.mapper.n_windows)


def test_a_keyframe_the_local_window_moved_takes_the_odometry_with_it(room):
    """When mapping moves the keyframe a frame was just inserted as (DSO's tracking reference), that frame's pose and
    the motion the next frames are predicted from move with it: no velocity is taken across the move."""
    # calm from the second frame on (the window runs only while the camera is calm: tracker.calm_s)
    config = load_config("synthetic", overrides={"tracker.calm_s": 0.0, "mapping.window_iterations": 2})
    odo = Odometry(config, CAM)
    T_wnew_wold = se3_exp(np.array([0.03, -0.02, 0.03, 0.0, np.radians(1.2), np.radians(0.8)]))  # 4.7 cm, 1.4 deg
    odo.mapper.refiner = _MoveTheMap(T_wnew_wold)
    step = se3_exp(np.array([0.03, 0.0, 0.01, 0.0, np.radians(1.5), 0.0]))
    truth = [np.linalg.matrix_power(step, k) for k in range(14)]
    T_w_odom = se3_inv(config.rig.T_base_rgb_matrix())
    k = 0
    while True:
        res = odo.process_frame(_frame(room, CAM, truth[k], k * 33 * MS, ss=1))
        assert res.status in (TrackingStatus.INITIALISING, TrackingStatus.OK), (k, res.reason)
        if k and res.keyframe_inserted:
            break
        k += 1
        assert k < len(truth) - 3, "no keyframe"
    # the keyframe's frame is published where the map put it
    dt, dr = _err(T_w_odom @ res.T_odom_camera, T_wnew_wold @ truth[k])
    assert dt < 0.01 and dr < 0.2, (k, dt, dr)
    for j in (k + 1, k + 2):
        # the next two frames are predicted in the moved world, from the motion before the move (measured: 11 and 7
        # mm, 0.21 and 0.15 deg off, as before the move with these aliased renders; a motion that did not follow the
        # map is off by the move, then takes it into its velocity: 3.4 and 3.8 cm, 1.6 deg for both)
        dt, dr = _err(se3_inv(odo.motion.predict(j * 33 * MS)), T_wnew_wold @ truth[j])
        assert dt < 0.02 and dr < 0.5, (j, dt, dr)
        res = odo.process_frame(_frame(room, CAM, truth[j], j * 33 * MS, ss=1))
        dt, dr = _err(T_w_odom @ res.T_odom_camera, T_wnew_wold @ truth[j])
        assert res.status is TrackingStatus.OK and dt < 0.01 and dr < 0.2, (j, res.reason, dt, dr)
