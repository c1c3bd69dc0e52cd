"""atsvo-eval on the real TUM trajectories: metrics.json keys, plots, one-line errors."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from atsvo_ros.eval.metrics import EvalOptions, evaluate, format_metrics
from atsvo_ros.io.trajectory import read_tum
from atsvo_ros.tools.eval import main

KEYS = {"ate_rmse_m", "rpe_rot_deg_per_frame", "rpe_trans_cm_per_frame", "rpe_rot_deg_per_deg",
        "rpe_trans_cm_per_deg", "diverged", "diverged_at_s", "tracked_fraction", "n_matched"}


def test_eval_writes_metrics_and_plots(realdata, tmp_path, capsys):
    d = realdata / "tum_rgbd_trajectories_evo"
    gt, est = d / "freiburg1_xyz-groundtruth.txt", d / "freiburg1_xyz-rgbdslam.txt"
    assert main([str(gt), str(est), "--align", "se3", "--out", str(tmp_path)]) == 0
    doc = json.loads((tmp_path / "metrics.json").read_text())
    assert KEYS <= set(doc) and set(doc) - KEYS == {"extra"}
    # ground truth interpolated at the estimate stamps by default, as atsvo-replay does
    ref = evaluate(read_tum(gt), read_tum(est), EvalOptions(align="se3", interpolate_gt=True)).metrics
    assert doc["ate_rmse_m"] == pytest.approx(ref["ate_rmse_m"], rel=1e-12)
    assert doc["extra"]["association"] == "interpolated"
    assert doc["n_matched"] == 785 and doc["diverged"] is False
    for name in ("trajectory", "position", "orientation", "error"):
        assert (tmp_path / f"{name}.png").stat().st_size > 1000
    assert "ATE RMSE" in capsys.readouterr().out


def test_eval_errors_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.txt"
    bad.write_text("1.0 2.0 3.0\n")
    ok = tmp_path / "ok.txt"
    ok.write_text("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")
    assert main([str(ok), str(bad)]) == 1
    err = capsys.readouterr().err.strip()
    assert "bad.txt:1" in err and "8 columns" in err and len(err.splitlines()) == 1
    far = tmp_path / "far.txt"
    far.write_text("100.0 0 0 0 0 0 0 1\n101.0 1 0 0 0 0 0 1\n")
    assert main([str(ok), str(far)]) == 1
    assert "time bases" in capsys.readouterr().err
    assert main([str(ok), str(tmp_path / "missing.txt")]) == 1
    assert "missing.txt" in capsys.readouterr().err


def test_eval_association_flags(realdata, tmp_path):
    """--nearest-gt scores as before the default changed; --interpolate (the old opt-in) is the default."""
    d = realdata / "tum_rgbd_trajectories_evo"
    gt, est = d / "freiburg1_xyz-groundtruth.txt", d / "freiburg1_xyz-rgbdslam.txt"
    docs = {}
    for flag in ("--nearest-gt", "--interpolate"):
        assert main([str(gt), str(est), "--no-plots", "--out", str(tmp_path / flag), flag]) == 0
        docs[flag] = json.loads((tmp_path / flag / "metrics.json").read_text())
    for flag, interp in (("--nearest-gt", False), ("--interpolate", True)):
        ref = evaluate(read_tum(gt), read_tum(est), EvalOptions(interpolate_gt=interp)).metrics
        assert docs[flag]["rpe_rot_deg_per_frame"] == pytest.approx(ref["rpe_rot_deg_per_frame"], rel=1e-12)
    assert docs["--nearest-gt"]["extra"]["association"] == "nearest"
    with pytest.raises(SystemExit):
        main([str(gt), str(est), "--nearest-gt", "--interpolate"])


# ------------------------------------------------------------------ the reproductions' cases (r01, r06, r09, r14)

FMT = "%.6f"


def _poses(t: np.ndarray) -> np.ndarray:
    """r06's trajectory rows: t, a 1 m circle at 0.3 rad/s yawing with it, bobbing 10 cm."""
    a = (t - t[0]) * 0.3
    return np.c_[t, np.cos(a), np.sin(a), 0.1 * np.sin(3 * a), 0 * a, 0 * a, np.sin(a / 2), np.cos(a / 2)]


def _r06(tmp_path: Path) -> dict[str, Path]:
    """r06_eval_duplicate_stamps.sh's files: 100 Hz ground truth, 30 Hz estimate, doubled, all-equal stamps."""
    gt = _poses(1.7e9 + np.arange(2000) / 100.0)
    est = _poses(1.7e9 + np.arange(600) / 30.0)
    est[:, 1:4] += np.random.default_rng(0).normal(0, 0.005, (len(est), 3))
    same = est.copy()
    same[:, 0] = est[100, 0]
    files = {"gt": gt, "est": est, "est_dup": np.repeat(est, 2, axis=0), "est_same_stamp": same,
             "gt_dup": np.repeat(gt, 2, axis=0)}
    paths = {}
    for name, rows in files.items():
        paths[name] = tmp_path / f"ev_{name}.txt"
        np.savetxt(paths[name], rows, fmt=FMT)
    return paths


def test_eval_repeated_estimate_stamps_are_one_line_errors(tmp_path, capsys):
    """r06: a doubled estimate gave 1200 "matches" and half the RPE, all-equal stamps 600 matches, exit 0."""
    f = _r06(tmp_path)
    assert main([str(f["gt"]), str(f["est"]), "--no-plots"]) == 0
    assert capsys.readouterr().out.startswith("matched poses        600 of 600 estimate poses")
    for name in ("est_dup", "est_same_stamp"):
        assert main([str(f["gt"]), str(f[name]), "--no-plots"]) == 1
        err = capsys.readouterr().err
        stamp = "1700000000.000000000" if name == "est_dup" else "1700000003.333333000"
        assert err == (f"atsvo-eval: error: {f[name]}:2: stamp {stamp} repeats the stamp of line 1 ({stamp}); "
                       "the stamps of a trajectory must increase line by line\n")
    back = tmp_path / "back.txt"
    back.write_text("".join(reversed(f["est"].read_text().splitlines(keepends=True))))
    assert main([str(f["gt"]), str(back), "--no-plots"]) == 1
    assert f"{back}:2: stamp 1700000019.933333000 goes back in time from line 1" in capsys.readouterr().err


def test_eval_repeated_ground_truth_stamps_warn_and_keep_the_numbers(tmp_path, capsys):
    """Ground truth with every line twice scores as without, and says so (TUM fr2/desk repeats one stamp)."""
    f = _r06(tmp_path)
    assert main([str(f["gt"]), str(f["est"]), "--no-plots"]) == 0
    ref = capsys.readouterr()
    assert main([str(f["gt_dup"]), str(f["est"]), "--no-plots"]) == 0
    got = capsys.readouterr()
    assert got.out == ref.out and ref.err == ""
    assert got.err == ("atsvo-eval: warning: ground truth repeats 2000 stamps (first 1700000000.000000000 s); "
                       "the first pose of each is used\n")


def test_eval_infinity_never_reaches_metrics_json(tmp_path, capsys):
    """r09 e: one absurd (finite) position wrote the non-JSON constant Infinity."""
    f = _r06(tmp_path)
    lines = f["est"].read_text().splitlines(keepends=True)
    cols = lines[149].split()
    lines[149] = " ".join([cols[0], "1e200", *cols[2:]]) + "\n"  # the reproduction's awk 'NR==150 { $2="1e200" }'
    huge = tmp_path / "e_huge.tum"
    huge.write_text("".join(lines))
    assert main([str(f["gt"]), str(huge), "--no-plots", "--out", str(tmp_path / "o")]) == 0
    doc = json.loads((tmp_path / "o" / "metrics.json").read_text(),
                     parse_constant=lambda c: pytest.fail(f"metrics.json holds {c}"))
    assert doc["ate_rmse_m"] is None and doc["diverged"] is True
    err = capsys.readouterr().err
    assert err.startswith("atsvo-eval: warning: ate_rmse_m, ") and "overflows their squares; written as null" in err
    assert doc["extra"]["notes"] == [err.strip().removeprefix("atsvo-eval: ")]


def test_eval_reads_a_byte_order_mark(tmp_path, capsys):
    """r09 f: a BOM gave "not a number in '\\ufeff1700...'"."""
    f = _r06(tmp_path)
    bom = tmp_path / "est_bom.txt"
    bom.write_bytes(b"\xef\xbb\xbf" + f["est"].read_bytes())
    assert main([str(f["gt"]), str(f["est"]), "--no-plots"]) == 0
    ref = capsys.readouterr().out
    assert main([str(f["gt"]), str(bom), "--no-plots"]) == 0
    assert capsys.readouterr().out == ref


def test_eval_warns_about_sparse_ground_truth(tmp_path, capsys):
    """r09 h: 1 Hz ground truth, 46 frames at 30 Hz: 2 matched poses and no warning."""
    gt, est = tmp_path / "gt_1hz.txt", tmp_path / "est.txt"
    np.savetxt(gt, _poses(1.7e9 + np.arange(3) * 1.0), fmt=FMT)
    np.savetxt(est, _poses(1.7e9 + np.arange(46) / 30.0), fmt=FMT)
    assert main([str(gt), str(est), "--no-plots", "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert err.startswith("atsvo-eval: warning: only 2 of the 46 estimate poses within the ground truth's time span "
                          "are within 10 ms of a ground-truth pose (ground truth has one pose every 1.000 s")
    assert len(err.splitlines()) == 1 and "matched poses        2 of 46 estimate poses" in out
    doc = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert doc["extra"]["notes"] == [err.strip().removeprefix("atsvo-eval: ")]


def test_eval_one_pose_estimate_says_so(tmp_path, capsys):
    """r09 a: one pose was reported as "only 1 estimate poses match ... check the time bases"."""
    f = _r06(tmp_path)
    one = tmp_path / "one.txt"
    one.write_text(f["est"].read_text().splitlines()[0] + "\n")
    assert main([str(f["gt"]), str(one), "--no-plots"]) == 1
    assert capsys.readouterr().err == ("atsvo-eval: error: the estimate has only 1 pose (at 1700000000.000000000 s): "
                                       "at least 2 are needed to score it against ground truth\n")


def test_eval_tracked_fraction_is_over_the_estimate(tmp_path, capsys):
    """r14: a perfect estimate of the first 10 s of a 20 s ground truth printed tracked fraction 0.500."""
    rows = _poses(1.7e9 + np.arange(2000) / 100.0)
    gt, est = tmp_path / "tf_gt.txt", tmp_path / "tf_est.txt"
    np.savetxt(gt, rows, fmt=FMT)
    np.savetxt(est, rows[:1000:3], fmt=FMT)
    assert main([str(gt), str(est), "--no-plots", "--out", str(tmp_path / "o")]) == 0
    assert "tracked fraction     1.000 (334 of 334 estimate poses matched to ground truth)" in capsys.readouterr().out
    doc = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert doc["tracked_fraction"] == 1.0 and doc["extra"]["gt_span_covered"] == pytest.approx(0.5, abs=0.01)


def test_eval_out_that_is_a_file_fails_first(tmp_path, capsys):
    """r01: --out naming an existing file gave a FileExistsError traceback after the evaluation."""
    f = _r06(tmp_path)
    existing = tmp_path / "existing_file"
    existing.write_text("")
    assert main([str(f["gt"]), str(f["est"]), "--out", str(existing), "--no-plots"]) == 1
    assert capsys.readouterr() == ("", f"atsvo-eval: error: --out {existing} is a file, not a folder\n")
    # before any work: a missing estimate is not even looked at
    assert main([str(f["gt"]), str(tmp_path / "missing.txt"), "--out", str(existing / "sub")]) == 1
    assert capsys.readouterr().err == (f"atsvo-eval: error: --out {existing / 'sub'} is under {existing}, which is a "
                                       "file, not a folder\n")


def test_eval_into_a_closed_pipe_exits_quietly(tmp_path):
    """`atsvo-eval GT EST --no-plots | true`: the reader has gone; exit 0, no BrokenPipeError traceback."""
    f = _r06(tmp_path)
    r, w = os.pipe()
    os.close(r)  # the reader left before the first line
    try:
        proc = subprocess.run([sys.executable, "-m", "atsvo_ros.tools.eval", str(f["gt"]), str(f["est"]), "--no-plots"],
                              stdout=w, stderr=subprocess.PIPE, text=True, timeout=300)
    finally:
        os.close(w)
    assert (proc.returncode, proc.stderr) == (0, "")


def test_eval_prints_what_replay_prints(tmp_path, capsys):
    """One vocabulary: atsvo-eval's default is atsvo-replay's (ground truth interpolated at the stamps), so the
    same trajectory prints the same ATE and RPE lines; the alignment and the RPE statistic are named."""
    f = _r06(tmp_path)
    assert main([str(f["gt"]), str(f["est"]), "--no-plots"]) == 0
    out = capsys.readouterr().out.splitlines()
    replay_like = evaluate(read_tum(f["gt"]), read_tum(f["est"]), EvalOptions(interpolate_gt=True))
    assert out[:4] == format_metrics(replay_like.to_json()).splitlines()[:4]
    assert out[1].endswith("cm (aligned: SE(3) Umeyama on the first 2.00 s (61 poses), then the first orientation)")
    assert out[2].startswith("RPE per frame, RMSE, ground truth interpolated at the stamps: 0.0397 deg/f  1.2065 cm/f")
