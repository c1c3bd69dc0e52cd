"""Streaming bag reading (ROS 1 .bag, ROS 2 sqlite3 / mcap) with rosbags, no ROS install needed.

:class:`Bag` opens a ROS 1 ``.bag`` file, a ROS 2 bag directory, or a bare ``.mcap`` / ``.db3``
file (also a directory whose ``metadata.yaml`` is missing or names no storage plugin: its single
storage file is read directly). It resolves the topics
the replay needs (explicit names > the configuration's topics > every bundled preset's topics >
detection by message type and name) and yields the messages merged in time order, one at a time,
so memory does not grow with the bag. Event messages are decoded from the raw bytes (no per-event
Python objects) by the stateful decoder of :mod:`atsvo_ros.io.decode`.
"""
from __future__ import annotations

import logging
import struct
from collections.abc import Iterable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rosbags.highlevel import AnyReader

from atsvo_ros.config import load_config
from atsvo_ros.core.geometry import pose_from_tq, se3_inv
from atsvo_ros.errors import BagError, TransformError
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.msgtypes import EVENT_MSGTYPES, register_event_types, typestore
from atsvo_ros.io.read_report import ReadReport, container_errors, describe, iter_messages
from atsvo_ros.io.restamp import cdr_stamp_ns

_log = logging.getLogger(__name__)

#: roles the replay understands, in the order they are reported
ROLES = ("rgb", "depth", "events", "rgb_info", "event_info", "ground_truth", "tf_static", "imu")
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry")
TF_TYPES = ("tf2_msgs/msg/TFMessage",)
IMU_TYPES = ("sensor_msgs/msg/Imu",)
PRESETS = ("mini_cheetah", "mvsec", "synthetic")


def _role_types() -> dict[str, tuple[str, ...]]:
    return {"rgb": IMAGE_TYPES, "depth": IMAGE_TYPES, "events": tuple(EVENT_MSGTYPES), "rgb_info": INFO_TYPES,
            "event_info": INFO_TYPES, "ground_truth": POSE_TYPES, "tf_static": TF_TYPES, "imu": IMU_TYPES}


@dataclass(frozen=True)
class TopicSelection:
    """Topic chosen for each role (None = not in the bag)."""

    rgb: str | None = None
    depth: str | None = None
    events: str | None = None
    rgb_info: str | None = None
    event_info: str | None = None
    ground_truth: str | None = None
    tf_static: str | None = None
    imu: str | None = None

    def items(self) -> list[tuple[str, str]]:
        return [(f.name, getattr(self, f.name)) for f in fields(self) if getattr(self, f.name)]

    def role_of(self) -> dict[str, str]:
        """topic -> role."""
        return {topic: role for role, topic in self.items()}


@dataclass(frozen=True)
class BagMessage:
    """One message of the stream: deserialized ``msg``, or decoded ``events`` for event topics."""

    role: str
    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any = None
    events: Any = None
    stamp_ns: int | None = None  #: header stamp of an event message (None when it has none)


def _raw_stamp_ns(raw: bytes | bytearray | memoryview, ros_version: int) -> int | None:
    """header.stamp of a serialized message with a header first (ROS 2 CDR, or ROS 1: seq, sec, nsec)."""
    if ros_version == 2:
        return cdr_stamp_ns(raw)
    if len(raw) < 12:
        return None
    sec, nsec = struct.unpack_from("<II", raw, 4)
    return sec * 1_000_000_000 + nsec


# ---------------------------------------------------------------------------- opening


def _metadata_ok(folder: Path) -> bool:
    meta = folder / "metadata.yaml"
    if not meta.is_file():
        return False
    try:
        info = yaml.safe_load(meta.read_bytes().decode("utf-8"))["rosbag2_bagfile_information"]
        return info.get("storage_identifier") in ("sqlite3", "mcap")
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, AttributeError):
        return False  # unreadable metadata: read the storage file directly


def open_any_reader(path: str | Path | Sequence[str | Path]) -> Any:
    """An (unopened) rosbags AnyReader for any supported layout; BagError when it is not a bag.

    A bare ``.mcap`` / ``.db3`` file is read directly (rosbags >= 0.11); so is the single storage
    file of a bag directory whose ``metadata.yaml`` is missing or names no storage plugin. Several
    ROS 1 bags (e.g. MVSEC's ``*_data.bag`` and ``*_gt.bag``) are read as one, merged in time.
    """


    if not isinstance(path, (str, Path)):
        paths = [Path(q) for q in path]
        if len(paths) != 1:
            for q in paths:
                if not q.exists():
                    raise BagError(f"bag {q} does not exist")
            if not paths or any(q.suffix != ".bag" for q in paths):
                raise BagError("several bags can be read together only if all are ROS 1 .bag files, got "
                               + ", ".join(q.name for q in paths))
            try:
                return AnyReader(paths, default_typestore=typestore(1))
            except container_errors() as exc:
                raise BagError(f"cannot open bags {', '.join(map(str, paths))}: {describe(exc)}") from None
        path = paths[0]
    p = Path(path)
    if not p.exists():
        raise BagError(f"bag {p} does not exist")
    target = p
    if p.is_file() and p.suffix == ".bag":
        store = typestore(1)
    else:
        store = typestore(2)
        if p.is_dir() and not _metadata_ok(p):
            files = sorted(p.glob("*.mcap")) or sorted(p.glob("*.db3"))
            if len(files) != 1:
                raise BagError(f"{p} has no usable metadata.yaml and {len(files)} storage files; "
                               "expected a ROS 2 bag directory with metadata.yaml or a single .mcap/.db3 file")
            target = files[0]
        elif p.is_file() and p.suffix not in (".mcap", ".db3"):
            raise BagError(f"{p} is not a bag: expected a ROS 1 .bag file, a ROS 2 bag directory "
                           "or a .mcap / .db3 file")
    try:
        return AnyReader([target], default_typestore=store)
    except container_errors() as exc:
        raise BagError(f"cannot open bag {p}: {describe(exc)}") from None


# ---------------------------------------------------------------------------- topic resolution


def preset_topics(name: str) -> dict[str, str]:
    """The ``topics`` section of a bundled preset (or of a YAML path) as role -> topic."""

    t = load_config(name).topics
    return {r: getattr(t, r) for r in ("rgb", "depth", "events", "rgb_info", "event_info", "ground_truth", "imu")}


def _detect(role: str, topics: dict[str, str], chosen: dict[str, str | None]) -> str | None:
    """Pick a topic for ``role`` from message types and names when no preset names it."""

    def only(cands: list[str]) -> str | None:
        return cands[0] if len(cands) == 1 else None

    images = [t for t, m in topics.items() if m in IMAGE_TYPES]
    if role == "events":
        return only([t for t, m in topics.items() if m in EVENT_MSGTYPES]) or \
            next((t for t, m in topics.items() if m in EVENT_MSGTYPES and "left" in t), None)
    if role == "depth":
        return only([t for t in images if "depth" in t.lower()])
    if role == "rgb":
        cands = [t for t in images if "depth" not in t.lower()]
        return only(cands) or only([t for t in cands if any(k in t.lower() for k in ("color", "rgb"))]) or \
            only([t for t in cands if "left" in t.lower() and "image_raw" in t.lower()])
    if role in ("rgb_info", "event_info"):
        base = chosen.get("rgb" if role == "rgb_info" else "events")
        if not base:
            return None
        ns = base.rsplit("/", 1)[0]
        cand = [t for t, m in topics.items() if m in INFO_TYPES and t.rsplit("/", 1)[0] == ns]
        return only(cand)
    if role == "ground_truth":
        cands = [t for t, m in topics.items() if m in POSE_TYPES]
        return only(cands) or only([t for t in cands if any(k in t.lower() for k in ("ground_truth", "gt", "pose"))])
    if role == "tf_static":
        return "/tf_static" if topics.get("/tf_static") in TF_TYPES else None
    if role == "imu":
        # realsense2_camera's gyro/sample and accel/sample carry one sensor each: only a united topic will do.
        cands = [t for t, m in topics.items() if m in IMU_TYPES and not t.endswith(("/gyro/sample", "/accel/sample"))]
        return only(cands) or only([t for t in cands if t.rsplit("/", 1)[-1] == "imu"])
    return None


def resolve_topics(topics: dict[str, str], explicit: dict[str, str | None] | None = None,
                   config_topics: dict[str, str] | None = None, presets: Iterable[str] = PRESETS) -> TopicSelection:
    """Choose a topic per role: explicit > config > presets > detection. Explicit names must exist."""
    explicit = {k: v for k, v in (explicit or {}).items() if v}
    chosen: dict[str, str | None] = {}
    for role, name in explicit.items():
        if role not in ROLES:
            raise BagError(f"unknown topic role {role!r} (known: {', '.join(ROLES)})")
        if name not in topics:
            raise BagError(f"topic {name} (given for {role}) is not in the bag; it has: {', '.join(sorted(topics))}")
        allowed = _role_types()[role]
        if topics[name] not in allowed:
            flag = f"--{role.replace('_', '-')}-topic"
            raise BagError(f"{flag} {name} is a {topics[name]} topic; it must be one of: {', '.join(allowed)}")
        twice = next((r for r, t in chosen.items() if t == name and {r, role} & {"rgb", "depth", "ground_truth"}), None)
        if twice:
            raise BagError(f"topic {name} is given for both {twice} and {role}; each role needs its own topic")
        chosen[role] = name
    candidates = [config_topics or {}] + [preset_topics(p) for p in presets]
    for role in ROLES:
        if role in chosen:
            continue
        allowed = _role_types()[role]  # a configured name of another type is passed over, as a missing one is
        chosen[role] = next((c[role] for c in candidates if c.get(role) in topics and topics[c[role]] in allowed),
                            None)
        if chosen[role] is None:
            chosen[role] = _detect(role, topics, chosen)
    return TopicSelection(**chosen)


# ---------------------------------------------------------------------------- the stream


def _event_decoder(msgtype: str, ros_version: int) -> Any:
    """The events engineer's stateful per-topic decoder (roll-over state, counted drops)."""

    return EventDecoder(msgtype, ros_version)


def _open_with_default_types(reader: Any) -> bool:
    """Open an AnyReader ignoring the bag's embedded message definitions (bundled typestore instead).

    Mirrors what AnyReader does for bags without definitions; False when the storage itself
    cannot be opened (then the bag is really unreadable).
    """

    reader.stack = ExitStack()
    try:
        for sub in reader.readers:
            reader.stack.enter_context(sub)
    except container_errors():
        reader.stack.close()
        reader.stack = None
        return False
    reader.connections = [c for sub in reader.readers for c in sub.connections]
    reader.typestore = reader.default_typestore
    return True


class Bag:
    """A bag opened for streaming. Use as a context manager.

    Args:
        path: ROS 1 .bag, ROS 2 bag directory, or .mcap/.db3 file; or several ROS 1 .bag files.
        topics: explicit role -> topic names (e.g. ``{"rgb": "/cam/image"}``); they win.
        config_topics: role -> topic from the configuration in use.
        presets: bundled presets whose topic names are tried after the configuration's.
    """

    def __init__(self, path: str | Path | Sequence[str | Path], topics: dict[str, str | None] | None = None,
                 config_topics: dict[str, str] | None = None, presets: Iterable[str] = PRESETS) -> None:
        paths = [Path(path)] if isinstance(path, (str, Path)) else [Path(q) for q in path]
        self.path = paths[0] if len(paths) == 1 else Path(" + ".join(str(q) for q in paths))
        self._paths = paths
        errors = container_errors()
        self.reader = open_any_reader(paths)
        try:
            self.reader.open()
        except errors as exc:
            # Embedded definitions rosbags cannot parse (e.g. some IDL with @verbatim comments):
            # read with the bundled typestore instead, or report the original error.
            self.reader = open_any_reader(paths)
            if not _open_with_default_types(self.reader):
                raise BagError(f"cannot open bag {self.path}: {describe(exc)}") from None

        self.ros_version = 2 if self.reader.is2 else 1
        register_event_types(self.reader.typestore, self.ros_version)
        self.topic_types = {c.topic: c.msgtype for c in self.reader.connections}
        self.selection = resolve_topics(self.topic_types, topics, config_topics, presets)
        self.event_decoders: dict[str, Any] = {}  # topic -> EventDecoder (its .stats count drops)
        self._reports: list[ReadReport] = []  # one per pass of messages(), see read_stats

    # -- context manager / info
    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if getattr(self, "reader", None) is not None and self.reader.stack:
            self.reader.close()

    @property
    def start_ns(self) -> int:
        return int(self.reader.start_time)

    @property
    def end_ns(self) -> int:
        return int(self.reader.end_time)

    @property
    def duration_s(self) -> float:
        return max(0.0, (self.end_ns - self.start_ns) * 1e-9)

    def message_count(self, role: str) -> int:
        topic = getattr(self.selection, role)
        return sum(c.msgcount for c in self.reader.connections if c.topic == topic) if topic else 0

    def require(self, *roles: str) -> None:
        """BagError naming the first missing role and the topics that are there."""
        for role in roles:
            if not getattr(self.selection, role):
                have = ", ".join(f"{t} [{m}]" for t, m in sorted(self.topic_types.items())) or "no topics"
                raise BagError(f"bag {self.path} has no {role} topic (pass --{role.replace('_', '-')}-topic); "
                               f"it has: {have}")

    @property
    def read_stats(self) -> ReadReport:
        """Per topic (and role): records the index lists, read, unreadable (skipped) and undecodable.

        Merged over the passes of :meth:`messages` (each topic as counted by the latest pass that
        read it); ``skipped`` counts are final once that pass has finished.
        """
        merged = ReadReport(str(self.path))
        for rep in self._reports:
            merged.topics.update(rep.topics)
            for e in rep.errors:
                merged.add_error(e)
            merged.n_errors += rep.n_errors - len(rep.errors)
            merged.stopped = merged.stopped or rep.stopped
        merged.finished = all(rep.finished for rep in self._reports)
        return merged

    # -- streaming
    def messages(self, roles: Iterable[str] = ROLES) -> Iterator[BagMessage]:
        """Messages of the chosen topics for ``roles``, merged in bag (receive) time order.

        Unreadable records are skipped and messages that fail to decode are dropped, both counted
        in :attr:`read_stats` (and logged once per topic), so a damaged bag still replays and says
        what it lost.
        """
        by_topic = {t: r for r, t in self.selection.items() if r in set(roles)}
        conns = [c for c in self.reader.connections if c.topic in by_topic]
        if not conns:
            return
        report = ReadReport(str(self.path))
        self._reports = [r for r in self._reports if not set(r.topics) <= set(by_topic)] + [report]
        for topic, role in by_topic.items():
            report.topic(topic).role = role
        rank = {t: (ROLES.index(r), t) for t, r in by_topic.items()}
        group: list[tuple[Any, int, Any]] = []
        for item in iter_messages(self.reader, conns, report):
            if group and item[1] != group[0][1]:
                yield from self._emit(group, by_topic, rank, report)
                group = []
            group.append(item)
        yield from self._emit(group, by_topic, rank, report)
        if not report.clean:
            _log.warning("%s", report.summary())

    def first_messages(self, roles: Iterable[str]) -> dict[str, Any]:
        """The first deserialized message of each role present (reads only until all are found)."""
        wanted = {r: t for r, t in self.selection.items() if r in set(roles)}
        conns = [c for c in self.reader.connections if c.topic in set(wanted.values())]
        found: dict[str, Any] = {}
        if not conns:
            return found
        report = ReadReport(str(self.path))
        for conn, t_ns, raw in iter_messages(self.reader, conns, report):
            for role, topic in wanted.items():  # one topic may serve two roles (MVSEC camera_info)
                if topic == conn.topic and role not in found:
                    msg = self._deserialize(conn, t_ns, raw, report)
                    if msg is not None:
                        found[role] = msg
            if len(found) == len(wanted):
                break
        return found

    def _deserialize(self, conn: Any, t_ns: int, raw: Any, report: ReadReport) -> Any:
        """The message, or None (counted, logged once per topic) when its bytes do not deserialize."""
        try:
            return self.reader.deserialize(raw, conn.msgtype)
        except container_errors() as exc:
            counts = report.topic(conn.topic)
            counts.undecodable += 1
            if counts.undecodable == 1:
                _log.warning("%s: dropped a %s message on %s at %.3f s that does not deserialize (%s); "
                             "further ones are counted in Bag.read_stats", self.path, conn.msgtype, conn.topic,
                             t_ns * 1e-9, describe(exc))
            return None

    def _emit(self, group: list[tuple[Any, int, Any]], by_topic: dict[str, str],
              rank: dict[str, tuple[int, str]], report: ReadReport) -> Iterator[BagMessage]:
        """Messages sharing one timestamp, in role order: the stream does not depend on the container."""
        if len(group) > 1:
            group.sort(key=lambda item: rank[item[0].topic])  # stable: per-topic order is kept
        for conn, t_ns, raw in group:
            role = by_topic[conn.topic]
            if role == "events":
                if conn.topic not in self.event_decoders:
                    self.event_decoders[conn.topic] = _event_decoder(conn.msgtype, self.ros_version)
                dec = self.event_decoders[conn.topic]
                dropped = dec.stats.dropped_messages
                events = dec.decode_raw(raw)
                if dec.stats.dropped_messages != dropped:
                    report.topic(conn.topic).undecodable += 1
                    continue
                yield BagMessage(role, conn.topic, conn.msgtype, int(t_ns), events=events,
                                 stamp_ns=_raw_stamp_ns(raw, self.ros_version))
            else:
                msg = self._deserialize(conn, t_ns, raw, report)
                if msg is not None:
                    yield BagMessage(role, conn.topic, conn.msgtype, int(t_ns), msg=msg)


# ---------------------------------------------------------------------------- poses and TF


def _stamp_ns(msg: Any) -> int | None:
    st = getattr(getattr(msg, "header", None), "stamp", None)
    if st is None:
        return None
    sec = getattr(st, "sec", getattr(st, "secs", 0))
    nsec = getattr(st, "nanosec", getattr(st, "nsecs", 0))
    return int(sec) * 1_000_000_000 + int(nsec)


def pose_from_msg(msg: Any, topic: str = "") -> np.ndarray:
    """4x4 pose from a PoseStamped / PoseWithCovarianceStamped / Odometry / TransformStamped.

    Raises :class:`TransformError` naming the topic, frames and stamp when the translation or the
    quaternion is not finite or the quaternion has zero norm (a non-unit quaternion is normalised).
    """

    if hasattr(msg, "transform"):
        tr, q = msg.transform.translation, msg.transform.rotation
    else:
        pose = msg.pose
        pose = getattr(pose, "pose", pose)  # *WithCovariance / Odometry
        tr, q = pose.position, pose.orientation
    t = np.array([tr.x, tr.y, tr.z], dtype=np.float64)
    quat = np.array([q.x, q.y, q.z, q.w], dtype=np.float64)
    problem = None
    if not np.all(np.isfinite(t)):
        problem = f"translation is not finite {t.tolist()}"
    elif not np.all(np.isfinite(quat)):
        problem = f"rotation quaternion (x, y, z, w) is not finite {quat.tolist()}"
    elif float(np.linalg.norm(quat)) < 1e-9:
        problem = f"rotation quaternion (x, y, z, w) has zero norm {quat.tolist()}"
    if problem is not None:
        parent = str(getattr(getattr(msg, "header", None), "frame_id", "") or "")
        child = str(getattr(msg, "child_frame_id", "") or "")
        stamp = _stamp_ns(msg)
        frames = f"{parent or '?'} -> {child}" if child else f"frame {parent or '?'}"
        when = f" at {stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d} s" if stamp is not None else ""
        raise TransformError(f"{topic or 'pose message'} ({frames}{when}): {problem}", topic, parent, child, stamp)
    return pose_from_tq(t, quat)


class StaticTf:
    """Static transforms from /tf_static, composed along the frame tree on request."""

    def __init__(self) -> None:
        self.edges: dict[str, dict[str, np.ndarray]] = {}

    def add(self, msg: Any, topic: str = "/tf_static") -> None:
        """Add every transform of a TFMessage; unusable ones raise :class:`TransformError` (the
        first, with the count) after the good ones have been added."""
        bad: list[TransformError] = []
        for tf in msg.transforms:
            parent, child = tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/")
            try:
                T = pose_from_msg(tf, topic)
            except TransformError as exc:
                bad.append(exc)
                continue
            self.edges.setdefault(parent, {})[child] = T
            self.edges.setdefault(child, {})[parent] = se3_inv(T)
        if bad:
            first = bad[0]
            more = f" (and {len(bad) - 1} more bad transforms in this message)" if len(bad) > 1 else ""
            raise TransformError(f"{first}{more}", first.topic, first.parent, first.child, first.stamp_ns)

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """``T_target_source`` by breadth-first search over the tree (None when not connected)."""
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return np.eye(4)
        frontier = [(target, np.eye(4))]
        seen = {target}
        while frontier:
            nxt = []
            for frame, T in frontier:
                for child, T_fc in self.edges.get(frame, {}).items():
                    if child in seen:
                        continue
                    T_tc = T @ T_fc
                    if child == source:
                        return T_tc
                    seen.add(child)
                    nxt.append((child, T_tc))
            frontier = nxt
        return None


__all__ = ["IMU_TYPES", "PRESETS", "ROLES", "Bag", "BagMessage", "StaticTf", "TopicSelection", "open_any_reader",
           "pose_from_msg", "preset_topics", "resolve_topics"]
