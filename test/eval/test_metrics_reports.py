"""What the metrics say about themselves: repeated stamps, too few poses, sparse ground truth, overflow,
tracked fraction, and the one vocabulary of format_metrics (reproductions r06, r09, r14)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from atsvo_ros.core.geometry import so3_exp
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.metrics import EvalOptions, evaluate, format_metrics, metrics_json
from atsvo_ros.io.trajectory import Trajectory


def _orbit(t_s: np.ndarray) -> Trajectory:
    """The reproductions' trajectory: a 1 m circle at 0.3 rad/s, yawing with it, bobbing a little."""
    a = (t_s - t_s[0]) * 0.3
    T = np.repeat(np.eye(4)[None], len(t_s), 0)
    T[:, :3, :3] = so3_exp(np.stack([0 * a, 0 * a, a], 1))
    T[:, :3, 3] = np.stack([np.cos(a), np.sin(a), 0.1 * np.sin(3 * a)], 1)
    return Trajectory(np.round(t_s * 1e9).astype(np.int64), T)


T0 = 1_700_000_000.0
GT = _orbit(T0 + np.arange(2000) / 100.0)  # 100 Hz motion capture, 20 s
EST = _orbit(T0 + np.arange(600) / 30.0)  # 30 Hz camera


def test_repeated_estimate_stamps_are_an_error():
    """r06: every pose twice used to give 1200 matches and half the RPE; all stamps equal, 600 matches."""
    twice = Trajectory(np.repeat(EST.stamps_ns, 2), np.repeat(EST.T_w_b, 2, axis=0))
    with pytest.raises(EvaluationError, match=r"the estimate repeats 600 stamps \(first 1700000000\.000000000 s\)"):
        evaluate(GT, twice)
    same = Trajectory(np.full(len(EST), EST.stamps_ns[100]), EST.T_w_b)
    with pytest.raises(EvaluationError, match="the estimate repeats 599 stamps"):
        evaluate(GT, same)


def test_repeated_ground_truth_stamps_keep_the_first_pose_and_say_so():
    """Ground truth repeating a stamp (TUM fr2/desk does once) scores as without the copy, with a warning."""
    ref = evaluate(GT, EST)
    twice = evaluate(Trajectory(np.repeat(GT.stamps_ns, 2), np.repeat(GT.T_w_b, 2, axis=0)), EST)
    assert twice.metrics == ref.metrics and ref.extra["notes"] == []
    assert twice.extra["notes"] == ["warning: ground truth repeats 2000 stamps (first 1700000000.000000000 s); "
                                    "the first pose of each is used"]
    same = Trajectory(np.full(len(GT), GT.stamps_ns[0]), GT.T_w_b)
    with pytest.raises(EvaluationError, match=r"the ground truth has only 1 pose .* \(its 2000 poses share that "):
        evaluate(same, EST)


def test_one_pose_estimate_is_named_not_the_time_bases():
    """r09 a: a one-frame run used to read "only 1 estimate poses match ... check the time bases"."""
    with pytest.raises(EvaluationError) as info:
        evaluate(GT, Trajectory(EST.stamps_ns[:1], EST.T_w_b[:1]))
    assert str(info.value) == ("the estimate has only 1 pose (at 1700000000.000000000 s): at least 2 are needed "
                               "to score it against ground truth")
    with pytest.raises(EvaluationError, match="the estimate has no poses"):
        evaluate(GT, Trajectory(EST.stamps_ns[:0], EST.T_w_b[:0]))
    far = Trajectory(EST.stamps_ns + 10**12, EST.T_w_b)
    with pytest.raises(EvaluationError, match="the time ranges do not overlap; check the time bases"):
        evaluate(GT, far)


def test_sparse_ground_truth_is_a_warning_note():
    """r09 h: 1 Hz ground truth against a 30 Hz estimate: 2 of 46 poses matched, no warning before."""
    gt = _orbit(T0 + np.arange(3) * 1.0)
    est = _orbit(T0 + np.arange(46) / 30.0)
    res = evaluate(gt, est, EvalOptions(interpolate_gt=True))
    assert res.metrics["n_matched"] == 2
    assert res.extra["notes"] == [
        "warning: only 2 of the 46 estimate poses within the ground truth's time span are within 10 ms of a "
        "ground-truth pose (ground truth has one pose every 1.000 s and the estimate one every 0.033 s, medians): "
        "the metrics rest on these 2 poses and the RPE per frame spans 1.000 s"]
    assert evaluate(GT, EST).extra["notes"] == []  # 100 Hz against 30 Hz: every frame finds its pose


def test_tracked_fraction_counts_the_estimate_poses():
    """r14: a perfect estimate of the first 10 s of 20 s of ground truth used to score 0.500."""
    est = Trajectory(GT.stamps_ns[:1000:3], GT.T_w_b[:1000:3])
    res = evaluate(GT, est)
    assert res.metrics["tracked_fraction"] == 1.0
    assert res.extra["gt_span_covered"] == pytest.approx(0.5, abs=0.01)
    assert (res.extra["n_tracked"], res.extra["n_estimate"], res.extra["tracked_by"]) == (334, 334,
                                                                                          "matched to ground truth")
    ok = np.ones(len(est), bool)
    ok[7] = False  # the replay's case: 299 of 300 frames ok -> 0.997, not the ground-truth span's 0.906
    res = evaluate(GT, est, est_ok=ok)
    assert res.metrics["tracked_fraction"] == pytest.approx(333 / 334)
    assert res.extra["tracked_by"] == "reported ok"
    half = Trajectory(np.r_[est.stamps_ns, GT.stamps_ns[-1] + 10**9 + np.arange(10) * 33_000_000],
                      np.r_[est.T_w_b, np.repeat(est.T_w_b[-1:], 10, 0)])
    assert evaluate(GT, half).metrics["tracked_fraction"] == pytest.approx(334 / 344)  # 10 poses without GT


def test_overflowing_metrics_are_null_with_the_reason():
    """r09 e: one absurd (finite) position put "ate_rmse_m": Infinity into metrics.json."""
    T = EST.T_w_b.copy()
    T[149, 0, 3] = 1e200
    res = evaluate(GT, Trajectory(EST.stamps_ns, T))
    doc = res.to_json()
    assert doc["ate_rmse_m"] is None and res.metrics["ate_rmse_m"] == np.inf  # the document, not the numbers
    json.dumps(doc, allow_nan=False)  # atsvo-replay writes the document with json.dumps: it must be JSON already
    text = metrics_json(doc)
    parsed = json.loads(text, parse_constant=lambda c: pytest.fail(f"not JSON: {c}"))
    assert parsed["ate_rmse_m"] is None and parsed["diverged"] is True and parsed["extra"]["partial"]["n_matched"]
    note = parsed["extra"]["notes"][0]
    assert note.startswith("warning: ate_rmse_m, rpe_trans_cm_per_frame, ") and note.endswith(
        "not finite: an aligned estimate position of 1e+200 m (at 4.967 s) overflows their squares; written as null")
    assert "ATE RMSE             n/a cm" in format_metrics(doc)
    assert metrics_json({"a": float("nan"), "b": [float("inf"), 1.5]}) == '{\n  "a": null,\n  "b": [\n    null,\n' \
                                                                          '    1.5\n  ]\n}\n'
    with pytest.raises(EvaluationError, match=r"the alignment overflows: positions reach 1e\+200 m"):
        evaluate(GT, Trajectory(EST.stamps_ns, T), EvalOptions(align="sim3"))  # used to give scale 0, "17 cm"


def test_format_metrics_names_alignment_statistic_and_association():
    """One vocabulary: the ATE with its alignment, the RPE with its statistic and association."""
    rng = np.random.default_rng(0)
    T = EST.T_w_b.copy()
    T[:, :3, 3] += rng.normal(0, 0.005, (len(T), 3))
    est = Trajectory(EST.stamps_ns + 3_000_000, T)  # 3 ms off the 100 Hz ground truth: the associations differ
    interp = evaluate(GT, est, EvalOptions(align="se3", interpolate_gt=True))
    text = format_metrics(interp.to_json()).splitlines()
    assert text[0] == "matched poses        600 of 600 estimate poses (within 10 ms of a ground-truth pose)"
    assert text[1].endswith(" cm (aligned: SE(3) Umeyama over all 600 matched poses)")
    rmse = interp.extra["rpe_rot_deg_per_frame_rmse"]
    assert text[2] == (f"RPE per frame, RMSE, ground truth interpolated at the stamps: {rmse:.4f} deg/f  "
                       f"{interp.extra['rpe_trans_cm_per_frame_rmse']:.4f} cm/f")
    assert text[3].startswith(f"RPE per degree, mean over {interp.extra['n_segments_per_deg']} segments of 1 deg: ")
    assert text[4] == "tracked fraction     1.000 (600 of 600 estimate poses matched to ground truth)"
    nearest = format_metrics(evaluate(GT, est, EvalOptions(align="paper")).to_json()).splitlines()
    assert nearest[1].endswith("(aligned: SE(3) Umeyama on the first 2.00 s (61 poses), then the first orientation)")
    assert nearest[2].startswith("RPE per frame, RMSE, nearest ground-truth pose: ")
    assert nearest[2] != text[2].replace("ground truth interpolated at the stamps", "nearest ground-truth pose")
    bare = format_metrics(interp.metrics).splitlines()  # no extra: the mean, labelled so
    assert bare[2].startswith(f"RPE per frame, mean, association not recorded: "
                              f"{interp.metrics['rpe_rot_deg_per_frame']:.4f} deg/f")
