"""Unit tests of the metrics on constructed trajectories with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import se3_exp, so3_exp
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.metrics import EvalOptions, angle_segments, associate, evaluate, rotation_angle_deg, umeyama
from atsvo_ros.io.trajectory import Trajectory


def _circle(n: int = 300, hz: float = 30.0, t0_ns: int = 1_000_000_000) -> Trajectory:
    """Camera on a 1 m circle, yawing 1 deg per frame, with some height change."""
    k = np.arange(n)
    T = np.repeat(np.eye(4)[None], n, 0)
    a = np.radians(k * 1.0)
    T[:, :3, :3] = so3_exp(np.stack([np.zeros(n), np.zeros(n), a], 1))
    T[:, :3, 3] = np.stack([np.cos(a), np.sin(a), 0.2 * np.sin(3 * a)], 1)
    return Trajectory(t0_ns + (k * 1e9 / hz).astype(np.int64), T)


def test_associate_nearest_within_tolerance():
    a = np.array([0, 100, 200, 300], np.int64)
    b = np.array([5, 96, 260, 1000, 2000], np.int64)
    ia, ib = associate(a, b, max_diff_ns=10)
    assert ia.tolist() == [0, 1] and ib.tolist() == [0, 1]
    # exact tie goes to the earlier stamp
    ia, ib = associate(np.array([10, 20, 30]), np.array([15]), 5)
    assert ia.tolist() == [0] and ib.tolist() == [0]
    assert len(associate(np.array([0]), np.array([100]), 10)[0]) == 0


def test_umeyama_recovers_sim3():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 3))
    R = so3_exp(np.array([0.3, -0.2, 0.9]))
    y = 2.5 * x @ R.T + np.array([1.0, -2.0, 0.5])
    R2, t2, s2 = umeyama(x, y, with_scale=True)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    assert s2 == pytest.approx(2.5)
    with pytest.raises(EvaluationError, match="degenerate"):
        umeyama(np.zeros((5, 3)), np.zeros((5, 3)))


@pytest.mark.parametrize("method", ["paper", "se3", "sim3"])
def test_rigidly_moved_estimate_scores_zero(method):
    gt = _circle()
    T_off = se3_exp(np.array([3.0, -1.0, 0.5, 0.4, -0.3, 1.2]))
    est = gt.transformed(T_left=T_off)
    m = evaluate(gt, est, EvalOptions(align=method)).metrics
    assert m["ate_rmse_m"] < 1e-9
    assert m["rpe_rot_deg_per_frame"] < 1e-6 and m["rpe_trans_cm_per_frame"] < 1e-6
    assert m["n_matched"] == len(gt) and not m["diverged"] and m["tracked_fraction"] == pytest.approx(1.0, abs=0.01)


def test_none_alignment_keeps_offset():
    gt = _circle()
    est = Trajectory(gt.stamps_ns, gt.transformed(T_left=se3_exp(np.array([0.0, 0, 1.0, 0, 0, 0]))).T_w_b)
    assert evaluate(gt, est, EvalOptions(align="none")).metrics["ate_rmse_m"] == pytest.approx(1.0)


def test_known_constant_drift_per_frame_and_per_degree():
    gt = _circle(200)
    # add a 0.1 deg extra roll per frame in the body frame: each relative motion is off by 0.1 deg
    drift = so3_exp(np.array([np.radians(0.1), 0.0, 0.0]))
    T = gt.T_w_b.copy()
    for i in range(1, len(T)):
        rel = np.linalg.inv(gt.T_w_b[i - 1]) @ gt.T_w_b[i]
        rel[:3, :3] = rel[:3, :3] @ drift
        T[i] = T[i - 1] @ rel
    m = evaluate(gt, Trajectory(gt.stamps_ns, T), EvalOptions(align="none", delta_deg=0.9)).metrics
    assert m["rpe_rot_deg_per_frame"] == pytest.approx(0.1, rel=1e-6)
    # ground truth turns 1 deg per frame, so each 0.9-degree segment is one frame long
    assert m["rpe_rot_deg_per_deg"] == pytest.approx(0.1, rel=1e-3)


def test_angle_segments_accumulate():
    gt = _circle(50)  # 1 deg per frame
    i, j = angle_segments(gt.T_w_b, 2.5)
    assert (j - i).tolist() == [3] * len(i)
    assert rotation_angle_deg(so3_exp(np.array([0, 0, np.pi - 1e-9])))[()] == pytest.approx(180, abs=1e-6)


def test_divergence_time_and_partial_score():
    gt = _circle(300)
    T = gt.T_w_b.copy()
    T[200:, :3, 3] += np.linspace(0, 60.0, 100)[:, None] * np.array([1.0, 0, 0])  # runs away at frame 200
    res = evaluate(gt, Trajectory(gt.stamps_ns, T), EvalOptions(align="paper"))
    m = res.metrics
    assert m["diverged"] is True
    t_div = m["diverged_at_s"]
    assert 200 / 30 < t_div < 300 / 30
    doc = res.to_json()
    part = doc["extra"]["partial"]
    assert part["n_matched"] < m["n_matched"]
    assert part["ate_rmse_m"] < m["ate_rmse_m"]
    assert set(m) == {"ate_rmse_m", "rpe_rot_deg_per_frame", "rpe_trans_cm_per_frame", "rpe_rot_deg_per_deg",
                      "rpe_trans_cm_per_deg", "diverged", "diverged_at_s", "tracked_fraction", "n_matched"}


def test_tracked_fraction_counts_ok_status_and_gaps():
    gt = _circle(300, hz=100.0)
    est_idx = np.arange(0, 300, 3)
    est = Trajectory(gt.stamps_ns[est_idx], gt.T_w_b[est_idx])
    ok = np.ones(len(est), bool)
    ok[len(ok) // 2:] = False  # lost for the second half
    m = evaluate(gt, est, EvalOptions(align="se3"), est_ok=ok).metrics
    assert m["tracked_fraction"] == pytest.approx(0.5, abs=0.03)
    gap = Trajectory(np.delete(est.stamps_ns, range(20, 60)), np.delete(est.T_w_b, range(20, 60), axis=0))
    res = evaluate(gt, gap, EvalOptions(align="se3"))
    # every pose the estimate has was tracked; the ground-truth view of the gap is kept under its own name
    assert res.metrics["tracked_fraction"] == 1.0
    assert res.extra["gt_span_covered"] == pytest.approx(0.6, abs=0.03)


def test_no_overlap_is_an_error_naming_the_time_bases():
    gt = _circle(50)
    est = Trajectory(gt.stamps_ns + 10**12, gt.T_w_b)
    with pytest.raises(EvaluationError, match="time bases"):
        evaluate(gt, est)


def test_static_start_paper_alignment_falls_back():
    gt = _circle(120)
    T = gt.T_w_b.copy()
    T[:80] = T[0]  # stationary for the first 2.6 s
    gtst = Trajectory(gt.stamps_ns, T)
    est = gtst.transformed(T_left=se3_exp(np.array([1.0, 2.0, 0.0, 0.0, 0.0, 0.7])))
    res = evaluate(gtst, est, EvalOptions(align="paper"))
    assert "fallback" in res.extra["alignment"]
    assert res.metrics["ate_rmse_m"] < 1e-9


def test_sum_ratio_per_degree_in_extra():
    gt = _circle(100)  # 1 deg of rotation per frame
    T = gt.T_w_b.copy()
    T[:, :3, 3] += np.arange(100)[:, None] * np.array([0.001, 0, 0])  # 1 mm extra per frame
    res = evaluate(gt, Trajectory(gt.stamps_ns, T), EvalOptions(align="none"))
    assert res.extra["rpe_trans_cm_per_deg_sum_ratio"] == pytest.approx(0.1, rel=0.05)
    assert res.extra["rpe_rot_deg_per_deg_sum_ratio"] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("kwargs, message", [
    ({"align_s": 0.0}, r"align_s \(--align-s\) must be > 0, got 0"),
    ({"max_diff_s": -1.0}, r"max_diff_s \(--t-max-diff\) must be >= 0, got -1"),
    ({"delta_deg": float("nan")}, r"delta_deg \(--delta-deg\) must be in \(0, 180\], got nan"),
])
def test_a_bad_option_is_named_with_its_value(kwargs, message):
    with pytest.raises(EvaluationError, match=message):
        EvalOptions(**kwargs)
