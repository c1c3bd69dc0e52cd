"""Fed the D455's IMU, the robot's configuration: the gyro gates the event term, carries the flight, and a map the
flight starved is refilled.

Split from test_fast_motion.py so that pytest-xdist's workers (``--dist loadfile``) share the simulations: each
module's fixtures simulate several seconds of 848x480 active stereo. Figures: ATE over the frames reported ok, cm,
measured November 2026 (see each test).
"""
from __future__ import annotations

import pytest

from atsvo_ros.bench.tracking import run_sequence


def _robot_run(tmp_path_factory, scenario: str, seed: int, duration_s: float = 2.5) -> dict:
    """A sequence (2.5 s by default) at the D455's 640x480, fused, the IMU fed (the robot's configuration)."""
    mp = pytest.MonkeyPatch()
    mp.setenv("ATSVO_CACHE", str(tmp_path_factory.mktemp(f"{scenario}640")))
    try:
        return run_sequence(scenario=scenario, seed=seed, duration_s=duration_s, width=640, height=480,
                            progress=False, use_events=True, use_imu=True)
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def robot_bound(tmp_path_factory):
    return _robot_run(tmp_path_factory, "bound", 0)


@pytest.fixture(scope="module")
def robot_flip(tmp_path_factory):
    # seed 3: the tuning seed whose flight coasted furthest
    return _robot_run(tmp_path_factory, "backflip", 3)


def test_with_the_gyro_the_event_term_waits_for_faster_turns(robot_bound):
    """Fed the IMU, the fused bound holds within RGB-D's reach: the event term joins from 220 deg/s measured by the
    gyro (``fusion.rate_threshold_gyro_deg_s``), at the strides' peaks only. Measured 0.76 cm (RGB-D + IMU 0.58);
    with the 150 deg/s of the gate without a gyro, 3.71, the event term on 33 of 76 frames (at 320x240 the two
    are alike: 1.74 and 1.77)."""
    fused = robot_bound
    assert fused["ate_rmse_cm"] < 2.0, fused["ate_rmse_cm"]
    assert 0 < fused["modes"].get("fused", 0) < 30, fused["modes"]
    assert not any(fused["statuses"].get(s, 0) for s in ("lost", "reinitialised"))


def test_the_imu_carries_the_flight_with_the_gyros_prior_and_the_accelerometers_centre(robot_flip):
    """Fed the IMU, the flip's rotation is held to the gyro's (``tracker.gyro_prior_sigma_deg``) and its centre
    predicted by the accelerometer (``tracker.imu_translation``): 6.69 cm. Neither: 18.61 (the depth term pulls the
    coasting frames past the flight's peak 6-11 cm a frame off, and constant velocity carries that on); the
    accelerometer alone 16.14; the gyro's prior alone 35.65 (tuning seeds 0-9: docs/odometry.md)."""
    flip = robot_flip
    assert flip["ate_rmse_cm"] < 8.0, flip["ate_rmse_cm"]
    assert flip["modes"].get("fused", 0) >= 10, flip["modes"]
    assert not any(flip["statuses"].get(s, 0) for s in ("lost", "reinitialised"))


@pytest.fixture(scope="module")
def harder_flip(tmp_path_factory):
    """A 3 s flip on harder sensors (15 ms exposure, contrast threshold 0.3, 1 noise event per pixel and second, a
    dim room), fused, the IMU fed: the flight's keyframes take blurred colour and few points."""
    mp = pytest.MonkeyPatch()
    mp.setenv("ATSVO_CACHE", str(tmp_path_factory.mktemp("hardflip")))
    try:
        return run_sequence(scenario="backflip", seed=1, duration_s=3.0, width=320, height=240, progress=False,
                            use_events=True, use_imu=True, sensors={"exposure_s": 0.015, "contrast": 0.3,
                                                                    "noise_rate_hz": 1.0, "ambient_ir": 0.1})
    finally:
        mp.undo()


def test_a_map_the_flight_starved_is_refilled_once_the_robot_stands(harder_flip):
    """After the landing the map holds 42 points, 19 in view: colour alone fails for want of points while the few it
    sees agree with the image, and the fused retry holds the pose. That frame is trusted (it is slow and its colour
    is sharp), so it refills the map and colour tracking takes over again. Measured: every frame ok (at 640x480,
    tuning seed 1: 2.61 -> 2.90 cm). Mutation (such a frame stays degraded, as every fused retry did before): the
    last 25 frames, the robot standing, stay degraded because degraded frames make no keyframe."""
    flip = harder_flip
    assert flip["statuses"].get("degraded", 0) <= 3, flip["statuses"]
    assert not any(flip["statuses"].get(s, 0) for s in ("lost", "reinitialised"))

