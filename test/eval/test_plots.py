"""Plots: files are written; roll/pitch/yaw stay continuous through a flip, a wrap and near gimbal lock."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import so3_exp, so3_log
from atsvo_ros.eval.metrics import EvalOptions, evaluate
from atsvo_ros.eval.plots import orientation_series, plot_comparison, plot_memory, plot_run, rpy_deg
from atsvo_ros.io.trajectory import Trajectory


def test_rpy_continuous_through_a_backflip():
    n = 200
    pitch = np.linspace(0, -2 * np.pi, n)
    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, :3, :3] = so3_exp(np.stack([np.zeros(n), pitch, np.zeros(n)], 1))
    rpy = rpy_deg(T)
    assert np.abs(np.diff(rpy, axis=0)).max() < 5.0  # no 180-degree jumps
    np.testing.assert_allclose(rpy[:, 1], np.degrees(pitch), atol=1e-6)
    np.testing.assert_allclose(rpy[:, [0, 2]], 0.0, atol=1e-6)


def _poses(R: np.ndarray) -> np.ndarray:
    T = np.repeat(np.eye(4)[None], len(R), 0)
    T[:, :3, :3] = R
    return T


def _zyx(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), angles in degrees."""
    z = np.zeros_like(roll)
    return (so3_exp(np.stack([z, z, np.radians(yaw)], 1)) @ so3_exp(np.stack([z, np.radians(pitch), z], 1))
            @ so3_exp(np.stack([np.radians(roll), z, z], 1)))


def _noisy(R: np.ndarray, sigma_deg: float, seed: int) -> np.ndarray:
    """``R`` times a random small rotation (per-axis sigma in degrees): an estimate with that error."""
    rng = np.random.default_rng(seed)
    return R @ so3_exp(np.radians(sigma_deg) * rng.standard_normal((len(R), 3)))


def _largest_step(series: np.ndarray) -> float:
    """Largest change between consecutive drawn samples (NaN marks a gap, which is not a step)."""
    d = np.abs(np.diff(series, axis=0))
    return float(np.nanmax(d)) if np.isfinite(d).any() else 0.0


def _check_drawn(s, max_error_deg: float) -> None:
    """Every plotted series is free of jumps, and estimate and ground truth differ only by the error."""
    for series in (s.rpy_est_deg, s.rpy_gt_deg, s.rot_error_deg):
        assert _largest_step(series) < 20.0
    gap = np.abs(s.rpy_est_deg - s.rpy_gt_deg)
    assert np.nanmax(gap) < 4 * max_error_deg  # the curves lie on each other, no 360- or 180-deg offsets
    assert np.isfinite(s.rpy_est_deg[:, 1]).all() and np.isfinite(s.rpy_gt_deg[:, 1]).all()  # pitch always drawn


def test_orientation_series_yaw_crossing_180_has_no_jump():
    n = 300
    yaw = 178.0 + np.linspace(0.0, 60.0, n)  # ground truth starts just below +180, the estimate just past it
    R_gt = _zyx(10 * np.sin(np.linspace(0, 6, n)), 20 * np.sin(np.linspace(0, 4, n)), yaw)
    R_est = _noisy(so3_exp(np.array([0.0, 0.0, np.radians(4.0)]))[None] @ R_gt, 0.1, 1)  # 4 deg yaw error
    s = orientation_series(np.arange(n) / 30.0, _poses(R_est), _poses(R_gt))
    _check_drawn(s, 4.0)
    assert s.rpy_gt_deg[-1, 2] == pytest.approx(238.0, abs=1e-6)  # unwrapped, not folded back to -122
    np.testing.assert_allclose(s.rpy_est_deg[:, 2] - s.rpy_gt_deg[:, 2], 4.0, atol=1.0)  # the error, not 360 - it
    np.testing.assert_allclose(s.rot_error_deg, 4.0, atol=1.0)
    assert not s.gimbal.any()


def test_orientation_series_near_pitch_90_has_no_spikes():
    n = 400
    pitch = 89.5 * np.sin(np.linspace(0, np.pi, n))  # up to 0.5 deg from gimbal lock and back
    R_gt = _zyx(np.linspace(-30, 30, n), pitch, np.linspace(170, 200, n))
    R_est = _noisy(R_gt, 0.3, 2)  # per-frame jitter like a real estimate's (fr1_rpy: 0.2 to 0.3 deg)
    s = orientation_series(np.arange(n) / 30.0, _poses(R_est), _poses(R_gt))
    _check_drawn(s, 2.0)
    assert s.gimbal.any() and not s.gimbal.all()
    assert np.isnan(s.rpy_est_deg[s.gimbal][:, [0, 2]]).all()  # roll and yaw left out where ill-defined
    err = np.degrees(np.linalg.norm(so3_log(np.swapaxes(R_gt, 1, 2) @ R_est), axis=1))
    np.testing.assert_allclose(s.rot_error_deg, err, atol=1e-6)  # the error panel: the true angle, no spike
    assert s.rot_error_deg.max() < 3.0


def test_orientation_series_passing_by_the_pole_has_no_spikes():
    # a rotation about one axis that passes 2 deg from pitch 90: true Euler roll and yaw swing by 180 deg
    n = 360
    R_gt = so3_exp(np.array([np.radians(2.0), 0.0, 0.0]))[None] @ so3_exp(
        np.stack([np.zeros(n), np.radians(np.linspace(0, 180, n)), np.zeros(n)], 1))
    R_est = _noisy(R_gt, 0.2, 3)
    s = orientation_series(np.arange(n) / 30.0, _poses(R_est), _poses(R_gt))
    _check_drawn(s, 1.0)
    assert _largest_step(s.rpy_gt_deg[:, 1]) < 5.0 and _largest_step(s.rpy_est_deg[:, 1]) < 6.0
    assert s.rpy_gt_deg[-1, 1] == pytest.approx(180.0, abs=0.5)  # pitch goes on over the top, no bounce


def test_orientation_series_without_ground_truth_flip_and_pass_by_the_pole():
    n = 200
    pitch = np.linspace(0, -2 * np.pi, n)  # a backflip: pitch goes on through -90 and -270
    T = _poses(so3_exp(np.stack([np.zeros(n), pitch, np.zeros(n)], 1)))
    s = orientation_series(np.arange(n) / 30.0, T)
    assert s.rpy_gt_deg is None and s.rot_error_deg is None
    np.testing.assert_allclose(s.rpy_est_deg[:, 1], np.degrees(pitch), atol=1.0)  # within half a sample step
    np.testing.assert_allclose(s.rpy_est_deg[~s.gimbal][:, [0, 2]], 0.0, atol=1e-6)
    n = 360  # 6 deg from the pole: pitch turns back at 84 deg, roll and yaw swing by 180 inside the gap
    R = so3_exp(np.array([np.radians(6.0), 0.0, 0.0]))[None] @ so3_exp(
        np.stack([np.zeros(n), np.radians(np.linspace(0, 180, n)), np.zeros(n)], 1))
    s = orientation_series(np.arange(n) / 30.0, _poses(_noisy(R, 0.2, 4)))
    assert _largest_step(s.rpy_est_deg) < 20.0 and np.nanmax(s.rpy_est_deg[:, 1]) < 86.0


def test_plot_run_with_and_without_ground_truth(tmp_path):
    n = 60
    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, 0, 3] = np.linspace(0, 1, n)
    T[:, 1, 3] = np.sin(np.linspace(0, 3, n))
    T[:, :3, :3] = so3_exp(np.stack([np.zeros(n), np.zeros(n), np.linspace(0, 1, n)], 1))
    traj = Trajectory(np.arange(n) * 33_000_000, T)
    res = evaluate(traj, traj, EvalOptions(align="se3"))
    names = {p.name for p in plot_run(tmp_path / "a", traj, res)}
    assert names == {"trajectory.png", "position.png", "orientation.png", "error.png"}
    assert {p.name for p in plot_run(tmp_path / "b", traj)} == {"trajectory.png", "position.png", "orientation.png"}


def test_plot_comparison_draws_every_run_against_ground_truth(tmp_path):
    import matplotlib.image as mpimg

    n = 60
    T = np.repeat(np.eye(4)[None], n, 0)
    T[:, 0, 3] = np.linspace(0, 1, n)
    T[:, 1, 3] = np.sin(np.linspace(0, 3, n))
    gt = Trajectory(np.arange(n) * 33_000_000, T)
    off = T.copy()
    off[:, 2, 3] += np.linspace(0, 0.2, n)  # a drifting estimate
    runs = {"fused": evaluate(gt, gt, EvalOptions(align="se3")),
            "rgbd": evaluate(gt, Trajectory(gt.stamps_ns, off), EvalOptions(align="none"))}
    path = plot_comparison(tmp_path / "c" / "comparison.png", runs, title="t")
    img = mpimg.imread(path)
    assert img.shape[0] > 500 and img.shape[1] > 800 and img.std() > 0.05  # a drawn figure, not a blank page
    with pytest.raises(ValueError):
        plot_comparison(tmp_path / "d.png", {})


def test_plot_memory_writes_one_png_for_several_runs(tmp_path):
    t = np.linspace(0.0, 60.0, 50)
    runs = {"real time": np.stack([t, 280 + 5 * t], 1), "3x": np.stack([t, 300 + 0 * t], 1).tolist()}
    path = plot_memory(tmp_path / "sub" / "rss.png", runs, "soak")
    assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000
