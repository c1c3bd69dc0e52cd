"""``atsvo-replay BAG --out DIR``: run the odometry pipeline over a recorded bag, offline, without ROS.

BAG is a ROS 1 .bag (several are read as one, e.g. MVSEC's data and gt bags), a ROS 2 bag
directory (sqlite3 / mcap), a bare .mcap / .db3 file, an MVSEC ``*_data.hdf5`` file (its
``*_gt.hdf5`` sibling is read for depth and pose) or a TUM RGB-D folder (rgb.txt, depth.txt,
groundtruth.txt; :mod:`atsvo_ros.io.tum_rgbd`).

Exactly the core the ROS node runs, through the same :class:`~atsvo_ros.runtime.runtime.OdometryRuntime`;
deterministic, streaming (memory does not grow with the bag). Undecodable images, duplicated or
out-of-order frames are skipped and counted (timing.json ``counters``, and a note each).
Writes DIR/trajectory.tum (robot base pose, or the colour optical frame with ``--frame
camera``), DIR/timing.json (per-frame tracking time, mode, status), DIR/metrics.json when ground
truth is available (the bag's pose topic or ``--gt``), and PNG plots. ``--record OUT.mcap`` also
writes the run as a ROS 2 bag for Foxglove, RViz and ``ros2 bag play`` (:mod:`atsvo_ros.io.record`).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from atsvo_ros.config import AtsvoConfig, config_dir, load_config, parse_overrides
from atsvo_ros.core.frame import TrackingStatus
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.errors import BagError, ConfigError, EvaluationError, TrackingError
from atsvo_ros.eval.metrics import ALIGN_METHODS, EvalOptions, evaluate, format_metrics, metrics_json
from atsvo_ros.eval.plots import plot_run
from atsvo_ros.io.record import BagRecorder, check_record_path
from atsvo_ros.io.sources import detect_preset, open_source
from atsvo_ros.io.trajectory import Trajectory, read_tum, write_tum
from atsvo_ros.runtime.runtime import OdometryRuntime
from atsvo_ros.tools._cli import add_config_args, prepare_out_dir, run
from atsvo_ros.tools._help import description
from atsvo_ros.tools.replay_log import FrameLog, PoseLog

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
    #: the full evaluation against ground truth (aligned poses, errors), when there was ground truth
    evaluation: Any = None
    #: the bag written with ``record`` and its message count per topic
    record_path: Path | None = None
    record_counts: dict[str, int] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Sequence time over wall time (> 1 is faster than real time)."""
        span = (self.stamps_ns[-1] - self.stamps_ns[0]) * 1e-9 if len(self.stamps_ns) > 1 else 0.0
        return span / self.wall_time_s if self.wall_time_s > 0 else float("inf")


#: Tracking time per frame the benchmarks hold to (DESIGN budgets, 640x480), by mode.
TRACKING_BUDGET_MS = {"rgbd": 10.0, "fused": 15.0}
#: A median this many times above the budget means something is wrong, not a slow machine.
SLOW_FACTOR = 3.0
#: Per-frame cost that does not shrink with the image (Python around the kernels, the 320x240 event sensor):
#: 6-7 ms medians at 160x120 on a healthy install (2-core machine, Nov 2026) set it; a recompiling kernel costs
#: hundreds of ms per frame.
FIXED_BUDGET_MS = 5.0


def slow_tracking_warning(tracking_time_s: np.ndarray, width: int, height: int, mode: str) -> str | None:
    """A warning when the median tracking time is far above its benchmark, else None.

    A median several times over budget is the sign of numba compiling on every call or of a
    kernel falling back to a slow path, which once hid a tracker that never optimised. The first
    three frames (kernel loading, map initialisation) are left out; the budget scales with the
    pixel count, down to :data:`FIXED_BUDGET_MS`.
    """
    t = np.asarray(tracking_time_s, dtype=np.float64)[3:]
    if len(t) < 5:
        return None
    budget_ms = max(FIXED_BUDGET_MS, TRACKING_BUDGET_MS.get(mode, 10.0) * width * height / (640 * 480))
    median_ms = float(np.median(t)) * 1e3
    if median_ms <= SLOW_FACTOR * budget_ms:
        return None
    return (f"tracking takes {median_ms:.0f} ms per frame (median), {median_ms / budget_ms:.0f}x its "
            f"{budget_ms:.0f} ms benchmark at {width}x{height}: numba may be recompiling or a kernel is "
            f"falling back; run atsvo-info to check the kernel cache and library versions")


def replay(bag_path: str | Path | Sequence[str | Path], out_dir: str | Path, config: AtsvoConfig | None = None, *,
           mode: str | None = None, gt_path: str | Path | None = None, frame: str | None = None,
           topics: dict[str, str | None] | None = None, plots: bool = True, progress: bool | None = None,
           odometry_factory: Callable[..., Any] | None = None, eval_options: Any = None,
           record: str | Path | None = None, force: bool = False,
           overrides: dict[str, Any] | None = None) -> ReplayResult:
    """Replay a recording (bag, MVSEC HDF5 file, TUM folder) through the odometry runtime and write the outputs.

    ``config=None`` picks the preset from the recording (topics, or a TUM folder's name), with
    ``overrides`` (``--set``) on top of it; ``mode``
    defaults to ``config.mode``; ``frame`` to the source's default (``base``; ``camera`` for a TUM
    folder, whose ground truth is the camera pose); ``odometry_factory(config, rgb_camera,
    event_camera)`` defaults to the core's ``Odometry``. ``record`` names a ``.mcap`` file to write the
    run to as a ROS 2 bag (:class:`~atsvo_ros.io.record.BagRecorder`; an existing one only with ``force``,
    checked before the run). Raises :class:`TrackingError` (after writing the outputs) when not a single
    frame could be tracked, saying why.
    """
    if frame not in (None, "base", "camera"):
        raise ConfigError(f"--frame must be base or camera, got {frame!r}")
    paths = [Path(bag_path)] if isinstance(bag_path, (str, Path)) else [Path(p) for p in bag_path]
    if record is not None:
        check_record_path(record, force, inputs=paths)  # before the run, not after it
    created = not Path(out_dir).exists()
    out = prepare_out_dir(out_dir)  # an unusable --out fails now, not after the whole bag
    try:
        return _replay(paths, out, config, mode, gt_path, frame, topics, plots, progress, odometry_factory,
                       eval_options, record, force, overrides)
    except BaseException:
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # made for this run, nothing written: leave no empty folder behind
        raise


def _replay(paths: list[Path], out: Path, config: AtsvoConfig | None, mode: str | None, gt_path: str | Path | None,
            frame: str | None, topics: dict[str, str | None] | None, plots: bool, progress: bool | None,
            odometry_factory: Callable[..., Any] | None, eval_options: Any, record: str | Path | None,
            force: bool, overrides: dict[str, Any] | None) -> ReplayResult:
    """:func:`replay` once its arguments and output folder are checked."""
    notes: list[str] = []
    gt_file = read_tum(gt_path, order="nondecreasing") if gt_path else None
    name = " + ".join(p.name for p in paths)
    source = open_source(paths, topics, config)
    log_lines: deque[str] = deque(maxlen=200)  # the last log lines go to timing.json; a long run keeps no more
    recorder = None
    try:
        frame = frame or source.default_frame
        if config is None:
            if source.preset:
                config = load_config(source.preset, overrides=overrides)
                notes.append(source.preset_note)
            else:
                preset = detect_preset(source.topic_types)
                config = load_config(preset, overrides=overrides)
                notes.append(f"config preset {preset} (from the bag's topics)")
            if overrides:
                notes[-1] += f", with {len(overrides)} --set override{'s' if len(overrides) > 1 else ''}"
        elif overrides:
            raise ConfigError("overrides go with config=None (applied to the recording's preset) or into the config")
        mode = mode or config.mode
        if mode not in ("fused", "rgbd"):
            raise ConfigError(f"--mode must be fused or rgbd, got {mode!r}")
        source.require()
        config, rgb_cam, ev_cam = source.setup(config, notes)
        bar = tqdm(total=source.n_frames(), unit="frame", desc="replay",
                   disable=None if progress is None else not progress, leave=False)

        def log(level: str, text: str) -> None:
            log_lines.append(f"{level}: {text}")

        if record is not None:
            recorder = BagRecorder(record, config, force=force).open()
        runtime = OdometryRuntime(config, rgb_cam, ev_cam, use_events=mode == "fused" and source.has("events"),
                                  logger=log, core_factory=odometry_factory, sinks=(recorder,) if recorder else (),
                                  expect_imu=source.has("imu"))
        use_events = runtime.use_events
        if mode == "fused" and not use_events:
            notes.append("RGB-D only: the recording has no event topic")
        outputs = FrameLog("base" if frame == "base" else "camera")
        gt_samples = PoseLog() if gt_file is None and source.has("ground_truth") else None
        t_wall0 = time.perf_counter()

        def collect(batch: list) -> None:
            for o in batch:
                outputs.append(o)
                wall = time.perf_counter() - t_wall0
                span = (o.result.stamp_ns - outputs.first_stamp_ns) * 1e-9
                bar.update(1)
                bar.set_postfix(rtf=f"{span / wall:.2f}" if wall > 0 else "-", status=o.result.status.value,
                                refresh=False)

        roles = ("rgb", "depth", "imu") + (("events",) if use_events else ())
        for _ in source.feed(runtime, roles, gt_samples):
            collect(runtime.poll())
        collect(runtime.flush())
        bar.close()
        wall = time.perf_counter() - t_wall0
        bag_duration = source.duration_s()
        sync_stats = dataclasses.asdict(runtime.assembler.stats)
        dec_stats = {**source.decoder_stats(), **runtime.decoder_stats}
        read_stats, read_notes = source.read_problems()
        notes.extend(read_notes)
        notes.extend(_decoder_notes(dec_stats))
        notes.extend(_counter_notes(runtime))
        record_counts: dict[str, int] = {}
        if recorder is not None and outputs:
            gt_rec = _ground_truth(gt_file, gt_samples)
            if gt_rec is not None:  # the recorder wants the base pose
                recorder.write_ground_truth(_in_frame(gt_rec, source.default_frame, "base", config))
            record_counts = recorder.close()
    except BaseException:
        if recorder is not None:
            recorder.abort()
        raise
    finally:
        source.close()
    if not len(outputs):
        if recorder is not None:
            recorder.abort()
        problems = _counter_notes(runtime)
        if problems:  # the frames were formed but refused: say why, not "no pair"
            raise BagError(f"no frame of {name} could be used: " + "; ".join(problems))
        raise BagError(f"no colour/depth pair could be formed from {name} (sync tolerance "
                       f"{config.rig.sync_tolerance_s} s; dropped {sync_stats['dropped_rgb']} colour and "
                       f"{sync_stats['dropped_depth']} depth images)")
    used_mode = "fused" if use_events and outputs["n_events"].any() else "rgbd"
    if use_events and used_mode == "rgbd":
        notes.append("warning: RGB-D only: the bag has events, but not one reached a frame (see the warnings)")
    statuses = list(outputs.statuses)
    result = ReplayResult(out, used_mode, outputs["stamp_ns"].copy(), outputs.poses, statuses,
                          outputs["tracking_time_s"].copy(), wall, bag_duration, notes=notes,
                          record_path=Path(record) if record is not None else None, record_counts=record_counts)
    est = Trajectory(result.stamps_ns, result.T_odom_x)
    write_tum(out / "trajectory.tum", est, header=f"atsvo-replay {name} mode={used_mode} "
              f"frame={'base' if frame == 'base' else 'colour optical'} (T_odom_{frame})")
    tt = result.tracking_time_s
    slow = slow_tracking_warning(tt, rgb_cam.width, rgb_cam.height, used_mode)
    if slow:
        notes.append("warning: " + slow)
    timing = {"mode": used_mode, "frame": frame, "n_frames": len(outputs), "wall_time_s": wall,
              "bag_duration_s": bag_duration, "real_time_factor": result.real_time_factor,
              "tracking_time_mean_s": float(np.mean(tt)), "tracking_time_median_s": float(np.median(tt)),
              "tracking_time_p95_s": float(np.percentile(tt, 95)), "tracking_time_max_s": float(np.max(tt)),
              "status_counts": {s: statuses.count(s) for s in sorted(set(statuses))},
              "mode_counts": {m: outputs.modes.count(m) for m in sorted(set(outputs.modes))},
              "counters": dict(runtime.counters), "event_time_offset_s": runtime.event_time_offset_s,
              "sync": sync_stats, "event_decoders": dec_stats,
              "bag_read": read_stats, "notes": notes, "log": list(log_lines)}
    if record is not None:
        timing["recording"] = {"path": str(record), "messages": record_counts}
    outputs.write_json(out / "timing.json", timing, "frames")
    gt = _ground_truth(gt_file, gt_samples)
    if gt is not None and frame != source.default_frame:
        # ground truth comes in the recording's frame (a bag's base, a TUM folder's camera): score like with like
        gt = _in_frame(gt, source.default_frame, frame, config)
        notes.append(f"ground truth moved from the {_FRAME_NAMES[source.default_frame]} to the "
                     f"{_FRAME_NAMES[frame]} with rig.T_base_rgb, as the estimate")
    if gt_file is None and gt is not None:
        write_tum(out / "groundtruth.tum", gt, header=f"ground truth from {name} ({_FRAME_NAMES[frame]})")
    eval_result = None
    if gt is not None:
        ok = np.array([s == "ok" for s in statuses])
        opts = eval_options or EvalOptions(interpolate_gt=True)
        try:
            eval_result = evaluate(gt, est, opts, est_ok=ok)
        except EvaluationError as exc:  # the run's outputs are there: say so, they can be scored again
            raise EvaluationError(f"{exc} (the run's trajectory.tum and timing.json are in {out}: score them "
                                  "with atsvo-eval against the right ground truth)") from None
        result.metrics = eval_result.to_json()
        result.evaluation = eval_result
        notes.extend(result.metrics["extra"]["notes"])
        (out / "metrics.json").write_text(metrics_json(result.metrics))
    if plots:
        plot_run(out, est, eval_result, title=f"{name} ({used_mode})")
    if not any(TrackingStatus(st).tracked for st in set(statuses)):
        reasons = Counter(r for r in outputs.reasons if r)
        why = reasons.most_common(1)[0][0] if reasons else "no frame produced a map"
        raise TrackingError(f"not a single frame of {name} could be tracked ({len(statuses)} frames): {why}; "
                            f"outputs in {out}")
    return result


_FRAME_NAMES = {"base": "robot base", "camera": "colour optical frame"}


def _in_frame(traj: Trajectory, from_frame: str, to_frame: str, config: AtsvoConfig) -> Trajectory:
    """``traj`` (poses of ``from_frame`` in some world) as poses of ``to_frame`` (``base`` or ``camera``)."""
    if from_frame == to_frame:
        return traj
    T_base_rgb = config.rig.T_base_rgb_matrix()
    return traj.transformed(T_right=T_base_rgb if to_frame == "camera" else se3_inv(T_base_rgb))


def _ground_truth(gt_file: Any, gt_samples: PoseLog | None) -> Any:
    """The ground truth: the ``--gt`` file, else the bag's pose samples (a Trajectory), else None."""

    if gt_file is not None:
        return gt_file
    if not gt_samples:
        return None
    return gt_samples.trajectory()


def _decoder_notes(dec_stats: dict[str, Any]) -> list[str]:
    """One warning per event topic that lost events in decoding, with the totals (the log shows the first only)."""
    notes = []
    for topic, st in dec_stats.items():
        if not isinstance(st, dict):
            continue
        why = {"outside the sensor": st.get("dropped_out_of_range", 0),
               "time went backwards": st.get("dropped_backwards", 0),
               **{k.replace("_", " "): v for k, v in (st.get("dropped_by_kind") or {}).items()}}
        why = {k: int(v) for k, v in why.items() if v}
        lost = sum(why.values())
        if lost or st.get("dropped_messages"):
            size = f" (sensor {st['width']}x{st['height']})" if st.get("width") else ""
            kept = int(st.get("n_events", 0))
            notes.append(f"warning: {topic}: {lost:,} of {lost + kept:,} events dropped in decoding{size}: "
                         + ", ".join(f"{k} {v:,}" for k, v in why.items())
                         + (f"; {st['dropped_messages']:,} messages undecodable" if st.get("dropped_messages") else ""))
    return notes


def _counter_notes(runtime: Any) -> list[str]:
    """One note per kind of skipped input, with the first message of that kind."""
    labels = {"images_rejected": "unreadable images skipped", "frames_duplicate": "duplicated frames skipped",
              "frames_out_of_order": "out-of-order frames skipped", "frames_failed": "frames the core rejected",
              "clock_jumps": "clock jumps (motion model reset)", "imu_rejected": "unusable IMU messages skipped",
              "frames_waiting_camera_info": "frames before the first camera_info",
              "events_dropped": "events dropped by the event-rate cap (flood)"}
    counters = runtime.counters
    clocks = [f"warning: {runtime.first_problem[k]}" for k in ("events_on_camera_clock", "clock_events", "clock_imu",
                                                                 "event_offset_not_estimated") if counters.get(k)]
    if counters.get("event_offset_estimated"):
        clocks.append(runtime.first_problem["event_offset_estimated"])
    late = runtime.assembler.stats.late_events
    if late:
        clocks.append(f"warning: {late} events arrived after their frame had gone (logged more than "
                      f"{runtime.REPLAY_EVENT_WAIT_S:g} s after the images of their time) and were dropped")
    return clocks + [f"{counters[k]} {v} (first: {runtime.first_problem.get(k, '?')})" for k, v in labels.items()
                     if counters.get(k)]


def _main(args: argparse.Namespace) -> int:
    overrides = parse_overrides(args.set)
    config = None
    if args.config or args.preset:
        config = load_config(args.config or args.preset, overrides=overrides)
        overrides = {}  # in the config already; alone, they go on the preset the recording names

    topics = {r: getattr(args, f"{r}_topic") for r in TOPIC_FLAGS}
    res = replay(args.bag, args.out, config, mode=args.mode, gt_path=args.gt, frame=args.frame, topics=topics,
                 plots=not args.no_plots, progress=False if args.no_progress else None,
                 eval_options=EvalOptions(align=args.align, align_s=args.align_s, interpolate_gt=not args.nearest_gt),
                 record=args.record, force=args.force, overrides=overrides or None)
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
    if res.record_path is not None:
        print(f"wrote {res.record_path} ({sum(res.record_counts.values())} messages on {len(res.record_counts)} "
              f"topics; Foxglove layout: {config_dir() / 'foxglove_layout.json'})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``atsvo-replay``."""
    parser = argparse.ArgumentParser(prog="atsvo-replay", description=description(__doc__))
    parser.add_argument("bag", nargs="+", help="ROS 1 .bag (several are merged, e.g. MVSEC data + gt), ROS 2 bag "
                        "directory (sqlite3/mcap), a .mcap/.db3 file, an MVSEC *_data.hdf5 file, or a TUM RGB-D "
                        "folder")
    parser.add_argument("--out", required=True, help="output directory")
    add_config_args(parser)
    parser.add_argument("--preset", choices=("mini_cheetah", "mvsec", "synthetic", "tum_fr1", "tum_fr2", "tum_fr3"),
                        help="bundled preset (default: chosen from the bag's topics, or a TUM folder's name); "
                             "--config wins")
    parser.add_argument("--mode", choices=("fused", "rgbd"), help="fused (events + RGB-D) or rgbd (never events)")
    parser.add_argument("--gt", help="ground truth TUM file, poses of the recording's own frame (a bag's robot "
                                      "base, a TUM folder's camera) (default: the bag's pose topic, if any)")
    parser.add_argument("--frame", choices=("base", "camera"), default=None,
                        help="pose written to trajectory.tum: robot base (default) or colour optical frame "
                             "(default for a TUM folder)")
    parser.add_argument("--align", choices=ALIGN_METHODS, default="paper",
                        help="alignment for metrics.json (default: paper)")
    parser.add_argument("--align-s", type=float, default=2.0,
                        help="paper alignment: seconds of matched poses used for the SE(3) step (default 2)")
    parser.add_argument("--nearest-gt", action="store_true",
                        help="pair each frame with the nearest ground-truth pose instead of interpolating")
    for role in TOPIC_FLAGS:
        parser.add_argument(f"--{role.replace('_', '-')}-topic", dest=f"{role}_topic", metavar="TOPIC",
                            help=f"{role.replace('_', ' ')} topic (default: auto-detected)")
    parser.add_argument("--record", metavar="OUT.mcap",
                        help="also write the run as a ROS 2 bag (mcap): odometry, path, TF, map cloud, debug images, "
                             "ground truth; for Foxglove (config/foxglove_layout.json), RViz and ros2 bag play")
    parser.add_argument("--force", action="store_true", help="replace an existing --record file")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-replay``."""
    return run(_main, build_parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
