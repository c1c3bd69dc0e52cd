"""The turn history that keeps the local window closed while the camera turns fast between frames."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.core.odometry.calm import TurnHistory

MS = 1_000_000


def _yaw(deg: float) -> np.ndarray:
    return se3_exp(np.array([0.0, 0.0, 0.0, 0.0, np.radians(deg), 0.0]))


def test_a_fast_frame_keeps_the_window_closed_for_the_span_then_it_opens():
    turns = TurnHistory(500 * MS, 4.0)
    yaw = 0.0
    for k in range(10):  # 2 deg per frame at 30 Hz: calm
        yaw += 2.0
        turns.push(k * 33 * MS, _yaw(yaw))
    assert turns.calm(10 * 33 * MS, _yaw(yaw + 2.0))
    assert not turns.calm(10 * 33 * MS, _yaw(yaw + 6.0))  # this frame's own turn counts
    yaw += 6.0
    turns.push(10 * 33 * MS, _yaw(yaw))  # one 6 deg frame at 330 ms
    for k in range(11, 26):
        yaw += 1.0
        turns.push(k * 33 * MS, _yaw(yaw))
        assert turns.calm(k * 33 * MS, _yaw(yaw)) == (k * 33 > 330 + 500), k


def test_the_turn_is_the_rotation_between_frames_not_the_heading():
    turns = TurnHistory(500 * MS, 4.0)
    turns.push(0, _yaw(170.0))
    turns.push(33 * MS, _yaw(173.0))
    assert turns.calm(66 * MS, _yaw(176.0))
    assert turns._turns[-1][1] == pytest.approx(3.0)


def test_a_move_of_the_world_moves_the_last_pose_so_it_is_not_counted_as_a_turn():
    turns = TurnHistory(500 * MS, 4.0)
    turns.push(0, _yaw(0.0))
    shift = _yaw(5.0)  # T_wnew_wold: the window turned the map by 5 deg
    turns.shift_world(shift)
    assert turns.calm(33 * MS, _yaw(1.0) @ np.linalg.inv(shift))


def test_a_limit_of_zero_never_calls_it_calm():
    turns = TurnHistory(500 * MS, 0.0)
    turns.push(0, _yaw(0.0))
    assert not turns.calm(33 * MS, _yaw(0.0))
