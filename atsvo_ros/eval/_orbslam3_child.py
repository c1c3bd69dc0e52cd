"""One ORB-SLAM3 RGB-D run in a process of its own (see :mod:`atsvo_ros.eval.orbslam3`).

``python -m atsvo_ros.eval._orbslam3_child FOLDER VOCABULARY REAL_TIME PROGRESS`` reads ``rgbd.yaml``,
``stamps.npy``, ``rgb.npy`` and ``depth.npy`` from FOLDER and writes ``result.npz`` there: each frame's emitted pose
``T_w_c`` (the last valid one when it gave none), whether it was ``OK``, the track call's time and how many times the
map changed (a loop closure or a merge).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm


def main(argv: list[str]) -> int:
    import pyorbslam3

    folder, vocabulary, real_time, progress = Path(argv[0]), argv[1], argv[2] == "1", argv[3] == "1"
    stamps = np.load(folder / "stamps.npy")
    rgb = np.load(folder / "rgb.npy", mmap_mode="r")
    depth = np.load(folder / "depth.npy", mmap_mode="r")
    n = len(stamps)
    poses, ok, times = np.tile(np.eye(4), (n, 1, 1)), np.zeros(n, bool), np.zeros(n)
    changed = 0
    slam = pyorbslam3.Slam(vocabulary, str(folder / "rgbd.yaml"), pyorbslam3.Sensor.RGBD)
    try:
        T_last = np.eye(4)
        wall0 = time.perf_counter()
        for i in tqdm(range(n), desc="ORB-SLAM3", unit="frame", disable=not progress, leave=False):
            if real_time:  # no earlier than the stamps say, as ORB-SLAM3's examples feed it
                time.sleep(max(0.0, wall0 + (stamps[i] - stamps[0]) * 1e-9 - time.perf_counter()))
            t0 = time.perf_counter()
            r = slam.track_rgbd(np.ascontiguousarray(rgb[i]), np.ascontiguousarray(depth[i]), stamps[i] * 1e-9)
            times[i] = time.perf_counter() - t0
            if r.pose_valid:
                T_last = np.array(r.pose_wc, float)
            poses[i] = T_last
            ok[i] = bool(r.pose_valid) and r.state == pyorbslam3.TrackingState.OK
            changed += int(slam.map_changed())
    finally:
        slam.shutdown()
    np.savez(folder / "result.npz", T_w_c=poses, ok=ok, time_s=times, map_changes=np.int64(changed))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
