"""The motion prior: its normal equations, and in the tracker it decides only what the data leaves free."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import TrackerConfig
from atsvo_ros.core.geometry import se3_exp, se3_inv, se3_log
from atsvo_ros.core.tracking.residuals import BlockSystem
from atsvo_ros.core.tracking.residuals.prior import MotionPrior
from atsvo_ros.core.tracking.tracker import Tracker
from atsvo_ros.errors import TrackingError


class _Quadratic:
    """A stand-in residual block: ``sqrt(weight) (log(T T_target^-1))[rows]``, seen on levels ``>= first_level``.

    ``rows`` picks the twist components the "data" constrains (a plane facing the camera: z, rot x, rot y).
    """

    estimate_affine = False

    def __init__(self, name, T_target, rows, weight=1e6, levels=3, first_level=0):
        self.name, self.T_target, self.rows, self.weight = name, T_target, list(rows), weight
        self.levels, self.first_level = levels, first_level
        self.state = np.zeros(1, np.int8)

    @property
    def n_levels(self) -> int:
        return self.levels

    def __len__(self) -> int:
        return 1

    def linearise(self, level, T, affine, relax=1.0) -> BlockSystem:
        if level < self.first_level:
            return BlockSystem(np.zeros((6, 6)), np.zeros(6), 0.0, 0, 0, 0, 0.0)
        n = 100  # as many inliers as a real block (the tracker stops below 6)
        r = se3_log(T @ se3_inv(self.T_target))
        S = np.zeros((6, 6))
        S[self.rows, self.rows] = self.weight
        return BlockSystem(S, S @ r, float(r @ S @ r), n, n, n * len(self.rows), float(r @ S @ r))


TARGET = se3_exp(np.array([0.03, -0.02, 0.05, 0.02, -0.03, 0.04]))
PREDICTED = se3_exp(np.array([0.01, 0.01, 0.02, 0.0, 0.0, 0.01]))
PLANE = (2, 3, 4)


def test_the_prior_is_zero_at_the_prediction_and_whitened_around_it():
    prior = MotionPrior(PREDICTED, 0.02, 0.03)
    at = prior.linearise(PREDICTED)
    assert at.energy == pytest.approx(0.0, abs=1e-18) and np.allclose(at.g, 0.0)
    assert np.allclose(np.diag(at.H), [1 / 0.02 ** 2] * 3 + [1 / 0.03 ** 2] * 3)
    T = se3_exp(np.array([0.01, 0, 0, 0, 0, 0.006])) @ PREDICTED  # 0.5 sigma in each part
    near = prior.linearise(T)
    r = se3_log(T @ se3_inv(PREDICTED))
    assert np.allclose(near.g, near.H @ r) and near.energy == pytest.approx(0.25 + 0.04)


def test_beyond_the_huber_threshold_the_pull_stays_constant():
    prior = MotionPrior(PREDICTED, 0.01, 0.01, huber=2.0)
    g = [np.linalg.norm(prior.linearise(se3_exp(np.array([d, 0, 0, 0, 0, 0])) @ PREDICTED).g) for d in (0.05, 0.2)]
    assert g[0] == pytest.approx(g[1], rel=1e-6) == pytest.approx(2.0 / 0.01)


def test_the_prior_decides_only_what_the_data_leaves_free():
    data = _Quadratic("plane", TARGET, PLANE)
    tracker = Tracker(TrackerConfig())
    alone = tracker.track([data], [PREDICTED])
    assert alone.singular  # a plane leaves three directions free: without a prior the system is singular
    res = tracker.track([data], [PREDICTED], prior=MotionPrior(PREDICTED, 0.02, np.radians(2.0)))
    e_target = se3_log(res.T_rgb_w @ se3_inv(TARGET))
    e_pred = se3_log(res.T_rgb_w @ se3_inv(PREDICTED))
    assert np.abs(e_target[list(PLANE)]).max() < 1e-4  # the data's directions follow the data
    assert np.abs(e_pred[[0, 1, 5]]).max() < 3e-3  # the free ones stay at the prediction
    # the covariance reports what the data supports, not the prior: the free directions stay unknown
    assert np.diag(res.covariance)[[0, 1, 5]].min() > 1e3


def test_strong_data_overrides_a_wrong_prediction():
    far = se3_exp(np.array([0.1, 0, 0, 0.1, 0, 0])) @ TARGET  # 5 cm-sigmas and 6 deg off: a landing's impact
    res = Tracker(TrackerConfig()).track([_Quadratic("all", TARGET, range(6))], [far],
                                         prior=MotionPrior(far, 0.02, np.radians(2.0)))
    assert np.abs(se3_log(res.T_rgb_w @ se3_inv(TARGET))).max() < 1e-3


def test_tracking_starts_on_the_coarsest_level_where_a_block_sees_points():
    # mid-flip the 5-level RGB and depth terms see nothing; the 4-level ATS term still does
    blind = _Quadratic("depth", TARGET, range(6), levels=5, first_level=9)
    ats = _Quadratic("ats", TARGET, range(6), levels=4)
    res = Tracker(TrackerConfig()).track([blind, ats], [PREDICTED])
    assert np.abs(se3_log(res.T_rgb_w @ se3_inv(TARGET))).max() < 1e-4
    with pytest.raises(TrackingError, match="no initial guess sees any map point"):
        Tracker(TrackerConfig()).track([blind], [PREDICTED])
