"""The odometry's IMU buffer: the last seconds of gyro samples, and the rotation they measure between two frames."""
from __future__ import annotations

from collections import deque

import numpy as np

from atsvo_ros.core.geometry import so3_log
from atsvo_ros.core.imu import ImuBatch, gyro_rotation
from atsvo_ros.errors import ImuError


class GyroBuffer:
    """IMU batches in time order, kept for :data:`BUFFER_NS`, integrated between two frame stamps.

    Args:
        R_rgb_imu: rotation of the IMU frame in the colour optical frame.
    """

    #: IMU kept for the gyro prediction: long enough to carry the rotation across a camera dropout of a few
    #: seconds (~1,200 samples at 400 Hz), when the constant-motion model knows nothing any more
    BUFFER_NS = 3_000_000_000

    def __init__(self, R_rgb_imu: np.ndarray) -> None:
        self.R_rgb_imu = R_rgb_imu
        self._batches: deque[ImuBatch] = deque()
        self._joined: ImuBatch | None = None  # the batches as one, until the next add (several queries per frame)
        # rotations asked for: a frame asks for the same interval several times, and the next frame for the last
        # frame's interval again; an add keeps those its samples cannot change
        self._rotations: dict[tuple[int, int], np.ndarray | None] = {}

    def __bool__(self) -> bool:
        """Whether any samples are buffered."""
        return bool(self._batches)

    def add(self, batch: ImuBatch) -> None:
        """Buffer a time-ordered batch (empty ones are ignored) and drop the batches older than :data:`BUFFER_NS`."""
        if len(batch) == 0:
            return
        old_last = self._batches[-1].t_last_ns if self._batches else None
        self._batches.append(batch)
        self._joined = None
        newest = batch.t_last_ns
        while self._batches and self._batches[0].t_last_ns < newest - self.BUFFER_NS:
            self._batches.popleft()
        if old_last is None or batch.t_first_ns < old_last:
            self._rotations.clear()
            return
        # a rotation between samples that were already in (no rate held past the newest) stays what it was
        first = self._batches[0].t_first_ns
        self._rotations = {k: R for k, R in self._rotations.items()
                           if R is not None and k[1] <= old_last and k[0] >= first}

    def samples(self) -> ImuBatch:
        """The buffered samples as one batch (joined once per add: several queries per frame read it)."""
        if self._joined is None:
            self._joined = ImuBatch.concatenate(list(self._batches))
        return self._joined

    def rotation(self, t0_ns: int, t1_ns: int) -> np.ndarray | None:
        """``R_i0_i1``: the IMU's rotation from ``t0_ns`` to ``t1_ns``.

        Returns:
            The 3x3 rotation, or None when no samples are buffered or they do not cover the interval.
        """
        if not self._batches:
            return None
        key = (int(t0_ns), int(t1_ns))
        if key not in self._rotations:
            try:
                self._rotations[key] = gyro_rotation(self.samples(), t0_ns, t1_ns)
            except ImuError:
                self._rotations[key] = None
        R = self._rotations[key]
        return None if R is None else R.copy()

    def camera_rotation(self, t0_ns: int, t1_ns: int) -> np.ndarray | None:
        """``R_c0_c1``: the colour camera's rotation from ``t0_ns`` to ``t1_ns`` (None as :meth:`rotation`).

        Gyro integration over one frame is accurate to a small fraction of a degree even in a backflip
        (turn-on bias ~1 deg/s adds ~0.03 deg per frame), far inside the photometric basin.
        """
        R_i0_i1 = self.rotation(t0_ns, t1_ns)
        if R_i0_i1 is None:
            return None
        return self.R_rgb_imu @ R_i0_i1 @ self.R_rgb_imu.T

    def angular_rate(self, t0_ns: int, t1_ns: int) -> float | None:
        """Mean angular rate (rad/s) from ``t0_ns`` to ``t1_ns`` (None as :meth:`rotation`)."""
        R = self.rotation(t0_ns, t1_ns)
        if R is None:
            return None
        return float(np.linalg.norm(so3_log(R))) / max((t1_ns - t0_ns) * 1e-9, 1e-9)

    def rate_change(self, t0_ns: int, t1_ns: int) -> float | None:
        """How much the angular rate (rad/s) changed from ``t0_ns`` to ``t1_ns``: twice the difference of the mean
        rates over the two halves (exact for a linear ramp); None as :meth:`rotation`."""
        mid = (int(t0_ns) + int(t1_ns)) // 2
        first, second = self.rotation(t0_ns, mid), self.rotation(mid, t1_ns)
        if first is None or second is None or mid <= t0_ns:
            return None
        half_s = (mid - int(t0_ns)) * 1e-9
        return 2.0 * float(np.linalg.norm(so3_log(second) - so3_log(first))) / half_s


__all__ = ["GyroBuffer"]
