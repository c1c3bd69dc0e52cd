"""Recorded sensor streams as replay sources: ROS 1/2 bags, MVSEC HDF5 files, TUM RGB-D folders.

A source knows its cameras and extrinsics (:meth:`ReplaySource.setup`) and feeds its messages, in
recording order, into a :class:`SensorSink` (the :class:`~atsvo_ros.runtime.runtime.OdometryRuntime`), one
message per generator step, collecting ground truth on the side. Damage it survives (unreadable
records, unusable poses) is reported by :meth:`ReplaySource.read_problems`.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import yaml

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import BagError, CalibrationError, TransformError
from atsvo_ros.io.bags import Bag, StaticTf, pose_from_msg
from atsvo_ros.io.images import depth_to_metres, stamp_ns
from atsvo_ros.io.mvsec import MvsecReader
from atsvo_ros.io.tum_rgbd import TumSource, is_tum_folder


class SensorSink(Protocol):
    """Where a source puts its data (implemented by :class:`atsvo_ros.runtime.runtime.OdometryRuntime`)."""

    def add_rgb(self, stamp_ns: int, image: np.ndarray) -> None: ...

    def add_depth(self, stamp_ns: int, depth_m: np.ndarray) -> None: ...

    def add_rgb_msg(self, msg: Any, topic: str = ...) -> None: ...

    def add_depth_msg(self, msg: Any, topic: str = ...) -> None: ...

    def add_events(self, batch: Any, complete_to_ns: int | None = None) -> None: ...

    def add_imu_msg(self, msg: Any, topic: str = ...) -> None: ...


class ReplaySource(Protocol):
    """A recording the replay can run (see the module docstring)."""

    topic_types: dict[str, str]
    #: trajectory.tum frame by default: ``base`` (robot) or ``camera`` (when ground truth is a camera pose)
    default_frame: str
    #: the bundled preset this recording implies, or None to choose from its topics
    preset: str | None

    def close(self) -> None: ...

    def has(self, role: str) -> bool: ...

    def require(self) -> None: ...

    def n_frames(self) -> int: ...

    def duration_s(self) -> float: ...

    def setup(self, config: AtsvoConfig, notes: list[str]) -> tuple[AtsvoConfig, CameraModel, CameraModel]: ...

    def feed(self, sink: SensorSink, roles: tuple[str, ...], gt: list | None) -> Iterator[None]: ...

    def decoder_stats(self) -> dict[str, Any]: ...

    def read_problems(self) -> tuple[dict[str, Any] | None, list[str]]: ...


#: Presets an atsvo-sim sequence.yaml may name (its ``config``).
SIM_PRESETS = ("synthetic", "mvsec")


def read_sim_description(path: Path) -> dict[str, Any] | None:
    """atsvo-sim's ``sequence.yaml`` in the bag folder (or beside a bag file), None when there is none.

    It records the preset the bag was made for (its rig and topics) and the sensor models, among them the
    D455's drawn depth-against-colour exposure offset.
    """
    folder = path if path.is_dir() else path.parent
    file = folder / "sequence.yaml"
    if not file.is_file():
        return None
    try:
        doc = yaml.safe_load(file.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise BagError(f"{file} is not readable YAML: {exc}") from None
    return doc if isinstance(doc, dict) and doc.get("generator") == "atsvo-sim" else None


def sim_depth_phase_s(description: dict[str, Any] | None) -> float | None:
    """The simulated D455's drawn depth-against-colour exposure offset (s) from a ``sequence.yaml``, or None."""
    phase_s = ((description or {}).get("models") or {}).get("depth", {}).get("phase_s_this_seed")
    return None if phase_s is None else float(phase_s)


def detect_preset(topics: dict[str, str]) -> str:
    """``mvsec`` for MVSEC topic names, else ``mini_cheetah`` (the robot and the simulator's layout)."""
    return "mvsec" if any(t.startswith("/davis/left/") for t in topics) else "mini_cheetah"


def _flat(T: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) for v in np.asarray(T).reshape(-1))


def _cameras(cfg: AtsvoConfig, first: dict[str, Any], notes: list[str],
             topics: dict[str, str | None] | None = None) -> tuple[CameraModel, CameraModel]:
    """Colour / event camera models: camera_info when present and allowed, else the config.

    ``topics`` (role -> topic) names the camera_info topic in a :class:`CalibrationError` (NaN in K or D).
    """
    rgb_cam = CameraModel.from_config(cfg.rgb_camera)
    if cfg.rgb_camera.use_camera_info and "rgb_info" in first:
        rgb_cam = _camera_from_info(first["rgb_info"], (topics or {}).get("rgb_info") or "rgb_info")
        notes.append("colour intrinsics from camera_info")
    ev_cam = CameraModel.from_config(cfg.event_camera)
    if cfg.event_camera.use_camera_info and "event_info" in first:
        ev_cam = _camera_from_info(first["event_info"], (topics or {}).get("event_info") or "event_info")
    return rgb_cam, ev_cam


def _camera_from_info(msg: Any, topic: str) -> CameraModel:
    """:meth:`CameraModel.from_camera_info`, its error naming the topic the message came from."""
    try:
        return CameraModel.from_camera_info(msg)
    except CalibrationError as exc:
        raise CalibrationError(f"camera_info on {topic}: {exc}") from None


def _extrinsics(cfg: AtsvoConfig, bag: Any, first: dict[str, Any], notes: list[str]) -> AtsvoConfig:
    """T_base_rgb / T_rgb_event / T_rgb_imu from /tf_static when it connects the frames, else the config."""

    if "tf_static" not in first:
        return cfg
    tf = StaticTf()
    for m in bag.messages(["tf_static"]):
        tf.add(m.msg, m.topic)
    updates: dict[str, Any] = {}
    rgb_frame = first["rgb"].header.frame_id if "rgb" in first else ""
    links = (("T_base_rgb", cfg.topics.base_frame, rgb_frame),
             ("T_rgb_event", rgb_frame, first["events"].header.frame_id if "events" in first else ""),
             ("T_rgb_imu", rgb_frame, first["imu"].header.frame_id if "imu" in first else ""))
    for name, parent, child in links:
        if parent and child:
            T = tf.lookup(parent, child)
            if T is not None:
                updates[name] = _flat(T)
                notes.append(f"{name} from /tf_static ({parent} -> {child})")
    return dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, **updates)) if updates else cfg


class BagSource:
    """A ROS 1 / ROS 2 bag: messages go to the sink as they come, poses to the ground truth."""

    default_frame = "base"

    def __init__(self, paths: list[Path], topics: dict[str, str | None] | None, config: AtsvoConfig | None) -> None:
        self.bag = Bag(paths, topics=topics, config_topics=vars(config.topics) if config else None)
        self.topic_types = self.bag.topic_types
        self.bad_poses: list[str] = []  # ground-truth messages skipped (NaN, zero quaternion)
        self.sim = read_sim_description(paths[0])
        self.preset = self.sim.get("config") if self.sim and self.sim.get("config") in SIM_PRESETS else None
        self.preset_note = f"config preset {self.preset} (atsvo-sim's sequence.yaml)"

    def close(self) -> None:
        self.bag.close()

    def has(self, role: str) -> bool:
        return getattr(self.bag.selection, role) is not None

    def require(self) -> None:
        self.bag.require("rgb", "depth")

    def n_frames(self) -> int:
        return self.bag.message_count("rgb")

    def duration_s(self) -> float:
        return self.bag.duration_s

    def setup(self, config: AtsvoConfig, notes: list[str]) -> tuple[AtsvoConfig, CameraModel, CameraModel]:
        first = self.bag.first_messages(["rgb", "rgb_info", "event_info", "tf_static", "events", "imu"])
        config = _extrinsics(config, self.bag, first, notes)
        phase_s = sim_depth_phase_s(self.sim)
        if phase_s and config.rig.depth_time_offset_s != phase_s:
            # said, not applied: the gyro-only turn helps flips and hurts bounds (docs/simulator.md)
            notes.append(f"sequence.yaml: the simulated D455 exposes depth {float(phase_s) * 1e3:+.1f} ms off colour; "
                         f"--set rig.depth_time_offset_s={float(phase_s):g} turns each depth image to the colour's "
                         "time by the gyro, as atsvo-bench does")
        return (config, *_cameras(config, first, notes, dict(self.bag.selection.items())))

    def feed(self, sink: SensorSink, roles: tuple[str, ...], gt: list | None) -> Iterator[None]:
        """Generator: one message of ``roles`` into ``sink`` per step (ground truth into ``gt``)."""

        wanted = [r for r in roles if self.has(r)] + (["ground_truth"] if gt is not None else [])
        for m in self.bag.messages(wanted):
            if m.role == "rgb":
                sink.add_rgb_msg(m.msg, m.topic)
            elif m.role == "depth":
                sink.add_depth_msg(m.msg, m.topic)
            elif m.role == "events":
                sink.add_events(m.events, m.stamp_ns)
            elif m.role == "imu":
                sink.add_imu_msg(m.msg, m.topic)
            elif m.role == "ground_truth":
                try:
                    gt.append((stamp_ns(m.msg), pose_from_msg(m.msg, m.topic)))
                except TransformError as exc:
                    self.bad_poses.append(str(exc))
            yield

    def decoder_stats(self) -> dict[str, Any]:
        return {t: d.stats.as_dict() for t, d in self.bag.event_decoders.items() if hasattr(d, "stats")}

    def read_problems(self) -> tuple[dict[str, Any] | None, list[str]]:
        """(the bag's read report, notes on what was lost: unreadable records, skipped poses)."""
        report = self.bag.read_stats
        notes = [] if report.clean else [f"bag damaged: {report.summary()}"]
        if self.bad_poses:
            notes.append(f"skipped {len(self.bad_poses)} unusable ground-truth poses, first: {self.bad_poses[0]}")
        return report.as_dict(), notes


class MvsecSource:
    """MVSEC HDF5 (``*_data.hdf5``, with ``*_gt.hdf5`` next to it used automatically)."""

    topic_types = {"/davis/left/": "mvsec"}
    default_frame = "base"
    preset = "mvsec"

    def __init__(self, path: Path) -> None:
        gt = path.with_name(path.name.replace("_data", "_gt"))
        self.reader = MvsecReader(path, gt if gt != path and gt.is_file() else None)
        self.preset_note = "config preset mvsec (MVSEC HDF5 file)"

    def close(self) -> None:
        self.reader.close()

    def has(self, role: str) -> bool:
        return role in ("rgb", "depth", "events", "ground_truth") and self.reader.has(role)

    def require(self) -> None:
        for role in ("rgb", "depth"):
            if not self.reader.has(role):
                raise BagError(f"the MVSEC files have no {role} dataset (depth is in the *_gt.hdf5 file)")

    def n_frames(self) -> int:
        d = self.reader._get("image_raw")
        return 0 if d is None else len(d)

    def duration_s(self) -> float:
        ts = self.reader._get("image_raw_ts")
        return float(ts[-1] - ts[0]) if ts is not None and len(ts) > 1 else 0.0

    def setup(self, config: AtsvoConfig, notes: list[str]) -> tuple[AtsvoConfig, CameraModel, CameraModel]:
        notes.append("cameras and extrinsics from the configuration (MVSEC HDF5)")
        self._rig = config.rig
        return config, CameraModel.from_config(config.rgb_camera), CameraModel.from_config(config.event_camera)

    def feed(self, sink: SensorSink, roles: tuple[str, ...], gt: list | None) -> Iterator[None]:
        """Generator: one image, depth map or event slice into ``sink`` per step (after :meth:`setup`)."""

        if gt is not None and self.reader.has("ground_truth"):
            g = self.reader.ground_truth()
            gt.extend(zip(g.stamps_ns.tolist(), g.T_w_b))
        rig = self._rig
        for item in self.reader.stream(tuple(r for r in ("rgb", "depth", "events") if r in roles)):
            if item.role == "rgb":
                sink.add_rgb(item.stamp_ns, item.data)
            elif item.role == "depth":
                sink.add_depth(item.stamp_ns, depth_to_metres(item.data, rig.depth_scale_m, rig.depth_min_m,
                                                              rig.depth_max_m))
            else:
                sink.add_events(item.data)
            yield

    def decoder_stats(self) -> dict[str, Any]:
        return {}

    def read_problems(self) -> tuple[dict[str, Any] | None, list[str]]:
        return None, []


def open_source(paths: list[Path], topics: dict[str, str | None] | None, config: AtsvoConfig | None) -> ReplaySource:
    """The source for ``paths``: a TUM folder, an MVSEC HDF5 file, or ROS bags (several ROS 1 bags merge;
    an atsvo-sim bag's ``sequence.yaml`` names its preset: :func:`read_sim_description`)."""

    if is_tum_folder(paths[0]):
        if len(paths) > 1:
            raise BagError("give one TUM RGB-D folder (the one holding rgb.txt and depth.txt)")
        flags = [f"--{role.replace('_', '-')}-topic" for role, topic in (topics or {}).items() if topic]
        if flags:
            raise BagError(f"{' and '.join(flags)} {'do' if len(flags) > 1 else 'does'} not apply to a TUM RGB-D "
                           f"folder: {paths[0]} is read from rgb.txt, depth.txt and groundtruth.txt")
        return TumSource(paths[0])
    if paths[0].is_dir() and (paths[0] / "rgb.txt").is_file():
        raise BagError(f"{paths[0]} has rgb.txt but no depth.txt: a TUM RGB-D folder needs both (the odometry needs "
                       "depth)")
    if paths[0].suffix.lower() in (".hdf5", ".h5"):
        if len(paths) > 1:
            raise BagError("give one MVSEC *_data.hdf5 file (its *_gt.hdf5 sibling is found automatically)")
        return MvsecSource(paths[0])
    return BagSource(paths, topics, config)


__all__ = ["SIM_PRESETS", "BagSource", "MvsecSource", "ReplaySource", "SensorSink", "detect_preset", "open_source",
           "read_sim_description"]
