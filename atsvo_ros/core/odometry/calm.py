"""Is the camera calm? The largest turn between consecutive frames over the last span.

Two refinements help slow hand-held motion and hurt fast motion, so they run only while the camera is calm:
the local window optimisation (``mapping.window_iterations``) moves the keyframes, and the map with them, by up to
a centimetre and a degree under the tracker; a lighter depth term (``tracker.calm_depth_factor``) lets sharp colour
settle the pose against a depth camera's systematic error. At 5-20 degrees per frame (TUM fr1_rpy with frames
dropped) the tracker starts near the edge of its basin: a moved map tipped one run in twelve into a lost map, and
the lighter depth term let wrong poses through. Turns per frame (not per second) are what matters: the basin is in
pixels between frames.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from atsvo_ros.core.geometry import se3_inv, so3_log


class TurnHistory:
    """The camera's turns between consecutive frames over the last ``span_ns``.

    Args:
        span_ns: how far back a fast frame counts.
    """

    def __init__(self, span_ns: int) -> None:
        self.span_ns = int(span_ns)
        self._turns: deque[tuple[int, float]] = deque()  # (stamp of the later frame, turn from the one before)
        self._last: tuple[int, np.ndarray] | None = None
        self._first_ns: int | None = None  # the first frame pushed: calm needs a whole span of frames seen

    def _turn_deg(self, T_c_w: np.ndarray) -> float:
        if self._last is None:
            return 0.0
        R = np.asarray(T_c_w, dtype=np.float64)[:3, :3] @ self._last[1][:3, :3].T
        return float(np.degrees(np.linalg.norm(so3_log(R))))

    def push(self, stamp_ns: int, T_c_w: np.ndarray) -> None:
        """Record a frame's pose (in the order the frames were tracked)."""
        if self._last is not None:
            self._turns.append((int(stamp_ns), self._turn_deg(T_c_w)))
        elif self._first_ns is None:
            self._first_ns = int(stamp_ns)
        self._last = (int(stamp_ns), np.asarray(T_c_w, dtype=np.float64).copy())
        while self._turns and self._turns[0][0] < stamp_ns - self.span_ns:
            self._turns.popleft()

    def largest_deg(self, stamp_ns: int, T_c_w: np.ndarray) -> float:
        """The largest turn within ``span_ns`` before ``stamp_ns``, this frame's (at ``T_c_w``) included."""
        recent = [t for s, t in self._turns if s >= stamp_ns - self.span_ns]
        return max([self._turn_deg(T_c_w), *recent])

    def calm(self, stamp_ns: int, T_c_w: np.ndarray, max_turn_deg: float) -> bool:
        """No turn of :meth:`largest_deg` is above ``max_turn_deg`` (<= 0: never calm), and the frames seen span
        ``span_ns`` (the first frames of a run are not calm: nothing is known of the motion yet)."""
        if max_turn_deg <= 0 or self._first_ns is None or self._first_ns > stamp_ns - self.span_ns:
            return False
        return self.largest_deg(stamp_ns, T_c_w) <= max_turn_deg

    def shift_world(self, T_wnew_wold: np.ndarray) -> None:
        """The world moved (the local window moved the map): the last pose moves with it."""
        if self._last is not None:
            self._last = (self._last[0], self._last[1] @ se3_inv(T_wnew_wold))


__all__ = ["TurnHistory"]
