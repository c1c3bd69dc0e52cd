"""The tracking benchmark's whole-run figures beside the paper's: evo's SE(3) ATE, the path's scale and the ATE
anchored at the first pose."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.bench.tracking import whole_run_figures
from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.io.trajectory import Trajectory


def _walk(n: int) -> np.ndarray:
    T = np.repeat(np.eye(4)[None], n, 0)
    s = np.linspace(0.0, 3.0, n)
    T[:, 0, 3], T[:, 1, 3], T[:, 2, 3] = 2.0 * s, np.sin(s), 0.1 * np.cos(2 * s)
    return T


def test_a_path_one_percent_short_is_reported_as_such_whatever_its_frame():
    gt = _walk(120)
    est = gt.copy()
    est[:, :3, 3] *= 0.99  # depth 1 % short: every displacement 1 % short
    est = np.stack([se3_exp(np.array([0.3, -0.2, 0.1, 0.05, 0.2, -0.1])) @ T for T in est])  # another odom frame
    stamps = np.arange(120, dtype=np.int64) * 33_000_000
    ate_m, scale, anchored_m = whole_run_figures(Trajectory(stamps, gt), Trajectory(stamps, est), np.ones(120, bool))
    assert abs(scale - 0.99) < 1e-9
    assert 0.001 < ate_m < 0.05  # the SE(3) fit cannot take the scale out
    # anchored at the first pose, each pose is off by 1 % of its displacement from the start (no rotation here)
    from_start = np.linalg.norm(gt[:, :3, 3] - gt[0, :3, 3], axis=1)
    assert anchored_m == pytest.approx(0.01 * np.sqrt(np.mean(from_start ** 2)), rel=1e-9)
    assert anchored_m > ate_m  # nothing is fitted: the whole scale error stays in


def test_the_figures_are_none_where_the_fits_are_undefined():
    stamps = np.arange(2, dtype=np.int64) * 33_000_000
    T = _walk(2)
    assert whole_run_figures(Trajectory(stamps, T), Trajectory(stamps, T), np.ones(2, bool)) == (None, None, 0.0)
