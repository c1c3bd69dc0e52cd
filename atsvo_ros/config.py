"""Configuration: frozen dataclasses loaded and validated from the ROS-parameter YAML files.

The same file serves ``ros2 launch`` (``node_name: ros__parameters: {...}`` or ``/**:``) and the
offline tools. Nested mappings become sections; every field declares its allowed range in its
metadata, and a bad value raises :class:`ConfigError` naming the key, the value and the range.
"""
from __future__ import annotations

import dataclasses
import math
import sys
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from atsvo_ros.errors import ConfigError

_IDENTITY16 = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _f(default: Any, lo: float | None = None, hi: float | None = None, *, choices: tuple = (),
       lo_open: bool = False, doc: str = "") -> Any:
    """Dataclass field with a validated range (``lo``/``hi`` inclusive unless ``lo_open``)."""
    meta = {"lo": lo, "hi": hi, "choices": choices, "lo_open": lo_open, "doc": doc}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda d=tuple(default): d, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class CameraConfig:
    """Fallback intrinsics when no camera_info message is available (ROS camera model fields)."""

    width: int = _f(640, 1, 10000)
    height: int = _f(480, 1, 10000)
    fx: float = _f(386.0, 0.0, 1e5, lo_open=True)
    fy: float = _f(386.0, 0.0, 1e5, lo_open=True)
    cx: float = _f(320.0, -1e4, 1e4)
    cy: float = _f(240.0, -1e4, 1e4)
    distortion_model: str = _f("plumb_bob", choices=("none", "plumb_bob", "rational_polynomial", "equidistant"))
    D: tuple[float, ...] = _f((0.0, 0.0, 0.0, 0.0, 0.0))
    use_camera_info: bool = _f(True, doc="prefer the camera_info topic over these values")
    readout_time_s: float = _f(0.0, 0.0, 1.0, doc="rolling-shutter readout time, first to last row (0 = global "
                               "shutter, e.g. the D455's colour and depth imagers)")
    time_offset_s: float = _f(0.0, -1e4, 1e4, doc="colour camera: exposure time of the middle row minus the image "
                              "stamp (a host-stamping driver's latency, negative); the odometry is stamped at that "
                              "time. Event camera: added to the event times (and event message stamps) to put them "
                              "on the colour images' clock, e.g. -5.0 for events stamped 5 s ahead (a camera on "
                              "another clock; the run says so at its start and names the value)")
    time_offset_search_s: float = _f(0.0, 0.0, 1.0, doc="event camera: estimate the event clock's offset to the "
                                     "colour images at start-up, within +- this (0 = off), by correlating event "
                                     "counts with the colour images' change (needs motion); the estimate is added to "
                                     "time_offset_s, said once. Keep it below half the gait's period (a trot or "
                                     "bound repeats every 0.3-0.4 s); drivers on one host differ by 10-100 ms")
    frame_clock_frames: int = _f(30, 0, 10000, doc="frames of the line fitted to the image stamps to recover the "
                                 "camera's frame clock from host-stamp jitter (0 = use the stamps as they are)")


@dataclass(frozen=True)
class RigConfig:
    """Extrinsics (row-major 4x4) and depth conventions of the sensor rig."""

    T_base_rgb: tuple[float, ...] = _f(_IDENTITY16, doc="colour optical frame in the robot base frame")
    T_rgb_event: tuple[float, ...] = _f(_IDENTITY16, doc="event camera frame in the colour optical frame")
    T_rgb_imu: tuple[float, ...] = _f(_IDENTITY16, doc="IMU frame (of the imu topic's samples) in the colour "
                                                       "optical frame")
    depth_scale_m: float = _f(0.001, 0.0, 10.0, lo_open=True, doc="metres per 16UC1 depth unit")
    depth_min_m: float = _f(0.3, 0.0, 100.0)
    depth_max_m: float = _f(6.0, 0.0, 1000.0, lo_open=True)
    sync_tolerance_s: float = _f(0.01, 0.0, 1.0, doc="max RGB/depth stamp difference for a pair")
    imu_time_offset_s: float = _f(0.0, -1e4, 1e4, doc="added to the IMU stamps to put them on the colour images' "
                                  "clock (an IMU on another clock; the run says so at its start and names the value)")
    imu_accel_range_m_s2: float = _f(4.0 * 9.80665, 0.0, 1e4,
                                     doc="the accelerometer's range: a sample at it is clipped (the D4xx firmware "
                                         "sets the BMI055 to +-4 g, librealsense PR #2777; a push-off or landing "
                                         "exceeds it). Over a span with a clipped sample the accelerometer's "
                                         "prediction is not held as measured (tracker.imu_prior_sigma_m); 0 = "
                                         "never clipped")
    depth_time_offset_s: float = _f(0.0, -0.1, 0.1,
                                    doc="depth exposure centre minus colour exposure centre, for a depth image "
                                        "registered to colour and stamped with it: a D455 cannot synchronise the "
                                        "two (librealsense#11609) and its frames' hardware timestamps give the "
                                        "offset. With an IMU, each depth image is turned to the colour's time by "
                                        "the gyro's rotation in between (0 = in sync, no turn). Measured on the "
                                        "D455 model, tuning seeds 0-4, IMU fed, turned / not: 2.4 s flips mean "
                                        "ATE 8.9 / 22.7 cm, 4 s running 1.7 / 3.8, bound 12.6 / 17.4, trot 1.4 / "
                                        "1.6, pronk 1.5 / 1.6. The constant-motion prediction's rotation instead "
                                        "of the gyro's made flips worse (26 against 17 cm): not used")

    def T_base_rgb_matrix(self) -> np.ndarray:
        return np.asarray(self.T_base_rgb, dtype=np.float64).reshape(4, 4)

    def T_rgb_event_matrix(self) -> np.ndarray:
        return np.asarray(self.T_rgb_event, dtype=np.float64).reshape(4, 4)

    def T_rgb_imu_matrix(self) -> np.ndarray:
        return np.asarray(self.T_rgb_imu, dtype=np.float64).reshape(4, 4)


@dataclass(frozen=True)
class TopicsConfig:
    """Topic and frame names (REP 105: the odometry is odom -> base_link)."""

    rgb: str = _f("/camera/camera/color/image_raw", doc="colour image (sensor_msgs/Image rgb8/bgr8/mono8, or "
                  "CompressedImage)")
    rgb_info: str = _f("/camera/camera/color/camera_info", doc="colour camera_info")
    depth: str = _f("/camera/camera/aligned_depth_to_color/image_raw",
                    doc="depth aligned to colour (16UC1 scaled by rig.depth_scale_m, or 32FC1 metres)")
    events: str = _f("/dvxplorer/events", doc="event messages (type: node.event_msg_type)")
    event_info: str = _f("/dvxplorer/camera_info", doc="event camera_info")
    ground_truth: str = _f("/ground_truth/pose", doc="ground-truth pose (offline tools only)")
    imu: str = _f("/camera/camera/imu", doc="sensor_msgs/Imu (realsense2_camera with unite_imu_method set)")
    odometry: str = _f("/atsvo/odometry", doc="nav_msgs/Odometry out, one per processed frame")
    status: str = _f("/atsvo/status", doc="diagnostic_msgs/DiagnosticArray out, one per odometry message with the "
                     "same stamp: tracking status, mode, reason")
    map: str = _f("/atsvo/map", doc="sensor_msgs/PointCloud2 out: the local map in the odom frame (latched)")
    debug_ats: str = _f("/atsvo/debug/ats", doc="sensor_msgs/Image mono8 out: the time surface at each frame "
                        "(computed only while someone subscribes)")
    debug_selection: str = _f("/atsvo/debug/selected_pixels", doc="sensor_msgs/Image rgb8 out: the time surface "
                              "with the selected event pixels in red (only while someone subscribes)")
    keyframe_requests: str = _f("/atsvo/mapping/keyframe_requests", doc="tracking_node -> mapping_node: keyframe "
                                "requests (std_msgs/UInt8MultiArray, atsvo wire format)")
    map_snapshots: str = _f("/atsvo/mapping/snapshots", doc="mapping_node -> tracking_node: map snapshots "
                            "(std_msgs/UInt8MultiArray, atsvo wire format)")
    reset_service: str = _f("/atsvo/reset", doc="std_srvs/Trigger: restart the odometry (new map, pose back to "
                            "the identity at the next frame)")
    odom_frame: str = _f("odom", doc="frame_id of the odometry and parent of the TF")
    base_frame: str = _f("base_link", doc="child_frame_id of the odometry and child of the TF")


@dataclass(frozen=True)
class AtsConfig:
    """Adaptive time surface (Eq. 1-2): decay bounds, neighbour pattern, smoothing."""

    tau_u_s: float = _f(0.03, 0.0, 10.0, lo_open=True, doc="upper bound of the decay time constant")
    tau_l_s: float = _f(0.003, 0.0, 10.0, lo_open=True, doc="lower bound of the decay time constant")
    n_latest: int = _f(4, 1, 16, doc="number of latest neighbours of the 16-pixel ring used in Eq. 2 (tau_mode "
                                     "mean_age / eq2_printed; fire_age uses every neighbour that fired before "
                                     "the pixel)")
    pattern_radius_px: int = _f(3, 1, 8, doc="radius of the 16-pixel neighbour ring (3 = FAST circle)")
    blur_ksize: int = _f(3, 1, 31, doc="box blur kernel after Eq. 2 (1 = off)")
    median_ksize: int = _f(3, 1, 31, doc="median blur kernel after Eq. 2 (1 = off, odd)")
    constant_tau_s: float = _f(0.03, 0.0, 10.0, lo_open=True, doc="tau of the constant-tau baseline")
    tau_mode: str = _f("fire_age", choices=("fire_age", "mean_age", "eq2_printed"),
                       doc="fire_age: tau = clip(fire_age_gain x mean age of the ring neighbours at the moment the "
                           "pixel fired, tau_l, tau_u): decays faster under dense/fast events as the paper describes, "
                           "monotonically behind a moving edge; mean_age: tau = clip(mean age of the n latest "
                           "neighbours at the query time, tau_l, tau_u) (leaves a dark notch and a flat ghost band "
                           "behind an edge); eq2_printed: tau = max(tau_u - mean age, tau_l), Eq. 2 as printed "
                           "(decays slower under dense/fast events)")
    fire_age_gain: float = _f(4.0, 0.0, 1000.0, lo_open=True,
                              doc="tau_mode fire_age: tau per second of neighbour age; behind an edge the neighbours "
                                  "fired ~1.7 px of motion before the pixel, so the trail fades to 1/e over ~1.7 x "
                                  "this many pixels (while tau stays within its bounds)")
    sits_radius_px: int = _f(3, 1, 10, doc="patch radius of the speed-invariant time surface baseline")


@dataclass(frozen=True)
class RgbSelectionConfig:
    """DSO-style block-gradient pixel selection on the colour image."""

    block_size_px: int = _f(16, 4, 256, doc="d in d x d blocks")
    target_points: int = _f(1200, 10, 100000)
    min_gradient: float = _f(7.0, 0.0, 255.0, doc="absolute floor of the gradient threshold")
    border_px: int = _f(8, 0, 100)


@dataclass(frozen=True)
class EventSelectionConfig:
    """Event pixel selection on the ATS (Section II-B, Eq. 3)."""

    alpha: float = _f(1.0, 0.0, 100.0, doc="gradient scale in I + alpha * grad > h")
    h: float = _f(60.0, 0.0, 2000.0, doc="threshold h of Eq. 3 on the 0-255 ATS (after blur and median blur an "
                                         "edge's newest pixels sit at ~150-255 and its trail decays from there; 60 "
                                         "keeps ~170-400 pixels at 0.1-0.3 Mev/s on the real DVXplorer sample with "
                                         "tau_mode fire_age, ~120-300 with mean_age)")
    min_distance_px: int = _f(3, 0, 100, doc="d of Eq. 3: minimum spacing in x and y")
    mask_median_ksize: int = _f(5, 1, 31, doc="median blur kernel of the ATS mask (odd)")
    window_fraction: float = _f(0.25, 0.0, 1.0, lo_open=True, doc="share of the ATS window whose events are candidates")
    max_points: int = _f(600, 1, 100000)
    border_px: int = _f(4, 0, 100)


@dataclass(frozen=True)
class TrackerConfig:
    """Coarse-to-fine photometric alignment (Eq. 4)."""

    pyramid_levels: int = _f(5, 1, 8, doc="pyramid levels (fewer when the coarsest would be under 16 px): the "
                             "coarsest sets the basin of convergence (5 at 640x480: 40x30 px, ~4x the rotation that "
                             "4 levels take)")
    coarse_level_points: int = _f(300, 0, 100000,
                                  doc="map points used on level l > 0: max(this, N / 4^l), 0 = all (speed)")
    max_iterations: int = _f(20, 1, 200, doc="Gauss-Newton/LM iterations per pyramid level")
    huber_delta: float = _f(9.0, 0.0, 255.0, lo_open=True, doc="Huber threshold on the patch residual (intensity)")
    outlier_threshold: float = _f(20.0, 0.0, 1000.0, lo_open=True,
                                  doc="RMS patch residual (intensity) above which a point is an outlier")
    convergence_eps: float = _f(5e-4, 0.0, 1.0, lo_open=True,
                                doc="stop when the update norm (m, rad) falls below this (x2 per pyramid level): "
                                    "0.5 mm / 0.03 deg on the finest level; 1e-4 cost ~20 % more time for "
                                    "no measurable accuracy on the synthetic or TUM sequences")
    w_rgb: float = _f(1.0, 0.0, 1e6, doc="omega_1 of Eq. 4")
    w_event: float = _f(1.0, 0.0, 1e6, doc="omega_2 of Eq. 4, the event (ATS) term's weight (0 = RGB-D only)")
    photometric_sigma: float = _f(8.0, 0.0, 255.0, lo_open=True,
                                  doc="noise scale of a photometric residual (intensity): residuals are divided by "
                                      "it so the depth term combines with them in one system")
    w_depth: float = _f(1.0, 0.0, 1e6, doc="weight of the point-to-plane depth term (0 = the paper's formulation: "
                                           "photometric only)")
    calm_turn_deg: float = _f(4.0, 0.0, 180.0,
                              doc="the camera is calm while no turn between consecutive frames over the last "
                                  "tracker.calm_s (and, for tracking, the constant-motion prediction's) is larger, the "
                                  "motion is known and that span of frames was seen (core/odometry/calm.py): then "
                                  "the local window runs and the depth term takes tracker.calm_depth_factor; 0 = never")
    calm_s: float = _f(0.5, 0.0, 10.0, doc="how long a fast frame keeps the camera from being calm")
    calm_depth_factor: float = _f(1.0, 0.0, 1.0,
                                  doc="the depth term's weight is multiplied by this while the camera is calm "
                                      "(tracker.calm_turn_deg): sharp colour then carries the pose, and the depth "
                                      "camera's systematic error pulls less; 1 = no change (the TUM presets: 0.25)")
    depth_sigma_at_1m_m: float = _f(0.004, 0.0, 1.0, lo_open=True,
                                    doc="depth noise at 1 m (grows with z^2): the depth term's noise scale")
    depth_sigma_min_m: float = _f(0.002, 0.0, 1.0, lo_open=True, doc="floor of the depth noise scale")
    depth_huber: float = _f(2.0, 0.0, 100.0, lo_open=True, doc="Huber threshold of the depth term (noise units)")
    depth_outlier: float = _f(10.0, 0.0, 1000.0, lo_open=True,
                              doc="depth residual (noise units) above which a point is an outlier")
    rotation_hypotheses_deg: float = _f(0.0, 0.0, 45.0, doc="besides constant and zero motion, start from the "
                                        "prediction rotated by +-this about each camera axis (0 = off)")
    relocalisation_rings: int = _f(3, 1, 10, doc="relocalisation without a trusted velocity (the frame after a "
                                   "(re)initialisation or a doubtful one) starts from rotations of k x max(2 x "
                                   "rotation_hypotheses_deg, 4) deg about each camera axis, k = 1..rings: a robot "
                                   "that starts tracking mid-bound turns 7-8 deg in that frame")
    refine_guesses: int = _f(1, 1, 32, doc="initial guesses optimised on the coarsest level before the best is kept")
    feature_check_deg: float = _f(4.0, 0.0, 180.0, doc="a frame that turned more than this since the previous one "
                                  "is checked against ORB matches to the last trusted frame (PnP on its depth), and "
                                  "a frame the checks reject is tracked again from that pose; 0 = off")
    feature_check_m: float = _f(0.03, 0.0, 10.0, doc="a frame whose camera centre is further than this from the "
                                "constant-velocity prediction is checked as well: a wrong optimum that takes a turn "
                                "for a slide turns too little to be checked (fr1_rpy every 5th frame: 2.8 deg and "
                                "7.4 cm estimated where the camera turned 6.9 deg and moved 1.7 cm). 3 cm is 2.8 g "
                                "over a 30 Hz frame, beyond a hand-held camera. Every 5th from frames 1 / 2 / 4: "
                                "2.51 / 2.78 / 29.7 -> 1.43 / 1.45 / 2.02 cm, wrong-but-ok 2 / 2 / 2 -> 0; "
                                "fr1_rpy_300, every 2nd, 3rd, 4th unchanged; 0 = off")
    feature_points: int = _f(500, 100, 10000, doc="ORB keypoints per frame for feature_check_deg (matching costs "
                             "grow with their square: 3.5 ms for 500, 14 ms for 1000)")
    feature_level: int = _f(1, 0, 3, doc="pyramid level the ORB features are taken on (1 = half resolution: "
                            "2.8 ms per frame at 640x480 against 5.7 at full)")
    feature_disagreement_deg: float = _f(1.5, 0.1, 45.0, doc="a checked frame whose direct and feature-matched "
                                         "rotations differ by more than this (or feature_disagreement_share of the "
                                         "frame's rotation, if larger) is tracked again from the matches, and "
                                         "degraded if that does not settle it")
    feature_disagreement_share: float = _f(0.25, 0.0, 1.0, doc="... the share of the frame's rotation allowed as "
                                           "disagreement on a large turn (PnP is 0.3-0.6 deg off, median; the "
                                           "wrong-but-ok bound is 25 % of the true rotation)")
    feature_unverified_deg: float = _f(0.0, 0.0, 180.0, doc="a checked frame that turned more than this with no "
                                       "feature match to check it (too few keypoints matched) is degraded (0 = off). "
                                       "Opt-in: at 8, fr1_rpy every 5th from frames 1-3 went from 2 + 2 + 2 "
                                       "wrong-but-ok frames to 1 + 0 + 0 (with feature_check_m: 0 + 0 + 2 to 0 + 0 "
                                       "+ 0), but the held-out simulated backflips "
                                       "without an IMU went 8.8 -> 20.0 cm fused with 28 frames lost or "
                                       "re-initialised (blurred flips leave nothing to match)")
    feature_disagreement_m: float = _f(0.08, 0.001, 10.0, doc="... or whose camera centres differ by more than "
                                       "this (PnP's translation between two frames is off by up to 7 cm on TUM "
                                       "fr1_rpy subsamples, 4-5 cm at the 99th percentile)")
    velocity_scales: tuple[float, ...] = _f((0.5, 1.5, 2.0, 3.0),
                                            doc="while the camera turns faster than fusion.rate_threshold_deg_s, also "
                                                "start from the constant-motion prediction with the last motion scaled "
                                                "by these factors: a legged robot accelerates (push-off, landing) "
                                                "mostly about the axis it already turns about")
    min_inlier_fraction: float = _f(0.3, 0.0, 1.0, doc="below this the frame is lost")
    min_inliers: int = _f(30, 6, 100000, doc="fewer inlier map points than this and the frame is lost")
    gradient_weight: float = _f(50.0, 0.0, 1000.0,
                                doc="c of the pixel weight c^2/(c^2+|grad I|^2) (DSO); 0 = off")
    affine_brightness: bool = _f(True, doc="model a per-frame brightness gain (auto-exposure); with zero-mean "
                                 "patches it is measured from patch means, otherwise gain/offset are fitted (DSO)")
    zero_mean_patches: bool = _f(True, doc="remove each patch's mean before comparing (vignetting, uneven light)")
    max_scale_change: float = _f(1.6, 0.0, 100.0, doc="skip map points now nearer/farther than this factor times "
                                 "their keyframe depth (patch at another scale); 0 = off")
    max_step_m: float = _f(0.5, 0.0, 100.0, lo_open=True,
                           doc="camera translation per frame beyond which the estimate counts as diverged")
    max_step_rot_deg: float = _f(30.0, 0.0, 180.0, lo_open=True,
                                 doc="camera rotation per frame beyond which the estimate counts as diverged")
    max_position_std_m: float = _f(0.05, 0.0, 100.0, lo_open=True,
                                   doc="pose translation std above which the frame is lost (degenerate geometry)")
    covariance_scale: float = _f(4.0, 0.0, 1e6, lo_open=True,
                                 doc="factor on the inverse normal equations x residual variance: neighbouring "
                                     "pattern pixels and interpolation errors are correlated, which the "
                                     "independent-residual model ignores (measured: 4x makes the normalised "
                                     "pose error match the covariance on rendered frames)")
    max_gain_ratio: float = _f(2.0, 1.0, 100.0, lo_open=True,
                               doc="brightness gain change between frames beyond [1/x, x] counts as lost")
    min_zncc: float = _f(0.3, -1.0, 1.0, doc="mean ZNCC of the inlier patches after alignment below which the "
                         "frame is degraded (the patches landed on other texture). Measured: right poses 0.33-0.9 "
                         "(the low end under heavy blur while bounding, >= 0.4 on TUM fr1_rpy), wrong ones "
                         "(> 1.5 deg off) 0.02-0.25")
    lost_zncc: float = _f(0.15, -1.0, 1.0, doc="mean ZNCC below which the frame is lost")
    min_depth_inlier_fraction: float = _f(0.5, 0.0, 1.0, doc="depth-term inliers / visible below which the frame "
                                          "is degraded (the photometric optimum disagrees with the geometry)")
    max_gyro_disagreement_deg: float = _f(2.0, 0.0, 180.0, lo_open=True,
                                          doc="rotation between the estimate and the gyro's prediction beyond which "
                                              "the frame is degraded (a wrong visual optimum)")
    max_acceleration_m_s2: float = _f(60.0, 0.0, 1e4, lo_open=True,
                                      doc="largest acceleration of the camera over a frame interval; a pose whose "
                                          "camera centre is further from the constant-velocity prediction than this "
                                          "allows (a dt (dt + dt0) / 2 + tracker.motion_noise_m) is degraded. "
                                          "Mini-Cheetah gaits and flips in the simulator reach 4.1 g (backflip), "
                                          "3.2 g (pronk); 6 g leaves room for harder landings. Hand-held: ~2 g")
    motion_noise_m: float = _f(0.02, 0.0, 10.0, doc="noise of the estimated camera centres that the "
                               "constant-velocity check allows on top of the acceleration's reach")
    motion_prior_acceleration_m_s2: float = _f(
        20.0, 0.0, 1e4, doc="typical camera acceleration for the motion prior: the optimiser pulls the camera centre "
        "towards the constant-velocity prediction with sigma a dt (dt + dt0) / 2 (2.2 cm at 30 fps). The prior decides "
        "only what images and depth leave free (mid-flip: a blank floor seen as one plane). Measured on simulated "
        "bound / backflip, seeds 0-4: 5 / 10 / 20 / 40 m/s^2 gave bound ATE 0.8-1.8 / 1.1-1.6 / 0.9-1.1 / 0.9-1.6 cm; "
        "at 40 one backflip doubled to 5 cm. 0 = no prior")
    motion_prior_angular_acceleration_rad_s2: float = _f(
        32.0, 0.0, 1e5, doc="typical angular acceleration for the motion prior's rotation sigma (same formula: "
        "2 deg at 30 fps). In flight the body keeps its angular momentum (simulated backflips: the constant-rate "
        "prediction is 0.1-0.7 deg off); a landing's 9 deg is left to the data by the Huber kernel. With a gyro the "
        "rotation is centred on the gyro's instead (tracker.gyro_prior_sigma_deg), the centre on the "
        "accelerometer's prediction (tracker.imu_translation); 0 = no prior")
    imu_translation: bool = _f(True, doc="with an IMU, the camera centre's prediction (the first guess, the motion "
                               "prior's centre and the constant-velocity check's) integrates the accelerometer from "
                               "the last trusted velocity instead of assuming constant velocity; gravity is "
                               "estimated while tracking. A push-off's 4 g is what constant velocity misses. "
                               "Earns its place with the gyro's prior (tracker.gyro_prior_sigma_deg): tuning seeds "
                               "0-9, 2.5 s, 640x480, fused + IMU, backflip mean ATE both 4.39 cm, prior alone 9.69, "
                               "accelerometer alone 10.76, neither 7.49 (docs/odometry.md)")
    depth_time_translation: bool = _f(True, doc="when depth is moved to the colour's time (rig.depth_time_offset_s, "
                                      "with an IMU), move it by the camera's translation over the offset as well as "
                                      "by the gyro's rotation (a bound's 2 m/s over 16 ms is 3 cm of depth): the "
                                      "IMU's velocity fitted over the trusted poses of "
                                      "tracker.imu_velocity_window_s, and the map rebuilt from its first frame "
                                      "once that velocity exists. Tuning seeds 0-4 (2.4-2.5 s, 320x240, IMU fed, "
                                      "mean ATE on / off): bound RGB-D 3.97 / 6.20 cm, fused 4.80 / 5.61; backflip "
                                      "fused 8.12 / 8.39 (docs/odometry.md)")
    imu_velocity_window_s: float = _f(0.15, 0.03, 2.0,
                                      doc="span of the trusted poses the IMU's velocity is fitted to (at least 3), "
                                          "for the depth's timing (tracker.depth_time_translation) and the "
                                          "accelerometer's prediction (tracker.imu_translation): longer averages "
                                          "more pose noise, shorter lets less of the accelerometer's bias in (the "
                                          "BMI055's 70 mg over 0.15 s: under 1 mm)")
    imu_prior_sigma_m: float = _f(0.0, 0.0, 1.0,
                                  doc="opt-in (0 = off): the accelerometer's prediction starts from the IMU velocity "
                                      "fitted over tracker.imu_velocity_window_s instead of the last two poses', and "
                                      "where the accelerometer measured the whole span unclipped "
                                      "(rig.imu_accel_range_m_s2) the motion prior's centre gets this sigma instead "
                                      "of constant velocity's reach (2.2 cm); 0.003 is about the trusted poses' own "
                                      "noise. Tuning seeds 0-9 (2.5 s, 640x480, fused + IMU) backflip mean ATE 4.39 "
                                      "-> 3.18 cm at 0.003, but held-out seeds 100-102 (10 s) 4.20 -> 5.30, bound "
                                      "2.65 -> 2.32 (docs/odometry.md)")
    imu_dead_reckoning_s: float = _f(0.5, 0.0, 10.0,
                                     doc="with an IMU (tracker.imu_translation), after frames that were not trusted "
                                         "the first guess (and a lost frame's published pose) comes from the IMU "
                                         "alone, integrated from the state fitted at the last trusted frame, for at "
                                         "most this long; 0 = constant motion from the last pose")
    max_coast_s: float = _f(0.3, 0.0, 10.0, doc="how long tracking may coast on the depth term and the motion prior "
                            "when no image term holds (frames reported degraded; mid-flip a camera faces a blank "
                            "floor for 3-5 frames, a Mini-Cheetah flip's flight lasts ~0.3 s); 0 = never")
    gyro_prior_sigma_deg: float = _f(0.1, 0.0, 180.0,
                                     doc="with an IMU, centre the motion prior's rotation on the gyro's rotation since "
                                         "the last frame instead of the constant-rate prediction, with a sigma of "
                                         "this (the gyro's offset and noise over a frame: 1 deg/s of uncalibrated "
                                         "offset is 0.033 deg at 30 Hz), tracker.gyro_prior_relative_error x the "
                                         "turn and the change of rate x tracker.gyro_prior_time_error_s, added in "
                                         "quadrature (mid-flip the share of the turn dominates: ~0.3 deg); 0 = off "
                                         "(the gyro is then a first guess and a check only). With "
                                         "tracker.imu_translation: see there")
    gyro_prior_relative_error: float = _f(0.015, 0.0, 1.0,
                                          doc="error of the gyro's rotation over a frame as a share of it: the gyro's "
                                              "scale error and the IMU axes' misalignment with the colour camera "
                                              "(a rotation off by e turns about an axis off by e): 1 % and 0.3 deg "
                                              "per axis after calibration give ~0.012")
    gyro_prior_time_error_s: float = _f(0.0005, 0.0, 0.1,
                                        doc="error of the IMU's stamps against the colour camera's after calibration: "
                                            "the gyro's window is shifted by it, which costs the change of rate over "
                                            "the frame times it (a take-off's 300 deg/s over 0.5 ms: 0.15 deg)")
    motion_prior_huber: float = _f(2.0, 0.0, 100.0, lo_open=True,
                                   doc="Huber threshold of the motion prior (sigmas): beyond it the pull is constant")
    degraded_covariance_scale: float = _f(100.0, 1.0, 1e12, doc="factor on the covariance of a degraded frame")
    min_contrast: float = _f(2.0, 0.0, 255.0,
                             doc="standard deviation of the grey image (0-255) at 1/4 resolution below which the "
                                 "colour image is unusable (lens covered, dark, saturated): the frame is tracked on "
                                 "depth (and events) alone and reported degraded. Sensor noise alone averages to "
                                 "< 1 at that scale; measured: motion-blurred backflip frames 7.5-10, real and "
                                 "rendered scenes 20-60")


@dataclass(frozen=True)
class FusionConfig:
    """Event + RGB-D fusion (Eq. 4 with the ATS term): when it is used and how the ATS term is weighed."""

    surface: str = _f("ats", choices=("ats", "constant", "sits"),
                      doc="time surface of the event term: ats (the paper's adaptive one), constant (constant tau) "
                          "or sits (speed-invariant); the last two are ablations")
    rate_threshold_deg_s: float = _f(150.0, 0.0, 10000.0,
                                     doc="camera angular rate over the last two frames (or the gyro's) above which "
                                         "the event term is used: 5 deg per frame at 30 Hz. Measured November 2026 "
                                         "on the D455 depth model (320x240, 4 s, tuning seeds 0-4; ATE cm at 300 / "
                                         "200 / 150 / 100): bound, peaks ~260 deg/s, means 48.4 / 44.3 / 10.2 / 20.7 "
                                         "(seed 0: 39.0 -> 6.8); 2.4 s backflip 17.1 / 17.1 / 15.2 / -; running 3.8 at "
                                         "300 against 8.2 at 150 (seed 2: 7.7 -> 28.7, the others within 1.1); trot "
                                         "and pronk never reach it. On the old sharp depth 300 was better (bound "
                                         "0.99-1.38 cm against 1.23-2.59): RGB-D alone held the bound there")
    rate_threshold_gyro_deg_s: float = _f(220.0, 0.0, 10000.0,
                                          doc="the same gate when the gyro measured the rate (an IMU fed): its "
                                              "rotation puts RGB-D's alignment in its basin at higher rates, and the "
                                              "event term joining earlier cost the bounds. Measured 27 Nov 2026 "
                                              "(640x480, 2.5 s, IMU fed, tuning seeds 0-9, mean ATE cm at 150 / 190 "
                                              "/ 220 / 300): bound 2.75 / 1.77 / 1.66 / 1.81 (RGB-D alone 1.70), "
                                              "backflip 7.25 / 7.51 / 7.49 / 7.46 (seed 2 2.9 -> 11.7, seed 3 24.2 "
                                              "-> 18.6 from 190 up); running, trot, pronk unchanged")
    speed_threshold_m_s: float = _f(5.0, 0.0, 100.0,
                                    doc="camera speed over the last two frames above which the event term is used. "
                                        "Translation at v blurs a surface at depth Z as a turn at v / Z rad/s does: "
                                        "5 m/s at 1 m is a 300 deg/s turn, above a Mini-Cheetah's "
                                        "top speed (3.7 m/s). The former 1.5 m/s fused every sixth frame of a "
                                        "bound (1.2 m/s median, 1.9 peak), where the frame-to-frame event term "
                                        "only added drift (bound ATE 1.47-3.57 cm against 0.88-1.38)")
    sigma: float = _f(12.0, 0.0, 255.0, lo_open=True, doc="noise scale of an ATS residual (0-255 units)")
    huber: float = _f(15.0, 0.0, 255.0, lo_open=True, doc="Huber threshold of the ATS term")
    outlier: float = _f(40.0, 0.0, 1000.0, lo_open=True,
                        doc="RMS ATS patch residual above which an event map point is an outlier")
    gradient_weight: float = _f(0.0, 0.0, 1000.0, doc="c of the pixel weight c^2/(c^2+|grad|^2) on the ATS (0 = off)")
    min_points: int = _f(30, 1, 100000, doc="fewer event map points than this and the event term is not used")
    min_inlier_fraction: float = _f(0.3, 0.0, 1.0, doc="ATS inliers / visible below which the event term "
                                    "does not count as constraining the pose")
    max_event_rate_ev_s: float = _f(50e6, 1e3, 1e10,
                                    doc="events folded into the surface per second at most (bursts up to 50 ms "
                                        "of it): beyond, the oldest events of a batch are dropped and counted, so "
                                        "a flood (flickering light, a hot sensor) keeps the per-frame time bounded. "
                                        "Above the robot's own peaks (simulated backflip: 43 M ev/s over 10 ms; a "
                                        "20 M ev/s cap dropped up to 2.6 M events mid-flip); 50 M ev/s is ~2.5 ms "
                                        "of surface update per 33 ms frame at the measured 700 M ev/s")


@dataclass(frozen=True)
class MappingConfig:
    """Keyframes from the nine-region health rule (Section II-C) and map bookkeeping."""

    region_min_points: int = _f(20, 1, 100000, doc="tracked points that make one of the 3x3 regions healthy")
    min_healthy_regions: int = _f(7, 1, 9)
    min_tracked_fraction: float = _f(0.75, 0.0, 1.0,
                                     doc="tracked points / those right after the last keyframe below which a keyframe "
                                         "is added (frame-to-map tracking degrades fast as coverage drops)")
    max_keyframes: int = _f(6, 1, 1000, doc="keyframes in the local map")
    keyframe_culling: str = _f("covisible", choices=("oldest", "covisible"),
                               doc="which keyframes make the local map after an insertion. oldest: the newest "
                                   "mapping.max_keyframes. covisible (default): the newest "
                                   "mapping.recent_keyframes, then the newest of those, in the map or among the "
                                   "mapping.memory_keyframes retired, that see mapping.covisible_min_share of their "
                                   "points from the new keyframe's pose, so a camera back over ground it mapped "
                                   "before (a flip's landing, a hand-held sweep) tracks against those older, less "
                                   "drifted points. Measured, 10 s, 640x480, fused + IMU: development flips (seeds "
                                   "0, 10-16) mean ATE 7.20 -> 4.06 cm, held-out flips 100-102 4.20 -> 1.71; TUM "
                                   "fr1_rpy_300 0.96 -> 0.87, every 2nd / 3rd frame 1.44 / 1.45 -> 0.98 / 1.03 "
                                   "(docs/odometry.md)")
    memory_keyframes: int = _f(30, 0, 10000, doc="keyframes kept aside with their points after leaving the "
                               "local map, for mapping.keyframe_culling covisible")
    recent_keyframes: int = _f(2, 1, 1000, doc="the newest keyframes that always stay in the local map "
                               "(mapping.keyframe_culling covisible)")
    covisible_min_share: float = _f(0.5, 0.0, 1.0, doc="share of its points an older keyframe must show the new "
                                    "keyframe's camera to take a place in the local map (keyframe_culling covisible)")
    covisible_max_scale_change: float = _f(1.3, 1.0, 100.0, lo_open=True,
                                           doc="a point counts as seen only within this factor of its distance from "
                                               "its host (a patch seen much nearer or further no longer matches; "
                                               "1.15 lost half the flips' gain)")
    max_points: int = _f(6000, 100, 10000000)
    depth_edge_ratio: float = _f(0.05, 0.0, 10.0, lo_open=True,
                                 doc="reject a point whose 3x3 depth range exceeds this share of its depth")
    max_outlier_frames: int = _f(5, 1, 1000, doc="cull a map point after this many consecutive outlier frames")
    depth_window_px: int = _f(5, 1, 31, doc="a map point's depth is the mean of the valid depths in this window "
                                         "(and the depth-edge test spans it); 1 = the pixel's own depth")
    depth_points: int = _f(800, 0, 100000, doc="geometric points (smooth valid depth, regular grid) per keyframe "
                                               "for the depth term")
    window_iterations: int = _f(0, 0, 50, doc="after each keyframe, Levenberg-Marquardt steps of the joint photometric "
                                "optimisation of the local map's keyframe poses (each keyframe's image against the "
                                "others' points, the oldest held; core/tracking/window.py); 0 = off, the default; "
                                "the TUM presets run 2 while the camera is calm (tracker.calm_turn_deg): TUM "
                                "fr1_rpy_300 1.36 -> 1.15 cm with it alone, its subsamples as without "
                                "(docs/odometry.md)")
    synchronous: bool = _f(False, doc="ROS nodes: tracking waits for each keyframe it asks mapping for (what "
                           "atsvo-replay does, so node and replay agree pose for pose); false (default): tracking "
                           "goes on against the last map snapshot while mapping inserts the keyframe (PTAM)")


@dataclass(frozen=True)
class NodeConfig:
    """ROS node behaviour (ignored by the offline tools, except ``imu_max_wait_s`` in the shared runtime)."""

    event_msg_type: str = _f("event_camera_msgs/msg/EventPacket",
                             choices=("event_camera_msgs/msg/EventPacket", "event_array_msgs/msg/EventArray",
                                      "dvs_msgs/msg/EventArray", "dv_ros2_msgs/msg/EventArray"),
                             doc="message type on topics.events (libcaer_driver: EventPacket)")
    queue_size: int = _f(2, 1, 100, doc="frames waiting for the tracker; when full the oldest is dropped (counted) "
                         "and its events and IMU samples go to the next, so the odometry stays fresh; with "
                         "sensor_qos reliable and mapping.synchronous (loss-free) a full queue waits instead")
    sensor_qos: str = _f("best_effort", choices=("best_effort", "reliable"),
                         doc="QoS of the image, event and IMU subscriptions: best_effort (sensor data, keep last: "
                             "matches any publisher, a late message is dropped, never waited for; the robot) or "
                             "reliable (reliable, keep all: every message of a reliable publisher arrives, a slow "
                             "node slows the publisher down; replaying a bag where every frame must count)")
    use_imu: bool = _f(True, doc="feed topics.imu (gyro and accelerometer) to the motion prediction")
    imu_max_wait_s: float = _f(0.25, 0.0, 10.0,
                               doc="longest a paired frame waits for the IMU sample after it: an IMU this far "
                                   "behind in stamp time (and, in the node, silent this long in wall time: a "
                                   "backlog still draining is late, not dead) counts as stalled and frames go "
                                   "without gyro, counted as frames_without_imu (a dead IMU costs this much "
                                   "latency once; samples arriving after their frame are dropped, imu_late). "
                                   "When an IMU is expected (node.use_imu in the node, an IMU topic in a "
                                   "recording) the first frames wait as long for its first sample")
    publish_tf: bool = _f(True, doc="broadcast odom -> base_link on /tf")
    diagnostics_period_s: float = _f(1.0, 0.0, 3600.0, lo_open=True, doc="period of /diagnostics")
    executor: str = _f("events", choices=("events", "multi_threaded", "single_threaded"),
                       doc="rclpy executor of the node process: events (rclpy.experimental.EventsExecutor, C++; "
                           "measured to take every 1 kHz event packet where rclpy's Python executors lost 30-65 %), "
                           "or rclpy's multi_threaded / single_threaded executors. The odometry and mapping run in "
                           "their own threads either way")
    core_process: bool = _f(False, doc="atsvo_node: run the odometry core (tracking, its mapping thread, the event-map "
                            "builder) in a child process, started and warmed up before subscribing; the worker then no "
                            "longer waits for the GIL that the executor's callbacks hold (docs/nodes.md). No debug "
                            "images in this mode (the time surface lives in the child); about 250 MB more memory")
    nice: int = _f(0, -20, 19, doc="nice value for every thread of the node process, set before the odometry's "
                   "threads start; 0 = as started. Below 0 the node outweighs best-effort work on a shared "
                   "computer (nice -10: 9.3x a nice-0 process's CPU share); needs root, CAP_SYS_NICE or a nice "
                   "limit, else one warning and it runs on as started (docs/nodes.md)")
    realtime_priority: int = _f(0, 0, 99, doc="SCHED_RR real-time priority for every thread of the node process "
                                "(1-99; 0 = off): runs before all normal-priority work, the kernel's RT throttling "
                                "still leaving it 5 %. Needs root, CAP_SYS_NICE or an rtprio limit, else one warning")
    mapping_timeout_s: float = _f(5.0, 0.0, 600.0, lo_open=True,
                                  doc="tracking_node + mapping_node: a keyframe request unanswered this long is given "
                                      "up (counted); also the longest a synchronous insert waits")


@dataclass(frozen=True)
class AtsvoConfig:
    """Everything the pipeline needs; one instance is passed into the core."""

    rgb_camera: CameraConfig = field(default_factory=CameraConfig)
    event_camera: CameraConfig = field(default_factory=lambda: CameraConfig(320, 240, 270.0, 268.0, 160.0, 120.0))
    rig: RigConfig = field(default_factory=RigConfig)
    topics: TopicsConfig = field(default_factory=TopicsConfig)
    ats: AtsConfig = field(default_factory=AtsConfig)
    rgb_selection: RgbSelectionConfig = field(default_factory=RgbSelectionConfig)
    event_selection: EventSelectionConfig = field(default_factory=EventSelectionConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    node: NodeConfig = field(default_factory=NodeConfig)
    mode: str = _f("fused", choices=("fused", "rgbd"), doc="rgbd = never use events")


# ---------------------------------------------------------------------------- loading


class _ConfigLoader(yaml.SafeLoader):
    """SafeLoader that refuses what a parameter file never needs and YAML would accept silently.

    A repeated mapping key (PyYAML keeps the last one: a stray ``fx: 38.2`` wins) and aliases (``*a``:
    a dozen lines of nested aliases expand to billions of nodes) raise a one-line :class:`ConfigError`.
    """

    config_source = "config"  # names the text in messages: ``config <path>`` or ``--set 'key=value'``
    config_prefix = ""  # dotted key of the text's top level (the --set key)
    config_numbered = True  # messages give lines (a file) or columns (a one-line --set value)

    def _at(self, mark: yaml.Mark) -> str:
        return f"line {mark.line + 1}" if self.config_numbered else f"column {mark.column + 1}"

    def _problem(self, mark: yaml.Mark, text: str) -> ConfigError:
        where = f"{self.config_source}:{mark.line + 1}" if self.config_numbered else self.config_source
        return ConfigError(f"{where}: {text}")

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):  # refused before the composer resolves (and shares) it
            event = self.peek_event()
            raise self._problem(event.start_mark, f"YAML alias *{event.anchor} is not allowed in a config "
                                                  "(write the value out)")
        return super().compose_node(parent, index)

    def construct_document(self, node: yaml.Node) -> Any:
        self._check_duplicates(node, self.config_prefix)
        return super().construct_document(node)

    def _check_duplicates(self, node: yaml.Node, path: str) -> None:
        """Raise on a key repeated in one mapping, named by its dotted path below ``ros__parameters``."""
        if isinstance(node, yaml.SequenceNode):
            for item in node.value:
                self._check_duplicates(item, path)
        if not isinstance(node, yaml.MappingNode):
            return
        first: dict[tuple[str, str], yaml.Mark] = {}
        for key_node, value_node in node.value:
            name = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else "?"
            if isinstance(key_node, yaml.ScalarNode):
                seen = first.setdefault((key_node.tag, name), key_node.start_mark)
                if seen is not key_node.start_mark:
                    raise self._problem(key_node.start_mark, f"duplicate key {path}{name} (first at "
                                                             f"{self._at(seen)}; YAML would keep only the last)")
            self._check_duplicates(value_node, "" if name == "ros__parameters" else f"{path}{name}.")


def _safe_load(text: str, source: str, prefix: str = "") -> Any:
    """``yaml.safe_load`` that rejects duplicate keys and aliases, naming ``source`` and the line.

    ``prefix`` (a --set key, ``rgb_camera.``) is put before the keys named, and turns lines into columns.
    """
    loader = _ConfigLoader(text)
    loader.config_source, loader.config_prefix, loader.config_numbered = source, prefix, not prefix
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _coerce(key: str, value: Any, typ: Any, f: dataclasses.Field) -> Any:
    """Convert a YAML/ROS value to the field's type and check its range; raise ConfigError."""
    meta = f.metadata
    origin = typing.get_origin(typ)
    try:
        if origin is tuple:
            if not isinstance(value, (list, tuple)):
                raise TypeError("expected a list")
            out: Any = tuple(float(v) for v in value)
            for i, v in enumerate(out):
                if not math.isfinite(v):
                    raise ConfigError(f"{key}[{i}] is {v} (every element must be a finite number)")
            default = f.default_factory() if f.default_factory is not dataclasses.MISSING else ()
            if key.split(".")[-1].startswith("T_") and len(out) != 16:
                raise ConfigError(f"{key} = {value!r} must be a row-major 4x4 matrix (16 numbers)")
            if default and key.split(".")[-1] != "D" and len(out) != len(default):
                raise ConfigError(f"{key} = {value!r} must have {len(default)} elements")
            return out
        if typ is bool:
            if not isinstance(value, bool):
                raise TypeError("expected true or false")
            return value
        if typ is int:
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise TypeError("expected an integer")
            out = int(value)
        elif typ is float:
            if isinstance(value, bool):
                raise TypeError("expected a number")
            out = float(value)
        elif typ is str:
            if not isinstance(value, str):
                raise TypeError("expected a string")
            out = value
        else:
            out = value
    except ConfigError:
        raise
    except OverflowError:  # an integer beyond a float's range (10**400)
        raise ConfigError(f"{key} = {value!r} is out of range: {_allowed(meta) or 'too large for a number'}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{key} = {value!r} has the wrong type: {exc}") from None
    if meta.get("choices") and out not in meta["choices"]:
        raise ConfigError(f"{key} = {value!r} is not allowed (choose one of {', '.join(meta['choices'])})")
    lo, hi = meta.get("lo"), meta.get("hi")
    if isinstance(out, (int, float)) and (lo is not None or hi is not None):
        # math.isfinite, not np.isfinite: a Python int beyond int64 (1e32 written out) is no numpy number
        bad = ((isinstance(out, float) and not math.isfinite(out))
               or (lo is not None and (out <= lo if meta.get("lo_open") else out < lo))
               or (hi is not None and out > hi))
        if bad:
            raise ConfigError(f"{key} = {value!r} is out of range: {_allowed(meta)}")
    return out


def _allowed(meta: typing.Mapping[str, Any]) -> str:
    """The allowed range of a field as the messages show it (``allowed (0.0, 10.0]``), empty without one."""
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is None and hi is None:
        return ""
    return f"allowed {'(' if meta.get('lo_open') else '['}{lo}, {hi}]"


def _build(cls: type, data: dict[str, Any], prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'} must be a mapping, got {type(data).__name__}")
    types_ = _field_types(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"unknown key {prefix}{unknown[0]} (known in {prefix.rstrip('.') or 'top level'}: "
                          f"{', '.join(sorted(fields))})")
    kwargs = {}
    for name, value in data.items():
        typ = types_[name]
        if dataclasses.is_dataclass(typ):
            kwargs[name] = _build(typ, value, f"{prefix}{name}.")
        else:
            kwargs[name] = _coerce(prefix + name, value, typ, fields[name])
    obj = cls(**kwargs)
    _check_cross_fields(obj, prefix)
    return obj


def _check_cross_fields(obj: Any, prefix: str) -> None:
    if isinstance(obj, AtsConfig):
        if obj.tau_l_s > obj.tau_u_s:
            raise ConfigError(f"{prefix}tau_l_s = {obj.tau_l_s} must not exceed {prefix}tau_u_s = {obj.tau_u_s}")
        if obj.median_ksize % 2 == 0:
            raise ConfigError(f"{prefix}median_ksize = {obj.median_ksize} must be odd")
    if isinstance(obj, EventSelectionConfig) and obj.mask_median_ksize % 2 == 0:
        raise ConfigError(f"{prefix}mask_median_ksize = {obj.mask_median_ksize} must be odd")
    if isinstance(obj, RigConfig):
        if obj.depth_min_m >= obj.depth_max_m:
            raise ConfigError(f"{prefix}depth_min_m = {obj.depth_min_m} must be below "
                              f"{prefix}depth_max_m = {obj.depth_max_m}")
        for name in ("T_base_rgb", "T_rgb_event", "T_rgb_imu"):
            problem = _rigid_transform_problem(np.asarray(getattr(obj, name)).reshape(4, 4), tol=1e-4)
            if problem is not None:
                raise ConfigError(f"{prefix}{name} = {list(getattr(obj, name))} "
                                  f"is not a rigid transform: {problem}") from None


def _rigid_transform_problem(T: np.ndarray, tol: float) -> str | None:
    """Why a 4x4 matrix is not a rigid transform (None when it is): the config checks extrinsics on load."""
    if not np.all(np.isfinite(T)):
        return "pose contains NaN or inf"
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > tol or np.linalg.det(R) < 0:
        return "pose rotation block is not a proper rotation"
    if np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])).max() > tol:
        return "pose last row must be [0, 0, 0, 1]"
    return None


def config_from_dict(params: dict[str, Any]) -> AtsvoConfig:
    """Build a validated config from nested (``{'ats': {'tau_u_s': ..}}``) or dotted keys."""
    return _build(AtsvoConfig, unflatten(params), "")


def unflatten(params: dict[str, Any]) -> dict[str, Any]:
    """Turn ROS-style dotted keys (``ats.tau_u_s``) into nested dicts; nested input passes through."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        node = out
        parts = str(key).split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"key {key} conflicts with a value at {part}")
        if isinstance(value, dict):
            node.setdefault(parts[-1], {}).update(unflatten(value))
        else:
            node[parts[-1]] = value
    return out


def flatten(cfg: Any, prefix: str = "") -> dict[str, Any]:
    """Dotted-key dict of a config (what a ROS node declares as parameters)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.update(flatten(value, f"{prefix}{f.name}."))
        else:
            out[prefix + f.name] = list(value) if isinstance(value, tuple) else value
    return out


def ros_parameters(document: dict[str, Any], node_name: str | None = None) -> dict[str, Any]:
    """Merge the ``ros__parameters`` of ``/**`` and of ``node_name`` (node wins) from a YAML document."""
    if not isinstance(document, dict):
        raise ConfigError("parameter file must be a mapping of node names to ros__parameters")
    merged: dict[str, Any] = {}
    found = False
    for key in ("/**", "**", node_name, f"/{node_name}" if node_name else None):
        if key and isinstance(document.get(key), dict) and "ros__parameters" in document[key]:
            merged.update(unflatten(document[key]["ros__parameters"] or {}))
            found = True
    if not found:
        nodes = [k for k, v in document.items() if isinstance(v, dict) and "ros__parameters" in v]
        if len(nodes) == 1:
            merged = unflatten(document[nodes[0]]["ros__parameters"] or {})
        elif not nodes:
            raise ConfigError("parameter file has no 'ros__parameters' section")
        else:
            raise ConfigError(f"parameter file has several nodes ({', '.join(nodes)}); name one")
    return merged


def parse_overrides(pairs: Sequence[str]) -> dict[str, object]:
    """``['ats.tau_u_s=0.05']`` -> ``{'ats.tau_u_s': 0.05}`` (the command lines' ``--set``; values are YAML).

    Raises:
        ConfigError: A pair without ``=`` or a value that is not valid YAML, repeats a key or uses an alias.
    """
    out: dict[str, object] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ConfigError(f"--set expects KEY=VALUE, got {pair!r}")
        try:
            out[key.strip()] = _safe_load(value, f"--set {pair!r}", f"{key.strip()}.")
        except yaml.YAMLError as exc:
            raise ConfigError(f"--set {pair!r}: the value is not valid YAML "
                              f"({str(exc).splitlines()[0]})") from exc
    return out


def load_config(path: str | Path | None = None, node_name: str | None = None,
                overrides: dict[str, Any] | None = None) -> AtsvoConfig:
    """Load a ROS-parameter YAML (or a bundled preset name such as ``mini_cheetah``) into a config.

    ``path=None`` gives the defaults; ``overrides`` (dotted or nested keys) win over the file.
    """

    params: dict[str, Any] = {}
    if path is not None:
        p = resolve_config_path(path)
        try:
            data = p.read_bytes()
            document = _safe_load(data.decode("utf-8"), f"config {p}")
        except OSError as exc:
            raise ConfigError(f"cannot read config {p}: {exc.strerror or exc}") from None
        except UnicodeDecodeError as exc:
            line = data.count(b"\n", 0, exc.start) + 1
            raise ConfigError(f"config {p}:{line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                              f"{exc.start}); expected a ROS-parameter YAML file") from None
        except yaml.YAMLError as exc:
            raise ConfigError(f"cannot read config {p}: {' '.join(str(exc).split())}") from None
        try:
            params = ros_parameters(document, node_name)
            if not overrides:
                return config_from_dict(params)
        except ConfigError as exc:
            raise ConfigError(f"config {p}: {exc}") from None
    if overrides:
        params = _deep_merge(params, unflatten(overrides))
    return config_from_dict(params)


def _deep_merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def config_dir() -> Path:
    """Directory holding the bundled YAML presets (source tree, pip install or ament share)."""
    here = Path(__file__).resolve().parent
    for cand in (here / "config", here.parent / "config", Path(sys.prefix) / "share" / "atsvo_ros" / "config"):
        if (cand / "mini_cheetah.yaml").is_file():
            return cand
    try:  # installed by colcon: share/atsvo_ros/config
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory("atsvo_ros")) / "config"
    except Exception:
        return here / "config"


def resolve_config_path(path: str | Path) -> Path:
    """A file path, or the name of a bundled preset (``mini_cheetah``, ``mvsec``, ``synthetic``)."""
    p = Path(path)
    if p.is_file():
        return p
    preset = config_dir() / f"{Path(str(path)).stem}.yaml"
    if preset.is_file() and not p.suffix:
        return preset
    if p.is_dir():
        raise ConfigError(f"config file {path} is a directory, not a ROS-parameter YAML file")
    raise ConfigError(f"config file {path} not found (bundled presets: "
                      f"{', '.join(sorted(q.stem for q in config_dir().glob('*.yaml')))})")


__all__ = ["AtsConfig", "AtsvoConfig", "CameraConfig", "EventSelectionConfig", "FusionConfig", "MappingConfig",
           "NodeConfig", "RgbSelectionConfig", "RigConfig", "TopicsConfig", "TrackerConfig", "config_from_dict",
           "flatten", "load_config", "parse_overrides", "ros_parameters", "unflatten"]
