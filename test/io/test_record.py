"""BagRecorder on hand-made outputs: odometry, TF, path cadence, ground truth in the odom frame, safe file handling."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from atsvo_ros.config import load_config
from atsvo_ros.core.frame import OdometryResult, TrackingStatus
from atsvo_ros.core.geometry import se3_exp, se3_inv
from atsvo_ros.errors import RecordError
from atsvo_ros.io.record import GT_ODOMETRY_TOPIC, GT_PATH_TOPIC, PATH_TOPIC, BagRecorder, check_record_path
from atsvo_ros.io.ros_out import pose_from_transform_msg, time_to_ns
from atsvo_ros.io.trajectory import Trajectory
from atsvo_ros.runtime.types import RuntimeOutput

T0 = 1_700_000_000_000_000_000
MS = 1_000_000


def true_pose(t_s: float) -> np.ndarray:
    """The robot base in its motion-capture world."""
    return se3_exp(np.array([0.4 * t_s, 0.1 * np.sin(3 * t_s), 0.05 * t_s, 0.2 * np.sin(t_s), 0.3 * t_s, 0.1]))


def outputs(n: int, T_odom_base0: np.ndarray, period_ns: int = 40 * MS) -> list[RuntimeOutput]:
    """A perfect estimate at 25 Hz whose first pose is ``T_odom_base0``."""
    out = []
    for i in range(n):
        t = T0 + i * period_ns
        T = T_odom_base0 @ se3_inv(true_pose(0.0)) @ true_pose((t - T0) * 1e-9)
        cov = np.diag(np.full(6, 1e-4 * (i + 1)))
        out.append(RuntimeOutput(OdometryResult(t, T, T, cov, TrackingStatus.OK, "rgbd", 0.001, 10, 9, False),
                                 None, 0))
    return out


def read(path: Path) -> dict[str, list]:
    """topic -> [(log time, message)] in log-time order."""
    got: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, t, raw in reader.messages():
            got.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return got


def test_odometry_tf_path_and_ground_truth_in_the_odom_frame(tmp_path):
    config = load_config("synthetic")
    T_odom_base0 = se3_exp(np.array([0.1, -0.2, 0.0, 0.0, 0.0, 0.3]))  # the estimate need not start at identity
    outs = outputs(20, T_odom_base0)
    W = se3_exp(np.array([5.0, -3.0, 1.0, 0.2, -0.1, 1.0]))  # motion-capture world, far from odom
    gt_stamps = np.arange(T0 - 100 * MS, T0 + 1000 * MS, 10 * MS, dtype=np.int64)  # 100 Hz, beyond the run
    gt = Trajectory(gt_stamps, np.stack([W @ true_pose((t - T0) * 1e-9) for t in gt_stamps]))
    with BagRecorder(tmp_path / "run.mcap", config, path_period_s=0.3) as rec:
        for o in outs:
            rec(o, None)
        rec.write_ground_truth(gt)
    got = read(tmp_path / "run.mcap")
    assert set(got) == {"/atsvo/odometry", "/tf", PATH_TOPIC, GT_ODOMETRY_TOPIC, GT_PATH_TOPIC}
    odom = got["/atsvo/odometry"]
    assert [t for t, _ in odom] == [o.result.stamp_ns for o in outs]
    for (t, m), o in zip(odom, outs):
        assert time_to_ns(m.header.stamp) == t and m.header.frame_id == "odom" and m.child_frame_id == "base_link"
        np.testing.assert_allclose(pose_from_transform_msg(m.pose.pose), o.result.T_odom_base, atol=1e-12)
        np.testing.assert_allclose(np.reshape(m.pose.covariance, (6, 6)), o.result.covariance)
    for (_, m), o in zip(got["/tf"], outs):
        (tf,) = m.transforms
        assert tf.header.frame_id == "odom" and tf.child_frame_id == "base_link"
        np.testing.assert_allclose(pose_from_transform_msg(tf.transform), o.result.T_odom_base, atol=1e-12)
    # a path at the first frame, then at least every 0.3 s of bag time, and one at the last frame with every pose
    path_stamps = [t for t, _ in got[PATH_TOPIC]]
    assert path_stamps == [T0, T0 + 320 * MS, T0 + 640 * MS, T0 + 760 * MS]
    last = got[PATH_TOPIC][-1][1]
    assert len(last.poses) == 20
    np.testing.assert_allclose(pose_from_transform_msg(last.poses[-1].pose), outs[-1].result.T_odom_base, atol=1e-12)
    # ground truth: only within the run, in the odom frame where it starts on the estimate's first pose, so a
    # perfect estimate lies on it
    gt_msgs = got[GT_ODOMETRY_TOPIC]
    assert [t for t, _ in gt_msgs] == [int(s) for s in gt_stamps if T0 <= s <= T0 + 760 * MS]
    by_stamp = {t: pose_from_transform_msg(m.pose.pose) for t, m in gt_msgs}
    for o in outs:
        np.testing.assert_allclose(by_stamp[o.result.stamp_ns], o.result.T_odom_base, atol=1e-9)
    assert gt_msgs[0][1].header.frame_id == "odom" and gt_msgs[0][1].child_frame_id == "base_link_ground_truth"
    gt_paths = got[GT_PATH_TOPIC]
    assert [t for t, _ in gt_paths] == path_stamps
    assert [len(m.poses) for _, m in gt_paths] == [1, 33, 65, 77]


def test_output_checks_before_a_run(tmp_path, monkeypatch):
    with pytest.raises(RecordError, match=r"must end in \.mcap"):
        check_record_path(tmp_path / "run.bag")
    (tmp_path / "dir.mcap").mkdir()
    with pytest.raises(RecordError, match="is a directory"):
        check_record_path(tmp_path / "dir.mcap", force=True)
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"old")
    with pytest.raises(RecordError, match="exists .use --force"):
        check_record_path(existing)
    assert check_record_path(existing, force=True) == existing
    # where it cannot be written: one line before the run, not a traceback after it
    with pytest.raises(RecordError, match="is under .*old.mcap, which is a file, not a folder"):
        check_record_path(existing / "x.mcap")
    with pytest.raises(RecordError, match="is not writable"):
        check_record_path(Path("/proc/run.mcap"))
    assert check_record_path(tmp_path / "new" / "sub" / "run.mcap").parent.is_dir()  # its folder is made

    from rosbags.rosbag2 import Writer

    monkeypatch.setattr(Writer, "STORAGE_PLUGINS", {k: v for k, v in Writer.STORAGE_PLUGINS.items()
                                                     if k.name != "MCAP"})
    with pytest.raises(RecordError, match="no mcap storage writer"):
        check_record_path(tmp_path / "new.mcap")


def test_a_failed_run_leaves_nothing_and_force_replaces_only_at_the_end(tmp_path):
    config = load_config("synthetic")
    target = tmp_path / "run.mcap"
    with pytest.raises(ZeroDivisionError):
        with BagRecorder(target, config) as rec:
            rec(outputs(1, np.eye(4))[0], None)
            raise ZeroDivisionError  # any failure during the run
    assert list(tmp_path.iterdir()) == []  # no partial bag, no staging folder

    target.write_bytes(b"previous")
    rec = BagRecorder(target, config, force=True).open()
    rec(outputs(1, np.eye(4))[0], None)
    assert target.read_bytes() == b"previous"  # untouched while the run goes on
    assert rec.close() == {"/atsvo/odometry": 1, "/tf": 1, PATH_TOPIC: 1}
    assert len(read(target)["/atsvo/odometry"]) == 1 and [p.name for p in tmp_path.iterdir()] == ["run.mcap"]

    other = tmp_path / "other.mcap"
    rec = BagRecorder(other, config).open()
    rec(outputs(1, np.eye(4))[0], None)
    other.write_bytes(b"someone else's")  # appeared during the run: not overwritten without force
    with pytest.raises(RecordError, match="appeared during the run"):
        rec.close()
    assert other.read_bytes() == b"someone else's" and sorted(p.name for p in tmp_path.iterdir()) == [
        "other.mcap", "run.mcap"]


def test_ground_truth_starting_late_is_aligned_where_it_starts_and_a_disjoint_one_is_left_out(tmp_path):
    config = load_config("synthetic")
    outs = outputs(10, np.eye(4))
    W = se3_exp(np.array([1.0, 2.0, 0.0, 0.0, 0.3, -0.5]))
    late = np.arange(T0 + 95 * MS, T0 + 400 * MS, 5 * MS, dtype=np.int64)  # from between the 3rd and 4th frame
    # the estimate is perfect but for a 5 cm offset along x before the 4th frame
    for o in outs[:3]:
        o.result.T_odom_base[0, 3] += 0.05
    with BagRecorder(tmp_path / "late.mcap", config) as rec:
        for o in outs:
            rec(o, None)
        rec.write_ground_truth(Trajectory(late, np.stack([W @ true_pose((t - T0) * 1e-9) for t in late])))
    got = read(tmp_path / "late.mcap")
    by_stamp = {t: pose_from_transform_msg(m.pose.pose) for t, m in got[GT_ODOMETRY_TOPIC]}
    for o in outs[3:]:  # aligned at the 4th frame (120 ms), the first the ground truth covers
        np.testing.assert_allclose(by_stamp[o.result.stamp_ns], o.result.T_odom_base, atol=1e-9)
    assert min(by_stamp) == late[0]

    with BagRecorder(tmp_path / "disjoint.mcap", config) as rec:
        for o in outs:
            rec(o, None)
        after = np.arange(T0 + 2000 * MS, T0 + 3000 * MS, 10 * MS, dtype=np.int64)
        rec.write_ground_truth(Trajectory(after, np.stack([true_pose((t - T0) * 1e-9) for t in after])))
    assert set(read(tmp_path / "disjoint.mcap")) == {"/atsvo/odometry", "/tf", PATH_TOPIC}
