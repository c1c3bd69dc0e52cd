"""``atsvo-bench tracking``: tracking time and accuracy on synthetic legged-robot sequences.

Simulates each sequence (colour + depth, with ``--imu`` the IMU, with ``--events`` the event camera),
drives :class:`~atsvo_ros.runtime.runtime.OdometryRuntime` with it exactly as the replay does (mode fused when events
are given, unless ``--set mode=rgbd``), and reports per sequence: tracking time per frame (wall clock,
median / 90th percentile, preprocessing + alignment,
frames without keyframe insertion), ATE RMSE and RPE per frame against the simulator's ground truth
(paper protocol of :mod:`atsvo_ros.eval.metrics`), the status counts and whether the status left
``ok`` before the error grew past ``--loss-limit-cm`` (the "never silently wrong" check). Simulated
frames are cached in ``$ATSVO_CACHE`` (compressed npz), so reruns with other parameters are quick.
``--orbslam3`` runs ORB-SLAM3 RGB-D (no IMU) on the same frames as a peer (:func:`orbslam3_sequence`).
Also runnable as ``python -m atsvo_ros.bench.tracking``.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import sys
import time
import zipfile
from collections import Counter
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from tqdm import tqdm

from atsvo_ros.bench.peer_vocabulary import vocabulary_file
from atsvo_ros.config import load_config, parse_overrides
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.metrics import ASSOCIATION_TEXT, EvalOptions, describe_alignment, errors_by_label, evaluate
from atsvo_ros.eval.orbslam3 import run_orbslam3
from atsvo_ros.io.trajectory import Trajectory
from atsvo_ros.runtime.runtime import OdometryRuntime
from atsvo_ros.sim.motion import PHASES
from atsvo_ros.sim.rgbd import DepthModel
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation, model_key, spec_key, with_sensors
from atsvo_ros.sim.stereo import StereoModel
from atsvo_ros.tools._cli import add_config_args, run
from atsvo_ros.tools.demo import cache_dir

#: Bump when the cache's layout changes (the simulator's own changes are in :func:`model_key`).
#: 4: the IMU is simulated on every load, not cached (its model no longer invalidates the frames).
FRAME_CACHE_VERSION = 4


def _cache_file(spec: SequenceSpec) -> Path:
    """Where a spec's frames are cached: keyed on the simulator's camera models and the whole spec but the IMU's."""
    key = f"{FRAME_CACHE_VERSION}|{model_key(imu=False)}|{spec_key(spec, imu=False)}"
    return cache_dir() / "frames" / f"{spec.scenario}_{spec.seed}_{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"


def _events_cache_file(spec: SequenceSpec) -> Path:
    """The event stream's cache: the depth sensor does not change the events, so sequences that differ only in
    it share one."""
    same = dataclasses.replace(spec, depth=None, stereo_model=StereoModel(), depth_model=DepthModel())
    return _cache_file(same).with_name(f"{_cache_file(same).stem}_events.npz")


def _save_npz(path: Path, **arrays: np.ndarray) -> None:
    """``np.savez_compressed`` at zlib level 1: a 2.5 s bound's 28 M events in 1.9 s (63 MB), not 9.5 s (54 MB)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, array in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(array), allow_pickle=False)


def simulated_frames(spec: Any, progress: bool = True) -> tuple[list[tuple[int, np.ndarray, np.ndarray]], Any, Any]:
    """``[(stamp_ns, rgb, depth_m)]``, the IMU batch (or None) and the simulation; the frames are cached on disk,
    the IMU (milliseconds to simulate) is not, so a change of its model keeps the frames."""
    sim = make_simulation(spec)
    imu = ImuBatch.concatenate(list(sim.imu_sensor().batches())) if sim.has_imu else None
    path = _cache_file(spec)
    if path.is_file():
        with np.load(path) as z:
            frames = list(zip(z["stamps"].tolist(), z["rgb"], z["depth"]))
        return frames, imu, sim
    n = int(spec.duration_s * spec.rate_hz) + 1
    frames = [(f.stamp_ns, f.rgb, f.depth_m) for f in tqdm(sim.frames(), total=n, desc=f"simulate {spec.scenario}",
                                                           disable=not progress, file=sys.stderr, leave=False)]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")  # parallel runs may fill the same entry
    _save_npz(tmp, stamps=np.array([f[0] for f in frames], np.int64), rgb=np.stack([f[1] for f in frames]),
              depth=np.stack([f[2] for f in frames]))
    tmp.replace(path)
    return frames, imu, sim


def simulated_events(spec: Any, progress: bool = True) -> Any:
    """The whole event stream of a sequence as one EventBatch, cached on disk like the frames."""
    path = _events_cache_file(spec)
    if path.is_file():
        with np.load(path) as z:
            return EventBatch(z["x"], z["y"], z["t"], z["p"], int(z["w"]), int(z["h"]))
    sim = make_simulation(spec)
    batches = list(tqdm(sim.events(), desc=f"simulate events {spec.scenario}", disable=not progress,
                        file=sys.stderr, leave=False, unit="packet"))
    ev = EventBatch.concatenate(batches)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")  # parallel runs may fill the same entry
    _save_npz(tmp, x=ev.x, y=ev.y, t=ev.t, p=ev.p, w=np.int64(ev.width), h=np.int64(ev.height))
    tmp.replace(path)
    return ev


def flicker_events(events: Any, t0_ns: int, t1_ns: int, rate_ev_s: float, rng: np.random.Generator,
                   flicker_hz: float = 100.0) -> Any:
    """``events`` (those of ``[t0_ns, t1_ns)``) plus a flickering lamp firing ``rate_ev_s`` events per second.

    The lamp covers a quarter of the sensor (a centred rectangle) and fires ON events in the rising
    half of each flicker period and OFF events in the falling half, at random pixels and times
    (mains-powered lights flicker at 100 Hz: what floods a real event camera indoors). Generated per
    slice, so a 10x flood of a long sequence never sits in memory at once.
    """

    n = int(rng.poisson(rate_ev_s * max(0, t1_ns - t0_ns) * 1e-9))
    if n == 0:
        return events
    w, h = events.width, events.height
    t = np.sort(rng.integers(t0_ns, t1_ns, n)).astype(np.int64)
    period_ns = int(1e9 / flicker_hz)
    lamp = EventBatch(rng.integers(w // 4, 3 * w // 4, n), rng.integers(h // 4, 3 * h // 4, n), t,
                      ((t % period_ns) < period_ns // 2).astype(np.uint8), w, h)
    both = EventBatch.concatenate([events, lamp])
    return both.select(np.argsort(both.t, kind="stable"))


def _interleaved(frames: list, imu: Any, events: Any = None, flood_ev_s: float = 0.0,
                 seed: int = 0) -> Iterator[tuple[str, Any]]:
    """Frames, IMU samples and events in time order, as a live robot delivers them (all data up to each frame first).

    ``flood_ev_s`` > 0 adds a flickering lamp's events (:func:`flicker_events`) at that rate.
    """
    rng = np.random.default_rng(seed)
    t_prev = None if events is None or not len(events) else events.t_first_ns
    k = 0
    n_imu = 0 if imu is None else len(imu)
    e0 = 0
    for stamp, rgb, depth in frames:
        j = k
        while j < n_imu and imu.stamps_ns[j] <= stamp:
            j += 1
        if j > k:
            yield "imu", imu.select(slice(k, j))
            k = j
        if events is not None:
            e1 = int(np.searchsorted(events.t, stamp, side="right"))
            batch = events.select(slice(e0, e1))
            if flood_ev_s > 0 and t_prev is not None and stamp > t_prev:
                batch = flicker_events(batch, t_prev, stamp + 1, flood_ev_s, rng)
                t_prev = stamp + 1
            yield "events", (batch, stamp)
            e0 = e1
        yield "frame", (stamp, rgb, depth)


class WholeRun(NamedTuple):
    """Figures over the whole run beside the paper's ATE (each None where its fit is undefined).

    Attributes:
        ate_se3_m: evo's SE(3) ATE over all poses.
        path_scale: the estimated path's length against the truth's (Sim(3) over all poses: 0.99 = 1 % short).
        ate_origin_m: the ATE with the first pose put onto the truth's: the drift a controller sees.
    """

    ate_se3_m: float | None
    path_scale: float | None
    ate_origin_m: float | None


def whole_run_figures(gt: Trajectory, est: Trajectory, ok: np.ndarray) -> WholeRun:
    """evo's SE(3) ATE over all poses, the path's Sim(3) scale and the ATE anchored at the first pose.

    Beside the paper's figure, which fits the first 20 % of the poses: on a short run that fit can turn the whole
    trajectory by a few degrees, which the far end pays for in centimetres. The scale is what the 10 s bounds'
    drift mostly is (the D455 model's depth biased with range, docs/odometry.md); the anchored figure fits nothing:
    the drift a controller reading the odometry sees.
    """
    figures = []
    for method in ("se3", "sim3", "origin"):
        try:
            figures.append(evaluate(gt, est, EvalOptions(align=method, interpolate_gt=True), ok))
        except EvaluationError:
            figures.append(None)
    se3, sim3, origin = figures
    return WholeRun(None if se3 is None else se3.metrics["ate_rmse_m"],
                    None if sim3 is None else 1.0 / sim3.extra["alignment"]["scale"],
                    None if origin is None else origin.metrics["ate_rmse_m"])


def sequence_spec(scenario: str, seed: int, duration_s: float, config: str | None = None, width: int | None = None,
                  height: int | None = None, depth: str | None = None,
                  sensors: dict[str, float] | None = None) -> SequenceSpec:
    """The simulated sequence :func:`run_sequence` tracks (and a peer is run on)."""
    spec = SequenceSpec(scenario=scenario, duration_s=duration_s, seed=seed, config=config, width=width,
                        height=height, depth=depth)
    return with_sensors(spec, **(sensors or {}))


def orbslam3_sequence(spec: SequenceSpec, vocabulary: Path, progress: bool = True) -> dict[str, Any]:
    """ORB-SLAM3 RGB-D on the frames :func:`run_sequence` tracks (no IMU): its ATEs and the frames it lost.

    Scored against the colour camera's true pose (its poses are the camera's), with the paper's alignment, SE(3)
    over all poses and the first pose anchored, as ours; frames not ``OK`` keep its last pose.
    """
    frames, _, sim = simulated_frames(spec, progress)
    run = run_orbslam3(frames, sim.rig.rgb_camera, vocabulary, progress=progress)
    gt = Trajectory(run.stamps_ns, sim.T_world_rgb(run.stamps_ns))
    paper = evaluate(gt, run.trajectory(), EvalOptions(interpolate_gt=True), run.ok)
    whole = whole_run_figures(gt, run.trajectory(), run.ok)
    lost = np.flatnonzero(~run.ok)
    return {"ate_rmse_cm": paper.metrics["ate_rmse_m"] * 100.0,
            "ate_se3_cm": None if whole.ate_se3_m is None else whole.ate_se3_m * 100.0,
            "ate_origin_cm": None if whole.ate_origin_m is None else whole.ate_origin_m * 100.0,
            "ok": int(run.ok.sum()), "frames": len(run.ok), "first_not_ok": int(lost[0]) if len(lost) else None,
            "track_ms_median": float(np.median(run.time_s) * 1e3), "map_changes": run.info["map_changes"]}


def orbslam3_line(o: dict[str, Any]) -> str:
    """The peer's line under a sequence's."""
    return (f"  ORB-SLAM3 RGB-D, same frames, no IMU: ATE RMSE {o['ate_rmse_cm']:.2f} cm (SE(3) over all poses "
            f"{_fmt(o['ate_se3_cm'], '.2f')}; first pose onto the truth's {_fmt(o['ate_origin_cm'], '.2f')})  "
            f"ok {o['ok']}/{o['frames']} (first not ok: {_fmt(o['first_not_ok'], 'd')})  "
            f"track median {o['track_ms_median']:.1f} ms")


def run_sequence(scenario: str, seed: int, duration_s: float, config: str | None = None,
                 overrides: dict[str, Any] | None = None, width: int | None = None, height: int | None = None,
                 progress: bool = True, use_imu: bool = False, loss_limit_cm: float = 10.0,
                 use_events: bool = False, flood_factor: float = 1.0, stamp_jitter_s: float = 0.0,
                 stamp_latency_s: float = 0.0, depth: str | None = None,
                 sensors: dict[str, float] | None = None) -> dict[str, Any]:
    """Simulate (or load) one sequence, track it through the runtime, score it; a flat dict of figures.

    ``stamp_jitter_s`` / ``stamp_latency_s`` > 0 stamp the RGB-D frames as a host-stamping driver does
    (``RgbModel.stamp_jitter_s`` / ``stamp_latency_s``): the images stay on the frame clock, the poses are
    scored against the ground truth at the times they are published at. ``depth``: the simulator's depth
    sensor (``d455`` or ``sharp``; default the layout's, the D455). The figures include, per motion phase
    (stance, flight, landing), the ATE and RPE per frame of that phase's frames (``phases``). ``sensors``: other
    sensor settings, the keywords of :func:`~atsvo_ros.sim.sequence.with_sensors` (harder ones: a longer exposure, a
    higher contrast threshold, more noise, a dimmer room).
    """

    spec = sequence_spec(scenario, seed, duration_s, config, width, height, depth, sensors)
    # the events are simulated in a thread beside the frames: each stream keeps ~1.3-1.5 of the 2 cores busy
    with ThreadPoolExecutor(1, thread_name_prefix="atsvo-sim-events") as pool:
        events_job = pool.submit(simulated_events, spec, progress) if use_events else None
        frames, imu, sim = simulated_frames(spec, progress)
        events = events_job.result() if events_job is not None else None
    if stamp_jitter_s > 0 or stamp_latency_s > 0:
        delays_ns = sim.stamp_delays_ns(len(frames), stamp_jitter_s, stamp_latency_s)
        frames = [(t + int(d), rgb, depth) for (t, rgb, depth), d in zip(frames, delays_ns)]
    flood_ev_s = 0.0
    if events is not None and flood_factor > 1.0 and len(events) > 1:
        flood_ev_s = (flood_factor - 1.0) * len(events) / ((events.t_last_ns - events.t_first_ns) * 1e-9)
    # the D455 reports each frame's exposure time: the depth/colour offset is known to a driver reading both
    overrides = {"rig.depth_time_offset_s": sim.depth_phase_s, **(overrides or {})}
    cfg = load_config(spec.config or "synthetic", overrides=overrides)
    rt = OdometryRuntime(cfg, sim.rig.rgb_camera, sim.rig.event_camera,
                         use_events=use_events and cfg.mode == "fused", expect_imu=use_imu and imu is not None)
    results, cpu = [], []
    t_wall = time.perf_counter()
    for kind, item in _interleaved(frames, imu if use_imu else None, events, flood_ev_s, seed):
        if kind == "imu":
            rt.add_imu(item)
            continue
        if kind == "events":
            rt.add_events(item[0], complete_to_ns=item[1])
            continue
        stamp, rgb, depth = item
        rt.add_rgb(stamp, rgb)
        rt.add_depth(stamp, depth)
        c0 = time.thread_time()
        outs = rt.poll()
        cpu.append(time.thread_time() - c0)
        results += [o.result for o in outs]
    results += [o.result for o in rt.flush()]
    wall = time.perf_counter() - t_wall
    stamps_ns = np.array([r.stamp_ns for r in results], np.int64)
    poses = np.stack([r.T_odom_base for r in results])
    statuses = [r.status.value for r in results]
    gt = Trajectory(stamps_ns, sim.T_world_base(stamps_ns))
    ok = np.array([s == "ok" for s in statuses])
    est = Trajectory(stamps_ns, poses)
    ev = evaluate(gt, est, EvalOptions(interpolate_gt=True), ok)
    whole = whole_run_figures(gt, est, ok)  # the paper's figure above has its own fallback
    m = ev.metrics
    times = np.array([r.tracking_time_s for r in results if r.status.value == "ok" and not r.keyframe_inserted]) * 1e3
    fused_t = np.array([r.tracking_time_s for r in results if r.mode == "fused"]) * 1e3
    em_t = np.array([r.event_map_time_s for r in results if r.mode == "fused"]) * 1e3
    all_t = np.array([r.tracking_time_s for r in results]) * 1e3
    err_m = ev.position_errors_m
    bad = np.flatnonzero(err_m > loss_limit_cm * 0.01)
    first_bad = None if not len(bad) else int(np.searchsorted(stamps_ns, ev.stamps_ns[bad[0]]))
    # frame 0 defines odom (initialising); an error there is the alignment's, judged with the next frames
    flagged = first_bad is None or any(s != "ok" for s in statuses[1:max(first_bad, 1) + 1])
    return {
        "scenario": scenario, "seed": seed, "duration_s": duration_s, "frames": len(results), "imu": use_imu,
        "sensors": dict(sensors or {}),
        "ate_rmse_cm": m["ate_rmse_m"] * 100.0,
        "ate_se3_cm": None if whole.ate_se3_m is None else whole.ate_se3_m * 100.0,
        "ate_origin_cm": None if whole.ate_origin_m is None else whole.ate_origin_m * 100.0,
        "path_scale": whole.path_scale,
        "rpe_deg_per_frame": m["rpe_rot_deg_per_frame"],
        "rpe_cm_per_frame": m["rpe_trans_cm_per_frame"], "rpe_deg_per_deg": m["rpe_rot_deg_per_deg"],
        # what the line printed per sequence shows: the RMSE (atsvo-replay's statistic), the alignment, the association
        "rpe_deg_per_frame_rmse": ev.extra["rpe_rot_deg_per_frame_rmse"],
        "rpe_cm_per_frame_rmse": ev.extra["rpe_trans_cm_per_frame_rmse"],
        "aligned": describe_alignment(ev.extra["alignment"]),
        "association": ASSOCIATION_TEXT[ev.extra["association"]],
        "rpe_cm_per_deg": m["rpe_trans_cm_per_deg"],
        "diverged": m["diverged"], "track_ms_median": float(np.median(times)) if len(times) else None,
        "track_ms_p90": float(np.percentile(times, 90)) if len(times) else None,
        "frame_cpu_ms_median": float(np.median(cpu) * 1e3) if cpu else None, "wall_s": wall,
        "statuses": dict(Counter(statuses)), "keyframes": getattr(rt.core, "n_keyframes", None),
        "modes": dict(Counter(r.mode for r in results)), "events": int(rt.counters.get("events", 0)),
        "fused_ms_median": float(np.median(fused_t)) if len(fused_t) else None,
        "fused_ms_p95": float(np.percentile(fused_t, 95)) if len(fused_t) else None,
        "event_map_ms_median": float(np.median(em_t)) if len(em_t) else None,
        "max_error_cm": float(err_m.max() * 100.0), "status_left_ok_in_time": bool(flagged),
        "latency_ms_p50": float(np.median(all_t)), "latency_ms_p95": float(np.percentile(all_t, 95)),
        "latency_ms_p99": float(np.percentile(all_t, 99)), "latency_ms_max": float(np.max(all_t)),
        "events_dropped": int(rt.counters.get("events_dropped", 0)) + int(rt.assembler.stats.dropped_events),
        "flood_factor": flood_factor, "stamp_jitter_s": stamp_jitter_s, "stamp_latency_s": stamp_latency_s,
        "depth": spec.depth_sensor, "phases": errors_by_label(ev, sim.motion.phase(ev.stamps_ns), PHASES),
        "lost": statuses.count("lost"), "reinitialised": statuses.count("reinitialised"),
    }


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atsvo-bench tracking", description=__doc__.split("\n\n")[0])
    add_tracking_args(p)
    return p


def add_tracking_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the tracking benchmark (shared with the ``atsvo-bench`` front end)."""
    p.add_argument("--scenarios", nargs="+", default=["trot", "flying"], help="simulator scenarios")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--duration", type=float, default=20.0, help="seconds per sequence")
    p.add_argument("--width", type=int, default=None, help="colour image width (default: the config's)")
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--imu", action="store_true", help="feed the simulated IMU (gyro prior)")
    p.add_argument("--events", action="store_true", help="simulate the event camera and fuse it (mode fused)")
    p.add_argument("--flood", type=float, default=1.0, metavar="FACTOR",
                   help="with --events: add a 100 Hz flickering lamp multiplying the event rate by FACTOR "
                        "(load test: per-frame latency p50/p99 and the events the rate cap dropped)")
    p.add_argument("--stamp-jitter", type=float, default=0.0, metavar="S",
                   help="stamp the frames as a host-stamping driver does: delays of scale S seconds after the "
                        "exposure (TUM's Kinect: ~0.002; default 0, hardware stamps)")
    p.add_argument("--stamp-latency", type=float, default=0.0, metavar="S",
                   help="a constant S seconds more on every stamp, besides the jitter (TUM's Kinect: ~0.010; "
                        "the odometry takes it out with --set rgb_camera.time_offset_s=-S)")
    p.add_argument("--exposure", type=float, default=None, metavar="S",
                   help="colour exposure time in s (atsvo-sim's; default 0.008): more blur")
    p.add_argument("--contrast", type=float, default=None, help="event contrast threshold C+ = C- (default 0.2)")
    p.add_argument("--noise-rate", type=float, default=None, metavar="HZ",
                   help="event background activity per pixel and second (default 0.1)")
    p.add_argument("--ir-ambient", type=float, default=None,
                   help="the room's IR light against the D455's projector (default 0.25; lower: dimmer, more smear)")
    p.add_argument("--loss-limit-cm", type=float, default=10.0,
                   help="position error by which the status must have left ok (default 10)")
    p.add_argument("--orbslam3", action="store_true",
                   help="also run ORB-SLAM3 RGB-D on each sequence's frames (pip install 'atsvo_ros[orbslam3]')")
    p.add_argument("--json", default=None, help="write the per-sequence figures to this file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    add_config_args(p, default="synthetic")


def sensor_settings(args: argparse.Namespace) -> dict[str, float]:
    """The sensor settings given on the command line, as :func:`~atsvo_ros.sim.sequence.with_sensors` keywords."""
    given = {"exposure_s": args.exposure, "contrast": args.contrast, "noise_rate_hz": args.noise_rate,
             "ambient_ir": args.ir_ambient}
    return {k: float(v) for k, v in given.items() if v is not None}


def _fmt(v: Any, f: str) -> str:
    return "-" if v is None else format(v, f)


def main_tracking(args: argparse.Namespace) -> int:
    """Run the benchmark for parsed arguments; prints one line per sequence and a summary."""
    overrides = parse_overrides(args.set)
    vocabulary = vocabulary_file(cache_dir(), progress=not args.quiet) if args.orbslam3 else None
    rows = []
    for scenario in args.scenarios:
        for seed in args.seeds:
            r = run_sequence(scenario, seed, args.duration, args.config, overrides, args.width, args.height,
                             progress=not args.quiet, use_imu=args.imu, loss_limit_cm=args.loss_limit_cm,
                             use_events=args.events, flood_factor=args.flood, stamp_jitter_s=args.stamp_jitter,
                             stamp_latency_s=args.stamp_latency, sensors=sensor_settings(args))
            rows.append(r)
            print(sequence_line(r), flush=True)
            if vocabulary is not None:
                spec = sequence_spec(scenario, seed, args.duration, args.config, args.width, args.height,
                                     sensors=sensor_settings(args))
                r["orbslam3"] = orbslam3_sequence(spec, vocabulary, progress=not args.quiet)
                print(orbslam3_line(r["orbslam3"]), flush=True)
    med = [r["track_ms_median"] for r in rows if r["track_ms_median"] is not None]
    print(summary_line(rows, med))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


def sequence_line(r: dict[str, Any]) -> str:
    """One sequence's line: ATE RMSE with its alignment (evo's SE(3) over all poses, the ATE anchored at the first
    pose and the path's Sim(3) scale beside it) and RPE per frame as RMSE with its association (atsvo-replay's and
    atsvo-eval's vocabulary), then timing, statuses, events."""
    return (f"{r['scenario']:8s} seed {r['seed']}: ATE RMSE {r['ate_rmse_cm']:.2f} cm (max {r['max_error_cm']:.1f}; "
            f"aligned: {r['aligned']}; SE(3) over all poses {_fmt(r.get('ate_se3_cm'), '.2f')} cm; "
            f"first pose onto the truth's {_fmt(r.get('ate_origin_cm'), '.2f')} cm; "
            f"path length x{_fmt(r.get('path_scale'), '.4f')} of the truth's)  "
            f"RPE per frame, RMSE, {r['association']}: "
            f"{_fmt(r['rpe_deg_per_frame_rmse'], '.3f')} deg/f {_fmt(r['rpe_cm_per_frame_rmse'], '.3f')} cm/f  "
            f"track median {_fmt(r['track_ms_median'], '.2f')} ms (p90 {_fmt(r['track_ms_p90'], '.2f')})  "
            f"diverged {r['diverged']}  flagged-in-time {r['status_left_ok_in_time']}  {r['statuses']}  "
            f"{r['modes']}  fused median {_fmt(r['fused_ms_median'], '.2f')} ms  kf {r['keyframes']}  "
            f"latency p50/p99 {r['latency_ms_p50']:.1f}/{r['latency_ms_p99']:.1f} ms  "
            f"events {r['events']} (dropped {r['events_dropped']})")


def summary_line(rows: list[dict[str, Any]], med: list[float]) -> str:
    """The last line: worst ATE RMSE and worst RPE-per-frame RMSE over the sequences, tracking time, failures."""
    rpe = [r["rpe_deg_per_frame_rmse"] for r in rows if r["rpe_deg_per_frame_rmse"] is not None]
    return (f"summary: worst ATE RMSE {max(r['ate_rmse_cm'] for r in rows):.2f} cm, worst RPE per frame RMSE "
            f"{_fmt(max(rpe) if rpe else None, '.3f')} deg/f, median tracking "
            f"{np.median(med) if med else float('nan'):.2f} ms/frame, diverged {sum(r['diverged'] for r in rows)}/"
            f"{len(rows)}, silently wrong {sum(not r['status_left_ok_in_time'] for r in rows)}/{len(rows)}")


def main(argv: Sequence[str] | None = None) -> int:
    return run(main_tracking, _parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
