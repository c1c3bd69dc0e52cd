"""ImuBatch container and gyro integration against the exact rotation of an analytic motion."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import rotation_angle_rad, so3_exp, so3_log
from atsvo_ros.core.imu import ImuBatch, integrate_gyro, interpolate_gyro, preintegrate
from atsvo_ros.errors import ImuError

A1, A2 = np.array([0.0, 0.0, 1.0]), np.array([0.6, 0.8, 0.0])


def rotation(t_s: np.ndarray) -> np.ndarray:
    """R(t) = exp(A1 theta(t)) exp(A2 psi(t)): fast yaw swings plus a nodding motion (peaks ~500 deg/s)."""
    theta, psi = 1.5 * np.sin(4.0 * t_s), 0.4 * np.cos(9.0 * t_s)
    return so3_exp(A1 * theta[..., None]) @ so3_exp(A2 * psi[..., None])


def body_rate(t_s: np.ndarray) -> np.ndarray:
    """Exact angular velocity in the rotating frame: R2^T A1 theta' + A2 psi'."""
    theta_d, psi_d = 6.0 * np.cos(4.0 * t_s), -3.6 * np.sin(9.0 * t_s)
    R2 = so3_exp(A2 * (0.4 * np.cos(9.0 * t_s))[..., None])
    return np.einsum("nji,j->ni", R2, A1) * theta_d[:, None] + A2 * psi_d[:, None]


def _batch(rate_hz: float = 200.0, span_s: float = 2.0, bias: tuple[float, ...] = (0.0, 0.0, 0.0)) -> ImuBatch:
    stamps = np.round(np.arange(0.0, span_s, 1.0 / rate_hz) * 1e9).astype(np.int64) + 1_000
    t = stamps * 1e-9
    return ImuBatch(stamps, body_rate(t) + np.asarray(bias), np.zeros((len(t), 3)))


def test_batch_checks_shapes_and_slices():
    b = _batch(span_s=0.1)
    assert len(b) == 20 and b.gyro_rad_s.dtype == np.float64 and b.stamps_ns.dtype == np.int64
    assert b.is_sorted() and b.t_first_ns == 1_000
    part = b.time_slice(b.stamps_ns[3], b.stamps_ns[7])
    np.testing.assert_array_equal(part.stamps_ns, b.stamps_ns[3:7])
    both = ImuBatch.concatenate([b.select(slice(0, 5)), b.select(slice(5, None))])
    np.testing.assert_array_equal(both.gyro_rad_s, b.gyro_rad_s)
    assert len(ImuBatch.empty()) == 0 and len(ImuBatch.concatenate([])) == 0
    with pytest.raises(ImuError, match="differ in length"):
        ImuBatch(b.stamps_ns, b.gyro_rad_s[:-1], b.accel_m_s2)


def test_interpolation_is_linear_between_samples():
    b = ImuBatch([0, 10], [[0.0, 1.0, 2.0], [1.0, 3.0, 2.0]], np.zeros((2, 3)))
    np.testing.assert_allclose(interpolate_gyro(b, [0, 5, 10]), [[0, 1, 2], [0.5, 2, 2], [1, 3, 2]])
    with pytest.raises(ImuError, match="does not cover"):
        interpolate_gyro(b, [11])


@pytest.mark.parametrize("rate_hz", [200.0, 400.0, 1000.0])
def test_integration_matches_the_exact_rotation(rate_hz):
    # 1.9 s of rates up to ~340 deg/s integrated at 200 Hz: < 0.015 deg of drift (1e-3 deg over a 33 ms frame).
    tol_rad = 2.5e-4 * (200.0 / rate_hz) ** 2
    b = _batch(rate_hz)
    for t0_s, t1_s in [(0.1, 0.1333), (0.30, 0.41), (0.05, 1.95)]:
        t0, t1 = int(t0_s * 1e9) + 417, int(t1_s * 1e9) - 93  # between samples
        R_exact = rotation(np.array(t0 * 1e-9)).T @ rotation(np.array(t1 * 1e-9))
        R = integrate_gyro(b, t0, t1)
        angle = rotation_angle_rad(R_exact)
        err = rotation_angle_rad(R_exact.T @ R)
        assert err < tol_rad, (rate_hz, t0_s, t1_s, err, angle)
    assert angle > 1.0  # the long span really turns


def test_integration_error_is_second_order_in_the_sample_period():
    t0, t1 = 50_000_000, 1_950_000_000
    R_exact = rotation(np.array(t0 * 1e-9)).T @ rotation(np.array(t1 * 1e-9))
    errs = [rotation_angle_rad(R_exact.T @ integrate_gyro(_batch(r), t0, t1)) for r in (200.0, 400.0)]
    assert 3.0 < errs[0] / errs[1] < 5.0


def test_bias_is_subtracted_and_reverse_interval_inverts():
    bias = np.array([0.02, -0.01, 0.005])
    clean, biased = _batch(), _batch(bias=bias)
    t0, t1 = 200_000_123, 700_000_456
    R = integrate_gyro(clean, t0, t1)
    np.testing.assert_allclose(integrate_gyro(biased, t0, t1, bias_rad_s=bias), R, atol=1e-12)
    assert rotation_angle_rad(integrate_gyro(biased, t0, t1).T @ R) > 0.5 * np.linalg.norm(bias) * 0.5  # 0.5 s
    np.testing.assert_allclose(integrate_gyro(clean, t1, t0), R.T, atol=1e-12)
    np.testing.assert_array_equal(integrate_gyro(clean, t0, t0), np.eye(3))


def test_integration_needs_covering_sorted_samples():
    b = _batch(span_s=0.5)
    with pytest.raises(ImuError, match="does not cover"):
        integrate_gyro(b, 0, 100_000_000)  # first sample at 1 us
    with pytest.raises(ImuError, match="no IMU samples"):
        integrate_gyro(ImuBatch.empty(), 0, 1)
    shuffled = b.select(np.r_[1, 0, 2:len(b)])
    with pytest.raises(ImuError, match="must not decrease"):
        integrate_gyro(shuffled, 10_000_000, 20_000_000)


def test_gyro_rotation_holds_the_last_rate_briefly():
    from atsvo_ros.core.imu import gyro_rotation

    w = np.array([0.0, 2.0, 0.0])
    stamps = np.arange(0, 100_000_001, 5_000_000, dtype=np.int64)
    batch = ImuBatch(stamps, np.tile(w, (len(stamps), 1)), np.zeros((len(stamps), 3)))
    R = gyro_rotation(batch, 50_000_000, 103_000_000)  # 3 ms past the last sample
    assert np.allclose(so3_log(R), w * 0.053, atol=1e-9)
    R = gyro_rotation(batch, -2_000_000, 30_000_000)  # 2 ms before the first one
    assert np.allclose(so3_log(R), w * 0.032, atol=1e-9)
    with pytest.raises(ImuError):
        gyro_rotation(batch, 50_000_000, 140_000_000)  # 40 ms past it: not extrapolated
    # a depth exposed before the first frame's colour, both before the first sample: the first rate held
    R = gyro_rotation(batch, -11_000_000, -1_000_000)
    assert np.allclose(so3_log(R), w * 0.010, atol=1e-9)
    R = gyro_rotation(batch, 101_000_000, 110_000_000)  # wholly after the last one, within reach
    assert np.allclose(so3_log(R), w * 0.009, atol=1e-9)
    with pytest.raises(ImuError):
        gyro_rotation(batch, -40_000_000, -35_000_000)  # 35 ms before it: out of reach


def _position(t_s: np.ndarray) -> np.ndarray:
    """A bounding body's path (m): swaying sideways, bobbing, accelerating forward (peaks ~2.5 g)."""
    return np.stack([0.3 * np.sin(3.0 * t_s), 0.05 * np.cos(7.0 * t_s), 0.5 * t_s * t_s], axis=-1)


def _acceleration(t_s: np.ndarray) -> np.ndarray:
    return np.stack([-2.7 * np.sin(3.0 * t_s), -2.45 * np.cos(7.0 * t_s), np.ones_like(t_s)], axis=-1)


def _velocity(t_s: np.ndarray) -> np.ndarray:
    return np.stack([0.9 * np.cos(3.0 * t_s), -0.35 * np.sin(7.0 * t_s), t_s], axis=-1)


GRAVITY_W = np.array([0.0, 0.0, -9.81])


def _full_batch(rate_hz: float = 400.0, span_s: float = 2.0) -> ImuBatch:
    """Gyro and accelerometer (specific force R^T (a - g)) of the motion above, exact."""
    stamps = np.round(np.arange(0.0, span_s, 1.0 / rate_hz) * 1e9).astype(np.int64) + 1_000
    t = stamps * 1e-9
    f = np.einsum("nji,nj->ni", rotation(t), _acceleration(t) - GRAVITY_W)
    return ImuBatch(stamps, body_rate(t), f)


def test_preintegration_predicts_the_exact_motion():
    # 400 Hz samples over a 33 ms frame: position right to a fraction of a millimetre, at ~500 deg/s and 2.5 g
    b = _full_batch()
    for t0_s, t1_s in [(0.2003, 0.2336), (0.9, 0.9667), (0.5, 1.3)]:
        t0, t1 = int(t0_s * 1e9), int(t1_s * 1e9)
        pre = preintegrate(b, t0, t1)
        dt = pre.dt_s
        R0 = rotation(np.array(t0_s))
        v0, v1 = _velocity(np.array(t0_s)), _velocity(np.array(t1_s))
        p0, p1 = _position(np.array(t0_s)), _position(np.array(t1_s))
        p_pred = p0 + v0 * dt + 0.5 * GRAVITY_W * dt * dt + R0 @ pre.dp_m
        v_pred = v0 + GRAVITY_W * dt + R0 @ pre.dv_m_s
        tol = 3e-4 if dt < 0.1 else 5e-3  # m; the long span is 0.8 s of dead reckoning
        assert np.linalg.norm(p_pred - p1) < tol, (t0_s, p_pred - p1)
        assert np.linalg.norm(v_pred - v1) < 10 * tol / max(dt, 0.1), (t0_s, v_pred - v1)
        assert rotation_angle_rad(R0.T @ rotation(np.array(t1_s)) @ pre.R_i0_i1.T) < 1e-3
    # the specific force moves a frame by millimetres (gravity alone 5 mm): far above the error above
    pre = preintegrate(b, int(0.2003e9), int(0.2336e9))
    assert np.linalg.norm(pre.dp_m) > 4e-3


def test_preintegration_needs_covering_samples():
    b = _full_batch(span_s=0.2)
    with pytest.raises(ImuError, match="does not cover"):
        preintegrate(b, int(0.1e9), int(0.3e9))
    with pytest.raises(ImuError, match="forward"):
        preintegrate(b, int(0.1e9), int(0.05e9))
    short = preintegrate(b, int(0.19e9), int(0.21e9))  # 10 ms past the last sample: held
    assert short.dt_s == pytest.approx(0.02)
