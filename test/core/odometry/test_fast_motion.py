"""The event term earns its place where RGB-D cannot hold, on honest sensors: a backflip, and a bound frame to frame.

320x240 colour, the D455 model's depth (active stereo under motion, exposed at its own time), the
DVXplorer model's events; ATE over the frames reported ok, cm, measured November 2026.

* A 2.4 s backflip (seed 1: stand, crouch, push-off at 1.1 s, 0.53 s of flight at up to ~590 deg/s,
  landing): fused with the ATS 11.0; RGB-D alone 91.7; fused with a constant-tau surface 20.2; fused with
  the event term weighed ~0 (``tracker.w_event`` 1e-9) 45.7. Re-measured 29 Nov (covisible local map, the old map
  kept aside through the flight's re-initialisation): ATS 14.26, RGB-D 91.65, ``w_event`` 1e-9 46.45, and
  constant tau 2.94: on this seed, without the IMU, constant tau now holds the flip better.
* The same flip with the IMU fed (the robot's D455 IMU): its gyro turns each depth image to the colour's
  time (``rig.depth_time_offset_s``; the D455 exposes depth -11.1 ms off the colour on this seed) and the
  IMU's fitted velocity moves it (``tracker.depth_time_translation``): 2.35; without either 4.23 (8.19 before the
  covisible local map of 2026-11-29; with the gyro's prior and the accelerometer's centre, the defaults since
  2026-11-27; 2.54 without them).
* A 2.5 s bound (seed 0, turns of up to ~260 deg/s at every stride), the event term joining above 150 deg/s
  (``fusion.rate_threshold_deg_s``). Frame to frame (RPE per frame, RMSE; no alignment): fused 1.20 deg and
  2.32 cm, RGB-D alone 1.83 and 3.74, the event term weighed ~0 2.25 and 4.21, a constant-tau surface 1.75 and
  2.95 (28 Nov). Over the whole run the two are alike: SE(3) over all poses 3.59 against 3.72 cm, and anchored at
  the first frame (the odom frame a controller sees) 10.2 against 7.4. Only the paper's alignment, fitted on the
  first 0.5 s, sets them apart (6.86 against 13.49): the test below therefore compares them frame to frame.
  With the IMU fed, RGB-D alone: 1.19 with the depth moved by the translation over its 14.6 ms offset,
  12.19 turned only.

They fail when the event term is switched off or weighed to nothing and when the fusion gate goes back to
300 deg/s (docs/odometry.md). Swapping the surface for constant tau no longer fails them (above): the ATS keeps
the default on the eight 10 s development flips in the robot's configuration (mean ATE 4.06 against 7.89 cm,
constant tau losing two flips; docs/events.md), which a test would have to simulate at 640x480 for 10 s.
"""
from __future__ import annotations

import pytest

from atsvo_ros.bench.tracking import run_sequence

FLIP_BOUND_CM, BOUND_BOUND_CM = 15.0, 12.0


def _runs(tmp_path_factory, name: str, imu_overrides: tuple[dict, ...] = (), **common) -> tuple[dict, ...]:
    """The fused and the RGB-D-only run of one simulated sequence (cached in a temporary folder), then a fused run
    fed the IMU for each of ``imu_overrides`` (the simulation is shared: each costs only its tracking)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("ATSVO_CACHE", str(tmp_path_factory.mktemp(name)))
    try:
        common.update(width=320, height=240, progress=False)
        runs = [run_sequence(use_events=True, **common), run_sequence(overrides={"mode": "rgbd"}, **common)]
        runs += [run_sequence(use_events=True, use_imu=True, overrides=ov, **common) for ov in imu_overrides]
        return tuple(runs)
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def flip_runs(tmp_path_factory):
    # with the IMU: the depth turned to the colour's time, and not turned
    return _runs(tmp_path_factory, "flip", ({}, {"rig.depth_time_offset_s": 0.0}), scenario="backflip", seed=1,
                 duration_s=2.4)


@pytest.fixture(scope="module")
def bound_runs(tmp_path_factory):
    # RGB-D with the IMU: the depth moved by the camera's translation over the offset as well as turned
    return _runs(tmp_path_factory, "bound", ({"mode": "rgbd"},), scenario="bound", seed=0, duration_s=2.5)


def test_fused_holds_the_flip_where_rgbd_alone_does_not(flip_runs):
    fused, rgbd = flip_runs[:2]
    assert fused["modes"].get("fused", 0) >= 15  # the event term joined through the flight
    assert fused["ate_rmse_cm"] < FLIP_BOUND_CM, fused["ate_rmse_cm"]
    assert rgbd["ate_rmse_cm"] > 2 * FLIP_BOUND_CM, rgbd["ate_rmse_cm"]
    # and in the flight itself, where RGB-D has the least to go on
    assert fused["phases"]["flight"]["ate_rmse_cm"] < rgbd["phases"]["flight"]["ate_rmse_cm"] / 3


def test_fused_tracks_the_bound_frame_to_frame_better_than_rgbd_alone(bound_runs):
    """The bound's strides, fused against RGB-D alone: each frame's motion is a third closer to the truth with the
    events (ratios 1.53 in rotation, 1.61 in translation). A ratio is asked, not an ATE: the ATE that set them apart
    (6.86 against 13.49 cm) came from the paper's alignment on the first 0.5 s (module docstring)."""
    fused, rgbd = bound_runs[:2]
    assert fused["ate_rmse_cm"] < BOUND_BOUND_CM, fused["ate_rmse_cm"]
    assert fused["modes"].get("fused", 0) >= 30  # the event term joined at the strides' turns
    for key in ("rpe_deg_per_frame_rmse", "rpe_cm_per_frame_rmse"):
        assert fused[key] < rgbd[key] / 1.3, (key, fused[key], rgbd[key])
    assert not any(fused["statuses"].get(s, 0) for s in ("lost", "reinitialised"))


def test_the_gyro_turns_the_depth_to_the_colour_time(flip_runs):
    """The D455's depth of another moment, put back at the colour's: the flip fused with the IMU 2.35 cm, not put
    back 4.23 (4 frames degraded). Before the covisible local map (``mapping.keyframe_culling`` oldest) 2.35 and
    8.19 (26 degraded): the keyframes taken back after the landing now repair part of what the unturned depth
    costs in the air. The bound sits between the two (29 Nov)."""
    turned, unturned = flip_runs[2:]
    assert turned["ate_rmse_cm"] < 3.2, turned["ate_rmse_cm"]
    assert unturned["ate_rmse_cm"] > 3.2, unturned["ate_rmse_cm"]


def test_the_depth_moves_by_the_translation_over_its_offset(bound_runs):
    """The bound's depth is exposed 14.6 ms after its colour (1-2 m/s: 1.5-3 cm): moved by the IMU's fitted
    velocity as well as turned by the gyro, RGB-D ATE 1.19 cm; turned only (``tracker.depth_time_translation``
    off), 12.19, which fails here (the off run is not repeated: it would cost the suite a tracking run). Fused
    with the IMU, 1.16."""
    moved = bound_runs[2]
    assert moved["ate_rmse_cm"] < 3.5, moved["ate_rmse_cm"]
    assert not any(moved["statuses"].get(s, 0) for s in ("lost", "reinitialised"))
