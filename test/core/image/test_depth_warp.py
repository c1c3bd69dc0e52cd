"""Turning a depth image to another moment by the camera's rotation in between."""
from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.core.image.depth_warp import rotate_depth, warp_depth

CAM = CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5)


def _plane_depth() -> np.ndarray:
    """A tilted plane, Z = 1 + 0.3 X, seen by CAM."""
    u, _ = np.meshgrid(np.arange(CAM.width, dtype=np.float64), np.arange(CAM.height, dtype=np.float64))
    return (1.0 / (1.0 - 0.3 * (u - CAM.cx) / CAM.fx)).astype(np.float32)


def _rotation(axis: int, deg: float) -> np.ndarray:
    xi = np.zeros(6)
    xi[3 + axis] = np.radians(deg)
    return se3_exp(xi)[:3, :3]


def test_a_rotated_plane_lands_where_its_points_project_with_their_new_depth():
    z = _plane_depth()
    for axis, deg in ((1, 5.0), (0, -8.0), (2, 10.0)):
        R = _rotation(axis, deg)
        out = rotate_depth(z, CAM, R)
        u, v = np.meshgrid(np.arange(CAM.width, dtype=np.float64), np.arange(CAM.height, dtype=np.float64))
        P = np.stack([(u - CAM.cx) / CAM.fx * z, (v - CAM.cy) / CAM.fy * z, z], -1).reshape(-1, 3) @ R.T
        uu, vv = P[:, 0] / P[:, 2] * CAM.fx + CAM.cx, P[:, 1] / P[:, 2] * CAM.fy + CAM.cy
        inside = (uu > 1) & (uu < CAM.width - 2) & (vv > 1) & (vv < CAM.height - 2)
        iu, iv = np.round(uu[inside]).astype(int), np.round(vv[inside]).astype(int)
        got = out[iv, iu]
        rel = np.abs(got - P[inside, 2])[got > 0] / P[inside, 2][got > 0]
        assert np.median(rel) < 1e-3 and np.percentile(rel, 99) < 0.01, (axis, deg)
        # no cracks (a forward warp would leave some): only the image border can lose a pixel
        assert (got == 0).mean() < 0.005


def test_no_rotation_is_the_identity_and_holes_stay_holes():
    z = _plane_depth()
    z[100:120, 100:140] = 0.0
    out = rotate_depth(z, CAM, np.eye(3))
    np.testing.assert_allclose(out, z, rtol=1e-6)
    assert (out[100:120, 100:140] == 0).all()


def test_a_moved_plane_takes_the_translation_in_its_depths():
    # a camera moving 3 cm forward and 1 cm sideways while turning 4 deg (a bound's 2 m/s over 16 ms)
    z = _plane_depth()
    R, t = _rotation(1, 4.0), np.array([0.01, 0.0, -0.03])
    out = warp_depth(z, CAM, R, t)
    u, v = np.meshgrid(np.arange(CAM.width, dtype=np.float64), np.arange(CAM.height, dtype=np.float64))
    P = np.stack([(u - CAM.cx) / CAM.fx * z, (v - CAM.cy) / CAM.fy * z, z], -1).reshape(-1, 3) @ R.T + t
    uu, vv = P[:, 0] / P[:, 2] * CAM.fx + CAM.cx, P[:, 1] / P[:, 2] * CAM.fy + CAM.cy
    inside = (uu > 3) & (uu < CAM.width - 4) & (vv > 3) & (vv < CAM.height - 4)
    iu, iv = np.round(uu[inside]).astype(int), np.round(vv[inside]).astype(int)
    got, want = out[iv, iu], P[inside, 2]
    rel = np.abs(got - want)[got > 0] / want[got > 0]
    assert np.median(rel) < 2e-3 and np.percentile(rel, 99) < 0.01
    assert (got == 0).mean() < 0.01
    # the rotation alone leaves every depth off by about the translation
    rot = rotate_depth(z, CAM, R)[iv, iu]
    assert np.median(np.abs(rot - want)[rot > 0]) > 0.025
    np.testing.assert_array_equal(warp_depth(z, CAM, R, np.zeros(3)), rotate_depth(z, CAM, R))


def _mean_warped(_: int) -> float:
    return float(warp_depth(_plane_depth(), CAM, _rotation(1, 4.0), np.array([0.01, 0.0, -0.03])).mean())


# Run in a fresh interpreter: a fork from a pytest-xdist worker copies its I/O threads' locks as well, and a child
# that aborts or hangs is then killed by the timeout instead of hanging Pool.terminate() and the suite with it.
_FORK = """
import multiprocessing
from test.core.image.test_depth_warp import _mean_warped

want = _mean_warped(0)
with multiprocessing.get_context("fork").Pool(2) as pool:
    got = pool.map_async(_mean_warped, range(2)).get(timeout=60)
print(got == [want, want])
"""


def test_a_process_that_warped_can_fork_and_threads_can_share_it():
    """The kernel is a numba parallel loop: GNU OpenMP would abort a forked child of a process that ran it (the
    benchmarks' worker pools), and numba's workqueue layer must not be entered from two threads at once."""
    done = subprocess.run([sys.executable, "-c", _FORK], capture_output=True, text=True, timeout=180,
                          cwd=Path(__file__).resolve().parents[3])
    assert done.returncode == 0 and done.stdout.split() == ["True"], done.stdout + done.stderr[-3000:]
    want = _mean_warped(0)
    with ThreadPoolExecutor(3) as ex:
        assert list(ex.map(_mean_warped, range(6))) == [want] * 6
