"""atsvo-replay --record OUT.mcap: the run as a ROS 2 bag, read back with rosbags and with the mcap library.

A short synthetic trot (atsvo-sim, as in test_replay_sim) replayed with the real odometry gives every
topic (the debug images need the event front end, the cloud the mapper); the CLI's errors and the
topics of an RGB-D run without ground truth use the odometry double of test_replay.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.io.ros_out import DEBUG_IMAGE_FRAME, pose_from_transform_msg, time_to_ns
from atsvo_ros.io.trajectory import read_tum
from atsvo_ros.tools import replay as replay_mod
from atsvo_ros.tools.replay import main, replay
from test.io.test_bags import write_bag
from test.tools.test_replay import FakeOdometry, _with_fake

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = ROOT / "config" / "foxglove_layout.json"
TOPICS = {
    "/atsvo/odometry": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/atsvo/path": "nav_msgs/msg/Path",
    "/atsvo/map": "sensor_msgs/msg/PointCloud2",
    "/atsvo/debug/ats": "sensor_msgs/msg/Image",
    "/atsvo/debug/selected_pixels": "sensor_msgs/msg/Image",
    "/atsvo/ground_truth/odometry": "nav_msgs/msg/Odometry",
    "/atsvo/ground_truth/path": "nav_msgs/msg/Path",
}


def read_bag(path: Path) -> tuple[dict[str, str], dict[str, list]]:
    """(topic -> type, topic -> [(log time, message)]) of a bag."""
    msgs: dict[str, list] = {}
    with AnyReader([path]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, t, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return types, msgs


@pytest.fixture(scope="module")
def recorded(trot_1s_bags, tmp_path_factory):
    """The trot replayed twice, without and with --record (and --gt): (sequence, plain, recorded result, bag)."""
    root = tmp_path_factory.mktemp("rec")
    seq = trot_1s_bags["mcap"]
    plain = replay(seq, root / "plain", load_config("synthetic"), plots=False, progress=False)
    bag = root / "bags" / "run.mcap"  # its folder is made
    res = replay(seq, root / "rec", load_config("synthetic"), plots=False, progress=False, record=bag,
                 gt_path=seq / "groundtruth.tum")
    return seq, plain, res, bag


def test_recording_does_not_change_the_replay(recorded):
    _, plain, res, _ = recorded
    assert res.mode == "fused" and len(res.stamps_ns) >= 25
    np.testing.assert_array_equal(plain.stamps_ns, res.stamps_ns)
    np.testing.assert_array_equal(plain.T_odom_x, res.T_odom_x)
    timing = json.loads((res.out_dir / "timing.json").read_text())
    assert timing["recording"]["messages"] == res.record_counts


def test_topics_types_and_one_odometry_per_frame_equal_to_the_trajectory(recorded):
    _, _, res, bag = recorded
    types, msgs = read_bag(bag)
    assert types == TOPICS
    assert {t: len(m) for t, m in msgs.items()} == res.record_counts
    odom = msgs["/atsvo/odometry"]
    assert [t for t, _ in odom] == res.stamps_ns.tolist()  # log time = header stamp = frame stamp
    traj = read_tum(res.out_dir / "trajectory.tum")
    for (t, m), T, T_file in zip(odom, res.T_odom_x, traj.T_w_b):
        assert time_to_ns(m.header.stamp) == t and (m.header.frame_id, m.child_frame_id) == ("odom", "base_link")
        np.testing.assert_allclose(pose_from_transform_msg(m.pose.pose), T, atol=1e-12)
        np.testing.assert_allclose(pose_from_transform_msg(m.pose.pose), T_file, atol=1e-6)  # TUM: 9 digits
        cov = np.reshape(m.pose.covariance, (6, 6))
        assert np.all(np.isfinite(cov)) and np.all(np.diag(cov) > 0)
    tf = msgs["/tf"]
    assert [t for t, _ in tf] == res.stamps_ns.tolist()
    for (_, m), T in zip(tf, res.T_odom_x):
        (link,) = m.transforms
        assert (link.header.frame_id, link.child_frame_id) == ("odom", "base_link")
        np.testing.assert_allclose(pose_from_transform_msg(link.transform), T, atol=1e-12)
    (static,) = [m for _, m in msgs["/tf_static"]]
    assert [(x.header.frame_id, x.child_frame_id) for x in static.transforms] == [("base_link", DEBUG_IMAGE_FRAME)]
    path = msgs["/atsvo/path"][-1][1]
    assert len(path.poses) == len(res.stamps_ns) and path.header.frame_id == "odom"


def test_debug_images_show_the_surface_and_the_selected_pixels(recorded):
    seq, _, res, bag = recorded
    _, msgs = read_bag(bag)
    with AnyReader([seq]) as reader:  # the rectified event camera: pinhole model of the bag's camera_info
        (conn,) = [c for c in reader.connections if c.topic == "/dvxplorer/camera_info"]
        _, _, raw = next(reader.messages([conn]))
        cam = CameraModel.from_camera_info(reader.deserialize(raw, conn.msgtype)).pinhole()
    ats, sel = msgs["/atsvo/debug/ats"], msgs["/atsvo/debug/selected_pixels"]
    assert [t for t, _ in ats] == [t for t, _ in sel] == res.stamps_ns.tolist()
    n_red = 0
    for (_, a), (_, s) in zip(ats, sel):
        assert (a.encoding, a.width, a.height, a.step) == ("mono8", cam.width, cam.height, cam.width)
        assert (s.encoding, s.width, s.height, s.step) == ("rgb8", cam.width, cam.height, 3 * cam.width)
        assert a.header.frame_id == s.header.frame_id == DEBUG_IMAGE_FRAME
        grey = np.asarray(a.data, np.uint8).reshape(cam.height, cam.width)
        rgb = np.asarray(s.data, np.uint8).reshape(cam.height, cam.width, 3)
        red = np.all(rgb == (255, 0, 0), axis=2)
        n_red += int(red.sum())
        np.testing.assert_array_equal(rgb[~red], np.repeat(grey[~red][:, None], 3, axis=1))
    assert n_red > 100 and max(np.asarray(a.data).max() for _, a in ats) > 100  # selections on a live surface


def test_map_cloud_fields_and_points(recorded):
    _, _, res, bag = recorded
    _, msgs = read_bag(bag)
    clouds = msgs["/atsvo/map"]
    assert 1 <= len(clouds) < len(res.stamps_ns)  # one per map change (keyframe), not per frame
    assert set(t for t, _ in clouds) <= set(res.stamps_ns.tolist())
    cloud = clouds[-1][1]
    assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == [
        ("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)]
    assert cloud.header.frame_id == "odom" and cloud.point_step == 16 and cloud.height == 1
    assert cloud.width > 100 and len(cloud.data) == cloud.width * 16 == cloud.row_step
    pts = np.frombuffer(np.asarray(cloud.data, np.uint8).tobytes(), "<f4").reshape(-1, 4)
    assert np.all(np.isfinite(pts))
    # the map surrounds the trajectory: within the synthetic preset's depth range of the base
    dist = np.linalg.norm(pts[:, :3][:, None] - res.T_odom_x[None, :, :3, 3], axis=2).min(axis=1)
    assert np.all(dist < load_config("synthetic").rig.depth_max_m + 0.5)


def test_ground_truth_beside_the_estimate_in_the_odom_frame(recorded):
    _, _, res, bag = recorded
    _, msgs = read_bag(bag)
    gt = msgs["/atsvo/ground_truth/odometry"]
    stamps = np.array([t for t, _ in gt])
    assert len(gt) > len(res.stamps_ns)  # the 200 Hz ground truth, within the run
    assert stamps[0] >= res.stamps_ns[0] and stamps[-1] <= res.stamps_ns[-1]
    pos = np.stack([pose_from_transform_msg(m.pose.pose)[:3, 3] for _, m in gt])
    # it starts on the estimate's first pose and stays within the tracker's drift (ATE ~1 cm here)
    est_at_gt = np.stack([np.interp(stamps, res.stamps_ns, res.T_odom_x[:, k, 3]) for k in range(3)], axis=1)
    assert np.linalg.norm(pos[0] - est_at_gt[0]) < 0.005
    assert np.max(np.linalg.norm(pos - est_at_gt, axis=1)) < 0.05
    assert np.ptp(pos, axis=0).max() > 0.2  # and the robot did move: the check is not vacuous
    assert [t for t, _ in msgs["/atsvo/ground_truth/path"]] == [t for t, _ in msgs["/atsvo/path"]]


def test_foxglove_reads_every_message_by_the_schemas_in_the_file(recorded):
    """Foxglove decodes by the message definitions inside the mcap, not by a type store."""
    mcap_reader = pytest.importorskip("mcap.reader")
    mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")
    _, _, res, bag = recorded
    with bag.open("rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        assert {t: summary.schemas[c.schema_id].name for t, c in channels.items()} == TOPICS
        assert {c.message_encoding for c in channels.values()} == {"cdr"}
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        n, last, positions = 0, None, []
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            assert last is None or message.log_time >= last
            last = message.log_time
            n += 1
            if channel.topic == "/atsvo/odometry":
                p = decoded.pose.pose.position
                positions.append((p.x, p.y, p.z))
        assert n == sum(res.record_counts.values())
    np.testing.assert_allclose(positions, res.T_odom_x[:, :3, 3], atol=1e-12)  # the same values as rosbags reads
    # the latched topics are offered transient local, so `ros2 bag play` latches them as the node does
    with AnyReader([bag]) as reader:
        durability = {c.topic: [q.durability.name for q in c.ext.offered_qos_profiles] for c in reader.connections}
    assert durability["/tf_static"] == durability["/atsvo/map"] == ["TRANSIENT_LOCAL"]
    assert durability["/atsvo/odometry"] == []


def test_the_foxglove_layout_shows_recorded_topics(recorded):
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    kinds = sorted(k.split("!")[0] for k in panels)
    assert kinds == ["3D", "Image", "Image", "Plot"]
    scene = next(v for k, v in panels.items() if k.startswith("3D"))
    assert scene["followTf"] == "odom"
    named = set(scene["topics"])
    named |= {v["imageMode"]["imageTopic"] for k, v in panels.items() if k.startswith("Image")}
    plot = next(v for k, v in panels.items() if k.startswith("Plot"))
    named |= {p["value"].split(".")[0] for p in plot["paths"]}
    assert named <= set(TOPICS)
    assert {"/atsvo/path", "/atsvo/ground_truth/path", "/atsvo/map", "/atsvo/debug/ats",
            "/atsvo/debug/selected_pixels", "/atsvo/odometry", "/atsvo/ground_truth/odometry"} <= named
    # every panel of the layout tree is configured and vice versa
    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert sorted(leaves(layout["layout"])) == sorted(panels)
    assert "config/foxglove_layout.json" in (ROOT / "setup.py").read_text()  # installed with the presets


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_cli_refuses_an_existing_output_unless_forced(tmp_path, capsys, monkeypatch):
    FakeOdometry.instances = []
    monkeypatch.setattr(replay_mod, "replay", _with_fake(replay_mod.replay, FakeOdometry))
    bag = write_bag(tmp_path / "seq", "mcap", n_frames=6, events=False, gt=False)
    out = tmp_path / "run.mcap"
    out.write_bytes(b"an earlier recording")
    args = [str(bag), "--out", str(tmp_path / "out"), "--no-progress", "--no-plots", "--record", str(out)]
    assert main(args) == 1
    assert "exists (use --force" in _one_line_error(capsys)
    assert FakeOdometry.instances == [] and out.read_bytes() == b"an earlier recording"  # refused before the run
    assert main([*args, "--force"]) == 0
    assert "wrote " + str(out) in capsys.readouterr().out
    types, msgs = read_bag(out)
    # RGB-D run of the odometry double without ground truth: no images, no cloud, no ground-truth topics
    assert types == {t: TOPICS[t] for t in ("/atsvo/odometry", "/tf", "/atsvo/path")}
    assert len(msgs["/atsvo/odometry"]) == 6
    assert main([str(bag), "--out", str(tmp_path / "out"), "--record", str(tmp_path / "run.bag")]) == 1
    assert "must end in .mcap" in _one_line_error(capsys)


def test_cli_without_mcap_storage_and_a_failed_run_leave_nothing(tmp_path, capsys, monkeypatch):
    from rosbags.rosbag2 import Writer

    monkeypatch.setattr(replay_mod, "replay", _with_fake(replay_mod.replay, FakeOdometry))
    bag = write_bag(tmp_path / "seq", "mcap", n_frames=4, events=False, gt=False)
    # the recording starts, then no frame can be formed (undecodable colour images): the run fails
    bayer = write_bag(tmp_path / "bayer", "mcap", n_frames=3, rgb_encoding="bayer_rggb8")
    rec_dir = tmp_path / "recordings"
    assert main([str(bayer), "--out", str(tmp_path / "out"), "--record", str(rec_dir / "run.mcap")]) == 1
    err = _one_line_error(capsys)  # the reason, not "no colour/depth pair could be formed"
    assert "no frame of bayer could be used: 3 unreadable images skipped" in err and "bayer_rggb8" in err
    assert list(rec_dir.iterdir()) == []  # no bag, no staging folder
    monkeypatch.setattr(Writer, "STORAGE_PLUGINS", {k: v for k, v in Writer.STORAGE_PLUGINS.items()
                                                     if k.name != "MCAP"})
    assert main([str(bag), "--out", str(tmp_path / "out"), "--record", str(rec_dir / "run.mcap")]) == 1
    assert "no mcap storage writer" in _one_line_error(capsys)
