"""Simulated MEMS IMU: exact kinematics from the motion curves plus a datasheet noise model.

The truth is the angular velocity of the IMU frame and its specific force ``R_world_imu^T (a - g)``
(gravity along the world's -z), both in the IMU frame, from 5-point central differences of the
pose curve (accurate to ~1e-6 rad/s and m/s^2, far below the sensor noise; the curves have no
closed-form derivatives). Each axis of each sensor then gets, per sample ``k`` at rate ``f``:

    y_k = clip(truth_k + b_k + n_k, +-range), quantised to the LSB
    n_k ~ N(0, (noise_density * sqrt(f))^2)          white noise (Kalibr's discrete-time convention)
    b_k = b_0 + sum_{j<=k} w_j,  w_j ~ N(0, random_walk^2 / f),  b_0 ~ N(0, turn_on_bias_sigma^2)

Gyro and accelerometer run on their own clocks (per-seed rate error and phase); stamps are the
device's microsecond clock. Like realsense2_camera with ``unite_imu_method: linear_interpolation``
the united stream has one sample per gyro sample, with the accelerometer linearly interpolated at
the gyro stamps (gyro samples outside the accelerometer's span are dropped). Everything derives
from one SeedSequence, and the output does not depend on how it is chunked.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from atsvo_ros.core.geometry import so3_exp, so3_log
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import SimulationError

STANDARD_GRAVITY = 9.80665  # m/s^2 per g, the unit of accelerometer datasheets
_DEG = np.pi / 180.0


@dataclass(frozen=True)
class ImuModel:
    """Rates and noise of the IMU; defaults: the Bosch BMI055 of a RealSense D455.

    Sources: white-noise densities, turn-on offsets (typical = 1 sigma for Bosch) and the 16-bit
    gyro / 12-bit accelerometer from the BMI055 datasheet (BST-BMI055-DS000); ranges +-1000 deg/s
    and +-4 g as the D4xx firmware configures the BMI055 (librealsense PR #2777; the chip allows
    +-2000 deg/s, +-16 g); bias random walks from an Allan-variance calibration of a D455
    (ORB-SLAM3 Examples/RGB-D-Inertial/RealSense_D455.yaml: GyroWalk, AccWalk); gyro 200 Hz and
    accelerometer 250 Hz (realsense2_camera gyro_fps / accel_fps choices 200|400 and 63|250); a
    clock-rate error of a few percent as seen in D455 logs (librealsense issue #13139: nominal
    400 Hz gyro samples 2.4345 ms apart). ``accel_rate_hz = 0`` samples the accelerometer with the
    gyro (one clock, no interpolation).

    What the rig's calibration gets wrong, drawn per seed (the odometry is given the nominal rig): the gyro's
    scale per axis, the IMU's axes against the rig's ``T_rgb_imu`` and the IMU's stamps against the cameras'.
    These are assumptions, not datasheet figures, sized for a rig calibrated as users do (librealsense's
    rs-imu-calibration for the IMU's scale and offsets, Kalibr for the camera-IMU rotation and time shift):
    1 % of scale (an uncalibrated consumer MEMS gyro is off by a few percent), 0.3 deg of rotation per axis
    and 0.5 ms of time (the D455 stamps IMU and images on one device clock). A wrong rotation turns a frame's
    gyro rotation by about its angle times the misalignment; a time shift errs by the change of rate over it,
    so both matter most at a flip's take-off.
    """

    gyro_rate_hz: float = 200.0
    accel_rate_hz: float = 250.0
    rate_error_sigma: float = 0.02  # relative clock-rate error of each sensor, drawn per seed (clipped at 3 sigma)
    gyro_noise_density: float = 0.014 * _DEG  # rad/s/sqrt(Hz)   (0.014 deg/s/sqrt(Hz))
    accel_noise_density: float = 150e-6 * STANDARD_GRAVITY  # m/s^2/sqrt(Hz)   (150 ug/sqrt(Hz))
    gyro_random_walk: float = 2.4663463419911525e-06  # rad/s^2/sqrt(Hz)
    accel_random_walk: float = 0.00012548390342628348  # m/s^3/sqrt(Hz)
    gyro_turn_on_bias_sigma: float = 1.0 * _DEG  # rad/s   (zero-rate offset +-1 deg/s)
    accel_turn_on_bias_sigma: float = 0.070 * STANDARD_GRAVITY  # m/s^2   (zero-g offset +-70 mg)
    gyro_range_rad_s: float = 1000.0 * _DEG  # saturation (0 = none)
    accel_range_m_s2: float = 4.0 * STANDARD_GRAVITY  # saturation (0 = none)
    gyro_bits: int = 16  # ADC resolution over +-range (0 = no quantisation)
    accel_bits: int = 12
    stamp_resolution_ns: int = 1000  # device clock tick
    stamp_jitter_s: float = 0.0  # extra Gaussian jitter of the reported stamps (not of the sampling)
    gyro_scale_sigma: float = 0.01  # relative scale error of each gyro axis (1 sigma, clipped at 3)
    misalignment_sigma_rad: float = 0.3 * _DEG  # IMU axes against the nominal T_rgb_imu, per axis (1 sigma)
    time_offset_sigma_s: float = 0.0005  # IMU stamps minus the cameras' for the same instant (1 sigma)

    def __post_init__(self) -> None:
        if not 1.0 <= self.gyro_rate_hz <= 10000.0:
            raise SimulationError(f"IMU gyro rate must be in [1, 10000] Hz, got {self.gyro_rate_hz}")
        if self.accel_rate_hz and not 1.0 <= self.accel_rate_hz <= 10000.0:
            raise SimulationError(f"IMU accelerometer rate must be 0 or in [1, 10000] Hz, got {self.accel_rate_hz}")
        if not 0.0 <= self.rate_error_sigma <= 0.1:
            raise SimulationError(f"IMU rate_error_sigma must be in [0, 0.1], got {self.rate_error_sigma}")
        for name in ("gyro_noise_density", "accel_noise_density", "gyro_random_walk", "accel_random_walk",
                     "gyro_turn_on_bias_sigma", "accel_turn_on_bias_sigma", "gyro_range_rad_s", "accel_range_m_s2",
                     "stamp_jitter_s", "gyro_scale_sigma", "misalignment_sigma_rad", "time_offset_sigma_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0.0):
                raise SimulationError(f"IMU {name} must be finite and >= 0, got {v}")
        for name in ("gyro_bits", "accel_bits"):
            if not 0 <= getattr(self, name) <= 32:
                raise SimulationError(f"IMU {name} must be in [0, 32], got {getattr(self, name)}")
        if not 1 <= self.stamp_resolution_ns <= 1_000_000:
            raise SimulationError(f"IMU stamp resolution must be in [1, 1e6] ns, got {self.stamp_resolution_ns}")
        fastest = max(self.gyro_rate_hz, self.accel_rate_hz)
        if self.stamp_jitter_s * fastest > 0.05 or self.stamp_resolution_ns * 1e-9 * fastest > 0.25:
            raise SimulationError("IMU stamp jitter / resolution must stay well below the sample period")

    @classmethod
    def ideal(cls, **changes) -> ImuModel:
        """Noise-free, bias-free, exact-rate, unclipped, unquantised model (tests, references)."""
        base = dict(rate_error_sigma=0.0, gyro_noise_density=0.0, accel_noise_density=0.0, gyro_random_walk=0.0,
                    accel_random_walk=0.0, gyro_turn_on_bias_sigma=0.0, accel_turn_on_bias_sigma=0.0,
                    gyro_range_rad_s=0.0, accel_range_m_s2=0.0, gyro_bits=0, accel_bits=0, stamp_resolution_ns=1,
                    gyro_scale_sigma=0.0, misalignment_sigma_rad=0.0, time_offset_sigma_s=0.0)
        return cls(**{**base, **changes})

    def white_sigma(self, sensor: str, rate_hz: float | None = None) -> float:
        """Per-sample white-noise standard deviation of ``gyro`` or ``accel`` at ``rate_hz`` (default nominal)."""
        density = self.gyro_noise_density if sensor == "gyro" else self.accel_noise_density
        rate = rate_hz or (self.gyro_rate_hz if sensor == "gyro" or not self.accel_rate_hz else self.accel_rate_hz)
        return float(density * np.sqrt(rate))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


PoseFn = Callable[[np.ndarray], np.ndarray]


def imu_kinematics(T_world_imu: PoseFn, stamps_ns: np.ndarray, gravity_m_s2: float,
                   step_ns: int = 200_000) -> tuple[np.ndarray, np.ndarray]:
    """True angular velocity (N, 3) rad/s and specific force (N, 3) m/s^2 of the IMU frame, in that frame.

    ``T_world_imu(stamps)`` gives (M, 4, 4) poses (world z up). Fourth-order central differences with
    ``step_ns``: the rotation vectors ``log(R(t)^T R(t + k h))`` for the rate, positions for the
    acceleration; truncation and round-off both stay below ~1e-6 for the gait curves at 0.2 ms.
    """
    t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    h = int(step_ns)
    offsets = np.arange(-2, 3, dtype=np.int64) * h
    T = np.asarray(T_world_imu((t[:, None] + offsets[None]).reshape(-1))).reshape(len(t), 5, 4, 4)
    R0 = T[:, 2, :3, :3]
    phi = so3_log(np.swapaxes(R0, -1, -2)[:, None] @ T[:, :, :3, :3])  # (N, 5, 3); phi[:, 2] = 0
    hs = h * 1e-9
    omega = (phi[:, 0] - 8.0 * phi[:, 1] + 8.0 * phi[:, 3] - phi[:, 4]) / (12.0 * hs)
    p = T[:, :, :3, 3] - T[:, 2:3, :3, 3]  # relative to the centre: less cancellation
    acc = (-p[:, 0] + 16.0 * p[:, 1] + 16.0 * p[:, 3] - p[:, 4]) / (12.0 * hs * hs)
    acc[:, 2] += gravity_m_s2  # a - g with g = (0, 0, -gravity)
    return omega, np.einsum("nji,nj->ni", R0, acc)


class _Channel:
    """One 3-axis sensor (gyro or accelerometer): clock, turn-on bias, random walk, white noise, ADC."""

    def __init__(self, name: str, rate_hz: float, t_start_ns: int, t_end_ns: int, density: float, walk: float,
                 bias0: np.ndarray, range_: float, bits: int, model: ImuModel, seeds: list[np.random.SeedSequence],
                 phase_frac: float, stamp_offset_ns: int = 0) -> None:
        self.name, self.rate_hz = name, rate_hz
        self.stamp_offset_ns = int(stamp_offset_ns)  # reported minus true time (the calibration's residual)
        self.period_ns = 1e9 / rate_hz
        # Times relative to the (int64) start: float64 cannot hold absolute ns stamps exactly. The sensor samples
        # the span shifted by its stamps' offset, so the reported stamps lie in the sequence's span.
        self.t_start_ns = int(t_start_ns) - self.stamp_offset_ns
        self.offset_ns = phase_frac * self.period_ns
        span = t_end_ns - t_start_ns - self.offset_ns
        self.n_total = int(np.floor(span / self.period_ns)) + 1 if span >= 0 else 0
        self.sigma_white = density * np.sqrt(rate_hz)
        self.sigma_walk = walk / np.sqrt(rate_hz)
        self.bias = np.asarray(bias0, dtype=np.float64).copy()
        self.range, self.lsb = range_, (2.0 * range_ / 2.0**bits if bits and range_ else 0.0)
        self.model = model
        self.rng_white, self.rng_walk, self.rng_stamp = (np.random.default_rng(s) for s in seeds)
        self.next = 0

    def sample_times(self, k0: int, k1: int) -> np.ndarray:
        """True sampling instants (int64 ns) of samples k0..k1-1."""
        return self.t_start_ns + np.round(self.offset_ns + np.arange(k0, k1) * self.period_ns).astype(np.int64)

    def take(self, n: int, truth_fn: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The next ``n`` samples: reported stamps (int64 ns) and measurements (n, 3)."""
        k0, k1 = self.next, min(self.next + n, self.n_total)
        self.next = k1
        t_true = self.sample_times(k0, k1)
        n = k1 - k0
        y = truth_fn(t_true)
        if self.sigma_white > 0:
            y = y + self.rng_white.standard_normal((n, 3)) * self.sigma_white
        if self.sigma_walk > 0:
            walk = self.bias + np.cumsum(self.rng_walk.standard_normal((n, 3)) * self.sigma_walk, axis=0)
            y = y + walk
            if n:
                self.bias = walk[-1]
        else:
            y = y + self.bias
        if self.range > 0:
            y = np.clip(y, -self.range, self.range)
        if self.lsb > 0:
            y = np.round(y / self.lsb) * self.lsb
        rel = (t_true - self.t_start_ns).astype(np.float64)
        if self.model.stamp_jitter_s > 0:
            rel = rel + self.rng_stamp.standard_normal(n) * (self.model.stamp_jitter_s * 1e9)
        res = self.model.stamp_resolution_ns
        # The device clock ticks every ``res`` ns (absolute multiples of it).
        stamps = self.t_start_ns + self.stamp_offset_ns + np.round(rel).astype(np.int64)
        if res > 1:
            stamps = (stamps + res // 2) // res * res
        return stamps, y


class ImuSensor:
    """The IMU stream of one sequence: ``batches()`` yields the united samples in time order.

    Args:
        model: rates and noise.
        T_world_imu: pose of the IMU frame at int64 ns stamps (vectorised).
        t_start_ns, t_end_ns: the sequence span; samples lie inside it.
        seed: SeedSequence of this sensor (turn-on biases, clock errors, noise streams).
        gravity_m_s2: the world's gravity (along -z).
    """

    def __init__(self, model: ImuModel, T_world_imu: PoseFn, t_start_ns: int, t_end_ns: int,
                 seed: np.random.SeedSequence, gravity_m_s2: float) -> None:
        self.model = model
        self.T_world_imu = T_world_imu
        self.gravity = gravity_m_s2
        setup_seed, gyro_seed, accel_seed = seed.spawn(3)
        setup = np.random.default_rng(setup_seed)
        # Setup draws in a fixed order: clock errors, phases, turn-on biases.
        err = np.clip(setup.standard_normal(2) * model.rate_error_sigma, -3 * model.rate_error_sigma,
                      3 * model.rate_error_sigma)
        phase = setup.uniform(0.0, 1.0, 2)
        b_gyro = setup.standard_normal(3) * model.gyro_turn_on_bias_sigma
        b_accel = setup.standard_normal(3) * model.accel_turn_on_bias_sigma
        # The calibration's residuals, drawn after the rest so a seed's other draws stay what they were.
        self.gyro_scale = 1.0 + np.clip(setup.standard_normal(3), -3.0, 3.0) * model.gyro_scale_sigma
        self.R_nominal_true = so3_exp(setup.standard_normal(3) * model.misalignment_sigma_rad)
        offset_ns = int(round(float(np.clip(setup.standard_normal(), -3.0, 3.0)) * model.time_offset_sigma_s * 1e9))
        self.time_offset_ns = offset_ns
        self.united = bool(model.accel_rate_hz)
        self.gyro = _Channel("gyro", model.gyro_rate_hz * (1 + err[0]), t_start_ns, t_end_ns, model.gyro_noise_density,
                             model.gyro_random_walk, b_gyro, model.gyro_range_rad_s, model.gyro_bits, model,
                             gyro_seed.spawn(3), phase[0], offset_ns)
        accel_rate = model.accel_rate_hz * (1 + err[1]) if self.united else self.gyro.rate_hz
        self.accel = _Channel("accel", accel_rate, t_start_ns, t_end_ns, model.accel_noise_density,
                              model.accel_random_walk, b_accel, model.accel_range_m_s2, model.accel_bits, model,
                              accel_seed.spawn(3), phase[1] if self.united else phase[0], offset_ns)
        self.turn_on_bias = {"gyro_rad_s": b_gyro, "accel_m_s2": b_accel}

    def _measured(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rate (scaled per axis) and specific force on the sensor's true axes, turned off the nominal ones."""
        omega, force = imu_kinematics(self.T_world_imu, t_ns, self.gravity)
        R = self.R_nominal_true  # v_true = R^T v_nominal
        return (omega @ R) * self.gyro_scale, force @ R

    def _omega(self, t_ns: np.ndarray) -> np.ndarray:
        return self._measured(t_ns)[0]

    def _force(self, t_ns: np.ndarray) -> np.ndarray:
        return self._measured(t_ns)[1]

    def describe(self) -> dict:
        """What this seed drew: actual sample rates and turn-on biases (for sequence.yaml)."""
        return {"gyro_rate_hz": round(float(self.gyro.rate_hz), 6),
                "accel_rate_hz": round(float(self.accel.rate_hz), 6),
                "united": "linear_interpolation" if self.united else "same_clock",
                "gyro_turn_on_bias_rad_s": [round(float(v), 9) for v in self.turn_on_bias["gyro_rad_s"]],
                "accel_turn_on_bias_m_s2": [round(float(v), 9) for v in self.turn_on_bias["accel_m_s2"]],
                "gyro_scale": [round(float(v), 9) for v in self.gyro_scale],
                "misalignment_deg": round(float(np.degrees(np.linalg.norm(so3_log(self.R_nominal_true)))), 6),
                "time_offset_s": self.time_offset_ns * 1e-9}

    def raw(self, sensor: str, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The next ``n`` raw samples of one sensor (``gyro`` or ``accel``) at its own stamps.

        For tests and statistics; it advances the same state as :meth:`batches`, so use a fresh sensor.
        """
        return (self.gyro.take(n, self._omega) if sensor == "gyro" else self.accel.take(n, self._force))

    def batches(self, chunk_s: float = 0.5) -> Iterator[ImuBatch]:
        """United samples in chunks of about ``chunk_s`` (the samples do not depend on the chunking)."""
        n_chunk = max(1, int(round(chunk_s * self.gyro.rate_hz)))
        if not self.united:
            while self.gyro.next < self.gyro.n_total:
                k0 = self.gyro.next
                t_true = self.gyro.sample_times(k0, min(k0 + n_chunk, self.gyro.n_total))
                omega, force = self._measured(t_true)
                stamps, gyro = self.gyro.take(len(t_true), lambda _t, w=omega: w)
                _, accel = self.accel.take(len(t_true), lambda _t, f=force: f)
                yield ImuBatch(stamps, gyro, accel)
            return
        a_stamps = np.zeros(0, np.int64)
        a_vals = np.zeros((0, 3))
        while self.gyro.next < self.gyro.n_total:
            g_stamps, g_vals = self.gyro.take(n_chunk, self._omega)
            # Accelerometer samples up to (and including) the first one at or after the chunk's last gyro stamp.
            while (not len(a_stamps) or a_stamps[-1] < g_stamps[-1]) and self.accel.next < self.accel.n_total:
                n_a = max(2, int(np.ceil((g_stamps[-1] - (a_stamps[-1] if len(a_stamps) else g_stamps[0]))
                                         * 1e-9 * self.accel.rate_hz)) + 1)
                s, v = self.accel.take(n_a, self._force)
                a_stamps, a_vals = np.concatenate([a_stamps, s]), np.concatenate([a_vals, v])
            if len(a_stamps) < 2:
                continue
            keep = (g_stamps >= a_stamps[0]) & (g_stamps <= a_stamps[-1])
            if np.any(keep):
                x = (a_stamps - a_stamps[0]).astype(np.float64)
                tq = (g_stamps[keep] - a_stamps[0]).astype(np.float64)
                accel = np.stack([np.interp(tq, x, a_vals[:, k]) for k in range(3)], axis=-1)
                yield ImuBatch(g_stamps[keep], g_vals[keep], accel)
            # Keep the accelerometer samples still needed to interpolate later gyro samples.
            j = max(int(np.searchsorted(a_stamps, g_stamps[-1], side="right")) - 1, 0)
            a_stamps, a_vals = a_stamps[j:], a_vals[j:]


__all__ = ["STANDARD_GRAVITY", "ImuModel", "ImuSensor", "imu_kinematics"]
