"""Simulated IMU: exact kinematics, agreement with the gait curves, noise statistics, clocks, seeds."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from atsvo_ros.core.geometry import pose_from_tq, so3_exp, so3_log
from atsvo_ros.core.imu import ImuBatch, integrate_gyro
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.imu import STANDARD_GRAVITY, ImuModel, ImuSensor, imu_kinematics
from atsvo_ros.sim.motion import GRAVITY
from atsvo_ros.sim.sequence import SequenceSpec, Simulation

START = 1_700_000_000_000_000_000
A1, A2 = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])


def _analytic_pose(t_ns: np.ndarray) -> np.ndarray:
    """R = exp(A1 2 sin 3t) exp(A2 0.5 cos 7t), p = (cos 5t, sin 10t, 0.1 t^2) with t from START."""
    t = (np.asarray(t_ns) - START) * 1e-9
    T = np.zeros((len(t), 4, 4))
    T[:, :3, :3] = so3_exp(A1 * (2 * np.sin(3 * t))[:, None]) @ so3_exp(A2 * (0.5 * np.cos(7 * t))[:, None])
    T[:, :3, 3] = np.stack([np.cos(5 * t), np.sin(10 * t), 0.1 * t * t], -1)
    T[:, 3, 3] = 1.0
    return T


def _static_pose(t_ns: np.ndarray) -> np.ndarray:
    T = pose_from_tq(np.array([1.0, 2.0, 0.3]), np.array([0.1, -0.2, 0.3, 0.9]))
    return np.broadcast_to(T, (len(np.atleast_1d(t_ns)), 4, 4))


def _sensor(model: ImuModel, pose=_static_pose, duration_s: float = 10.0, seed: int = 0) -> ImuSensor:
    return ImuSensor(model, pose, START, START + int(duration_s * 1e9), np.random.SeedSequence(seed), GRAVITY)


def _white_only(**kw) -> ImuModel:
    return ImuModel.ideal(gyro_noise_density=ImuModel.gyro_noise_density,
                          accel_noise_density=ImuModel.accel_noise_density, **kw)


def _allan_dev(x: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """Non-overlapping Allan deviation per axis at cluster time tau."""
    m = int(round(tau_s * rate_hz))
    n = len(x) // m
    means = x[: n * m].reshape(n, m, -1).mean(axis=1)
    return np.sqrt(0.5 * np.mean(np.diff(means, axis=0) ** 2, axis=0))


def test_kinematics_are_exact_on_an_analytic_motion():
    t_ns = START + np.arange(0, 2_000_000_000, 5_000_000, dtype=np.int64) + 123
    omega, force = imu_kinematics(_analytic_pose, t_ns, GRAVITY)
    t = (t_ns - START) * 1e-9
    R2 = so3_exp(A2 * (0.5 * np.cos(7 * t))[:, None])
    omega_exact = np.einsum("nji,j->ni", R2, A1) * (6 * np.cos(3 * t))[:, None] + A2 * (-3.5 * np.sin(7 * t))[:, None]
    acc = np.stack([-25 * np.cos(5 * t), -100 * np.sin(10 * t), np.full_like(t, 0.2 + GRAVITY)], -1)
    force_exact = np.einsum("nji,nj->ni", _analytic_pose(t_ns)[:, :3, :3], acc)
    assert np.abs(omega - omega_exact).max() < 1e-9
    assert np.abs(force - force_exact).max() < 1e-5  # of up to 100 m/s^2


def _euler_rates(sim: Simulation, t_ns: np.ndarray) -> np.ndarray:
    """Body angular velocity from the yaw/pitch/roll curves (5-point differences of the scalar angles)."""
    h = 1e-4
    t = (t_ns - sim.t_start_ns) * 1e-9
    ypr = [sim.motion._evaluate(t + k * h)[1] for k in (-2, -1, 0, 1, 2)]
    y, p, r = ypr[2].T
    yd, pd, rd = ((ypr[0] - 8 * ypr[1] + 8 * ypr[3] - ypr[4]) / (12 * h)).T
    return np.stack([rd - yd * np.sin(p), pd * np.cos(r) + yd * np.sin(r) * np.cos(p),
                     -pd * np.sin(r) + yd * np.cos(r) * np.cos(p)], -1)


def _frame_errors_deg(sim: Simulation, imu: ImuBatch) -> np.ndarray:
    """Angle between the integrated gyro and the ground-truth rotation of the IMU over each 30 Hz frame."""
    frames = np.arange(imu.t_first_ns, imu.t_last_ns, 33_333_333)
    R = sim.T_world_imu(frames)[:, :3, :3]
    return np.degrees([np.linalg.norm(so3_log((R[i].T @ R[i + 1]).T @ integrate_gyro(imu, frames[i], frames[i + 1])))
                       for i in range(len(frames) - 1)])


@pytest.mark.parametrize("scenario", ["backflip", "pronk"])
def test_noise_free_gyro_is_the_angular_velocity_of_the_gait_curves(scenario):
    spec = SequenceSpec(scenario=scenario, duration_s=3.0, seed=1, imu_model=ImuModel.ideal())
    sim = Simulation(spec)
    imu = ImuBatch.concatenate(list(sim.imu()))
    assert 590 <= len(imu) <= 601
    # Angular velocity of the body from the Euler-angle curves, rotated into the IMU frame. Both are
    # finite differences: they agree to 1e-6 rad/s except within ~0.4 ms of a touchdown, where the
    # curves' third derivative jumps (still < 2e-4 rad/s, 1/20 of the gyro's white noise).
    R_body_imu = (sim.rig.T_body_rgb @ sim.rig.T_rgb_imu)[:3, :3]
    err = np.abs(imu.gyro_rad_s - _euler_rates(sim, imu.stamps_ns) @ R_body_imu).max(axis=1)
    assert np.quantile(err, 0.99) < 1e-6 and err.max() < 2e-4
    if scenario == "backflip":
        assert np.degrees(np.abs(imu.gyro_rad_s).max()) > 550.0
    # Integrating the gyro over each frame interval gives the ground-truth rotation of the IMU frame:
    # at 200 Hz within 0.05 deg (sampling of the 15-23 Hz landing vibrations), second order in the period.
    err_200 = _frame_errors_deg(sim, imu)
    fast = Simulation(dataclasses.replace(spec, imu_model=ImuModel.ideal(gyro_rate_hz=1000.0)))
    err_1000 = _frame_errors_deg(fast, ImuBatch.concatenate(list(fast.imu())))
    assert err_200.max() < 0.05 and err_1000.max() < err_200.max() / 10


def test_noise_free_accelerometer_integrates_to_the_ground_truth_velocity():
    """Strapdown check: v(t1) - v(t0) = sum of (R_world_imu f - g) dt, with the same-clock accelerometer.

    Sampled at 1 kHz: the trapezoid rule follows the trot's 19 Hz touchdown shakes (1-2 g) only at that rate.
    """
    spec = SequenceSpec(scenario="trot", duration_s=2.0, seed=3,
                        imu_model=ImuModel.ideal(gyro_rate_hz=1000.0, accel_rate_hz=0.0))
    sim = Simulation(spec)
    imu = ImuBatch.concatenate(list(sim.imu()))
    R = sim.T_world_imu(imu.stamps_ns)[:, :3, :3]
    a_world = np.einsum("nij,nj->ni", R, imu.accel_m_s2) - np.array([0.0, 0.0, GRAVITY])
    dt = np.diff(imu.stamps_ns) * 1e-9
    dv = np.cumsum(0.5 * (a_world[1:] + a_world[:-1]) * dt[:, None], axis=0)

    def velocity(t_ns):
        return (sim.T_world_imu(t_ns + 50_000)[:, :3, 3] - sim.T_world_imu(t_ns - 50_000)[:, :3, 3]) / 1e-4

    v = velocity(imu.stamps_ns)
    assert np.abs(v[1:] - v[0] - dv).max() < 2e-3  # m/s after 2 s


def test_white_noise_has_the_datasheet_density():
    model = _white_only()
    sensor = _sensor(model, duration_s=100.0)
    omega, force = imu_kinematics(_static_pose, np.array([START]), GRAVITY)
    # At rest an accelerometer reads the reaction to gravity: +9.81 m/s^2 along the world's up axis.
    np.testing.assert_allclose(omega, 0.0, atol=1e-12)
    np.testing.assert_allclose(force[0], _static_pose(START)[0, :3, :3].T @ [0.0, 0.0, GRAVITY], atol=1e-6)
    g_stamps, gyro = sensor.raw("gyro", 20_000)
    a_stamps, accel = sensor.raw("accel", 25_000)
    assert len(gyro) == 20_000 and len(accel) == 25_000
    for x, truth, sensor_name, rate in ((gyro, omega, "gyro", 200.0), (accel, force, "accel", 250.0)):
        err = x - truth
        sigma = model.white_sigma(sensor_name)
        assert np.isclose(sigma, (model.gyro_noise_density if sensor_name == "gyro" else model.accel_noise_density)
                          * np.sqrt(rate))
        np.testing.assert_allclose(err.std(axis=0), sigma, rtol=0.03)
        assert np.all(np.abs(err.mean(axis=0)) < 5 * sigma / np.sqrt(len(x)))
        # Allan deviation of white noise: density / sqrt(tau).
        density = sigma / np.sqrt(rate)
        for tau in (0.1, 1.0):
            np.testing.assert_allclose(_allan_dev(err, rate, tau), density / np.sqrt(tau), rtol=0.15)
    assert np.isclose(np.degrees(model.gyro_noise_density), 0.014)
    assert np.isclose(model.accel_noise_density / STANDARD_GRAVITY, 150e-6)


def test_bias_random_walk_and_turn_on_bias():
    walk = ImuModel.ideal(gyro_random_walk=ImuModel.gyro_random_walk, accel_random_walk=ImuModel.accel_random_walk)
    sensor = _sensor(walk, duration_s=100.0)
    omega, force = imu_kinematics(_static_pose, np.array([START]), GRAVITY)
    _, gyro = sensor.raw("gyro", 20_000)
    _, accel = sensor.raw("accel", 25_000)
    np.testing.assert_allclose(np.diff(gyro - omega, axis=0).std(axis=0), walk.gyro_random_walk / np.sqrt(200.0),
                               rtol=0.03)
    np.testing.assert_allclose(np.diff(accel - force, axis=0).std(axis=0),
                               walk.accel_random_walk / np.sqrt(250.0), rtol=0.03)
    # Turn-on bias: a constant offset per seed (what sequence.yaml records), spread as the datasheet says.
    model = ImuModel.ideal(gyro_turn_on_bias_sigma=ImuModel.gyro_turn_on_bias_sigma,
                           accel_turn_on_bias_sigma=ImuModel.accel_turn_on_bias_sigma)
    biases = []
    for seed in range(150):
        s = _sensor(model, duration_s=0.1, seed=seed)
        _, g = s.raw("gyro", 5)
        drawn = np.array(s.describe()["gyro_turn_on_bias_rad_s"])
        np.testing.assert_allclose(g - omega, np.broadcast_to(drawn, g.shape), atol=1e-9)
        biases.append(drawn)
    np.testing.assert_allclose(np.std(biases), np.radians(1.0), rtol=0.12)


def test_seeded_and_independent_of_chunking():
    model = ImuModel()
    pose = _analytic_pose
    a = ImuBatch.concatenate(list(_sensor(model, pose, 3.0, seed=5).batches(chunk_s=0.05)))
    b = ImuBatch.concatenate(list(_sensor(model, pose, 3.0, seed=5).batches(chunk_s=2.0)))
    c = ImuBatch.concatenate(list(_sensor(model, pose, 3.0, seed=6).batches()))
    np.testing.assert_array_equal(a.stamps_ns, b.stamps_ns)
    np.testing.assert_array_equal(a.gyro_rad_s, b.gyro_rad_s)
    np.testing.assert_array_equal(a.accel_m_s2, b.accel_m_s2)
    assert len(a) != len(c) or not np.array_equal(a.gyro_rad_s, c.gyro_rad_s)
    spec = SequenceSpec(scenario="running", duration_s=2.0, seed=2)
    s1, s2 = ImuBatch.concatenate(list(Simulation(spec).imu())), ImuBatch.concatenate(list(Simulation(spec).imu()))
    np.testing.assert_array_equal(s1.accel_m_s2, s2.accel_m_s2)


def test_clocks_stamps_and_united_stream():
    model = ImuModel()
    rates = []
    for seed in range(20):
        s = _sensor(model, _analytic_pose, 2.0, seed=seed)
        imu = ImuBatch.concatenate(list(s.batches()))
        d = s.describe()
        assert np.all(imu.stamps_ns % 1000 == 0) and np.all(np.diff(imu.stamps_ns) > 0)
        assert imu.t_first_ns >= START and imu.t_last_ns <= START + 2_000_000_000
        np.testing.assert_allclose(np.mean(np.diff(imu.stamps_ns)), 1e9 / d["gyro_rate_hz"], atol=1000 / (len(imu) - 1))
        rates.append((d["gyro_rate_hz"], d["accel_rate_hz"]))
    rates = np.array(rates) / [200.0, 250.0] - 1.0
    assert np.all(np.abs(rates) <= 0.06 + 1e-12) and 0.005 < rates.std() < 0.04


def test_united_accelerometer_is_interpolated_at_gyro_stamps():
    # Uniform acceleration without rotation: the specific force is constant, so interpolation is exact.
    acc = np.array([0.5, -1.0, 2.0])

    def pose(t_ns):
        t = (np.asarray(t_ns) - START) * 1e-9
        T = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
        T[:, :3, 3] = 0.5 * acc * (t * t)[:, None]
        return T

    s = _sensor(ImuModel.ideal(), pose, 1.0)
    imu = ImuBatch.concatenate(list(s.batches()))
    np.testing.assert_allclose(imu.accel_m_s2, np.broadcast_to(acc + [0, 0, GRAVITY], imu.accel_m_s2.shape), atol=1e-5)
    np.testing.assert_allclose(imu.gyro_rad_s, 0.0, atol=1e-9)
    # Linear interpolation of the 250 Hz accelerometer at the 200 Hz gyro stamps (realsense2_camera's method).
    s = _sensor(ImuModel.ideal(), _analytic_pose, 1.0)
    imu = ImuBatch.concatenate(list(s.batches()))
    s2 = _sensor(ImuModel.ideal(), _analytic_pose, 1.0)
    a_st, a_val = s2.raw("accel", 1000)
    expected = np.stack([np.interp(imu.stamps_ns - START, a_st - START, a_val[:, k]) for k in range(3)], -1)
    np.testing.assert_allclose(imu.accel_m_s2, expected, atol=1e-9)
    assert imu.t_first_ns >= a_st[0] and imu.t_last_ns <= a_st[-1]


def test_saturation_quantisation_and_jitter():
    def spin(t_ns):  # 1500 deg/s about z, 6 g along x
        t = (np.asarray(t_ns) - START) * 1e-9
        T = np.zeros((len(t), 4, 4))
        T[:, :3, :3] = so3_exp(A1 * np.radians(1500.0) * t[:, None])
        T[:, 0, 3] = 0.5 * 6 * STANDARD_GRAVITY * t * t
        T[:, 3, 3] = 1.0
        return T

    model = ImuModel()
    s = _sensor(model, spin, 0.5)
    imu = ImuBatch.concatenate(list(s.batches()))
    assert np.all(np.abs(imu.gyro_rad_s) <= model.gyro_range_rad_s + 1e-12)
    assert np.abs(imu.gyro_rad_s[:, 2]).max() == pytest.approx(np.radians(1000.0), rel=1e-3)
    lsb = 2 * model.gyro_range_rad_s / 2**16
    q = imu.gyro_rad_s / lsb
    np.testing.assert_allclose(q, np.round(q), atol=1e-6)  # gyro values are whole LSBs
    _, accel = _sensor(model, spin, 0.5).raw("accel", 50)
    assert np.abs(accel).max() <= 4 * STANDARD_GRAVITY + 1e-12
    q = accel / (8 * STANDARD_GRAVITY / 2**12)
    np.testing.assert_allclose(q, np.round(q), atol=1e-6)
    jittery = _sensor(dataclasses.replace(ImuModel.ideal(), stamp_jitter_s=20e-6, stamp_resolution_ns=1000),
                      _static_pose, 20.0)
    st, _ = jittery.raw("gyro", 4000)
    np.testing.assert_allclose(np.diff(st).std(), 20e3 * np.sqrt(2), rtol=0.1)


def test_model_validation_and_sequence_options():
    with pytest.raises(SimulationError, match="gyro rate"):
        ImuModel(gyro_rate_hz=0.0)
    with pytest.raises(SimulationError, match="accel_noise_density"):
        ImuModel(accel_noise_density=-1.0)
    with pytest.raises(SimulationError, match="jitter"):
        ImuModel(stamp_jitter_s=1e-3)
    assert list(Simulation(SequenceSpec(scenario="trot", duration_s=0.2, imu=False)).imu()) == []
    assert list(Simulation(SequenceSpec(scenario="flying", duration_s=0.2, layout="mvsec")).imu()) == []


def test_calibration_residuals_scale_turn_and_shift_the_samples():
    """The gyro's scale, the IMU's axes and its clock are off by what the seed drew, as the odometry cannot know."""
    ideal = ImuModel.ideal(accel_rate_hz=0.0)
    off = dataclasses.replace(ideal, gyro_scale_sigma=0.01, misalignment_sigma_rad=np.radians(0.3),
                              time_offset_sigma_s=0.0005)
    ref, s = _sensor(ideal, _analytic_pose, 1.0, seed=3), _sensor(off, _analytic_pose, 1.0, seed=3)
    a, b = ImuBatch.concatenate(list(ref.batches())), ImuBatch.concatenate(list(s.batches()))
    d = s.describe()
    assert 0.0 < d["misalignment_deg"] < 2.0 and 0 < abs(d["time_offset_s"]) <= 0.0015
    assert all(0.97 <= k <= 1.03 for k in d["gyro_scale"]) and d["gyro_scale"] != [1.0, 1.0, 1.0]
    # the same sampling instants (the ideal sensor has no offset: its stamps are the true times)
    true_t = b.stamps_ns - s.time_offset_ns
    omega, force = imu_kinematics(_analytic_pose, true_t, GRAVITY)
    R = s.R_nominal_true
    assert np.allclose(b.gyro_rad_s, (omega @ R) * s.gyro_scale, atol=1e-9)
    assert np.allclose(b.accel_m_s2, force @ R, atol=1e-9)
    assert b.t_first_ns >= START and b.t_last_ns <= START + 1_000_000_000  # stamps stay in the span
    assert not np.allclose(a.gyro_rad_s[:50], b.gyro_rad_s[:50], atol=1e-3)
