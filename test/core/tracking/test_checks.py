"""The consistency checks on a tracking result: each rule alone turns an estimate degraded or lost."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.core.tracking.checks import DEGRADED, LOST, OK, Priors, judge
from atsvo_ros.core.tracking.residuals.prior import MotionPrior
from atsvo_ros.core.tracking.tracker import BlockStats, TrackResult

CFG = load_config("synthetic")


def _result(**changes) -> TrackResult:
    base = TrackResult(np.eye(4), {"rgb": (0.0, 0.0)}, np.eye(6) * 1e-6, 100.0, 900, 1000, 1000, 12, True, 0,
                       {"rgb": np.ones(1000, np.int8)},
                       {"rgb": BlockStats(1000, 1000, 900, 50.0, 40.0, 8100),
                        "depth": BlockStats(800, 700, 690, 30.0, 20.0, 690)})
    return dataclasses.replace(base, **changes)


I4 = np.eye(4)


def _judge(res=None, T=I4, ref=I4, aff=((0.0, 0.0), (0.0, 0.0)), zncc=0.9, gyro=None, centre=None):
    priors = Priors(gyro, *(centre or (None, float("inf"))))
    return judge(CFG, res or _result(), T, ref, aff[0], aff[1], zncc if isinstance(zncc, dict) else {"rgb": zncc},
                 priors)


def test_a_good_estimate_is_ok():
    v = _judge()
    assert v.level == OK and v.reason is None


@pytest.mark.parametrize("kwargs, level, words", [
    ({"res": _result(covariance=np.full((6, 6), np.nan))}, LOST, "NaN"),
    ({"res": _result(singular=True)}, LOST, "singular"),
    ({"res": _result(blocks={"rgb": BlockStats(1000, 1000, 200, 1, 1, 1)})}, LOST, "photometric inliers"),
    ({"res": _result(covariance=np.eye(6) * 0.01)}, LOST, "degenerate"),
    ({"aff": ((0.0, 0.0), (np.log(3.0), 0.0))}, LOST, "gain"),
    ({"T": se3_exp(np.array([0.8, 0, 0, 0, 0, 0]))}, LOST, "jump"),
    ({"zncc": 0.1}, LOST, "ZNCC"),  # below lost_zncc 0.15
    ({"zncc": 0.25}, DEGRADED, "ZNCC"),  # below min_zncc 0.3
    ({"gyro": se3_exp(np.array([0, 0, 0, 0.0, 0.06, 0]))}, DEGRADED, "gyro"),
    ({"centre": (np.array([0.0, 0.0, 0.12]), 0.085)}, DEGRADED, "constant-velocity"),
    ({"res": _result(blocks={"rgb": BlockStats(1000, 1000, 900, 1, 1, 1),
                             "depth": BlockStats(800, 700, 100, 1, 1, 1)})}, DEGRADED, "depth term"),
])
def test_each_rule_alone(kwargs, level, words):
    v = _judge(**kwargs)
    assert v.level == level and words in v.reason, v


def test_agreement_with_the_gyro_within_its_tolerance_is_ok():
    assert _judge(gyro=se3_exp(np.array([0, 0, 0, 0.0, 0.02, 0]))).level == OK  # 1.1 deg < 2 deg


def test_a_centre_within_the_acceleration_reach_is_ok():
    assert _judge(centre=(np.array([0.0, 0.05, 0.0]), 0.085)).level == OK


def test_zncc_of_a_term_too_small_to_count_does_not_lose_the_frame():
    # Mid-flip: a dozen blurred colour patches (fewer than min_inliers) correlate with nothing while the ATS
    # term holds the pose; the frame is judged on the ATS term.
    blocks = {"rgb": BlockStats(12, 12, 12, 1, 1, 1), "ats": BlockStats(331, 331, 330, 1, 1, 1),
              "depth": BlockStats(800, 389, 389, 1, 1, 1)}
    assert _judge(res=_result(blocks=blocks), zncc={"rgb": 0.05, "ats": 0.7}).level == OK
    # the same correlation on a colour term that carries the pose: lost
    carrying = {**blocks, "rgb": BlockStats(1000, 1000, 900, 1, 1, 1)}
    v = _judge(res=_result(blocks=carrying), zncc={"rgb": 0.05, "ats": float("nan")})
    assert v.level == LOST and "ZNCC 0.05" in v.reason


def _coast_judge(prior: bool, depth: BlockStats, **kw):
    res = _result(blocks={"rgb": BlockStats(1000, 12, 5, 1, 1, 1), "depth": depth},
                  covariance=np.eye(6) * 0.01)  # the data alone: degenerate (a plane)
    motion = MotionPrior(I4, 0.02, 0.03) if prior else None
    return judge(CFG, res, I4, I4, (0.0, 0.0), (0.0, 0.0), {"rgb": 0.1}, Priors(motion=motion), **kw)


def test_without_image_terms_a_frame_coasts_on_depth_and_the_motion_prior():
    v = _coast_judge(True, BlockStats(800, 700, 690, 1, 1, 1))
    assert v.level == DEGRADED and v.coasting and "motion prior" in v.reason and "photometric inliers" in v.reason


@pytest.mark.parametrize("prior, depth", [
    (False, BlockStats(800, 700, 690, 1, 1, 1)),  # no trusted motion to coast on
    (True, BlockStats(800, 700, 200, 1, 1, 1)),  # the depth term does not hold either
    (True, BlockStats(800, 20, 20, 1, 1, 1)),  # too few depth points
])
def test_coasting_needs_the_prior_and_a_depth_term_that_holds(prior, depth):
    v = _coast_judge(prior, depth)
    assert v.level == LOST and not v.coasting and "photometric inliers" in v.reason


def test_image_terms_left_out_on_purpose_are_judged_as_coasting():
    v = _coast_judge(True, BlockStats(800, 700, 690, 1, 1, 1), coast_reason="the image terms did not hold (x)")
    assert v.coasting and v.reason.startswith("the image terms did not hold")
