"""Bag streaming: the same small sequence written as ROS 1, ROS 2 sqlite3 and ROS 2 mcap gives the
same message stream; topic resolution; bare .mcap/.db3 files; errors name the problem.

``write_bag`` is also used by the replay tests to build small bags with rosbags' writers.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import pose_from_tq, se3_exp
from atsvo_ros.errors import BagError
from atsvo_ros.io.bags import Bag, StaticTf, pose_from_msg, resolve_topics
from atsvo_ros.io.encode import serialize_event_packet
from atsvo_ros.io.msgtypes import typestore

FORMATS = ("ros1", "sqlite3", "mcap")
TOPICS = {
    "rgb": "/camera/camera/color/image_raw", "rgb_info": "/camera/camera/color/camera_info",
    "depth": "/camera/camera/aligned_depth_to_color/image_raw", "events": "/dvxplorer/events",
    "ground_truth": "/ground_truth/pose", "tf_static": "/tf_static",
}


def _header(ts, ros: int, stamp_ns: int, frame: str):
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    t = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return Header(seq=0, stamp=t, frame_id=frame) if ros == 1 else Header(stamp=t, frame_id=frame)


def gt_pose(t_s: float) -> np.ndarray:
    """A smooth test motion (base in world)."""
    return se3_exp(np.array([0.3 * t_s, 0.1 * np.sin(t_s), 0.05 * t_s, 0.1 * np.sin(2 * t_s), 0.2 * t_s, 0.05]))


def write_bag(path: Path, fmt: str, n_frames: int = 6, hz: float = 30.0, t0_ns: int = 1_700_000_000_000_000_000,
              events: bool = True, gt: bool = True, depth: bool = True, rgb_encoding: str = "rgb8",
              size: tuple[int, int] = (32, 24), topics: dict[str, str] | None = None,
              depth_delay_ns: int = 0, gt_hz: float = 100.0, depth_fill: float | None = None,
              depth_encoding: str = "16UC1", rgb_fill: int | None = None,
              faults: dict[int, str] | None = None) -> Path:
    """Write a tiny robot-layout bag; returns the path that the readers take.

    ``depth_fill`` replaces the depth ramp (1.5 m + 1 cm per frame) with one value in the encoding's unit
    (mm for 16UC1, m for 32FC1); ``rgb_fill`` replaces the random colour with one grey level.
    ``faults`` damages frames by index: "bad_encoding" (colour as bayer_rggb8), "duplicate" (colour and
    depth written twice), "late" (stamped 3 frames earlier, as a frame stuck in a queue would be).
    """
    faults = faults or {}
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    topics = {**TOPICS, **(topics or {})}
    ros = 1 if fmt == "ros1" else 2
    ts = typestore(ros)
    if "tf2_msgs/msg/TFMessage" not in ts.fielddefs:  # not in rosbags' Noetic store
        from rosbags.typesys import get_types_from_msg
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    w, h = size
    rng = np.random.default_rng(7)
    msgs: list[tuple[int, str, str, bytes]] = []  # (log time, topic, msgtype, raw)

    def ser(msg, msgtype):
        return ts.serialize_ros1(msg, msgtype) if ros == 1 else ts.serialize_cdr(msg, msgtype)

    Image = ts.types["sensor_msgs/msg/Image"]
    dt_ns = int(1e9 / hz)
    for i in range(n_frames):
        log_t = t0_ns + i * dt_ns
        fault = faults.get(i)
        t = log_t - 3 * dt_ns + dt_ns // 2 if fault == "late" else log_t
        chans = 1 if rgb_encoding in ("mono8",) else 3
        img = rng.integers(0, 255, (h, w * chans), dtype=np.uint8)
        if rgb_fill is not None:
            img[:] = rgb_fill
        for _ in range(2 if fault == "duplicate" else 1):
            msgs.append((log_t + 1000, topics["rgb"], "sensor_msgs/msg/Image", ser(Image(
                header=_header(ts, ros, t, "camera_color_optical_frame"), height=h, width=w,
                encoding="bayer_rggb8" if fault == "bad_encoding" else rgb_encoding,
                is_bigendian=False, step=w * chans, data=img.reshape(-1)), "sensor_msgs/msg/Image")))
        for _ in range((2 if fault == "duplicate" else 1) if depth else 0):
            dtype = np.uint16 if depth_encoding == "16UC1" else np.float32
            d = np.full((h, w), 1500 + 10 * i if depth_fill is None else depth_fill, dtype)
            msgs.append((log_t + 2000 + depth_delay_ns, topics["depth"], "sensor_msgs/msg/Image", ser(Image(
                header=_header(ts, ros, t, "camera_color_optical_frame"), height=h, width=w,
                encoding=depth_encoding, is_bigendian=False, step=d.itemsize * w,
                data=d.view(np.uint8).reshape(-1)), "sensor_msgs/msg/Image")))
    if events:
        n_pk = int(n_frames * dt_ns / 1_000_000) + 2
        for k in range(n_pk):
            t_start = t0_ns - 1_000_000 + k * 1_000_000
            n = 20
            tt = np.sort(t_start + rng.integers(0, 1000, n) * 1000)
            b = EventBatch(rng.integers(0, 320, n), rng.integers(0, 240, n), tt, rng.integers(0, 2, n), 320, 240)
            raw = serialize_event_packet(b, "libcaer_cmp", stamp_ns=t_start, frame_id="dvxplorer", seq=k,
                                         ros_version=ros, time_base_ns=t_start)
            msgs.append((t_start + 1_000_000, topics["events"], "event_camera_msgs/msg/EventPacket", raw))
    Roi = ts.types["sensor_msgs/msg/RegionOfInterest"]
    names = ("D", "K", "R", "P") if ros == 1 else ("d", "k", "r", "p")
    info = ts.types["sensor_msgs/msg/CameraInfo"](
        header=_header(ts, ros, t0_ns, "camera_color_optical_frame"), height=h, width=w,
        distortion_model="plumb_bob", binning_x=0, binning_y=0,
        roi=Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        **dict(zip(names, (np.zeros(5), np.array([20.0, 0, w / 2, 0, 20.0, h / 2, 0, 0, 1]), np.eye(3).reshape(-1),
                           np.zeros(12)))))
    msgs.append((t0_ns, topics["rgb_info"], "sensor_msgs/msg/CameraInfo", ser(info, "sensor_msgs/msg/CameraInfo")))
    if gt:
        Pose, Point, Quat = (ts.types[f"geometry_msgs/msg/{n}"] for n in ("Pose", "Point", "Quaternion"))
        from atsvo_ros.core.geometry import tq_from_pose
        n_gt = int(n_frames / hz * gt_hz) + 5
        for k in range(n_gt):
            t = t0_ns - 20_000_000 + int(k * 1e9 / gt_hz)
            tr, q = tq_from_pose(gt_pose((t - t0_ns) * 1e-9))
            msg = ts.types["geometry_msgs/msg/PoseStamped"](
                header=_header(ts, ros, t, "world"),
                pose=Pose(position=Point(x=tr[0], y=tr[1], z=tr[2]), orientation=Quat(x=q[0], y=q[1], z=q[2], w=q[3])))
            msgs.append((t, topics["ground_truth"], "geometry_msgs/msg/PoseStamped",
                         ser(msg, "geometry_msgs/msg/PoseStamped")))
        TS, Tr, V3 = (ts.types[n] for n in ("geometry_msgs/msg/TransformStamped", "geometry_msgs/msg/Transform",
                                             "geometry_msgs/msg/Vector3"))
        tfs = []
        for parent, child, T in (("base_link", "camera_link", pose_from_tq(np.array([0.2, 0, 0.08]),
                                                                         np.array([0, 0, 0, 1.0]))),
                                 ("camera_link", "camera_color_optical_frame",
                                  pose_from_tq(np.zeros(3), np.array([-0.5, 0.5, -0.5, 0.5])))):
            tr, q = tq_from_pose(T)
            tfs.append(TS(header=_header(ts, ros, t0_ns, parent), child_frame_id=child,
                          transform=Tr(translation=V3(x=tr[0], y=tr[1], z=tr[2]),
                                       rotation=Quat(x=q[0], y=q[1], z=q[2], w=q[3]))))
        msgs.append((t0_ns, topics["tf_static"], "tf2_msgs/msg/TFMessage",
                     ser(ts.types["tf2_msgs/msg/TFMessage"](transforms=tfs), "tf2_msgs/msg/TFMessage")))
    msgs.sort(key=lambda m: m[0])
    if fmt == "ros1":
        path = path.with_suffix(".bag")
        writer = Writer1(path)
    else:
        writer = Writer2(path, version=9,
                         storage_plugin=StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3)
    with writer:
        conns = {}
        for t, topic, msgtype, raw in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], t, raw)
    return path


def _stream(path: Path) -> list[tuple]:
    out = []
    with Bag(path) as bag:
        for m in bag.messages():
            if m.role == "events":
                out.append((m.role, m.log_time_ns, m.events.t.tolist(), m.events.x.tolist(), m.events.p.tolist()))
            elif m.role in ("rgb", "depth"):
                from atsvo_ros.io.images import image_to_numpy, stamp_ns
                out.append((m.role, m.log_time_ns, stamp_ns(m.msg), image_to_numpy(m.msg).tobytes()))
            elif m.role == "ground_truth":
                out.append((m.role, m.log_time_ns, np.round(pose_from_msg(m.msg), 12).tobytes()))
            else:
                out.append((m.role, m.log_time_ns))
    return out


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    return {fmt: write_bag(root / f"seq_{fmt}", fmt) for fmt in FORMATS}


def test_three_containers_give_identical_streams(bags):
    streams = {fmt: _stream(p) for fmt, p in bags.items()}
    assert streams["ros1"] == streams["sqlite3"] == streams["mcap"]
    roles = [s[0] for s in streams["mcap"]]
    assert {"rgb", "depth", "events", "rgb_info", "ground_truth", "tf_static"} <= set(roles)
    times = [s[1] for s in streams["mcap"]]
    assert times == sorted(times)  # merged in time order


def test_selection_and_counts(bags):
    with Bag(bags["ros1"]) as bag:
        assert bag.ros_version == 1
        assert bag.selection.rgb == TOPICS["rgb"] and bag.selection.events == TOPICS["events"]
        assert bag.message_count("rgb") == 6 and bag.duration_s > 0.1
        assert bag.selection.event_info is None


def test_bare_storage_files_and_bad_metadata(bags, tmp_path):
    for fmt, ext in (("mcap", ".mcap"), ("sqlite3", ".db3")):
        storage = next(bags[fmt].glob(f"*{ext}"))
        bare = tmp_path / f"bare{ext}"
        shutil.copy(storage, bare)
        assert _stream(bare) == _stream(bags[fmt])
    # a directory whose metadata.yaml has an empty storage identifier (seen in the wild)
    d = tmp_path / "emptyid"
    shutil.copytree(bags["mcap"], d)
    meta = (d / "metadata.yaml").read_text()
    (d / "metadata.yaml").write_text(meta.replace("storage_identifier: mcap", "storage_identifier: ''"))
    assert _stream(d) == _stream(bags["mcap"])


def test_explicit_topics_override_and_unknown_topic_named(bags):
    with Bag(bags["mcap"], topics={"rgb": TOPICS["depth"]}) as bag:
        assert bag.selection.rgb == TOPICS["depth"]
    with pytest.raises(BagError, match="/nope"):
        Bag(bags["mcap"], topics={"rgb": "/nope"})


@pytest.mark.parametrize("role, topic, words", [
    ("ground_truth", "/tf_static", "--ground-truth-topic /tf_static is a tf2_msgs/msg/TFMessage topic"),
    ("ground_truth", "rgb", "must be one of: geometry_msgs/msg/PoseStamped"),
    ("ground_truth", "imu", "is a sensor_msgs/msg/Imu topic"),
    ("rgb_info", "rgb", "--rgb-info-topic .* is a sensor_msgs/msg/Image topic; it must be one of: sensor_msgs"),
    ("imu", "depth", "--imu-topic"),
])
def test_a_topic_of_the_wrong_type_is_one_line_not_a_traceback(role, topic, words):
    """r10: --ground-truth-topic /tf_static, an image as camera_info, the IMU as ground truth."""
    topics = {"/rgb": "sensor_msgs/msg/Image", "/depth": "sensor_msgs/msg/Image", "/imu": "sensor_msgs/msg/Imu",
              "/tf_static": "tf2_msgs/msg/TFMessage", "/info": "sensor_msgs/msg/CameraInfo"}
    name = topic if topic.startswith("/") else f"/{topic}"
    with pytest.raises(BagError, match=words):
        resolve_topics(topics, {role: name}, presets=())
    with pytest.raises(BagError, match="given for both rgb and depth"):
        resolve_topics(topics, {"rgb": "/rgb", "depth": "/rgb"}, presets=())
    sel = resolve_topics(topics, {"rgb": "/rgb", "depth": "/depth", "rgb_info": "/info"}, presets=())
    assert (sel.rgb, sel.depth, sel.rgb_info, sel.imu) == ("/rgb", "/depth", "/info", "/imu")


def test_detection_by_type_for_unknown_names():
    topics = {"/cam/color/img": "sensor_msgs/msg/Image", "/cam/depth/img": "sensor_msgs/msg/Image",
              "/cam/color/camera_info": "sensor_msgs/msg/CameraInfo", "/ev": "dvs_msgs/msg/EventArray",
              "/mocap/pose": "geometry_msgs/msg/PoseStamped"}
    sel = resolve_topics(topics, presets=())
    assert (sel.rgb, sel.depth, sel.events, sel.rgb_info, sel.ground_truth) == (
        "/cam/color/img", "/cam/depth/img", "/ev", "/cam/color/camera_info", "/mocap/pose")


def test_mvsec_preset_topics():
    topics = {"/davis/left/image_raw": "sensor_msgs/msg/Image", "/davis/right/image_raw": "sensor_msgs/msg/Image",
              "/davis/left/depth_image_raw": "sensor_msgs/msg/Image", "/davis/left/events": "dvs_msgs/msg/EventArray",
              "/davis/right/events": "dvs_msgs/msg/EventArray", "/davis/left/pose": "geometry_msgs/msg/PoseStamped",
              "/davis/left/camera_info": "sensor_msgs/msg/CameraInfo"}
    sel = resolve_topics(topics)
    assert (sel.rgb, sel.depth, sel.events, sel.ground_truth) == (
        "/davis/left/image_raw", "/davis/left/depth_image_raw", "/davis/left/events", "/davis/left/pose")


def test_missing_role_error_names_topics(bags, tmp_path):
    p = write_bag(tmp_path / "nodepth", "mcap", depth=False, n_frames=2)
    with Bag(p) as bag, pytest.raises(BagError, match="no depth topic.*color/image_raw"):
        bag.require("rgb", "depth")


def test_corrupt_and_missing_files(bags, tmp_path):
    with pytest.raises(BagError, match="does not exist"):
        Bag(tmp_path / "missing.bag")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + b"\x00garbage" * 50)
    with pytest.raises(BagError, match="junk.bag"):
        with Bag(junk) as bag:
            list(bag.messages())
    trunc = tmp_path / "trunc.mcap"
    data = next(bags["mcap"].glob("*.mcap")).read_bytes()
    trunc.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match="trunc"):
        with Bag(trunc) as bag:
            list(bag.messages())
    notbag = tmp_path / "notes.txt"
    notbag.write_text("hello")
    with pytest.raises(BagError, match="not a bag"):
        Bag(notbag)


def test_static_tf_chain(bags):
    tf = StaticTf()
    with Bag(bags["sqlite3"]) as bag:
        for m in bag.messages(["tf_static"]):
            tf.add(m.msg)
    T = tf.lookup("base_link", "camera_color_optical_frame")
    # optical z (forward) is base x; optical x (right) is base -y; origin at (0.2, 0, 0.08)
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(T[:3, 0], [0, -1, 0], atol=1e-9)
    np.testing.assert_allclose(T[:3, 3], [0.2, 0, 0.08], atol=1e-12)
    assert tf.lookup("base_link", "nowhere") is None


def test_one_topic_serving_two_roles(bags):
    info = TOPICS["rgb_info"]
    with Bag(bags["mcap"], topics={"event_info": info}) as bag:
        first = bag.first_messages(["rgb", "rgb_info", "event_info"])
        assert set(first) == {"rgb", "rgb_info", "event_info"}
        assert first["rgb_info"].width == 32


@pytest.mark.parametrize("rel, n_events", [
    ("event_camera_py_bags/test_events_2", 360_223 + 211_043),  # mcap, metadata with empty storage id
    ("event_camera_py_bags/test_events_1.bag", 218_291 + 125_183),  # ROS 1, evt3
    ("event_camera_py_bags/test_events_1", 218_291 + 125_183),  # ROS 2 sqlite3, evt3
])
def test_real_event_bags_stream_every_event(realdata, rel, n_events):
    with Bag(realdata / rel) as bag:
        assert bag.selection.events == "/event_camera/events"
        batches = [m.events for m in bag.messages(["events"])]
    assert sum(len(b) for b in batches) == n_events
    t = np.concatenate([b.t for b in batches])
    assert np.all(np.diff(t) >= 0)


def test_an_atsvo_sim_bag_names_its_preset_and_its_depth_phase(trot_3s_bag, tmp_path):
    """sequence.yaml picks the synthetic preset (not the robot's) and the D455 phase is said, not applied."""
    from atsvo_ros.config import load_config
    from atsvo_ros.io.sources import open_source, read_sim_description, sim_depth_phase_s

    source = open_source([trot_3s_bag], None, None)
    try:
        assert source.preset == "synthetic" and "sequence.yaml" in source.preset_note
        notes: list[str] = []
        config, *_ = source.setup(load_config("synthetic"), notes)
        assert config.rig.depth_time_offset_s == 0.0
        phase_s = sim_depth_phase_s(read_sim_description(trot_3s_bag))  # what atsvo-bench nodes sets
        assert phase_s is not None and 0.0 < abs(phase_s) <= 1 / 60
        assert any(f"--set rig.depth_time_offset_s={phase_s:g}" in n for n in notes), notes
    finally:
        source.close()
    assert sim_depth_phase_s(None) is None and sim_depth_phase_s({"models": {}}) is None
    assert read_sim_description(tmp_path) is None  # no sequence.yaml: chosen from the topics as before
    (tmp_path / "sequence.yaml").write_text("generator: [unclosed")
    with pytest.raises(BagError, match="not readable YAML"):
        read_sim_description(tmp_path)
