"""ORB-SLAM3 RGB-D (Campos et al., 2021) as a peer, through its pip bindings (optional extra ``orbslam3``).

Each frame goes in as the files hold it: the raw (distorted) colour image, whose keypoints ORB-SLAM3
undistorts with the plumb_bob coefficients written into its settings, and the depth in metres, unclipped.
The pose recorded per frame is the one it emits after tracking that frame (``pose_wc``), not the trajectory
its local bundle adjustment refines afterwards: what a controller would have read. A frame counts as ok when
ORB-SLAM3 says ``OK`` with a valid pose; a frame without a valid pose keeps the last one.

Loop closure stays on: this build of the bindings crashes (segmentation fault, after the first map) when
the settings switch it off (``loopClosing: 0``). :attr:`PeerRun.info` counts the frames after which the
map changed as a loop closure or merge does (``map_changed``), so a run that closed a loop is visible.
ORB-SLAM3 runs threads of its own and is not deterministic (at a flip's or a subsample's speed, runs differ several
times over: docs/odometry.md). Each run is a child
process (:mod:`atsvo_ros.eval._orbslam3_child`): ORB-SLAM3 keeps the first camera's image bounds and grid in static
members for the life of a process (``Frame::mbInitialComputations``), so a second camera in the same process was
tracked with the first one's (TUM frames after a simulated 320x240 run: lost after 32 of 90 frames). The child's
standard output (its banner, settings and map events) goes to a log, not our table.
"""
from __future__ import annotations

import importlib.util
import subprocess
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

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


def run_orbslam3(frames: Iterable[tuple[int, np.ndarray, np.ndarray]], camera: CameraModel, vocabulary: Path,
                 progress: bool = True, real_time: bool = True) -> PeerRun:
    """Track ``(stamp_ns, rgb, depth_m)`` frames (RGB uint8, float32 metres) with ORB-SLAM3 RGB-D, in a child process.

    ``real_time``: hand a frame over no earlier than its stamp says (from the first frame's), as ORB-SLAM3's own
    examples do. Its local mapping runs in a thread beside tracking; fed as fast as tracking returns, on a busy
    2-core machine it fell behind and tracking lost a simulated trot after 6 frames.

    Raises:
        EvaluationError: the bindings are not installed (``pip install 'atsvo_ros[orbslam3]'``), no frames, or the
            child failed (the end of its log in the message).
    """
    if importlib.util.find_spec("pyorbslam3") is None:
        raise EvaluationError("ORB-SLAM3 needs its pip bindings: pip install 'atsvo_ros[orbslam3]'")
    stamps, rgbs, depths = [], [], []
    for stamp_ns, rgb, depth_m in frames:
        stamps.append(int(stamp_ns))
        rgbs.append(np.ascontiguousarray(rgb))
        depths.append(np.asarray(depth_m, np.float32))
    if not stamps:
        raise EvaluationError("ORB-SLAM3 got no frames")
    with tempfile.TemporaryDirectory(prefix="atsvo-orbslam3-") as tmp:
        folder = Path(tmp)
        (folder / "rgbd.yaml").write_text(settings_text(camera))
        np.save(folder / "stamps.npy", np.array(stamps, np.int64))
        np.save(folder / "rgb.npy", np.stack(rgbs))
        np.save(folder / "depth.npy", np.stack(depths))
        del rgbs, depths
        log = folder / "orbslam3.log"
        with open(log, "wb") as out:
            cmd = [sys.executable, "-m", "atsvo_ros.eval._orbslam3_child", str(folder), str(vocabulary),
                   "1" if real_time else "0", "1" if progress else "0"]
            done = subprocess.run(cmd, stdout=out, check=False)
        if done.returncode != 0:
            tail = "\n".join(log.read_text(errors="replace").splitlines()[-15:])
            raise EvaluationError(f"ORB-SLAM3 failed (exit code {done.returncode}); the end of its log:\n{tail}")
        with np.load(folder / "result.npz") as r:
            poses, ok, times, changed = r["T_w_c"], r["ok"], r["time_s"], int(r["map_changes"])
    n = len(stamps)
    return PeerRun("orbslam3_rgbd", np.array(stamps, np.int64), poses, ok, times, np.zeros(n), np.full(n, np.nan),
                   np.full(n, np.nan), info={"map_changes": changed, "loop_closing": True, "real_time": real_time})
