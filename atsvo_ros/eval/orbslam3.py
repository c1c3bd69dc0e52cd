"""ORB-SLAM3 RGB-D (Campos et al., 2021) as a peer, through its pip bindings (optional extra ``orbslam3``).

Each frame goes in as the files hold it: the raw (distorted) colour image, whose keypoints ORB-SLAM3
undistorts with the plumb_bob coefficients written into its settings, and the depth in metres, unclipped.
The pose recorded per frame is the one it emits after tracking that frame (``pose_wc``), not the trajectory
its local bundle adjustment refines afterwards: what a controller would have read. A frame counts as ok when
ORB-SLAM3 says ``OK`` with a valid pose; a frame without a valid pose keeps the last one.

Loop closure stays on: this build of the bindings crashes (segmentation fault, after the first map) when
the settings switch it off (``loopClosing: 0``). :attr:`PeerRun.info` counts the frames after which the
map changed as a loop closure or merge does (``map_changed``), so a run that closed a loop is visible.
ORB-SLAM3 runs threads of its own and is not deterministic: a few percent between runs.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
from tqdm import tqdm

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.peers import PeerRun

#: ORB-SLAM's RGB-D settings for the TUM sequences (its Examples/RGB-D/TUM*.yaml): 1000 ORB features over
#: 8 levels of x1.2, FAST thresholds 20 / 7, close points within 40 virtual baselines (``bf`` 40 px m)
_SETTINGS = """%YAML:1.0
Camera.type: "PinHole"
Camera.fx: {fx}
Camera.fy: {fy}
Camera.cx: {cx}
Camera.cy: {cy}
Camera.k1: {k1}
Camera.k2: {k2}
Camera.p1: {p1}
Camera.p2: {p2}
Camera.k3: {k3}
Camera.width: {width}
Camera.height: {height}
Camera.fps: {fps}
Camera.bf: 40.0
Camera.RGB: 1
ThDepth: 40.0
DepthMapFactor: 1.0
ORBextractor.nFeatures: 1000
ORBextractor.scaleFactor: 1.2
ORBextractor.nLevels: 8
ORBextractor.iniThFAST: 20
ORBextractor.minThFAST: 7
Viewer.KeyFrameSize: 0.05
Viewer.KeyFrameLineWidth: 1.0
Viewer.GraphLineWidth: 0.9
Viewer.PointSize: 2.0
Viewer.CameraSize: 0.08
Viewer.CameraLineWidth: 3.0
Viewer.ViewpointX: 0.0
Viewer.ViewpointY: -0.7
Viewer.ViewpointZ: -1.8
Viewer.ViewpointF: 500.0
"""


def settings_text(camera: CameraModel, fps: float = 30.0) -> str:
    """ORB-SLAM3's settings for ``camera`` (pinhole, plumb_bob or none: the models its RGB-D mode reads)."""
    if camera.distortion_model not in ("plumb_bob", "none"):
        raise EvaluationError(f"ORB-SLAM3's RGB-D settings take plumb_bob distortion, not {camera.distortion_model}")
    d = [*camera.D, 0.0, 0.0, 0.0, 0.0, 0.0][:5] if camera.distortion_model == "plumb_bob" else [0.0] * 5
    return _SETTINGS.format(fx=camera.fx, fy=camera.fy, cx=camera.cx, cy=camera.cy, k1=d[0], k2=d[1], p1=d[2],
                            p2=d[3], k3=d[4], width=camera.width, height=camera.height, fps=fps)


@contextlib.contextmanager
def _stdout_to(path: Path) -> Iterator[None]:
    """File descriptor 1 (where ORB-SLAM3's C++ writes) into ``path`` for the block; Python's stdout flushed first."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(path, "wb") as log:
            os.dup2(log.fileno(), 1)
            try:
                yield
            finally:
                ctypes.CDLL(None).fflush(None)  # C stdio's buffer (std::cout writes through it) before fd 1 returns
                os.dup2(saved, 1)
    finally:
        os.close(saved)


def run_orbslam3(frames: Iterable[tuple[int, np.ndarray, np.ndarray]], camera: CameraModel, vocabulary: Path,
                 progress: bool = True, total: int | None = None) -> PeerRun:
    """Track ``(stamp_ns, rgb, depth_m)`` frames (RGB uint8, float32 metres) with ORB-SLAM3 RGB-D.

    Raises:
        EvaluationError: the bindings are not installed (``pip install 'atsvo_ros[orbslam3]'``).
    """
    try:
        import pyorbslam3
    except ImportError as exc:
        raise EvaluationError(f"ORB-SLAM3 needs its pip bindings ({exc}): pip install 'atsvo_ros[orbslam3]'") from exc
    stamps, poses, ok, times, changed = [], [], [], [], 0
    T_last = np.eye(4)
    with tempfile.TemporaryDirectory(prefix="atsvo-orbslam3-") as tmp:
        settings = Path(tmp) / "rgbd.yaml"
        settings.write_text(settings_text(camera))
        with _stdout_to(Path(tmp) / "orbslam3.log"):  # its banner, settings and map events, not our table
            slam = pyorbslam3.Slam(str(vocabulary), str(settings), pyorbslam3.Sensor.RGBD)
            try:
                for stamp_ns, rgb, depth_m in tqdm(frames, total=total, desc="ORB-SLAM3", unit="frame",
                                                   disable=not progress, leave=False):
                    t0 = time.perf_counter()
                    r = slam.track_rgbd(np.ascontiguousarray(rgb), np.asarray(depth_m, np.float32), stamp_ns * 1e-9)
                    times.append(time.perf_counter() - t0)
                    good = bool(r.pose_valid) and r.state == pyorbslam3.TrackingState.OK
                    if r.pose_valid:
                        T_last = np.array(r.pose_wc, float)
                    changed += int(slam.map_changed())
                    stamps.append(int(stamp_ns))
                    poses.append(T_last.copy())
                    ok.append(good)
            finally:
                slam.shutdown()
    n = len(stamps)
    if n == 0:
        raise EvaluationError("ORB-SLAM3 got no frames")
    return PeerRun("orbslam3_rgbd", np.array(stamps, np.int64), np.stack(poses), np.array(ok), np.array(times),
                   np.zeros(n), np.full(n, np.nan), np.full(n, np.nan),
                   info={"map_changes": changed, "loop_closing": True})
