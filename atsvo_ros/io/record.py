"""A run as a ROS 2 bag (mcap) that RViz (through ``ros2 bag play``), Foxglove and rosbags open.

:class:`BagRecorder` is an output sink of :class:`~atsvo_ros.runtime.runtime.OdometryRuntime` (``atsvo-replay
--record OUT.mcap``): after every frame it writes what the ROS nodes publish for it, built by the
same code (:mod:`atsvo_ros.io.ros_out`, :mod:`atsvo_ros.core.events.debug_images`) with rosbags' message
classes, stamped with the frame stamp (log time = header stamp):

=====================================  ===========================  =====================================
topic (names from ``config.topics``)   type                         when
=====================================  ===========================  =====================================
``topics.odometry``                    nav_msgs/Odometry            every processed frame (pose covariance)
``/tf``                                tf2_msgs/TFMessage           every frame: odom -> base_link
``/tf_static``                         tf2_msgs/TFMessage           once (fused runs): base_link -> the
                                                                    debug images' frame
``/atsvo/path``                        nav_msgs/Path                every :attr:`BagRecorder.path_period_s`
                                                                    of bag time and at the last frame
``topics.map``                         sensor_msgs/PointCloud2      whenever the map changes (latched)
``topics.debug_ats``                   sensor_msgs/Image mono8      every frame (fused runs)
``topics.debug_selection``             sensor_msgs/Image rgb8       every frame (fused runs)
``/atsvo/ground_truth/odometry``       nav_msgs/Odometry            every ground-truth pose within the run
``/atsvo/ground_truth/path``           nav_msgs/Path                with each estimate path
=====================================  ===========================  =====================================

Ground truth is put into the odom frame at the first frame it covers (its pose there is made the
estimate's), so both start together and the gap between the paths is the drift. The bag is written to a hidden
folder next to the output and moved into place when complete: a failed run leaves no partial file.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.events.debug_images import render_debug_images
from atsvo_ros.core.events.frontend import EventFrontEnd
from atsvo_ros.core.geometry import interpolate_trajectory, se3_inv
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.errors import RecordError
from atsvo_ros.io.msgtypes import transient_local_qos, typestore
from atsvo_ros.io.paths import ensure_writable_folder
from atsvo_ros.io.ros_out import (
    DEBUG_IMAGE_FRAME,
    MAP_CLOUD_FIELDS,
    MAP_CLOUD_POINT_STEP,
    MsgClasses,
    map_cloud_from_snapshot,
    odometry_msg,
    transform_msg,
)
from atsvo_ros.io.trajectory import Trajectory

PATH_TOPIC = "/atsvo/path"
GT_ODOMETRY_TOPIC = "/atsvo/ground_truth/odometry"
GT_PATH_TOPIC = "/atsvo/ground_truth/path"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"

ODOMETRY, PATH, TF = "nav_msgs/msg/Odometry", "nav_msgs/msg/Path", "tf2_msgs/msg/TFMessage"
IMAGE, CLOUD = "sensor_msgs/msg/Image", "sensor_msgs/msg/PointCloud2"


def check_record_path(path: str | Path, force: bool = False, inputs: Sequence[str | Path] = ()) -> Path:
    """The output path of a recording, checked before a run: a ``.mcap`` name, not there yet (unless ``force``).

    Raises :class:`RecordError` (with what to do) for another suffix, a directory, an existing file
    without ``force``, a path that is one of ``inputs`` or inside an input folder (``--force`` would
    destroy the recording being replayed), or a rosbags without an mcap writer.
    """
    out = Path(path)
    target = out.resolve()
    for src in inputs:
        src = Path(src).resolve()
        if target == src or (src.is_dir() and src in target.parents):
            raise RecordError(f"--record {out} would overwrite the input {src}; name another file")
    if out.suffix != ".mcap":
        raise RecordError(f"--record {out}: the file name must end in .mcap (a bare mcap file is written)")
    if out.is_dir():
        raise RecordError(f"--record {out} is a directory; name a .mcap file")
    if out.exists() and not force:
        raise RecordError(f"--record {out} exists (use --force to replace it)")
    ensure_writable_folder(out.parent, out, "--record", RecordError)  # the folder it goes into, checked now
    mcap_storage()
    return out


def mcap_storage() -> tuple[Any, Any]:
    """rosbags' ``(Writer, StoragePlugin.MCAP)``; :class:`RecordError` when this rosbags cannot write mcap."""


    plugin = getattr(StoragePlugin, "MCAP", None)
    if plugin is None or plugin not in getattr(Writer, "STORAGE_PLUGINS", {}):
        try:
            have = version("rosbags")
        except PackageNotFoundError:
            have = "unknown"
        raise RecordError(f"the installed rosbags ({have}) has no mcap storage writer; "
                          "pip install -U 'rosbags>=0.11' to use --record")
    return Writer, plugin


class BagRecorder:
    """Writes a run to an mcap bag (see the module docstring); call it as ``recorder(output, core)`` per frame.

    Use as a context manager, or :meth:`open` then :meth:`close` (:meth:`abort` on failure).
    """

    def __init__(self, path: str | Path, config: AtsvoConfig, *, force: bool = False,
                 path_period_s: float = 1.0) -> None:
        self.path = check_record_path(path, force)
        self.config = config
        self.force = force
        self.path_period_s = float(path_period_s)
        self.store = typestore(2)
        self.T = self.store.types
        self.classes = MsgClasses.from_typestore(self.store)
        self._writer: Any = None
        self._staging: Path | None = None
        self._conns: dict[str, Any] = {}
        #: messages written per topic
        self.counts: dict[str, int] = {}
        self._poses: list[Any] = []  # PoseStamped of every frame, for the path
        self._path_stamps: list[int] = []
        self._est: list[tuple[int, np.ndarray]] = []  # (stamp, T_odom_base) of every frame
        self._last_stamp: int | None = None
        self._snapshot_id: int | None = None

    # ------------------------------------------------------------------ life cycle
    def open(self) -> BagRecorder:
        """Start writing (into a hidden folder next to the output)."""
        writer_cls, plugin = mcap_storage()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._staging = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.atsvo-record-partial-", dir=self.path.parent))
        self._writer = writer_cls(self._staging / self.path.stem, version=9, storage_plugin=plugin)

        storage = getattr(CompressionMode, "STORAGE", None)
        if storage is not None:  # zstd chunks: the debug images are mostly black
            self._writer.set_compression(storage, CompressionFormat.ZSTD)
        self._writer.open()
        return self

    def close(self) -> dict[str, int]:
        """Finish the bag (the last path), move it into place; the message count per topic."""
        if self._writer is None:
            raise RecordError(f"recording {self.path} was not opened")
        self._finish_path()
        writer, self._writer = self._writer, None
        writer.close()
        inner = self._staging / self.path.stem / f"{self.path.stem}.mcap"
        if self.path.exists() and not self.force:  # appeared during the run
            self._remove_staging()
            raise RecordError(f"--record {self.path} appeared during the run; not replaced (use --force)")
        os.replace(inner, self.path)
        self._remove_staging()
        return dict(self.counts)

    def abort(self) -> None:
        """Drop the partial bag (after an error)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.abort()
        self._remove_staging()

    def __enter__(self) -> BagRecorder:
        return self.open()

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def _remove_staging(self) -> None:
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None

    # ------------------------------------------------------------------ writing
    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg: Any, latched: bool = False) -> None:
        conn = self._conns.get(topic)
        if conn is None:
            qos = [transient_local_qos()] if latched else []
            conn = self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=self.store,
                                                                    offered_qos_profiles=qos)
            self.counts[topic] = 0
        self._writer.write(conn, int(stamp_ns), self.store.serialize_cdr(msg, msgtype))
        self.counts[topic] += 1

    def __call__(self, output: Any, core: Any) -> None:
        """The runtime sink: everything the nodes publish for this frame (``output``: a RuntimeOutput)."""
        if self._writer is None:
            raise RecordError(f"recording {self.path} was not opened")
        r, topics = output.result, self.config.topics
        stamp = int(r.stamp_ns)
        T_odom_base = np.asarray(r.T_odom_base, np.float64)
        odom = odometry_msg(self.classes, stamp, T_odom_base, r.covariance, output.twist, topics.odom_frame,
                            topics.base_frame)
        self._write(topics.odometry, ODOMETRY, stamp, odom)
        tf = transform_msg(self.classes, stamp, T_odom_base, topics.odom_frame, topics.base_frame)
        self._write(TF_TOPIC, TF, stamp, self.T[TF](transforms=[tf]))
        self._poses.append(self.T["geometry_msgs/msg/PoseStamped"](header=odom.header, pose=odom.pose.pose))
        self._est.append((stamp, T_odom_base))
        self._last_stamp = stamp
        if not self._path_stamps or stamp - self._path_stamps[-1] >= self.path_period_s * 1e9:
            self._write_path(stamp)
        events = getattr(core, "events", None)
        if isinstance(events, EventFrontEnd):
            self._write_debug_images(events, stamp)
        snapshot = getattr(core, "map", None)
        if isinstance(snapshot, MapSnapshot) and snapshot.snapshot_id != self._snapshot_id:
            self._snapshot_id = snapshot.snapshot_id
            self._write_map(snapshot, stamp)

    def _header(self, stamp_ns: int, frame_id: str) -> Any:
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self.T["std_msgs/msg/Header"](stamp=self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                             frame_id=frame_id)

    def _finish_path(self) -> None:
        """The path up to the last frame, unless it was just written."""
        if self._last_stamp is not None and (not self._path_stamps or self._path_stamps[-1] != self._last_stamp):
            self._write_path(self._last_stamp)

    def _write_path(self, stamp_ns: int) -> None:
        self._path_stamps.append(int(stamp_ns))
        msg = self.T[PATH](header=self._header(stamp_ns, self.config.topics.odom_frame), poses=list(self._poses))
        self._write(PATH_TOPIC, PATH, stamp_ns, msg)

    def _write_debug_images(self, events: EventFrontEnd, stamp_ns: int) -> None:
        topics = self.config.topics
        if TF_STATIC_TOPIC not in self._conns:  # where the debug images are seen from, for the 3D views
            rig = self.config.rig
            T_base_event = rig.T_base_rgb_matrix() @ rig.T_rgb_event_matrix()
            link = transform_msg(self.classes, stamp_ns, T_base_event, topics.base_frame, DEBUG_IMAGE_FRAME)
            self._write(TF_STATIC_TOPIC, TF, stamp_ns, self.T[TF](transforms=[link]), latched=True)
        images = render_debug_images(events, stamp_ns, selection=True)
        for topic, img, encoding in ((topics.debug_ats, images.ats, "mono8"),
                                     (topics.debug_selection, images.selection, "rgb8")):
            h, w = img.shape[:2]
            msg = self.T[IMAGE](header=self._header(stamp_ns, DEBUG_IMAGE_FRAME), height=h, width=w,
                                encoding=encoding, is_bigendian=0, step=img[0].size,
                                data=np.ascontiguousarray(img).reshape(-1))
            self._write(topic, IMAGE, stamp_ns, msg)

    def _write_map(self, snapshot: MapSnapshot, stamp_ns: int) -> None:
        # odom is the base at the first frame and the map's world its colour camera: T_odom_world = T_base_rgb
        data = map_cloud_from_snapshot(snapshot, self.config.rig.T_base_rgb_matrix())
        field = self.T["sensor_msgs/msg/PointField"]
        msg = self.T[CLOUD](header=self._header(stamp_ns, self.config.topics.odom_frame), height=1, width=len(data),
                            fields=[field(name=n, offset=o, datatype=d, count=c) for n, o, d, c in MAP_CLOUD_FIELDS],
                            is_bigendian=False, point_step=MAP_CLOUD_POINT_STEP,
                            row_step=MAP_CLOUD_POINT_STEP * len(data), data=data.view(np.uint8).reshape(-1),
                            is_dense=True)
        self._write(self.config.topics.map, CLOUD, stamp_ns, msg, latched=True)

    def write_ground_truth(self, gt: Trajectory) -> None:
        """Ground truth of the robot base (in its own world frame) beside the estimate, in the odom frame.

        Call after the last frame. Its pose at the first frame it covers (interpolated) is made the
        estimate's pose there; the poses within the run's time span are written, and one path with each
        estimate path. Nothing is written when ground truth and the run do not overlap.
        """
        gt = gt.sorted_unique()
        covered = [(t, T) for t, T in self._est if len(gt) and gt.stamps_ns[0] <= t <= gt.stamps_ns[-1]]
        if not covered:
            return
        self._finish_path()
        t0, T_odom_base0 = covered[0]
        G0 = interpolate_trajectory(gt.stamps_ns, gt.T_w_b, np.array([t0], np.int64))[0][0]
        T_odom_gtworld = T_odom_base0 @ se3_inv(G0)
        inside = (gt.stamps_ns >= self._est[0][0]) & (gt.stamps_ns <= self._last_stamp)
        stamps, poses = gt.stamps_ns[inside], T_odom_gtworld @ gt.T_w_b[inside]
        topics = self.config.topics
        child = f"{topics.base_frame}_ground_truth"
        pose_stamped = []
        for stamp, T in zip(stamps.tolist(), poses):
            odom = odometry_msg(self.classes, stamp, T, np.zeros((6, 6)), None, topics.odom_frame, child)
            self._write(GT_ODOMETRY_TOPIC, ODOMETRY, stamp, odom)
            pose_stamped.append(self.T["geometry_msgs/msg/PoseStamped"](header=odom.header, pose=odom.pose.pose))
        for s in self._path_stamps:
            n = int(np.searchsorted(stamps, s, side="right"))
            msg = self.T[PATH](header=self._header(s, topics.odom_frame), poses=pose_stamped[:n])
            self._write(GT_PATH_TOPIC, PATH, s, msg)


__all__ = ["BagRecorder", "GT_ODOMETRY_TOPIC", "GT_PATH_TOPIC", "PATH_TOPIC", "TF_STATIC_TOPIC", "TF_TOPIC",
           "check_record_path", "mcap_storage"]
