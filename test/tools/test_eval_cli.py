"""atsvo-eval on the real TUM trajectories: metrics.json keys, plots, one-line errors."""
from __future__ import annotations

import json

import pytest

from atsvo_ros.eval.metrics import EvalOptions, evaluate
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
    ref = evaluate(read_tum(gt), read_tum(est), EvalOptions(align="se3")).metrics
    assert doc["ate_rmse_m"] == pytest.approx(ref["ate_rmse_m"], rel=1e-12)
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
