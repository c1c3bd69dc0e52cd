"""ImuBatch: time-stamped gyro and accelerometer samples of one IMU, and gyro integration.

Samples are expressed in the IMU frame: ``gyro_rad_s`` is the angular velocity of the IMU frame
(relative to the world), ``accel_m_s2`` the specific force an accelerometer measures (acceleration
minus gravity: about +9.81 m/s^2 along the up axis at rest). No I/O here; readers live in
:mod:`atsvo_ros.io.imu`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from atsvo_ros.core._imu_kernels import _integrate_gyro, _preintegrate_span
from atsvo_ros.core.geometry import project_to_so3
from atsvo_ros.errors import ImuError


@dataclass(frozen=True)
class ImuBatch:
    """IMU samples as parallel arrays: ``stamps_ns`` int64 (N,), ``gyro_rad_s`` and ``accel_m_s2`` float64 (N, 3)."""

    stamps_ns: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_ns, dtype=np.int64).reshape(-1)
        gyro = np.asarray(self.gyro_rad_s, dtype=np.float64).reshape(-1, 3)
        accel = np.asarray(self.accel_m_s2, dtype=np.float64).reshape(-1, 3)
        if not len(stamps) == len(gyro) == len(accel):
            raise ImuError(f"IMU arrays differ in length: {len(stamps)} stamps, {len(gyro)} gyro and "
                           f"{len(accel)} accel samples")
        object.__setattr__(self, "stamps_ns", stamps)
        object.__setattr__(self, "gyro_rad_s", gyro)
        object.__setattr__(self, "accel_m_s2", accel)

    @classmethod
    def empty(cls) -> ImuBatch:
        """A batch without samples."""
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))

    @classmethod
    def concatenate(cls, batches: list[ImuBatch]) -> ImuBatch:
        """Join batches in the given order."""
        if not batches:
            return cls.empty()
        return cls(np.concatenate([b.stamps_ns for b in batches]), np.concatenate([b.gyro_rad_s for b in batches]),
                   np.concatenate([b.accel_m_s2 for b in batches]))

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def t_first_ns(self) -> int:
        return int(self.stamps_ns[0]) if len(self) else 0

    @property
    def t_last_ns(self) -> int:
        return int(self.stamps_ns[-1]) if len(self) else 0

    def is_sorted(self) -> bool:
        """True when stamps never decrease."""
        return bool(len(self) < 2 or np.all(np.diff(self.stamps_ns) >= 0))

    def select(self, mask: np.ndarray | slice) -> ImuBatch:
        """Sub-batch by boolean mask, index array or slice."""
        return ImuBatch(self.stamps_ns[mask], self.gyro_rad_s[mask], self.accel_m_s2[mask])

    def time_slice(self, t_start_ns: int, t_end_ns: int) -> ImuBatch:
        """Samples with ``t_start_ns <= stamp < t_end_ns`` (binary search: the batch must be sorted)."""
        i0, i1 = np.searchsorted(self.stamps_ns, [t_start_ns, t_end_ns], side="left")
        return self.select(slice(int(i0), int(i1)))


def _check_covers(batch: ImuBatch, t0_ns: int, t1_ns: int) -> None:
    if len(batch) == 0:
        raise ImuError("no IMU samples to integrate")
    if not batch.is_sorted():
        raise ImuError("IMU stamps must not decrease")
    if t0_ns < batch.t_first_ns or t1_ns > batch.t_last_ns:
        raise ImuError(f"IMU samples span [{batch.t_first_ns}, {batch.t_last_ns}] ns, which does not cover "
                       f"[{t0_ns}, {t1_ns}] ns")


def _around(batch: ImuBatch, t0_ns: int, t1_ns: int) -> ImuBatch:
    """The samples linear interpolation from ``t0_ns`` to ``t1_ns`` needs: those between and one on each side.

    ``np.interp`` over them equals ``np.interp`` over the whole batch there; the odometry keeps 3 s of IMU
    (~1,200 samples) and interpolates over one frame's ~15 several times a frame.
    """
    i0 = max(int(np.searchsorted(batch.stamps_ns, t0_ns, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(batch.stamps_ns, t1_ns, side="left")) + 1, len(batch))
    return batch.select(slice(i0, i1))


def interpolate_gyro(batch: ImuBatch, t_ns: np.ndarray) -> np.ndarray:
    """Angular velocity (M, 3) at stamps ``t_ns``, linear between samples; stamps must lie inside the batch."""
    t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
    _check_covers(batch, int(t.min()), int(t.max()))
    part = _around(batch, int(t.min()), int(t.max()))
    x = (part.stamps_ns - batch.stamps_ns[0]).astype(np.float64)
    tq = (t - batch.stamps_ns[0]).astype(np.float64)
    return np.stack([np.interp(tq, x, part.gyro_rad_s[:, k]) for k in range(3)], axis=-1)


def integrate_gyro(batch: ImuBatch, t0_ns: int, t1_ns: int, bias_rad_s: np.ndarray | None = None) -> np.ndarray:
    """Rotation ``R_imu0_imu1`` (3x3) of the IMU frame from ``t0_ns`` to ``t1_ns`` from its gyro samples.

    The angular velocity (minus ``bias_rad_s``) is taken linear between samples (interpolated at
    ``t0``/``t1``); each interval adds the rotation vector ``(w_a + w_b) / 2 dt + (w_a x w_b) dt^2 / 12``,
    the exact third-order expansion for a linear rate (midpoint rule plus the coning term).
    ``t1 < t0`` gives the inverse rotation. Raises :class:`ImuError` when the samples do not cover
    the interval.
    """
    t0_ns, t1_ns = int(t0_ns), int(t1_ns)
    if t1_ns < t0_ns:
        return integrate_gyro(batch, t1_ns, t0_ns, bias_rad_s).T
    _check_covers(batch, t0_ns, t1_ns)
    return _rotation(batch, t0_ns, t1_ns, bias_rad_s)


def _rotation(batch: ImuBatch, t0_ns: int, t1_ns: int, bias_rad_s: np.ndarray | None = None) -> np.ndarray:
    """The kernel's rotation from ``t0_ns`` to ``t1_ns`` (rates held beyond the samples), re-orthonormalised."""
    if t1_ns == t0_ns:
        return np.eye(3)
    bias = np.zeros(3) if bias_rad_s is None else np.asarray(bias_rad_s, dtype=np.float64).reshape(3)
    part = _around(batch, t0_ns, t1_ns)
    return project_to_so3(_integrate_gyro(part.stamps_ns, np.ascontiguousarray(part.gyro_rad_s), t0_ns, t1_ns,
                                          np.ascontiguousarray(bias)))


def gyro_rotation(batch: ImuBatch, t0_ns: int, t1_ns: int, max_extrapolation_ns: int = 30_000_000) -> np.ndarray:
    """:func:`integrate_gyro` from ``t0_ns`` to ``t1_ns``, holding the first/last rate up to ``max_extrapolation_ns``.

    A frame is often processed before the IMU sample after its stamp has arrived (at 200 Hz the last one
    is up to 5 ms old, plus transport), and the first frame (and a depth exposed before it) may precede the
    first sample; over a few milliseconds the rate barely changes. Raises :class:`ImuError` when the samples
    miss the interval by more.
    """
    t0_ns, t1_ns = int(t0_ns), int(t1_ns)
    if len(batch) == 0:
        raise ImuError("no IMU samples to integrate")
    a, b = max(t0_ns, batch.t_first_ns), min(t1_ns, batch.t_last_ns)
    if a - t0_ns > max_extrapolation_ns or t1_ns - b > max_extrapolation_ns:
        return integrate_gyro(batch, t0_ns, t1_ns)  # raises with the spans
    if t1_ns < t0_ns:
        return gyro_rotation(batch, t1_ns, t0_ns, max_extrapolation_ns).T
    if not batch.is_sorted():
        raise ImuError("IMU stamps must not decrease")
    return _rotation(batch, t0_ns, t1_ns)


@dataclass(frozen=True)
class Preintegration:
    """What the IMU measured from ``t0`` to ``t1``, in the IMU frame at ``t0`` and without gravity.

    With ``R_w_i0`` the IMU's orientation at ``t0``, its velocity and position at ``t1`` are
    ``v1 = v0 + g_w dt + R_w_i0 dv_m_s`` and ``p1 = p0 + v0 dt + g_w dt^2 / 2 + R_w_i0 dp_m``.
    """

    dt_s: float
    R_i0_i1: np.ndarray
    dv_m_s: np.ndarray
    dp_m: np.ndarray


def preintegrate(batch: ImuBatch, t0_ns: int, t1_ns: int, max_extrapolation_ns: int = 30_000_000) -> Preintegration:
    """Integrate gyro and accelerometer from ``t0_ns`` to ``t1_ns`` (``t1 >= t0``).

    Rates and specific forces are linear between samples and held for up to ``max_extrapolation_ns``
    beyond the first or last sample (a frame's IMU cut ends at its exposure time). Raises
    :class:`ImuError` when the samples miss the interval by more.
    """
    t0_ns, t1_ns = int(t0_ns), int(t1_ns)
    if t1_ns < t0_ns:
        raise ImuError(f"preintegration runs forward in time, not from {t0_ns} to {t1_ns} ns")
    if len(batch) == 0:
        raise ImuError("no IMU samples to integrate")
    if batch.t_first_ns - t0_ns > max_extrapolation_ns or t1_ns - batch.t_last_ns > max_extrapolation_ns:
        raise ImuError(f"IMU samples span [{batch.t_first_ns}, {batch.t_last_ns}] ns, which does not cover "
                       f"[{t0_ns}, {t1_ns}] ns")
    part = _around(batch, t0_ns, t1_ns)
    out = _preintegrate_span(part.stamps_ns, np.ascontiguousarray(part.gyro_rad_s),
                             np.ascontiguousarray(part.accel_m_s2), t0_ns, t1_ns)
    return Preintegration((t1_ns - t0_ns) * 1e-9, project_to_so3(out[:9].reshape(3, 3)), out[9:12].copy(),
                          out[12:].copy())


__all__ = ["ImuBatch", "Preintegration", "gyro_rotation", "integrate_gyro", "interpolate_gyro", "preintegrate"]
