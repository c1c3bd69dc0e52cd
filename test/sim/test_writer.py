"""Bags written by the simulator read back with rosbags' AnyReader: topics, types, counts, content."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import pose_from_tq
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import SimulationError
from atsvo_ros.io.bags import Bag
from atsvo_ros.io.decode import decode_raw
from atsvo_ros.io.imu import imu_from_msgs
from atsvo_ros.io.msgtypes import register_event_types
from atsvo_ros.io.trajectory import read_tum
from atsvo_ros.sim.motion import SCENARIOS
from atsvo_ros.sim.sequence import RgbdFrame, SequenceSpec, iter_sequence, make_simulation, sequence_rig
from atsvo_ros.sim.writer import FORMATS, write_sequence

TINY = {"width": 32, "event_scale": 0.1, "texture_size": 16, "rate_hz": 15.0, "gt_rate_hz": 100.0,
        "event_packet_s": 0.005}

ROBOT_TOPICS = {
    "/camera/camera/color/image_raw": "sensor_msgs/msg/Image",
    "/camera/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
    "/camera/camera/aligned_depth_to_color/image_raw": "sensor_msgs/msg/Image",
    "/dvxplorer/events": "event_camera_msgs/msg/EventPacket",
    "/dvxplorer/camera_info": "sensor_msgs/msg/CameraInfo",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/ground_truth/pose": "geometry_msgs/msg/PoseStamped",
    "/camera/camera/imu": "sensor_msgs/msg/Imu",
}
MVSEC_TOPICS = {
    "/davis/left/events": "dvs_msgs/msg/EventArray",
    "/davis/left/image_raw": "sensor_msgs/msg/Image",
    "/davis/left/camera_info": "sensor_msgs/msg/CameraInfo",
    "/davis/left/depth_image_raw": "sensor_msgs/msg/Image",
    "/davis/left/pose": "geometry_msgs/msg/PoseStamped",
}


def _read(out: Path, fmt: str):
    path = out / "sequence.bag" if fmt == "ros1" else out
    msgs: dict[str, list] = {}
    with AnyReader([path]) as reader:
        register_event_types(reader.typestore, 1 if fmt == "ros1" else 2)
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, t, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t, raw, reader.deserialize(raw, conn.msgtype)))
    return types, msgs


@pytest.mark.parametrize("layout", ["robot", "mvsec"])
@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_scenario_format_and_layout_reads_back(tmp_path, scenario, fmt, layout):
    duration = 2.2 if scenario == "backflip" else 0.3
    # the flip's 2.2 s with sharp depth: the D455 model's 848x480 stereo would take ~8 s of each of its runs here (the
    # other scenarios' robot layout writes the D455's depth)
    depth = "sharp" if scenario == "backflip" and layout == "robot" else None
    spec = SequenceSpec(scenario=scenario, duration_s=duration, seed=1, layout=layout, depth=depth, **TINY)
    summary = write_sequence(spec, tmp_path / "seq", fmt=fmt, progress=False)
    types, msgs = _read(tmp_path / "seq", fmt)
    assert types == (ROBOT_TOPICS if layout == "robot" else MVSEC_TOPICS)
    n_frames = int(np.floor(duration * spec.rate_hz + 1e-9)) + 1
    n_poses = int(np.floor(duration * spec.gt_rate_hz + 1e-9)) + 1
    for topic in types:
        if topic.endswith(("image_raw", "camera_info", "depth_image_raw")):
            assert len(msgs[topic]) == n_frames, topic
    gt_topic = "/ground_truth/pose" if layout == "robot" else "/davis/left/pose"
    assert len(msgs[gt_topic]) == n_poses == summary["poses"]
    ev_topic = "/dvxplorer/events" if layout == "robot" else "/davis/left/events"
    assert len(msgs[ev_topic]) == summary["event_packets"] > 0
    if layout == "robot":  # ~200 Hz IMU (its clock is a few percent off), log time = header stamp
        imu = msgs["/camera/camera/imu"]
        assert len(imu) == summary["imu_samples"] and 170 * duration <= len(imu) <= 210 * duration + 1
        assert all(t == m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for t, _, m in imu)
    else:
        assert summary["imu_samples"] == 0
    assert (tmp_path / "seq" / "groundtruth.tum").is_file()
    desc = yaml.safe_load((tmp_path / "seq" / "sequence.yaml").read_text())
    assert desc["scenario"] == scenario and desc["seed"] == 1 and desc["layout"] == layout


def test_bag_content_matches_the_in_memory_sequence_and_rig(tmp_path):
    spec = SequenceSpec(scenario="trot", duration_s=0.3, seed=2, width=48, event_scale=0.2, texture_size=16)
    write_sequence(spec, tmp_path / "s", fmt="mcap", progress=False)
    _, msgs = _read(tmp_path / "s", "mcap")
    rig = sequence_rig(spec)
    items = list(iter_sequence(spec))
    frames = [i for i in items if isinstance(i, RgbdFrame)]
    events = EventBatch.concatenate([i for i in items if isinstance(i, EventBatch)])
    # Events: decoded libcaer_cmp packets give back exactly the generated events.
    decoded = EventBatch.concatenate([decode_raw(raw, "event_camera_msgs/msg/EventPacket", 2)
                                      for _, raw, _ in msgs["/dvxplorer/events"]])
    np.testing.assert_array_equal(decoded.t, events.t)
    np.testing.assert_array_equal(decoded.x, events.x)
    np.testing.assert_array_equal(decoded.p, events.p)
    # Images.
    img = msgs["/camera/camera/color/image_raw"][3][2]
    assert img.encoding == "rgb8" and (img.height, img.width) == (36, 48)
    np.testing.assert_array_equal(img.data.reshape(36, 48, 3), frames[3].rgb)
    dep = msgs["/camera/camera/aligned_depth_to_color/image_raw"][3][2]
    assert dep.encoding == "16UC1"
    np.testing.assert_array_equal(dep.data.view("<u2").reshape(36, 48), frames[3].depth_mm)
    # camera_info carries exactly the rig's intrinsics, /tf_static its extrinsics.
    assert CameraModel.from_camera_info(msgs["/camera/camera/color/camera_info"][0][2]) == rig.rgb_camera
    assert CameraModel.from_camera_info(msgs["/dvxplorer/camera_info"][0][2]) == rig.event_camera
    tf = msgs["/tf_static"][0][2].transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in tf] == [
        ("base_link", "camera_color_optical_frame"), ("camera_color_optical_frame", "dvxplorer"),
        ("camera_color_optical_frame", "camera_imu_optical_frame")]
    for tr, T in zip(tf, (rig.T_base_rgb, rig.T_rgb_event, rig.T_rgb_imu)):
        q, v = tr.transform.rotation, tr.transform.translation
        # atol: the config's rotations have 8 decimals, so they are orthonormal to ~4e-9 only.
        np.testing.assert_allclose(pose_from_tq(np.array([v.x, v.y, v.z]), np.array([q.x, q.y, q.z, q.w])), T,
                                   atol=1e-8)
    # IMU: the in-memory samples, in the D455 IMU frame, with realsense2_camera's message conventions.
    imu_ref = ImuBatch.concatenate([i for i in items if isinstance(i, ImuBatch)])
    imu = imu_from_msgs(m for _, _, m in msgs["/camera/camera/imu"])
    np.testing.assert_array_equal(imu.stamps_ns, imu_ref.stamps_ns)
    np.testing.assert_array_equal(imu.gyro_rad_s, imu_ref.gyro_rad_s)
    np.testing.assert_array_equal(imu.accel_m_s2, imu_ref.accel_m_s2)
    m = msgs["/camera/camera/imu"][0][2]
    assert m.header.frame_id == "camera_imu_optical_frame" and m.orientation_covariance[0] == -1.0
    assert m.angular_velocity_covariance[0] == pytest.approx(spec.imu_model.white_sigma("gyro") ** 2)
    np.testing.assert_allclose(rig.T_rgb_imu, load_config("synthetic").rig.T_rgb_imu_matrix())
    desc = yaml.safe_load((tmp_path / "s" / "sequence.yaml").read_text())
    assert desc["models"]["imu"]["gyro_rate_hz"] == 200.0 and desc["topics"]["imu"] == ["/camera/camera/imu",
                                                                                        "sensor_msgs/msg/Imu"]
    drawn = desc["models"]["imu"]["this_seed"]
    # the mean period matches the drawn rate up to the 1 us stamp rounding of the end samples
    np.testing.assert_allclose(np.mean(np.diff(imu.stamps_ns)), 1e9 / drawn["gyro_rate_hz"], atol=1000 / (len(imu) - 1))
    assert len(drawn["gyro_turn_on_bias_rad_s"]) == 3
    # Ground truth topic == groundtruth.tum.
    traj = read_tum(tmp_path / "s" / "groundtruth.tum")
    gt = msgs["/ground_truth/pose"]
    assert len(traj) == len(gt)
    for (t, _, m), s, T in zip(gt[::20], traj.stamps_ns[::20], traj.T_w_b[::20]):
        p, q = m.pose.position, m.pose.orientation
        assert t == s == m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        np.testing.assert_allclose(pose_from_tq(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])), T,
                                   atol=1e-7)


def test_dvs_event_arrays_and_mvsec_depth(tmp_path):
    spec = SequenceSpec(scenario="flying", duration_s=0.2, seed=0, **TINY)
    write_sequence(spec, tmp_path / "d", fmt="ros1", event_msg="dvs", progress=False)
    types, msgs = _read(tmp_path / "d", "ros1")
    assert types["/dvxplorer/events"] == "dvs_msgs/msg/EventArray"
    n = sum(len(m.events) for _, _, m in msgs["/dvxplorer/events"])
    assert n == sum(len(decode_raw(raw, "dvs_msgs/msg/EventArray", 1)) for _, raw, _ in msgs["/dvxplorer/events"])
    mv = dataclasses.replace(spec, layout="mvsec")
    write_sequence(mv, tmp_path / "m", fmt="sqlite3", progress=False)
    _, msgs = _read(tmp_path / "m", "sqlite3")
    img = msgs["/davis/left/image_raw"][0][2]
    depth = msgs["/davis/left/depth_image_raw"][0][2]
    assert img.encoding == "mono8" and depth.encoding == "32FC1"
    d = depth.data.view("<f4")
    assert np.isnan(d).any() or np.all(d > 0)
    assert np.nanmin(d) > 0.29 and np.nanmax(d) < 15.0


def test_output_directory_rules(tmp_path):
    spec = SequenceSpec(scenario="trot", duration_s=0.1, seed=0, **TINY)
    out = tmp_path / "o"
    write_sequence(spec, out, progress=False)
    with pytest.raises(SimulationError, match="not empty"):
        write_sequence(spec, out, progress=False)
    write_sequence(spec, out, force=True, progress=False)  # replaces our own files
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "notes.txt").write_text("mine")
    with pytest.raises(SimulationError, match="did not write"):
        write_sequence(spec, tmp_path / "x", force=True, progress=False)
    assert (tmp_path / "x" / "notes.txt").read_text() == "mine"
    with pytest.raises(SimulationError, match="format"):
        write_sequence(spec, tmp_path / "y", fmt="zip", progress=False)


def test_imu_round_trips_through_every_format_and_can_be_left_out(tmp_path):
    spec = SequenceSpec(scenario="bound", duration_s=0.4, seed=5, depth="sharp", **TINY)  # no stereo: IMU test
    ref = ImuBatch.concatenate(list(make_simulation(spec).imu()))  # the IMU alone needs no rendering
    assert len(ref) > 60
    for fmt in FORMATS:
        write_sequence(spec, tmp_path / fmt, fmt=fmt, progress=False)
        path = tmp_path / fmt / "sequence.bag" if fmt == "ros1" else tmp_path / fmt
        with Bag(path) as bag:
            assert bag.selection.imu == "/camera/camera/imu"
            got = imu_from_msgs(m.msg for m in bag.messages(["imu"]))
        np.testing.assert_array_equal(got.stamps_ns, ref.stamps_ns)
        np.testing.assert_array_equal(got.gyro_rad_s, ref.gyro_rad_s)
        np.testing.assert_array_equal(got.accel_m_s2, ref.accel_m_s2)
    write_sequence(dataclasses.replace(spec, imu=False), tmp_path / "none", progress=False)
    types, _ = _read(tmp_path / "none", "mcap")
    assert "/camera/camera/imu" not in types
    desc = yaml.safe_load((tmp_path / "none" / "sequence.yaml").read_text())
    assert "imu" not in desc["models"] and desc["summary"]["imu_samples"] == 0


@pytest.mark.parametrize("encoding", ["libcaer", "mono"])
def test_other_packet_encodings_round_trip(tmp_path, encoding):
    spec = SequenceSpec(scenario="bound", duration_s=0.2, seed=4, depth="sharp", **TINY)  # no stereo: events test
    write_sequence(spec, tmp_path / encoding, encoding=encoding, progress=False)
    _, msgs = _read(tmp_path / encoding, "mcap")
    assert all(m.encoding == encoding for _, _, m in msgs["/dvxplorer/events"])
    decoded = EventBatch.concatenate([decode_raw(raw, "event_camera_msgs/msg/EventPacket", 2)
                                      for _, raw, _ in msgs["/dvxplorer/events"]])
    events = EventBatch.concatenate(list(make_simulation(spec).events()))
    np.testing.assert_array_equal(decoded.t, events.t)
    np.testing.assert_array_equal(decoded.y, events.y)
    with pytest.raises(SimulationError, match="evt3"):
        write_sequence(spec, tmp_path / "e", encoding="evt3", progress=False)


def _fail_late(monkeypatch, where: str) -> None:
    """Make the generation fail after the bag is written (``description``) or in the middle of it (``stream``)."""
    import atsvo_ros.sim.writer as writer

    def boom(*_a, **_k):
        raise SimulationError("injected failure")

    if where == "description":
        monkeypatch.setattr(writer, "_write_description", boom)
    else:
        real = writer.iter_sequence

        def failing(*a, **k):
            for i, item in enumerate(real(*a, **k)):
                if i == 40:
                    boom()
                yield item

        monkeypatch.setattr(writer, "iter_sequence", failing)


@pytest.mark.parametrize("fmt, where", [("mcap", "description"), ("ros1", "stream"), ("sqlite3", "stream")])
def test_a_late_failure_leaves_nothing_and_a_rerun_works(tmp_path, monkeypatch, fmt, where):
    spec = SequenceSpec(scenario="trot", duration_s=0.2, seed=0, **TINY)
    out = tmp_path / "new" / "seq"
    with monkeypatch.context() as m:
        _fail_late(m, where)
        with pytest.raises(SimulationError, match="injected"):
            write_sequence(spec, out, fmt=fmt, progress=False)
    assert list(tmp_path.iterdir()) == []  # no partial bag, no temporary folder, no parent made for it
    summary = write_sequence(spec, out, fmt=fmt, progress=False)  # no --force needed
    assert sorted(p.name for p in out.parent.iterdir()) == ["seq"]
    assert (out / "sequence.yaml").is_file() and summary["bag"] == str(out / "sequence.bag" if fmt == "ros1"
                                                                          else out)
    types, _ = _read(out, fmt)
    assert types == ROBOT_TOPICS


def test_a_failed_forced_rerun_keeps_the_previous_output(tmp_path, monkeypatch):
    spec = SequenceSpec(scenario="trot", duration_s=0.1, seed=0, **TINY)
    out = tmp_path / "seq"
    write_sequence(spec, out, progress=False)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "seq.mcap" in before  # the storage file is named after the final folder, not the temporary one
    with monkeypatch.context() as m:
        _fail_late(m, "description")
        with pytest.raises(SimulationError, match="injected"):
            write_sequence(dataclasses.replace(spec, seed=1), out, force=True, progress=False)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]
    monkeypatch.chdir(out)
    with pytest.raises(SimulationError, match="own folder"):
        write_sequence(spec, ".", force=True, progress=False)  # would have to replace the working folder
