"""Write a synthetic sequence as a ROS 2 bag (mcap / sqlite3) or a ROS 1 bag, plus TUM ground truth.

Layout ``robot`` uses the robot's drivers' topics and types (realsense2_camera, libcaer_driver,
motion capture), including the D455's united IMU topic; layout ``mvsec`` those of MVSEC's
indoor_flying bags. Messages are built with
rosbags' classes from :func:`atsvo_ros.io.msgtypes.typestore`; event messages are serialized with
numpy by :mod:`atsvo_ros.io.encode` (never one Python object per event).
"""
from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from rosbags import rosbag1, rosbag2
from tqdm import tqdm

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.geometry import quat_from_rotmat
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import SimulationError
from atsvo_ros.io.encode import ENCODINGS, serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.io.msgtypes import transient_local_qos, typestore
from atsvo_ros.io.trajectory import Trajectory, write_tum
from atsvo_ros.sim.motion import make_motion
from atsvo_ros.sim.report import format_summary, summarise
from atsvo_ros.sim.scene import scene_free_xy
from atsvo_ros.sim.sequence import GroundTruth, RgbdFrame, SequenceSpec, SimRig, iter_sequence, model_key, sequence_rig

FORMATS = ("mcap", "sqlite3", "ros1")
EVENT_MSGS = ("packet", "dvs")
#: EventPacket encodings that carry absolute time (evt3 holds only a wrapping sensor clock).
EVENT_ENCODINGS = tuple(e for e in ENCODINGS if e != "evt3")
RGB_FRAME = "camera_color_optical_frame"
EVENT_FRAME = "dvxplorer"
IMU_FRAME = "camera_imu_optical_frame"  # realsense2_camera's frame of the united imu topic
WORLD_FRAME = "world"


@dataclasses.dataclass(frozen=True)
class BagTopics:
    """Topic names and message types of one layout."""

    rgb: tuple[str, str]
    rgb_info: tuple[str, str]
    depth: tuple[str, str]
    events: tuple[str, str]
    event_info: tuple[str, str] | None
    ground_truth: tuple[str, str]
    tf_static: tuple[str, str] | None
    imu: tuple[str, str] | None = None


def layout_topics(rig: SimRig, layout: str, event_msg: str = "packet", imu: bool = True) -> BagTopics:
    """Topics and types for ``layout`` (names from the rig's config ``topics`` section); ``imu`` for robot."""
    t = rig.config.topics
    img, info, pose = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo", "geometry_msgs/msg/PoseStamped"
    if layout == "mvsec":
        return BagTopics((t.rgb, img), (t.rgb_info, info), (t.depth, img), (t.events, "dvs_msgs/msg/EventArray"),
                         None, (t.ground_truth, pose), None)
    ev_type = "event_camera_msgs/msg/EventPacket" if event_msg == "packet" else "dvs_msgs/msg/EventArray"
    return BagTopics((t.rgb, img), (t.rgb_info, info), (t.depth, img), (t.events, ev_type),
                     (t.event_info, info), (t.ground_truth, pose), ("/tf_static", "tf2_msgs/msg/TFMessage"),
                     (t.imu, "sensor_msgs/msg/Imu") if imu else None)


class _Messages:
    """Builds rosbags message objects for one ROS version and serializes them."""

    def __init__(self, ros_version: int) -> None:
        self.ros1 = ros_version == 1
        self.store = typestore(ros_version)
        self.T = self.store.types
        self._seq = 0

    def serialize(self, msg: Any, msgtype: str) -> bytes:
        if self.ros1:
            return bytes(self.store.serialize_ros1(msg, msgtype))
        return bytes(self.store.serialize_cdr(msg, msgtype))

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        stamp = self.T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                                      nanosec=int(stamp_ns % 1_000_000_000))
        if self.ros1:
            self._seq += 1
            return self.T["std_msgs/msg/Header"](seq=self._seq, stamp=stamp, frame_id=frame_id)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def image(self, stamp_ns: int, frame_id: str, data: np.ndarray, encoding: str) -> Any:
        data = np.ascontiguousarray(data)
        h, w = data.shape[:2]
        step = data.strides[0]
        return self.T["sensor_msgs/msg/Image"](header=self.header(stamp_ns, frame_id), height=h, width=w,
                                               encoding=encoding, is_bigendian=0, step=step,
                                               data=data.view(np.uint8).reshape(-1))

    def camera_info(self, stamp_ns: int, frame_id: str, cam: CameraModel) -> Any:
        K = cam.K.reshape(-1)
        P = np.zeros(12)
        P[[0, 2, 5, 6, 10]] = [cam.fx, cam.cx, cam.fy, cam.cy, 1.0]
        roi = self.T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                         do_rectify=False)
        D = np.asarray(cam.D if cam.is_distorted else (0.0,) * 5, np.float64)  # as realsense2_camera does
        fields = {"D" if self.ros1 else "d": D,
                  "K" if self.ros1 else "k": K, "R" if self.ros1 else "r": np.eye(3).reshape(-1),
                  "P" if self.ros1 else "p": P}
        return self.T["sensor_msgs/msg/CameraInfo"](header=self.header(stamp_ns, frame_id), height=cam.height,
                                                    width=cam.width, distortion_model=cam.distortion_model
                                                    if cam.is_distorted else "plumb_bob",
                                                    binning_x=0, binning_y=0, roi=roi, **fields)

    def _pose_parts(self, T: np.ndarray) -> tuple[Any, Any]:
        q = quat_from_rotmat(T[:3, :3])
        quat = self.T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
        return T[:3, 3], quat

    def pose_stamped(self, stamp_ns: int, frame_id: str, T: np.ndarray) -> Any:
        t, quat = self._pose_parts(T)
        point = self.T["geometry_msgs/msg/Point"](x=float(t[0]), y=float(t[1]), z=float(t[2]))
        pose = self.T["geometry_msgs/msg/Pose"](position=point, orientation=quat)
        return self.T["geometry_msgs/msg/PoseStamped"](header=self.header(stamp_ns, frame_id), pose=pose)

    def imu(self, stamp_ns: int, frame_id: str, gyro: np.ndarray, accel: np.ndarray, gyro_var: float,
            accel_var: float) -> Any:
        """sensor_msgs/Imu without orientation (covariance[0] = -1, REP 145), diagonal noise covariances."""
        V3 = self.T["geometry_msgs/msg/Vector3"]
        q0 = self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=0.0)  # as realsense2_camera
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0
        return self.T["sensor_msgs/msg/Imu"](
            header=self.header(stamp_ns, frame_id), orientation=q0, orientation_covariance=no_orientation,
            angular_velocity=V3(x=float(gyro[0]), y=float(gyro[1]), z=float(gyro[2])),
            angular_velocity_covariance=np.eye(3).reshape(-1) * gyro_var,
            linear_acceleration=V3(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
            linear_acceleration_covariance=np.eye(3).reshape(-1) * accel_var)

    def tf(self, stamp_ns: int, links: list[tuple[str, str, np.ndarray]]) -> Any:
        out = []
        for parent, child, T in links:
            t, quat = self._pose_parts(T)
            vec = self.T["geometry_msgs/msg/Vector3"](x=float(t[0]), y=float(t[1]), z=float(t[2]))
            tr = self.T["geometry_msgs/msg/Transform"](translation=vec, rotation=quat)
            out.append(self.T["geometry_msgs/msg/TransformStamped"](header=self.header(stamp_ns, parent),
                                                                    child_frame_id=child, transform=tr))
        return self.T["tf2_msgs/msg/TFMessage"](transforms=out)


class _BagSink:
    """Uniform ``add(topic, type)`` / ``write(topic, t_ns, bytes)`` over rosbags' writers."""

    def __init__(self, path: Path, fmt: str) -> None:
        self.fmt = fmt
        if fmt == "ros1":
            self.writer = rosbag1.Writer(path)
        else:
            plugin = rosbag2.StoragePlugin.MCAP if fmt == "mcap" else rosbag2.StoragePlugin.SQLITE3
            self.writer = rosbag2.Writer(path, version=9, storage_plugin=plugin)
        self.conns: dict[str, Any] = {}

    def __enter__(self) -> _BagSink:
        self.writer.open()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.writer.close()

    def add(self, topic: str, msgtype: str, store: Any, latching: bool = False) -> None:
        kw: dict[str, Any] = {"typestore": store}
        if latching and self.fmt == "ros1":
            kw["latching"] = 1
        elif latching:  # /tf_static: transient local, so `ros2 bag play` latches it like tf2 expects
            kw["offered_qos_profiles"] = [transient_local_qos()]
        self.conns[topic] = self.writer.add_connection(topic, msgtype, **kw)

    def write(self, topic: str, t_ns: int, data: bytes) -> None:
        self.writer.write(self.conns[topic], int(t_ns), data)


_OURS = ("metadata.yaml", "sequence.bag", "groundtruth.tum", "sequence.yaml")


def _ours(p: Path) -> bool:
    return p.name in _OURS or p.suffix in (".mcap", ".db3") or p.name.endswith((".db3-shm", ".db3-wal"))


def _check_out(out: Path, force: bool) -> None:
    """Refuse an ``out`` that is a file, holds files atsvo-sim did not write, or (without ``force``) anything."""
    if not out.exists():
        return
    if not out.is_dir():
        raise SimulationError(f"output {out} exists and is not a directory")
    entries = list(out.iterdir())
    if entries and not force:
        raise SimulationError(f"output directory {out} is not empty (use --force to replace a sequence)")
    for p in entries:
        if not _ours(p):
            raise SimulationError(f"{out} holds {p.name}, which atsvo-sim did not write; choose another --out")


def _move_into_place(done: Path, out: Path) -> None:
    """Replace ``out`` (a previous atsvo-sim output, or nothing) by the complete output ``done``."""
    if out.exists():
        _check_out(out, force=True)  # again: it may have changed during the generation
        for p in out.iterdir():
            p.unlink()
        out.rmdir()
    done.rename(out)


def write_sequence(spec: SequenceSpec, out: str | Path, fmt: str = "mcap", event_msg: str = "packet",
                   encoding: str = "libcaer_cmp", force: bool = False, progress: bool = True) -> dict[str, Any]:
    """Generate ``spec`` into ``out`` (bag + ``groundtruth.tum`` + ``sequence.yaml``); return a summary.

    Everything is written to a hidden temporary folder next to ``out`` and moved into place when
    complete; on any failure (or Ctrl-C) the folder is removed, so ``out`` holds either the
    previous output (``force``) or nothing, and a rerun works.
    """
    if fmt not in FORMATS:
        raise SimulationError(f"unknown format {fmt!r} (choose one of {', '.join(FORMATS)})")
    if event_msg not in EVENT_MSGS:
        raise SimulationError(f"unknown event message {event_msg!r} (choose one of {', '.join(EVENT_MSGS)})")
    if encoding not in EVENT_ENCODINGS:
        raise SimulationError(f"event encoding {encoding!r} is not supported here "
                              f"(choose one of {', '.join(EVENT_ENCODINGS)})")
    out = Path(out)
    if out.name in ("", ".", ".."):
        raise SimulationError(f"--out {out} must name the sequence's own folder")
    _check_out(out, force)
    created = [p for p in (out.parent, *out.parent.parents) if not p.exists()]  # deepest first
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.atsvo-sim-partial-", dir=out.parent))
    done = False
    try:
        target = staging / out.name  # same folder name: a ROS 2 bag names its storage file after it
        summary = _generate(spec, target, fmt, event_msg, encoding, progress,
                            out / "sequence.bag" if fmt == "ros1" else out)
        _move_into_place(target, out)
        done = True
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        for p in created if not done else ():  # parent folders made for this run, if still empty
            try:
                p.rmdir()
            except OSError:
                break
    return summary


def _generate(spec: SequenceSpec, out: Path, fmt: str, event_msg: str, encoding: str, progress: bool,
              final_bag: Path) -> dict[str, Any]:
    """Write the bag, ``groundtruth.tum`` and ``sequence.yaml`` into the new folder ``out``."""
    rig = sequence_rig(spec)
    topics = layout_topics(rig, spec.layout, event_msg, imu=spec.imu)
    ros_version = 1 if fmt == "ros1" else 2
    msgs = _Messages(ros_version)
    if fmt == "ros1":
        out.mkdir()
        bag_path = out / "sequence.bag"
    else:
        bag_path = out  # rosbags creates the ROS 2 bag directory
    counts = {"frames": 0, "event_packets": 0, "events": 0, "poses": 0, "imu_samples": 0}
    event_counts: list[tuple[int, int]] = []
    stats: dict[str, Any] = {}
    gt_stamps, gt_poses = [], []
    mvsec = spec.layout == "mvsec"
    wall0 = time.perf_counter()
    bar = _progress(spec.duration_s, progress)
    t_start = spec.start_ns
    with _BagSink(bag_path, fmt) as sink:
        for name in ("rgb", "rgb_info", "depth", "events", "event_info", "ground_truth", "tf_static", "imu"):
            tt = getattr(topics, name)
            if tt is not None:
                sink.add(tt[0], tt[1], msgs.store, latching=name == "tf_static")
        if topics.tf_static is not None:
            links = [(rig.config.topics.base_frame, RGB_FRAME, rig.T_base_rgb),
                     (RGB_FRAME, EVENT_FRAME, rig.T_rgb_event)]
            if topics.imu is not None:
                links.append((RGB_FRAME, IMU_FRAME, rig.T_rgb_imu))
            sink.write(topics.tf_static[0], t_start, msgs.serialize(msgs.tf(t_start, links), topics.tf_static[1]))
        rgb_frame = RGB_FRAME if not mvsec else "davis_left"
        ev_frame = EVENT_FRAME if not mvsec else "davis_left"
        seq = 0
        gyro_var = spec.imu_model.white_sigma("gyro") ** 2
        accel_var = spec.imu_model.white_sigma("accel") ** 2
        for item in iter_sequence(spec, stats=stats):
            if isinstance(item, GroundTruth):
                gt_stamps.append(item.stamp_ns)
                gt_poses.append(item.T_world_base)
                m = msgs.pose_stamped(item.stamp_ns, WORLD_FRAME, item.T_world_base)
                sink.write(topics.ground_truth[0], item.stamp_ns, msgs.serialize(m, topics.ground_truth[1]))
                counts["poses"] += 1
                bar.update_to(item.stamp_ns - t_start)
            elif isinstance(item, RgbdFrame):
                _write_frame(sink, msgs, topics, rig, item, rgb_frame, mvsec)
                if topics.event_info is not None:
                    info = msgs.camera_info(item.stamp_ns, ev_frame, rig.event_camera)
                    sink.write(topics.event_info[0], item.stamp_ns, msgs.serialize(info, topics.event_info[1]))
                counts["frames"] += 1
            elif isinstance(item, EventBatch):
                stamp = int(item.t[-1])
                if topics.events[1].endswith("EventPacket"):
                    data = serialize_event_packet(item, encoding, frame_id=ev_frame, seq=seq, ros_version=ros_version)
                else:
                    data = serialize_dvs_event_array(item, frame_id=ev_frame, ros_version=ros_version, seq=seq)
                sink.write(topics.events[0], stamp, data)
                seq += 1
                counts["event_packets"] += 1
                counts["events"] += len(item)
                event_counts.append((stamp, len(item)))
            elif isinstance(item, ImuBatch) and topics.imu is not None:
                for s, g, a in zip(item.stamps_ns.tolist(), item.gyro_rad_s, item.accel_m_s2):
                    m = msgs.imu(s, IMU_FRAME, g, a, gyro_var, accel_var)
                    sink.write(topics.imu[0], s, msgs.serialize(m, topics.imu[1]))
                counts["imu_samples"] += len(item)
    bar.close()
    wall = time.perf_counter() - wall0
    write_tum(out / "groundtruth.tum", Trajectory(np.asarray(gt_stamps), np.asarray(gt_poses)),
              header=f"atsvo-sim {spec.scenario} seed {spec.seed}: T_world_{rig.config.topics.base_frame}")
    motion = make_motion(spec.scenario, spec.duration_s, spec.seed, scene_free_xy(spec.seed), t0_ns=spec.start_ns)
    phases = summarise(motion, stats.get("frames", []), event_counts)
    summary = {**counts, "event_renders": int(stats.get("event_renders", 0)),
               "rgb_renders": int(stats.get("rgb_renders", 0)), "wall_s": round(wall, 2),
               "bag": str(final_bag), "depth_sensor": spec.depth_sensor,
               "depth_phase_s": round(float(stats.get("depth_phase_s", 0.0)), 6),
               "phases": [r.as_dict() for r in phases], "phase_table": format_summary(phases)}
    _write_description(out / "sequence.yaml", spec, rig, topics, fmt, event_msg, encoding,
                       {k: v for k, v in summary.items() if k != "phase_table"},
                       stats.get("imu"))
    return summary


def _write_frame(sink: _BagSink, msgs: _Messages, topics: BagTopics, rig: SimRig, frame: RgbdFrame,
                 frame_id: str, mvsec: bool) -> None:
    s = frame.stamp_ns
    if mvsec:
        grey = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY)
        img = msgs.image(s, frame_id, grey, "mono8")
        depth = msgs.image(s, frame_id, frame.depth_m.astype("<f4"), "32FC1")
    else:
        img = msgs.image(s, frame_id, frame.rgb, "rgb8")
        depth = msgs.image(s, frame_id, frame.depth_mm.astype("<u2"), "16UC1")
    sink.write(topics.rgb[0], s, msgs.serialize(img, topics.rgb[1]))
    info = msgs.camera_info(s, frame_id, rig.rgb_camera)
    sink.write(topics.rgb_info[0], s, msgs.serialize(info, topics.rgb_info[1]))
    sink.write(topics.depth[0], s, msgs.serialize(depth, topics.depth[1]))


def _write_description(path: Path, spec: SequenceSpec, rig: SimRig, topics: BagTopics, fmt: str, event_msg: str,
                       encoding: str, summary: dict[str, Any], imu_draws: dict[str, Any] | None = None) -> None:
    def plain(v: Any) -> Any:
        if isinstance(v, np.ndarray):
            return np.round(v, 9).tolist()
        if isinstance(v, tuple):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    doc = {
        "generator": "atsvo-sim", "model": model_key(),
        "scenario": spec.scenario, "seed": spec.seed, "duration_s": spec.duration_s, "layout": spec.layout,
        "format": fmt, "config": spec.config or ("mvsec" if spec.layout == "mvsec" else "synthetic"),
        "event_message": topics.events[1], "event_encoding": encoding if event_msg == "packet" else None,
        "start_ns": spec.start_ns, "rate_hz": spec.rate_hz, "exposure_s": spec.exposure_s,
        "gt_rate_hz": spec.gt_rate_hz, "event_packet_s": spec.event_packet_s,
        "rig": {"rgb_camera": rig.rgb_camera.to_dict(), "depth_camera": rig.depth_camera.to_dict(),
                "event_camera": rig.event_camera.to_dict(), "T_base_rgb": plain(rig.T_base_rgb),
                "T_rgb_event": plain(rig.T_rgb_event), "T_rgb_imu": plain(rig.T_rgb_imu)},
        "topics": {k: list(v) for k, v in dataclasses.asdict(topics).items() if v is not None},
        "models": {"rgb": plain(dataclasses.asdict(spec.rgb_model)),
                   "depth": ({"sensor": "d455", **plain(dataclasses.asdict(spec.stereo_model)),
                              "phase_s_this_seed": summary.get("depth_phase_s")} if spec.depth_sensor == "d455"
                             else {"sensor": "sharp", **plain(dataclasses.asdict(spec.depth_model))}),
                   "events": plain(dataclasses.asdict(spec.event_model)),
                   **({"imu": {**plain(spec.imu_model.to_dict()), "frame": IMU_FRAME, "this_seed": imu_draws}}
                      if topics.imu is not None else {})},
        "ground_truth": "groundtruth.tum (T_world_base, TUM: t tx ty tz qx qy qz qw)",
        "summary": summary,
    }
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


class _NoBar:
    def update_to(self, _: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(duration_s: float, enabled: bool) -> Any:
    """A tqdm bar over simulated seconds (stderr), or a no-op."""
    if not enabled:
        return _NoBar()

    bar = tqdm(total=round(duration_s, 3), unit="sim s", desc="atsvo-sim", leave=False,
               bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} sim s [{elapsed}<{remaining}]")

    class _Bar:
        def __init__(self) -> None:
            self.last = 0.0

        def update_to(self, t_ns: int) -> None:
            n = t_ns * 1e-9
            if n - self.last >= 0.05:
                bar.update(round(n - self.last, 3))
                self.last = n

        def close(self) -> None:
            bar.close()

    return _Bar()


__all__ = ["BagTopics", "layout_topics", "write_sequence"]
