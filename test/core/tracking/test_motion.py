"""The motion model's constant-velocity prior: its reach from bounded acceleration and when it is withheld."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import camera_centre, se3_exp, se3_inv
from atsvo_ros.core.tracking.motion import MotionModel

DT_NS = 33_333_333


def _T_c_w(centre_w: np.ndarray) -> np.ndarray:
    T_w_c = se3_exp(np.array([0.0, 0.0, 0.0, 0.0, 0.1, 0.0]))
    T_w_c[:3, 3] = centre_w
    return se3_inv(T_w_c)


def _model(trusted: tuple[bool, bool] = (True, True)) -> MotionModel:
    m = MotionModel()
    m.push(0, _T_c_w(np.zeros(3)), trusted[0])
    m.push(DT_NS, _T_c_w(np.array([0.04, 0.0, 0.0])), trusted[1])
    return m


def test_centre_prior_extrapolates_and_bounds_the_reach_by_the_acceleration():
    centre, reach = _model().centre_prior(2 * DT_NS, 60.0, 0.02)
    np.testing.assert_allclose(centre, [0.08, 0.0, 0.0], atol=1e-9)
    assert reach == pytest.approx(60.0 * (DT_NS * 1e-9) ** 2 + 0.02)
    # a uniformly accelerating camera lands inside the reach, for any acceleration below the bound
    a = 59.0
    ts = np.array([0, DT_NS, 2 * DT_NS]) * 1e-9
    xs = 0.5 * a * ts ** 2
    m = MotionModel()
    for t, x in zip(ts, xs):
        m.push(int(round(t * 1e9)), _T_c_w(np.array([x, 0.0, 0.0])))
    centre, reach = m.centre_prior(3 * DT_NS, 60.0, 0.0)
    true = 0.5 * a * (3 * DT_NS * 1e-9) ** 2
    assert abs(true - centre[0]) <= reach
    assert abs(true - centre[0]) == pytest.approx(a * (DT_NS * 1e-9) ** 2, rel=1e-6)  # a dt (dt + dt0) / 2


def test_a_dropped_frame_widens_the_reach():
    _, reach1 = _model().centre_prior(2 * DT_NS, 60.0, 0.0)
    _, reach2 = _model().centre_prior(3 * DT_NS, 60.0, 0.0)
    assert reach2 == pytest.approx(3.0 * reach1)  # dt (dt + dt0) / 2: 2 x 3 / 2 against 1 x 2 / 2


@pytest.mark.parametrize("trusted", [(False, True), (True, False)])
def test_no_prior_from_an_untrusted_pose(trusted):
    assert _model(trusted).centre_prior(2 * DT_NS, 60.0, 0.02) is None


def test_no_prior_without_motion_history_or_after_a_reset():
    m = MotionModel()
    assert m.centre_prior(DT_NS, 60.0, 0.02) is None
    m = _model()
    m.reset()
    m.push(2 * DT_NS, _T_c_w(np.array([0.08, 0.0, 0.0])))
    assert m.centre_prior(3 * DT_NS, 60.0, 0.02) is None  # the pose kept across the reset is not trusted
    assert camera_centre(m.predict(3 * DT_NS))[0] == pytest.approx(0.12)  # the trajectory still continues


def test_a_moved_world_moves_the_history_and_keeps_the_motion():
    m = _model()
    before = m.predict(2 * DT_NS)
    twist = m.twist_per_s()
    T_wnew_wold = se3_exp(np.array([0.01, -0.02, 0.005, 0.01, 0.0, -0.02]))
    m.shift_world(T_wnew_wold)
    # the same camera, seen from the moved world: T_c_wnew = T_c_wold T_wold_wnew
    np.testing.assert_allclose(m.predict(2 * DT_NS), before @ se3_inv(T_wnew_wold), atol=1e-12)
    np.testing.assert_allclose(m.twist_per_s(), twist, atol=1e-9)
    assert m.velocity_trusted


def test_a_repeated_prediction_is_the_same_and_the_callers_own_it():
    m = _model()
    first = m.predict(2 * DT_NS)
    first[:3, 3] += 1.0  # a caller editing its copy
    again = m.predict(2 * DT_NS)
    np.testing.assert_allclose(camera_centre(again), [0.08, 0.0, 0.0], atol=1e-12)
    assert not np.allclose(m.predict_scaled(2 * DT_NS, 0.5), again)  # another scale: another prediction
    m.predict(2 * DT_NS)
    m.push(2 * DT_NS, _T_c_w(np.array([0.10, 0.0, 0.0])))  # a new pose: the motion changed
    np.testing.assert_allclose(camera_centre(m.predict(2 * DT_NS)), [0.10, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(camera_centre(m.predict(3 * DT_NS)), [0.16, 0.0, 0.0], atol=1e-12)
