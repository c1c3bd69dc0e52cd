"""``atsvo-replay BAG --out DIR``: run the odometry pipeline over a recorded bag, offline, without ROS.

BAG is a ROS 1 .bag (several are read as one, e.g. MVSEC's data and gt bags), a ROS 2 bag
directory (sqlite3 / mcap), a bare .mcap / .db3 file, an MVSEC ``*_data.hdf5`` file (its
``*_gt.hdf5`` sibling is read for depth and pose) or a TUM RGB-D folder (rgb.txt, depth.txt,
groundtruth.txt; :mod:`atsvo_ros.io.tum_rgbd`).

Exactly the core the ROS node runs (:class:`atsvo_ros.core.odometry.Odometry` fed by the same
:class:`~atsvo_ros.io.sync.FrameAssembler`), deterministic, streaming (memory does not grow with
the bag). Writes DIR/trajectory.tum (robot base pose, or the colour optical frame with ``--frame
camera``), DIR/timing.json (per-frame tracking time, mode, status), DIR/metrics.json when ground
truth is available (the bag's pose topic or ``--gt``), and PNG plots.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.errors import BagError, ConfigError
from atsvo_ros.tools._cli import add_config_args, parse_overrides, run

TOPIC_FLAGS = ("rgb", "depth", "events", "rgb_info", "event_info", "ground_truth")


@dataclass
class ReplayResult:
    """What a replay produced (also written to the output directory)."""

    out_dir: Path
    mode: str
    stamps_ns: np.ndarray
    T_odom_x: np.ndarray
    statuses: list[str]
    tracking_time_s: np.ndarray
    wall_time_s: float
    bag_duration_s: float
    metrics: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def real_time_factor(self) -> float:
        """Sequence time over wall time (> 1 is faster than real time)."""
        span = (self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9 if len(self.stamps_ns) > 1 else 0.0
        return span / self.wall_time_s if self.wall_time_s > 0 else float("inf")


#: Tracking time per frame the benchmarks hold to (DESIGN budgets, 640x480), by mode.
TRACKING_BUDGET_MS = {"rgbd": 10.0, "fused": 15.0}
#: A median this many times above the budget means something is wrong, not a slow machine.
SLOW_FACTOR = 3.0


def slow_tracking_warning(tracking_time_s: np.ndarray, width: int, height: int, mode: str) -> str | None:
    """A warning when the median tracking time is far above its benchmark, else None.

    A median several times over budget is the sign of numba compiling on every call or of a
    kernel falling back to a slow path, which once hid a tracker that never optimised. The first
    three frames (kernel loading, map initialisation) are left out; the budget scales with the
    pixel count.
    """
    t = np.asarray(tracking_time_s, dtype=np.float64)[3:]
    if len(t) < 5:
        return None
    budget_ms = max(2.0, TRACKING_BUDGET_MS.get(mode, 10.0) * width * height / (640 * 480))
    median_ms = float(np.median(t)) * 1e3
    if median_ms <= SLOW_FACTOR * budget_ms:
        return None
    return (f"tracking takes {median_ms:.0f} ms per frame (median), {median_ms / budget_ms:.0f}x its "
            f"{budget_ms:.0f} ms benchmark at {width}x{height}: numba may be recompiling or a kernel is "
            f"falling back; run atsvo-info to check the kernel cache and library versions")


def detect_preset(topics: dict[str, str]) -> str:
    """``mvsec`` for MVSEC topic names, else ``mini_cheetah`` (the robot and the simulator's layout)."""
    return "mvsec" if any(t.startswith("/davis/left/") for t in topics) else "mini_cheetah"


def _with_rig(cfg: AtsvoConfig, **rig: Any) -> AtsvoConfig:
    return dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, **rig))


def _flat(T: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) for v in np.asarray(T).reshape(-1))


def _cameras(cfg: AtsvoConfig, first: dict[str, Any], notes: list[str]):
    """Colour / event camera models: camera_info when present and allowed, else the config."""
    from atsvo_ros.core.camera import CameraModel

    rgb_cam = cfg.rgb_camera.model()
    if cfg.rgb_camera.use_camera_info and "rgb_info" in first:
        rgb_cam = CameraModel.from_camera_info(first["rgb_info"])
        notes.append("colour intrinsics from camera_info")
    ev_cam = cfg.event_camera.model()
    if cfg.event_camera.use_camera_info and "event_info" in first:
        ev_cam = CameraModel.from_camera_info(first["event_info"])
    return rgb_cam, ev_cam


def _extrinsics(cfg: AtsvoConfig, bag: Any, first: dict[str, Any], notes: list[str]) -> AtsvoConfig:
    """T_base_rgb / T_rgb_event / T_rgb_imu from /tf_static when it connects the frames, else the config."""
    from atsvo_ros.io.bags import StaticTf

    if "tf_static" not in first:
        return cfg
    tf = StaticTf()
    for m in bag.messages(["tf_static"]):
        tf.add(m.msg, m.topic)
    updates: dict[str, Any] = {}
    rgb_frame = first["rgb"].header.frame_id if "rgb" in first else ""
    if rgb_frame:
        T = tf.lookup(cfg.topics.base_frame, rgb_frame)
        if T is not None:
            updates["T_base_rgb"] = _flat(T)
            notes.append(f"T_base_rgb from /tf_static ({cfg.topics.base_frame} -> {rgb_frame})")
    ev_frame = first["events"].header.frame_id if "events" in first else ""
    if rgb_frame and ev_frame:
        T = tf.lookup(rgb_frame, ev_frame)
        if T is not None:
            updates["T_rgb_event"] = _flat(T)
            notes.append(f"T_rgb_event from /tf_static ({rgb_frame} -> {ev_frame})")
    imu_frame = first["imu"].header.frame_id if "imu" in first else ""
    if rgb_frame and imu_frame:
        T = tf.lookup(rgb_frame, imu_frame)
        if T is not None:
            updates["T_rgb_imu"] = _flat(T)
            notes.append(f"T_rgb_imu from /tf_static ({rgb_frame} -> {imu_frame})")
    return _with_rig(cfg, **updates) if updates else cfg


class _BagSource:
    """A ROS bag as a replay source: messages feed the assembler, poses go to the ground truth."""

    def __init__(self, paths: list[Path], topics: dict[str, str | None] | None, config: AtsvoConfig | None) -> None:
        from atsvo_ros.io.bags import Bag

        self.bag = Bag(paths, topics=topics, config_topics=vars(config.topics) if config else None)
        self.topic_types = self.bag.topic_types
        self.bad_poses: list[str] = []  # ground-truth messages skipped (NaN, zero quaternion)

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

    def setup(self, config: AtsvoConfig, notes: list[str]):
        first = self.bag.first_messages(["rgb", "rgb_info", "event_info", "tf_static", "events", "imu"])
        config = _extrinsics(config, self.bag, first, notes)
        return (config, *_cameras(config, first, notes))

    def feed(self, assembler: Any, use_events: bool, gt: list | None) -> Any:
        """Generator: feeds one message per step into ``assembler`` (and ground truth into ``gt``)."""
        from atsvo_ros.errors import TransformError
        from atsvo_ros.io.bags import pose_from_msg
        from atsvo_ros.io.images import stamp_ns

        roles = ["rgb", "depth"] + (["events"] if use_events else []) + (["ground_truth"] if gt is not None else [])
        for m in self.bag.messages(roles):
            if m.role == "rgb":
                assembler.add_rgb_msg(m.msg)
            elif m.role == "depth":
                assembler.add_depth_msg(m.msg)
            elif m.role == "events":
                assembler.add_events(m.events)
            else:
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


class _MvsecSource:
    """MVSEC HDF5 (``*_data.hdf5``, with ``*_gt.hdf5`` next to it used automatically)."""

    topic_types = {"/davis/left/": "mvsec"}

    def __init__(self, path: Path) -> None:
        from atsvo_ros.io.mvsec import MvsecReader

        gt = path.with_name(path.name.replace("_data", "_gt"))
        self.reader = MvsecReader(path, gt if gt != path and gt.is_file() else None)

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

    def setup(self, config: AtsvoConfig, notes: list[str]):
        notes.append("cameras and extrinsics from the configuration (MVSEC HDF5)")
        return config, config.rgb_camera.model(), config.event_camera.model()

    def feed(self, assembler: Any, use_events: bool, gt: list | None) -> Any:
        from atsvo_ros.io.images import depth_to_metres

        if gt is not None and self.reader.has("ground_truth"):
            g = self.reader.ground_truth()
            gt.extend(zip(g.stamps_ns.tolist(), g.T_w_b))
        rig = assembler.rig
        for item in self.reader.stream(("rgb", "depth", "events") if use_events else ("rgb", "depth")):
            if item.role == "rgb":
                assembler.add_rgb(item.stamp_ns, item.data)
            elif item.role == "depth":
                assembler.add_depth(item.stamp_ns, depth_to_metres(item.data, rig.depth_scale_m, rig.depth_min_m,
                                                                   rig.depth_max_m))
            else:
                assembler.add_events(item.data)
            yield

    def decoder_stats(self) -> dict[str, Any]:
        return {}

    def read_problems(self) -> tuple[dict[str, Any] | None, list[str]]:
        return None, []


def _open_source(paths: list[Path], topics: dict[str, str | None] | None, config: AtsvoConfig | None) -> Any:
    from atsvo_ros.io.tum_rgbd import TumSource as _TumSource
    from atsvo_ros.io.tum_rgbd import is_tum_folder

    if is_tum_folder(paths[0]):
        if len(paths) > 1:
            raise BagError("give one TUM RGB-D folder (the one holding rgb.txt and depth.txt)")
        return _TumSource(paths[0])
    if paths[0].suffix.lower() in (".hdf5", ".h5"):
        if len(paths) > 1:
            raise BagError("give one MVSEC *_data.hdf5 file (its *_gt.hdf5 sibling is found automatically)")
        return _MvsecSource(paths[0])
    return _BagSource(paths, topics, config)


def replay(bag_path: str | Path | Sequence[str | Path], out_dir: str | Path, config: AtsvoConfig | None = None, *,
           mode: str | None = None, gt_path: str | Path | None = None, frame: str | None = None,
           topics: dict[str, str | None] | None = None, plots: bool = True, progress: bool | None = None,
           odometry_factory: Callable[..., Any] | None = None, eval_options: Any = None) -> ReplayResult:
    """Replay one bag (or MVSEC HDF5 file) through the odometry and write the outputs.

    ``config=None`` picks the preset from the bag's topics (a TUM folder: from its name); ``mode``
    defaults to ``config.mode``; ``frame`` to ``base`` (``camera`` for a TUM folder, whose ground truth
    is the camera pose);
    ``odometry_factory(config, rgb_camera, event_camera)`` defaults to the core's ``Odometry``.
    """
    from tqdm import tqdm

    from atsvo_ros.config import load_config
    from atsvo_ros.io.sync import FrameAssembler
    from atsvo_ros.io.trajectory import Trajectory, read_tum, write_tum

    if frame not in (None, "base", "camera"):
        raise ConfigError(f"--frame must be base or camera, got {frame!r}")
    out = Path(out_dir)
    notes: list[str] = []
    gt_file = read_tum(gt_path) if gt_path else None
    paths = [Path(bag_path)] if isinstance(bag_path, (str, Path)) else [Path(p) for p in bag_path]
    name = " + ".join(p.name for p in paths)
    source = _open_source(paths, topics, config)
    try:
        frame = frame or getattr(source, "default_frame", "base")
        if config is None:
            if getattr(source, "preset", None):
                config = load_config(source.preset)
                notes.append(source.preset_note)
            else:
                preset = detect_preset(source.topic_types)
                config = load_config(preset)
                notes.append(f"config preset {preset} (from the bag's topics)")
        mode = mode or config.mode
        if mode not in ("fused", "rgbd"):
            raise ConfigError(f"--mode must be fused or rgbd, got {mode!r}")
        source.require()
        if odometry_factory is None:
            from atsvo_ros.core.odometry import Odometry

            odometry_factory = Odometry
        supports_events = bool(getattr(odometry_factory, "supports_events", False))
        use_events = mode == "fused" and source.has("events") and supports_events
        if mode == "fused" and not use_events:
            notes.append("RGB-D only: " + ("the bag has no event topic" if not source.has("events")
                                           else "the odometry core does not fuse events yet"))
        config, rgb_cam, ev_cam = source.setup(config, notes)
        odom = odometry_factory(config, rgb_cam, ev_cam if use_events else None)
        assembler = FrameAssembler(config.rig, with_events=use_events)
        stamps: list[int] = []
        poses: list[np.ndarray] = []
        statuses: list[str] = []
        frames_info: list[dict[str, Any]] = []
        gt_samples: list | None = [] if gt_file is None and source.has("ground_truth") else None
        t_wall0 = time.perf_counter()
        bar = tqdm(total=source.n_frames(), unit="frame", desc="replay",
                   disable=None if progress is None else not progress, leave=False)

        def process(pairs: list) -> None:
            for fr, events in pairs:
                if use_events and len(events):
                    odom.add_events(events)
                res = odom.process_frame(fr)
                stamps.append(int(res.stamp_ns))
                poses.append(np.asarray(res.T_odom_base if frame == "base" else res.T_odom_camera, dtype=np.float64))
                status = getattr(res.status, "value", str(res.status))
                statuses.append(status)
                frames_info.append({"stamp_ns": int(res.stamp_ns), "tracking_time_s": float(res.tracking_time_s),
                                    "mode": res.mode, "status": status, "n_points": int(res.n_points),
                                    "n_inliers": int(res.n_inliers), "keyframe": bool(res.keyframe_inserted),
                                    "n_events": int(len(events))})
                wall = time.perf_counter() - t_wall0
                span = (stamps[-1] - stamps[0]) * 1e-9
                bar.update(1)
                bar.set_postfix(rtf=f"{span / wall:.2f}" if wall > 0 else "-", status=status, refresh=False)

        for _ in source.feed(assembler, use_events, gt_samples):
            process(assembler.pop_ready())
        process(assembler.flush())
        bar.close()
        wall = time.perf_counter() - t_wall0
        bag_duration = source.duration_s()
        sync_stats = dataclasses.asdict(assembler.stats)
        dec_stats = source.decoder_stats()
        read_stats, read_notes = source.read_problems()
        notes.extend(read_notes)
    finally:
        source.close()
    if not stamps:
        raise BagError(f"no colour/depth pair could be formed from {name} (sync tolerance "
                       f"{config.rig.sync_tolerance_s} s; dropped {sync_stats['dropped_rgb']} colour and "
                       f"{sync_stats['dropped_depth']} depth images)")
    used_mode = "fused" if use_events else "rgbd"
    result = ReplayResult(out, used_mode, np.asarray(stamps, np.int64), np.stack(poses), statuses,
                          np.array([f["tracking_time_s"] for f in frames_info]), wall, bag_duration, notes=notes)
    out.mkdir(parents=True, exist_ok=True)
    est = Trajectory(result.stamps_ns, result.T_odom_x)
    write_tum(out / "trajectory.tum", est, header=f"atsvo-replay {name} mode={used_mode} "
              f"frame={'base' if frame == 'base' else 'colour optical'} (T_odom_{frame})")
    tt = result.tracking_time_s
    slow = slow_tracking_warning(tt, rgb_cam.width, rgb_cam.height, used_mode)
    if slow:
        notes.append("warning: " + slow)
    timing = {"mode": used_mode, "frame": frame, "n_frames": len(stamps), "wall_time_s": wall,
              "bag_duration_s": bag_duration, "real_time_factor": result.real_time_factor,
              "tracking_time_mean_s": float(np.mean(tt)), "tracking_time_p95_s": float(np.percentile(tt, 95)),
              "tracking_time_max_s": float(np.max(tt)),
              "status_counts": {s: statuses.count(s) for s in sorted(set(statuses))},
              "sync": sync_stats, "event_decoders": dec_stats, "bag_read": read_stats,
              "notes": notes, "frames": frames_info}
    (out / "timing.json").write_text(json.dumps(timing, indent=1) + "\n")
    gt = gt_file
    if gt is None and gt_samples:
        gt = Trajectory(np.asarray([g[0] for g in gt_samples], np.int64),
                        np.stack([g[1] for g in gt_samples])).sorted_unique()
        write_tum(out / "groundtruth.tum", gt, header=f"ground truth from {name}")
    eval_result = None
    if gt is not None:
        from atsvo_ros.eval.metrics import EvalOptions, evaluate

        ok = np.array([s in ("ok",) for s in statuses]) if statuses else None
        opts = eval_options or EvalOptions(interpolate_gt=True)
        eval_result = evaluate(gt, est, opts, est_ok=ok)
        result.metrics = eval_result.to_json()
        (out / "metrics.json").write_text(json.dumps(result.metrics, indent=2) + "\n")
    if plots:
        from atsvo_ros.eval.plots import plot_run

        plot_run(out, est, eval_result, title=f"{name} ({used_mode})")
    return result


def _main(args: argparse.Namespace) -> int:
    from atsvo_ros.config import load_config
    from atsvo_ros.eval.metrics import EvalOptions, format_metrics

    overrides = parse_overrides(args.set)
    config = None
    if args.config or args.preset or overrides:
        config = load_config(args.config or args.preset or "mini_cheetah", overrides=overrides)
    topics = {r: getattr(args, f"{r}_topic") for r in TOPIC_FLAGS}
    res = replay(args.bag, args.out, config, mode=args.mode, gt_path=args.gt, frame=args.frame, topics=topics,
                 plots=not args.no_plots, progress=False if args.no_progress else None,
                 eval_options=EvalOptions(align=args.align, align_s=args.align_s, interpolate_gt=not args.nearest_gt))
    for note in res.notes:
        if note.startswith("warning: "):
            print(f"atsvo-replay: {note}", file=sys.stderr)
        else:
            print(f"note: {note}")
    print(f"{len(res.stamps_ns)} frames, mode {res.mode}, {res.wall_time_s:.1f} s wall, "
          f"real-time factor {res.real_time_factor:.2f}, mean tracking {np.mean(res.tracking_time_s) * 1e3:.1f} ms")
    if res.metrics:
        print(format_metrics(res.metrics))
    print(f"wrote {Path(args.out) / 'trajectory.tum'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``atsvo-replay``."""
    parser = argparse.ArgumentParser(prog="atsvo-replay", description=__doc__.splitlines()[0])
    parser.add_argument("bag", nargs="+", help="ROS 1 .bag (several are merged, e.g. MVSEC data + gt), ROS 2 bag "
                        "directory (sqlite3/mcap), a .mcap/.db3 file, an MVSEC *_data.hdf5 file, or a TUM RGB-D "
                        "folder")
    parser.add_argument("--out", required=True, help="output directory")
    add_config_args(parser)
    parser.add_argument("--preset", choices=("mini_cheetah", "mvsec", "synthetic", "tum_fr1", "tum_fr2", "tum_fr3"),
                        help="bundled preset (default: chosen from the bag's topics, or a TUM folder's name); "
                             "--config wins")
    parser.add_argument("--mode", choices=("fused", "rgbd"), help="fused (events + RGB-D) or rgbd (never events)")
    parser.add_argument("--gt", help="ground truth TUM file (default: the bag's pose topic, if any)")
    parser.add_argument("--frame", choices=("base", "camera"), default=None,
                        help="pose written to trajectory.tum: robot base (default) or colour optical frame "
                             "(default for a TUM folder)")
    parser.add_argument("--align", choices=("paper", "se3", "sim3", "none"), default="paper",
                        help="alignment for metrics.json (default: paper)")
    parser.add_argument("--align-s", type=float, default=2.0,
                        help="paper alignment: seconds of matched poses used for the SE(3) step (default 2)")
    parser.add_argument("--nearest-gt", action="store_true",
                        help="pair each frame with the nearest ground-truth pose instead of interpolating")
    for role in TOPIC_FLAGS:
        parser.add_argument(f"--{role.replace('_', '-')}-topic", dest=f"{role}_topic", metavar="TOPIC",
                            help=f"{role.replace('_', ' ')} topic (default: auto-detected)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-replay``."""
    return run(_main, build_parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
