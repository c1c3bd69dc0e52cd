"""Plots: files are written; roll/pitch/yaw stay continuous through a flip."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.geometry import so3_exp
from atsvo_ros.eval.metrics import EvalOptions, evaluate
from atsvo_ros.eval.plots import plot_comparison, plot_memory, plot_run, rpy_deg
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
    import pytest

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
