"""The turn history that says when the camera is calm: no large turn between frames over the last span."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.core.odometry.calm import TurnHistory

MS = 1_000_000
FRAME = 33 * MS


def _yaw(deg: float) -> np.ndarray:
    return se3_exp(np.array([0.0, 0.0, 0.0, 0.0, np.radians(deg), 0.0]))


def _history(turns_deg: list[float], span_ms: int = 500) -> tuple[TurnHistory, float]:
    """A history of frames 33 ms apart turning by ``turns_deg`` (the first frame at yaw 0); the last yaw."""
    turns = TurnHistory(span_ms * MS)
    yaw = 0.0
    turns.push(0, _yaw(yaw))
    for k, d in enumerate(turns_deg, start=1):
        yaw += d
        turns.push(k * FRAME, _yaw(yaw))
    return turns, yaw


def test_a_fast_frame_keeps_the_camera_from_being_calm_for_the_span_then_it_is_calm_again():
    turns, yaw = _history([2.0] * 20)  # 2 deg per frame at 30 Hz for 0.66 s: calm
    now = 21 * FRAME
    assert turns.calm(now, _yaw(yaw + 2.0), 4.0)
    assert not turns.calm(now, _yaw(yaw + 6.0), 4.0)  # this frame's own turn counts
    assert turns.largest_deg(now, _yaw(yaw + 6.0)) == pytest.approx(6.0)
    yaw += 6.0
    turns.push(now, _yaw(yaw))  # one 6 deg frame
    for k in range(22, 40):
        yaw += 1.0
        turns.push(k * FRAME, _yaw(yaw))
        assert turns.calm(k * FRAME, _yaw(yaw), 4.0) == ((k - 21) * 33 > 500), k


def test_the_first_frames_are_not_calm_until_a_whole_span_was_seen():
    turns, yaw = _history([1.0] * 10)  # 0.33 s of frames
    assert not turns.calm(11 * FRAME, _yaw(yaw + 1.0), 4.0)
    for k in range(11, 17):
        yaw += 1.0
        turns.push(k * FRAME, _yaw(yaw))
    assert turns.calm(17 * FRAME, _yaw(yaw + 1.0), 4.0)  # 0.53 s seen


def test_the_turn_is_the_rotation_between_frames_not_the_heading():
    turns = TurnHistory(100 * MS)
    turns.push(0, _yaw(170.0))
    turns.push(FRAME, _yaw(173.0))
    turns.push(2 * FRAME, _yaw(176.0))
    turns.push(3 * FRAME, _yaw(179.0))
    assert turns.largest_deg(4 * FRAME, _yaw(182.0)) == pytest.approx(3.0)
    assert turns.calm(4 * FRAME, _yaw(182.0), 4.0)


def test_a_move_of_the_world_moves_the_last_pose_so_it_is_not_counted_as_a_turn():
    turns, yaw = _history([1.0] * 20)
    shift = _yaw(5.0)  # T_wnew_wold: the window turned the map by 5 deg
    turns.shift_world(shift)
    assert turns.calm(21 * FRAME, _yaw(yaw + 1.0) @ np.linalg.inv(shift), 4.0)
    assert not turns.calm(21 * FRAME, _yaw(yaw + 1.0), 4.0)  # a pose in the old world: the move counts, 6 deg


def test_a_limit_of_zero_is_never_calm():
    turns, yaw = _history([0.0] * 20)
    assert not turns.calm(21 * FRAME, _yaw(yaw), 0.0)
