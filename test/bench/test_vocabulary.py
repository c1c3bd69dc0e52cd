"""The benches print ATE and RPE in atsvo-replay's vocabulary: the ATE RMSE with its alignment, the RPE per
frame as RMSE with its association (as :func:`atsvo_ros.eval.metrics.format_metrics`)."""
from __future__ import annotations

import numpy as np

from atsvo_ros.bench.report import recording_lines
from atsvo_ros.bench.tracking import sequence_line, summary_line
from atsvo_ros.core.geometry import so3_exp
from atsvo_ros.eval.metrics import ASSOCIATION_TEXT, EvalOptions, describe_alignment, evaluate
from atsvo_ros.io.trajectory import Trajectory


def _evaluation():
    """A scored run whose per-frame RPE has a mean clearly below its RMSE (one bad frame among good ones)."""
    n = 90
    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, 0, 3] = np.linspace(0, 1, n)
    T[:, 1, 3] = 0.2 * np.sin(np.linspace(0, 3, n))
    gt = Trajectory(np.arange(n) * 33_000_000, T)
    est = T.copy()
    est[60:, 2, 3] += 0.05  # a 5 cm and 2 deg step at frame 60
    est[60:, :3, :3] = so3_exp(np.array([0.0, 0.0, np.radians(2.0)])) @ est[60:, :3, :3]
    return evaluate(gt, Trajectory(gt.stamps_ns, est), EvalOptions(interpolate_gt=True))


def test_tracking_lines_name_statistic_alignment_and_association():
    ev = _evaluation()
    x = ev.extra
    assert x["rpe_trans_cm_per_frame_rmse"] > 2 * ev.metrics["rpe_trans_cm_per_frame"]  # the two differ here
    assert x["rpe_rot_deg_per_frame_rmse"] > 2 * ev.metrics["rpe_rot_deg_per_frame"]
    se3, origin = (evaluate(Trajectory(ev.stamps_ns, ev.T_w_gt), Trajectory(ev.stamps_ns, ev.T_w_est),
                            EvalOptions(align=method, interpolate_gt=True)) for method in ("se3", "origin"))
    row = {"scenario": "trot", "seed": 0, "ate_rmse_cm": ev.metrics["ate_rmse_m"] * 100, "max_error_cm": 5.0,
           "ate_se3_cm": se3.metrics["ate_rmse_m"] * 100, "path_scale": 0.9927,
           "ate_origin_cm": origin.metrics["ate_rmse_m"] * 100,
           "rpe_deg_per_frame": ev.metrics["rpe_rot_deg_per_frame"],
           "rpe_cm_per_frame": ev.metrics["rpe_trans_cm_per_frame"],
           "rpe_deg_per_frame_rmse": x["rpe_rot_deg_per_frame_rmse"],
           "rpe_cm_per_frame_rmse": x["rpe_trans_cm_per_frame_rmse"],
           "aligned": describe_alignment(x["alignment"]), "association": ASSOCIATION_TEXT[x["association"]],
           "track_ms_median": 4.0, "track_ms_p90": 5.0, "diverged": False, "status_left_ok_in_time": True,
           "statuses": {"ok": 90}, "modes": {"rgbd": 90}, "fused_ms_median": None, "keyframes": 3,
           "latency_ms_p50": 4.0, "latency_ms_p99": 9.0, "events": 0, "events_dropped": 0}
    line = sequence_line(row)
    assert (f"ATE RMSE {row['ate_rmse_cm']:.2f} cm (max 5.0; aligned: {describe_alignment(x['alignment'])}; "
            f"SE(3) over all poses {row['ate_se3_cm']:.2f} cm; first pose onto the truth's "
            f"{row['ate_origin_cm']:.2f} cm; path length x0.9927 of the truth's)") in line
    assert row["ate_se3_cm"] < row["ate_rmse_cm"]  # a fit over every pose spreads the step at frame 60 over both
    # anchored at the first pose nothing is fitted: the 5 cm step stays in the last 30 of the 90 frames
    assert abs(row["ate_origin_cm"] - 5.0 * np.sqrt(30 / 90)) < 1e-9
    assert (f"RPE per frame, RMSE, ground truth interpolated at the stamps: {x['rpe_rot_deg_per_frame_rmse']:.3f} "
            f"deg/f {x['rpe_trans_cm_per_frame_rmse']:.3f} cm/f") in line
    summary = summary_line([row, {**row, "rpe_deg_per_frame_rmse": None}], [4.0])
    assert summary.startswith(f"summary: worst ATE RMSE {row['ate_rmse_cm']:.2f} cm, worst RPE per frame RMSE "
                              f"{x['rpe_rot_deg_per_frame_rmse']:.3f} deg/f")


def test_recordings_table_names_statistic_alignment_and_association():
    doc = _evaluation().to_json()
    x = doc["extra"]
    rows = [{"recording": "/data/indoor_flying1_data.bag", "mode": "fused", "metrics": doc,
             "paper": {"ate_cm": 6.89, "rpe_deg_per_deg": 0.36, "rpe_deg_per_frame": 0.15}}]
    lines = recording_lines(rows)
    assert lines[2] == (f"ATE RMSE (aligned: {describe_alignment(x['alignment'])}). RPE per frame: ground truth "
                        "interpolated at the stamps. `paper`: the paper's figures (Tables I and II).")
    assert lines[4] == ("| recording | mode | ATE RMSE cm | paper ATE cm | R_rpe deg/d, mean | paper deg/d "
                        "| R_rpe deg/f, RMSE | R_rpe deg/f, mean | paper deg/f |")
    cells = lines[6].strip("| ").split(" | ")
    assert cells[6:9] == [f"{x['rpe_rot_deg_per_frame_rmse']:.3f}", f"{doc['rpe_rot_deg_per_frame']:.3f}", "0.150"]
