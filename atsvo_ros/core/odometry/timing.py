"""The odometry's frame timing: a frame's exposure time off the frame clock, clock jumps, the published stamp."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.frame_clock import FrameClock
from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.core.tracking.motion import MotionModel


class FrameTiming:
    """When each frame was exposed, and when its pose is published.

    Internally a frame lives at the time its image was exposed (middle row: the frame clock's time of the
    stamp plus the configured offset). The pose is published at the stamp plus the offset, the exposure
    time on the stamps' clock: only the stamp's jitter off the frame clock is extrapolated over (see
    :meth:`published`), as moving it by the offset too would add the velocity's noise for nothing.

    Args:
        time_offset_s: ``rgb_camera.time_offset_s``, exposure time minus stamp.
        frame_clock_frames: ``rgb_camera.frame_clock_frames``, the window of the :class:`FrameClock` (0 = off).
    """

    def __init__(self, time_offset_s: float, frame_clock_frames: int) -> None:
        self.offset_ns = int(round(time_offset_s * 1e9))
        self.clock = FrameClock(frame_clock_frames)
        self.shift_ns = 0  # frame-clock time minus stamp of the frame being processed (its stamp jitter)
        self.last_stamp: int | None = None

    def exposure(self, stamp_ns: int) -> int:
        """The exposure time (ns) of the frame stamped ``stamp_ns``; it becomes the frame being processed."""
        on_clock = self.clock(stamp_ns)
        self.shift_ns = on_clock - int(stamp_ns)
        return on_clock + self.offset_ns

    def check(self, stamp: int, max_gap_s: float) -> str | None:
        """Record the exposure time ``stamp``; why the motion model must be reset, or None when it need not.

        A stamp not after the previous one, or a gap over ``max_gap_s``: the velocity is unknown.
        """
        last, self.last_stamp = self.last_stamp, stamp
        if last is None:
            return None
        dt_s = (stamp - last) * 1e-9
        if dt_s <= 0:
            return f"clock jumped back by {-dt_s:.3f} s: motion model reset"
        if dt_s > max_gap_s:
            return f"{dt_s:.1f} s since the previous frame: motion model reset"
        return None

    def published(self, stamp: int, T_c_w: np.ndarray, motion: MotionModel) -> tuple[int, np.ndarray]:
        """The published stamp and ``T_c_w`` of the frame being processed: moved by its stamp jitter along the
        motion model's velocity (unchanged when the stamp lies on the frame clock)."""
        if self.shift_ns:
            T_c_w = se3_exp(-self.shift_ns * 1e-9 * motion.twist_per_s()) @ T_c_w
            stamp -= self.shift_ns
        return stamp, T_c_w


__all__ = ["FrameTiming"]
