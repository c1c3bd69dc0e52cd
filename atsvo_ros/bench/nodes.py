"""``atsvo-bench nodes``: latency, drops and memory of the ROS nodes under load, over loopback DDS.

It imports no ROS module itself: the nodes and the player (:mod:`atsvo_ros.nodes.player`) do.

Starts the nodes as a user does (``atsvo_node``, or ``tracking_node`` + ``mapping_node`` with
``--split``), publishes a synthetic sequence message by message (sensor-data QoS) and subscribes to
the odometry like a controller. A first run at the recording's own rate measures how long the node
needs per frame (worker time: odometry, keyframe request, publishing); its inverse is the sustainable
frame rate. Then the sequence is published at 1x and 3x that frame rate (the whole recording sped up:
images and IMU, and the events re-cut into packets that still go out every millisecond, as a driver
sends them). Per run: latency from a frame's stamp (the time it was due on the publishing
clock) to its odometry at the subscriber, p50/p99/max; frames dropped by the node's queue (counted),
by DDS (published, never received) and still waiting; the node processes' resident memory over time
(first, last, max, and the slope over the second half; the series in the JSON and a plot beside it).
``--repeat N`` loops the sequence in the load runs with time running on: a soak test from a short
bag. ``--hogs N`` runs N busy-loop processes beside the nodes in every run (the robot's other
software); ``--loads`` with no value keeps only the run at the recording's own rate. Each single-pass
run also reports the share of frames answered and the ATE of the odometry the probe received against
the sequence's ground truth, beside ``atsvo-replay``'s on the same bag. Needs the ``ros`` extra
and the event messages (.ci/ros_env.sh); the simulated sequence is
cached in ``$ATSVO_CACHE``.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.config import load_config, resolve_config_path
from atsvo_ros.errors import AtsvoError
from atsvo_ros.eval.metrics import EvalOptions, evaluate
from atsvo_ros.eval.plots import plot_memory
from atsvo_ros.io.sources import read_sim_description, sim_depth_phase_s
from atsvo_ros.io.trajectory import Trajectory, read_tum
from atsvo_ros.tools.demo import cache_dir
from atsvo_ros.tools.replay import replay
from atsvo_ros.tools.sim import main as sim_main


def add_nodes_args(p: argparse.ArgumentParser) -> None:
    """Arguments of ``atsvo-bench nodes``."""
    p.add_argument("--scenario", default="trot", help="simulator scenario (default trot)")
    p.add_argument("--duration", type=float, default=10.0, help="sequence seconds (default 10)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=640, help="colour image width (default 640, the D455's)")
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--event-scale", type=float, default=1.0, help="event camera size factor (1: 320x240)")
    p.add_argument("--loads", type=float, nargs="*", default=[1.0, 3.0],
                   help="publishing rates as multiples of the sustainable frame rate (default 1 3; none: only the "
                        "run at the recording's own rate)")
    p.add_argument("--hogs", type=int, default=0,
                   help="busy-loop processes running beside the nodes in every run (default 0)")
    p.add_argument("--split", action="store_true", help="tracking_node + mapping_node instead of atsvo_node")
    p.add_argument("--queue-size", type=int, default=2, help="node.queue_size (default 2)")
    p.add_argument("--mode", choices=("fused", "rgbd"), default="fused")
    p.add_argument("--event-packet-ms", type=float, default=1.0,
                   help="wall-clock period of the event packets whatever the playing rate, as a driver publishes "
                        "them (default 1 ms)")
    p.add_argument("--cache", default=None, help="where the sequence is simulated (default $ATSVO_CACHE)")
    p.add_argument("--bag", default=None,
                   help="play this atsvo-sim bag (robot layout, synthetic config) instead of simulating one, e.g. "
                        "a long one for the memory trend")
    p.add_argument("--repeat", type=int, default=1,
                   help="play the sequence this many times back to back in each load run (stamps moved on, so "
                        "time keeps running; the scene jumps back to its start at each loop): a long run from "
                        "a short bag, for the memory trend (default 1)")
    p.add_argument("-p", "--ros-param", action="append", default=[], metavar="NAME:=VALUE",
                   help="one more node parameter (repeatable), e.g. -p node.core_process:=true")
    p.add_argument("--json", default=None, help="write the figures to this file")


def _sequence(args: argparse.Namespace) -> Path:
    if args.bag:
        bag = Path(args.bag)
        if not (bag / "metadata.yaml").is_file():
            raise AtsvoError(f"--bag {bag}: not a ROS 2 bag directory (no metadata.yaml)")
        return bag
    name = (f"nodes_{args.scenario}_{args.duration:g}s_seed{args.seed}_{args.width}x{args.height}"
            f"_ev{args.event_scale:g}")
    out = cache_dir(args.cache) / name
    if not (out / "metadata.yaml").is_file():
        print(f"simulating {name} into {out} ...", flush=True)
        code = sim_main(["--scenario", args.scenario, "--duration", str(args.duration), "--seed", str(args.seed),
                         "--width", str(args.width), "--height", str(args.height), "--event-scale",
                         str(args.event_scale), "--out", str(out), "--force", "--quiet"])
        if code != 0:
            raise AtsvoError(f"simulating the sequence failed (exit code {code})")
    return out


@contextmanager
def _hogs(n: int) -> Iterator[None]:
    """``n`` processes spinning a core each (what else runs on the robot), stopped on exit."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(max(0, n))]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _run(bag: Path, args: argparse.Namespace, rate: float, log_dir: Path, repeat: int = 1,
         gt: Trajectory | None = None) -> dict[str, Any]:
    """One run: start the nodes, publish ``repeat`` passes at ``rate`` x real time, measure, stop."""
    from atsvo_ros.nodes.player import node_session  # needs rclpy (the ros extra)

    rig = _rig_overrides(bag)
    cfg = load_config("synthetic", overrides={"mode": args.mode, **rig})
    scripts = ["mapping_node", "tracking_node"] if args.split else ["atsvo_node"]
    ros_args = ["--ros-args", "--params-file", str(_params_file()), "-p", f"node.queue_size:={args.queue_size}",
                "-p", f"mode:={args.mode}", "-p", "node.diagnostics_period_s:=0.5"]
    for name, value in rig.items():
        ros_args += ["-p", f"{name}:={value!r}"]
    for param in args.ros_param:
        ros_args += ["-p", param]
    with _hogs(args.hogs), node_session(bag, cfg, scripts, ros_args, log_dir, start_timeout_s=120.0,
                                        name="atsvo_bench_probe") as run:
        player, probe, procs = run.player, run.probe, run.procs
        if args.event_packet_ms:
            player.repacketized(args.event_packet_ms * 1e-3 * rate)  # cut before the clock starts (seconds of CPU)
        t_start = time.monotonic()
        cpu0_node, cpu0_own = procs.cpu_s(), time.process_time()
        played = player.play(rate=rate, event_packet_wall_s=args.event_packet_ms * 1e-3, repeat=repeat)
        t_played = time.monotonic()
        probe.wait_idle(len(played.frame_stamps_ns) - 1, idle_s=3.0)
        cpu_node, cpu_own = procs.cpu_s() - cpu0_node, time.process_time() - cpu0_own
        # the tracking node's own status, twice (the mapping node publishes /diagnostics as well)
        n_diag = probe.diag_count("atsvo_tracking: odometry")
        probe.wait(lambda: probe.diag_count("atsvo_tracking: odometry") > n_diag + 1, 5.0)
        diag = probe.diag("atsvo_tracking: odometry") or {}
        received = probe.received()
        statuses = probe.statuses()
        stamps, poses = probe.poses()
    codes = run.exit_codes
    ate = None
    if gt is not None and repeat == 1 and len(stamps) > 2 and len(statuses) == len(stamps):
        ev = evaluate(gt, Trajectory(stamps, poses), EvalOptions(interpolate_gt=True),
                      est_ok=np.array([s == "ok" for s in statuses]))
        ate = float(ev.metrics["ate_rmse_m"])
    stamped = sorted((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, tr) for tr, m in received)
    stamped = [(t, tr) for t, tr in stamped if t in played.scheduled_s]
    lat = np.array([(tr - played.scheduled_s[t]) * 1e3 for t, tr in stamped])
    n_frames = len(played.frame_stamps_ns)
    frames_in = int(diag.get("frames_in", 0))
    rss = np.array([[ts - t_start, sum(v for v in mb if v is not None)] for ts, mb in procs.rss
                    if ts >= t_start and all(v is not None for v in mb)])
    half = rss[rss[:, 0] >= 0.5 * rss[-1, 0]] if len(rss) > 4 else rss
    slope = float(np.polyfit(half[:, 0], half[:, 1], 1)[0]) * 60.0 if len(half) > 2 else float("nan")
    span_s = (played.frame_stamps_ns[-1] - played.frame_stamps_ns[0]) * 1e-9 if n_frames > 1 else 0.0
    return {
        "rate_x_real_time": rate, "passes": repeat, "run_s": t_played - t_start, "published_frames": n_frames,
        "publish_fps": (n_frames - 1) / max(t_played - t_start, 1e-9),
        "scheduled_fps": (n_frames - 1) / max(span_s / rate, 1e-9),
        "publisher_lag_ms_p99": float(np.percentile(played.lag_s, 99) * 1e3),
        "odometry": len(received), "odometry_fps": len(received) / max(t_played - t_start, 1e-9),
        "answered": len(received) / max(n_frames, 1), "hogs": args.hogs, "ate_m": ate,
        "latency_ms_p50": float(np.percentile(lat, 50)) if len(lat) else None,
        "latency_ms_p99": float(np.percentile(lat, 99)) if len(lat) else None,
        "latency_ms_max": float(lat.max()) if len(lat) else None,
        "queue_drops": int(diag.get("queue_drops", 0)),
        "dds_lost_frames": n_frames - int(diag.get("rgb_received", frames_in)),
        "node_missing_rgb": int(diag.get("missing_rgb", 0)),  # the node's own count, from stamp gaps
        "sync_dropped": int(diag.get("sync_dropped_rgb", 0)), "frames_waiting": int(diag.get("frames_waiting", 0)),
        "event_msgs_decoded": int(diag.get("count_event_msgs", 0)),
        "event_msgs_published": played.n_event_msgs,
        "worker_ms_mean": float(diag.get("worker_ms_mean", "nan")),
        "worker_cpu_ms_mean": float(diag.get("worker_cpu_ms_mean", "nan")),  # the worker thread's own CPU
        # CPU per published frame: the node processes, and this process (player and probe)
        "node_cpu_ms_per_frame": 1e3 * cpu_node / max(n_frames, 1),
        "player_cpu_ms_per_frame": 1e3 * cpu_own / max(n_frames, 1),
        "tracking_ms_p50": float(diag.get("tracking_time_ms_p50", "nan")),
        "rss_mb_first": float(rss[0, 1]) if len(rss) else None, "rss_mb_last": float(rss[-1, 1]) if len(rss) else None,
        "rss_mb_max": float(rss[:, 1].max()) if len(rss) else None, "rss_mb_per_min_second_half": slope,
        "statuses": {k: statuses.count(k) for k in sorted(set(statuses))},
        "exit_codes": codes,
        "rss_mb_series": [[round(float(a), 2), round(float(b), 1)] for a, b in rss[::max(1, len(rss) // 400)]],
        # per answered frame, in stamp order: where a p99 comes from (the first map, a backlog, the last frame)
        "latency_ms_series": [[int(t), round(float(v), 2)] for (t, _), v in zip(stamped, lat)] if repeat == 1 else [],
    }


def _params_file() -> Path:
    return resolve_config_path("synthetic")


def _rig_overrides(bag: Path) -> dict[str, float]:
    """The bag's depth-against-colour exposure offset, as the robot's calibration would give it (as
    ``atsvo-bench tracking`` does): without it a simulated flip's depth is read 15 ms off (replay ATE 44 cm
    against 4.1)."""
    phase_s = sim_depth_phase_s(read_sim_description(bag))
    return {} if phase_s is None else {"rig.depth_time_offset_s": phase_s}


def _row(name: str, r: dict[str, Any]) -> str:
    def f(v: Any, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    ate = "-" if r.get("ate_m") is None else f"{r['ate_m'] * 100:.2f}"
    return (f"| {name} | {r['rate_x_real_time']:.2f} | {r['scheduled_fps']:.0f} / {r['publish_fps']:.0f} | "
            f"{r['odometry']}/{r['published_frames']} ({100 * r['answered']:.0f} %) | {ate} | "
            f"{f(r['latency_ms_p50'], '.0f')} / "
            f"{f(r['latency_ms_p99'], '.0f')} / {f(r['latency_ms_max'], '.0f')} | {r['queue_drops']} | "
            f"{r['dds_lost_frames']} | {r['event_msgs_decoded']}/{r['event_msgs_published']} | "
            f"{r['node_cpu_ms_per_frame']:.0f} / {r['player_cpu_ms_per_frame']:.0f} | "
            f"{f(r['rss_mb_first'], '.0f')} -> {f(r['rss_mb_last'], '.0f')} (max {f(r['rss_mb_max'], '.0f')}, "
            f"{f(r['rss_mb_per_min_second_half'], '+.1f')}/min) | {r['exit_codes']} |")


def main_nodes(args: argparse.Namespace) -> int:
    """Calibrate at real time, then run each load; prints a table (and writes --json)."""
    if importlib.util.find_spec("rclpy") is None:
        raise AtsvoError("atsvo-bench nodes needs rclpy: pip install -e '.[ros]' && source .ci/ros_env.sh") from None
    bad = [p for p in args.ros_param if ":=" not in p]
    if bad:
        raise AtsvoError(f"--ros-param {bad[0]!r}: expected NAME:=VALUE")
    bag = _sequence(args)
    log_dir = Path(args.json).parent / "bench_nodes_logs" if args.json else Path(".atsvo_cache") / "bench_nodes_logs"
    results: dict[str, Any] = {"sequence": str(bag), "nodes": "tracking_node + mapping_node" if args.split
                               else "atsvo_node", "mode": args.mode, "queue_size": args.queue_size,
                               "ros_params": args.ros_param, "rig_overrides": _rig_overrides(bag), "runs": {}}
    ref = replay(bag, log_dir.parent / "bench_nodes_replay", load_config("synthetic", overrides=_rig_overrides(bag)),
                 mode=args.mode, plots=False, progress=False)  # the nodes run config/synthetic.yaml
    gt = read_tum(ref.out_dir / "groundtruth.tum") if (ref.out_dir / "groundtruth.tum").is_file() else None
    results["replay_ate_m"] = ref.metrics.get("ate_rmse_m") if ref.metrics else None
    results["hogs"] = args.hogs
    print(f"calibration: {bag.name} at its own rate ({results['nodes']}, mode {args.mode}, {args.hogs} CPU hog(s); "
          f"atsvo-replay ATE {100 * (results['replay_ate_m'] or float('nan')):.2f} cm)", flush=True)
    cal = _run(bag, args, 1.0, log_dir, gt=gt)
    results["runs"]["real_time"] = cal
    sustainable_fps = 1000.0 / cal["worker_ms_mean"]
    recorded_fps = cal["scheduled_fps"]
    results["sustainable_fps"] = sustainable_fps
    print(f"  worker {cal['worker_ms_mean']:.1f} ms per frame ({cal['worker_cpu_ms_mean']:.1f} ms of its own CPU) "
          f"-> sustainable {sustainable_fps:.1f} frames/s "
          f"(recording: {recorded_fps:.1f})", flush=True)
    for load in args.loads:
        rate = load * sustainable_fps / recorded_fps
        print(f"{load:g}x sustainable: publishing at {rate:.2f}x real time"
              + (f", {args.repeat} passes" if args.repeat > 1 else ""), flush=True)
        results["runs"][f"{load:g}x"] = _run(bag, args, rate, log_dir, args.repeat, gt=gt)
    header = ("| run | x real time | frames/s due / sent | odometry / frames | ATE cm | latency ms p50 / p99 / max | "
              "queue drops | DDS lost | event msgs decoded | CPU ms/frame node / player | "
              "RSS MB (all node processes) | exit |")
    print()
    print(header)
    print("|" + "---|" * (header.count("|") - 1))
    for name, r in results["runs"].items():
        print(_row(name, r))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1) + "\n")
        png = plot_memory(Path(args.json).with_suffix(".rss.png"),
                          {f"{name} ({r['rate_x_real_time']:.2f}x real time, {r['passes']} pass"
                           f"{'es' if r['passes'] > 1 else ''})": np.array(r["rss_mb_series"])
                           for name, r in results["runs"].items()},
                          f"{results['nodes']}, {results['mode']}: RSS of the node processes")
        print(f"wrote {args.json} and {png}")
    return 0


__all__ = ["add_nodes_args", "main_nodes"]
