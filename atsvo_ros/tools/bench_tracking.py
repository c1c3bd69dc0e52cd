"""``atsvo-bench tracking``: RGB-D tracking time and accuracy on synthetic legged-robot sequences.

Generates each sequence with the simulator (colour + depth only: events are not needed in RGB-only
mode), runs :class:`~atsvo_ros.core.odometry.Odometry` frame by frame and reports per sequence the
tracking time per frame (wall clock, median / 90th percentile, preprocessing + alignment, frames
without keyframe insertion), the CPU time of the whole ``process_frame`` call (median; robust to
other processes sharing the machine), ATE RMSE and RPE per frame against the simulator's ground
truth (paper protocol of :mod:`atsvo_ros.eval.metrics`) and the status counts. Also runnable as
``python -m atsvo_ros.tools.bench_tracking``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from atsvo_ros.tools._cli import add_config_args, parse_overrides, run


def run_sequence(scenario: str, seed: int, duration_s: float, config: str | None = None,
                 overrides: dict[str, Any] | None = None, width: int | None = None, height: int | None = None,
                 progress: bool = True) -> dict[str, Any]:
    """Simulate one sequence, track it, score it; returns a flat dict of figures."""
    from tqdm import tqdm

    from atsvo_ros.config import load_config
    from atsvo_ros.core.odometry import Odometry, RgbdFrame, TrackingStatus
    from atsvo_ros.eval.metrics import EvalOptions, evaluate
    from atsvo_ros.io.trajectory import Trajectory
    from atsvo_ros.sim.sequence import SequenceSpec, make_simulation

    spec = SequenceSpec(scenario=scenario, duration_s=duration_s, seed=seed, config=config, width=width,
                        height=height)
    sim = make_simulation(spec)
    cfg = load_config(spec.config or "synthetic", overrides=overrides)
    odo = Odometry(cfg, sim.rig.rgb_camera)
    stamps, poses, ok, times, cpu_times = [], [], [], [], []
    statuses: Counter[str] = Counter()
    t_wall = time.perf_counter()
    n_frames = int(duration_s * spec.rate_hz) + 1
    for f in tqdm(sim.frames(), total=n_frames, desc=f"{scenario} seed {seed}", disable=not progress,
                  file=sys.stderr, leave=False):
        frame = RgbdFrame(f.stamp_ns, f.rgb, f.depth_m)
        c0 = time.thread_time()
        res = odo.process_frame(frame)
        cpu = time.thread_time() - c0
        stamps.append(res.stamp_ns)
        poses.append(res.T_odom_base)
        ok.append(res.status in (TrackingStatus.OK, TrackingStatus.INITIALISING))
        statuses[res.status.value] += 1
        if res.status is TrackingStatus.OK and not res.keyframe_inserted:
            times.append(res.tracking_time_s)
            cpu_times.append(cpu)
    wall = time.perf_counter() - t_wall
    stamps_ns = np.asarray(stamps, dtype=np.int64)
    gt = Trajectory(stamps_ns, sim.T_world_base(stamps_ns))
    ev = evaluate(gt, Trajectory(stamps_ns, np.asarray(poses)), EvalOptions(), np.asarray(ok))
    m = ev.metrics
    t = np.asarray(times) * 1e3
    return {
        "scenario": scenario, "seed": seed, "duration_s": duration_s, "frames": len(stamps),
        "ate_rmse_cm": m["ate_rmse_m"] * 100.0, "rpe_deg_per_frame": m["rpe_rot_deg_per_frame"],
        "rpe_cm_per_frame": m["rpe_trans_cm_per_frame"], "rpe_deg_per_deg": m["rpe_rot_deg_per_deg"],
        "diverged": m["diverged"], "track_ms_median": float(np.median(t)) if len(t) else None,
        "track_ms_p90": float(np.percentile(t, 90)) if len(t) else None,
        "frame_cpu_ms_median": float(np.median(cpu_times) * 1e3) if cpu_times else None,
        "wall_s": wall, "statuses": dict(statuses), "keyframes": odo.n_keyframes,
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
    p.add_argument("--json", default=None, help="write the per-sequence figures to this file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    add_config_args(p, default="synthetic")


def main_tracking(args: argparse.Namespace) -> int:
    """Run the benchmark for parsed arguments; prints one line per sequence and a summary."""
    overrides = parse_overrides(args.set)
    rows = []
    for scenario in args.scenarios:
        for seed in args.seeds:
            r = run_sequence(scenario, seed, args.duration, args.config, overrides, args.width, args.height,
                             progress=not args.quiet)
            rows.append(r)
            print(f"{scenario:8s} seed {seed}: ATE {r['ate_rmse_cm']:.2f} cm  RPE {r['rpe_deg_per_frame']:.3f} deg/f "
                  f"{r['rpe_cm_per_frame']:.3f} cm/f  track median {r['track_ms_median']:.2f} ms "
                  f"(p90 {r['track_ms_p90']:.2f}, CPU {r['frame_cpu_ms_median']:.2f})  "
                  f"diverged {r['diverged']}  {r['statuses']}  kf {r['keyframes']}",
                  flush=True)
    med = np.median([r["track_ms_median"] for r in rows if r["track_ms_median"] is not None])
    print(f"summary: worst ATE {max(r['ate_rmse_cm'] for r in rows):.2f} cm, worst RPE "
          f"{max(r['rpe_deg_per_frame'] for r in rows):.3f} deg/f, median tracking {med:.2f} ms/frame, "
          f"diverged {sum(r['diverged'] for r in rows)}/{len(rows)}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return run(main_tracking, _parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
