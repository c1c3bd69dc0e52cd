"""The replay's per-frame and ground-truth logs: the same record as the result objects, in bounded bytes."""
from __future__ import annotations

import json
import tracemalloc

import numpy as np

from atsvo_ros.core.frame import OdometryResult, TrackingStatus
from atsvo_ros.runtime.types import RuntimeOutput
from atsvo_ros.tools.replay_log import FrameLog, PoseLog


def _output(k: int) -> RuntimeOutput:
    T = np.eye(4)
    T[:3, 3] = [k, 2 * k, 3 * k]
    res = OdometryResult(1_000 + k, T, T @ np.diag([1.0, -1.0, -1.0, 1.0]), np.eye(6) * k, TrackingStatus.OK,
                         "fused" if k % 2 else "rgbd", 0.01 * k, 500 + k, 400 + k, k % 5 == 0,
                         reason=None if k % 3 else f"reason {k % 2}",
                         inliers={"rgb": k, "depth": 2 * k, **({"ats": 3 * k} if k % 2 else {})},
                         event_map_time_s=0.001 * k)
    return RuntimeOutput(res, None, 10 * k)


def test_frame_log_keeps_what_the_outputs_need():
    log = FrameLog("camera")
    outs = [_output(k) for k in range(100)]
    for o in outs:
        log.append(o)
    assert len(log) == 100
    assert np.array_equal(log["stamp_ns"], [o.result.stamp_ns for o in outs])
    assert np.array_equal(log.poses, np.stack([o.result.T_odom_camera for o in outs]))
    assert log.statuses == ["ok"] * 100 and log.modes[1] == "fused"
    info = log.frames_info()
    for o, f in zip(outs, info):
        r = o.result
        assert f == {"stamp_ns": r.stamp_ns, "tracking_time_s": r.tracking_time_s, "mode": r.mode, "status": "ok",
                     "reason": r.reason, "n_points": r.n_points, "n_inliers": r.n_inliers, "inliers": r.inliers,
                     "keyframe": r.keyframe_inserted, "n_events": o.n_events, "event_map_time_s": r.event_map_time_s}
    base = FrameLog("base")
    base.append(outs[3])
    assert np.array_equal(base.poses[0], outs[3].result.T_odom_base)


def _bytes_per_item(make, add, n: int) -> float:
    log = make()
    tracemalloc.start()
    try:
        for k in range(200):  # past the first growth steps
            add(log, k)
        t0 = tracemalloc.get_traced_memory()[0]
        for k in range(200, 200 + n):
            add(log, k)
        t1 = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    return (t1 - t0) / n


def test_memory_per_frame_and_per_ground_truth_pose_is_bounded():
    """A 5-minute bag (9,000 frames, 60,000 poses at 200 Hz) must not grow the replay by more than a few MiB:
    the result objects cost ~1.6 KiB a frame, a (stamp, 4x4 array) tuple ~330 B a pose."""
    outs = [_output(k % 7) for k in range(4096 + 200)]
    per_frame = _bytes_per_item(lambda: FrameLog("camera"), lambda log, k: log.append(outs[k]), 4096)
    assert per_frame < 300, per_frame  # measured ~230 (128 B pose, 52 B numbers, 4 list refs; chunked arrays)
    T = np.eye(4)
    per_pose = _bytes_per_item(PoseLog, lambda log, k: log.append((k, T)), 8192)
    assert per_pose < 200, per_pose  # 136 B of arrays
    gt = PoseLog()
    gt.extend([(3, T * 3), (1, T), (2, T * 2), (2, T * 2)])
    traj = gt.trajectory()
    assert traj.stamps_ns.tolist() == [1, 2, 3] and traj.T_w_b[2][0, 0] == 3
    assert gt.trajectory() is traj and len(gt) == 3  # built once, the chunks freed


def test_timing_json_is_written_a_frame_at_a_time_and_reads_back_whole(tmp_path):
    log = FrameLog("camera")
    for k in range(7):
        log.append(_output(k))
    doc = {"mode": "rgbd", "counters": {"frames": 7}, "notes": ["a", "b"]}
    log.write_json(tmp_path / "timing.json", doc, "frames")
    assert json.loads((tmp_path / "timing.json").read_text()) == {**doc, "frames": log.frames_info()}
    log.write_json(tmp_path / "empty.json", {}, "frames")
    assert json.loads((tmp_path / "empty.json").read_text()) == {"frames": log.frames_info()}
