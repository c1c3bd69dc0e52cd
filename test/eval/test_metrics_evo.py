"""Cross-check of atsvo_ros.eval.metrics against the evo package on real TUM RGB-D trajectories."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.eval.metrics import EvalOptions, associate, evaluate
from atsvo_ros.io.trajectory import read_tum

evo_metrics = pytest.importorskip("evo.core.metrics")
evo_sync = pytest.importorskip("evo.core.sync")
evo_traj = pytest.importorskip("evo.core.trajectory")

PAIRS = [("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
         ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt")]


def _evo(traj) -> evo_traj.PoseTrajectory3D:
    return evo_traj.PoseTrajectory3D(poses_se3=list(traj.T_w_b), timestamps=traj.stamps_ns * 1e-9)


def _stat(metric, pair, kind="mean") -> float:
    metric.process_data(pair)
    return metric.get_statistic(getattr(evo_metrics.StatisticsType, kind))


@pytest.fixture(scope="module", params=PAIRS, ids=["fr1_xyz", "fr2_desk"])
def trajectories(request, realdata):
    folder = realdata / "tum_rgbd_trajectories_evo"
    return read_tum(folder / request.param[0]), read_tum(folder / request.param[1])


def test_association_matches_evo_except_exact_ties(trajectories):
    gt, est = trajectories
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, 10_000_000)
    e_est, e_gt = evo_sync.matching_time_indices(est.stamps_ns * 1e-9, gt.stamps_ns * 1e-9, 0.01)
    assert np.array_equal(ie, e_est)
    differ = np.flatnonzero(ig != np.asarray(e_gt))
    # evo compares float seconds; where it disagrees, the two candidates are exactly equidistant in
    # integer nanoseconds and we keep the earlier one (evo's own tie rule).
    for k in differ:
        t = est.stamps_ns[ie[k]]
        assert t - gt.stamps_ns[ig[k]] == gt.stamps_ns[e_gt[k]] - t
        assert ig[k] < e_gt[k]
    assert len(differ) <= 2


@pytest.mark.parametrize("method", ["se3", "sim3"])
def test_metrics_agree_with_evo(trajectories, method):
    gt, est = trajectories
    ours = evaluate(gt, est, EvalOptions(align=method))
    m = ours.metrics
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, 10_000_000)
    ref, e = _evo(gt), _evo(est)
    ref.reduce_to_ids(ig)
    e.reduce_to_ids(ie)  # same pairing as ours
    e.align(ref, correct_scale=method == "sim3")
    pair = (ref, e)
    PR, U = evo_metrics.PoseRelation, evo_metrics.Unit
    assert m["n_matched"] == ref.num_poses
    assert m["ate_rmse_m"] == pytest.approx(_stat(evo_metrics.APE(PR.translation_part), pair, "rmse"),
                                            rel=1e-6, abs=1e-9)
    rot_f = _stat(evo_metrics.RPE(PR.rotation_angle_deg, delta=1, delta_unit=U.frames), pair)
    trans_f = _stat(evo_metrics.RPE(PR.translation_part, delta=1, delta_unit=U.frames), pair)
    assert m["rpe_rot_deg_per_frame"] == pytest.approx(rot_f, rel=1e-6)
    assert m["rpe_trans_cm_per_frame"] == pytest.approx(trans_f * 100, rel=1e-6)
    rot_d = _stat(evo_metrics.RPE(PR.rotation_angle_deg, delta=1, delta_unit=U.degrees,
                                  pairs_from_reference=True), pair)
    trans_d = _stat(evo_metrics.RPE(PR.translation_part, delta=1, delta_unit=U.degrees,
                                    pairs_from_reference=True), pair)
    assert m["rpe_rot_deg_per_deg"] == pytest.approx(rot_d, rel=1e-6)
    assert m["rpe_trans_cm_per_deg"] == pytest.approx(trans_d * 100, rel=1e-6)
    assert not m["diverged"]


@pytest.mark.parametrize("align_s", [0.5, 5.0])
def test_paper_alignment_matches_evo_first_n_plus_orientation(trajectories, align_s):
    gt, est = trajectories
    ours = evaluate(gt, est, EvalOptions(align="paper", align_s=align_s, align_fraction=0.2))
    n = ours.extra["alignment"]["n_poses"]
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, 10_000_000)
    ref, e = _evo(gt), _evo(est)
    ref.reduce_to_ids(ig)
    e.reduce_to_ids(ie)
    if "fallback" in ours.extra["alignment"]:
        e.align_origin(ref)  # evo --align_origin
        P = np.asarray(e.poses_se3)
    else:
        e.align(ref, n=n)  # evo -a --n_to_align n
        P = np.asarray(e.poses_se3)
        # then the SO(3) step: one body-frame rotation so the first orientations agree
        C = P[0, :3, :3].T @ ref.poses_se3[0][:3, :3]
        P[:, :3, :3] = P[:, :3, :3] @ C
    assert 3 <= n <= 0.2 * len(P) + 1
    np.testing.assert_allclose(ours.T_w_est, P, atol=1e-9)
    np.testing.assert_allclose(ours.T_w_est[0, :3, :3], ours.T_w_gt[0, :3, :3], atol=1e-12)
    ate = np.sqrt(np.mean(np.sum((P[:, :3, 3] - np.asarray(ref.positions_xyz)) ** 2, axis=1)))
    assert ours.metrics["ate_rmse_m"] == pytest.approx(ate, rel=1e-6)


def test_origin_alignment_matches_evo_align_origin(trajectories):
    """``origin`` is ``evo_ape --align_origin``: the first pose onto ground truth's, nothing fitted."""
    gt, est = trajectories
    ours = evaluate(gt, est, EvalOptions(align="origin"))
    ig, ie = associate(gt.stamps_ns, est.stamps_ns, 10_000_000)
    ref, e = _evo(gt), _evo(est)
    ref.reduce_to_ids(ig)
    e.reduce_to_ids(ie)
    e.align_origin(ref)
    np.testing.assert_allclose(ours.T_w_est, np.asarray(e.poses_se3), atol=1e-9)
    assert ours.metrics["ate_rmse_m"] == pytest.approx(
        _stat(evo_metrics.APE(evo_metrics.PoseRelation.translation_part), (ref, e), "rmse"), rel=1e-6)
