"""``atsvo-bench longrun``: memory and latency over a long synthetic run (is anything growing?).

A robot runs for hours; a map that is never culled or a buffer that is never trimmed shows as
resident memory that climbs minute after minute. This benchmark drives
:class:`~atsvo_ros.runtime.runtime.OdometryRuntime` for ``--minutes`` of sequence time and reports, at each
minute, the resident set size (RSS), the tracking time p50/p99 of that minute, the map size and the
statuses. Rendering 10 minutes at 640x480 would take over an hour on two cores, so a ``--segment``
of the scenario is simulated once (frames cached one file each in ``$ATSVO_CACHE/longrun``) and
played forwards and backwards in turn with steadily increasing stamps: the motion stays continuous
(the robot walks back along its path, re-observing the same scene, which is exactly when a map that
is never culled would grow). RGB-D mode: the event stream has no such time reversal.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import resource
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from atsvo_ros.bench.tracking import FRAME_CACHE_VERSION
from atsvo_ros.config import load_config, parse_overrides
from atsvo_ros.eval.metrics import EvalOptions, evaluate
from atsvo_ros.io.trajectory import Trajectory
from atsvo_ros.runtime.runtime import OdometryRuntime
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation
from atsvo_ros.tools._cli import add_config_args
from atsvo_ros.tools.demo import cache_dir

MINUTE_NS = 60_000_000_000


def _proc_status_mb(key: str) -> float | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def rss_mb() -> float:
    """Resident set size of this process in MiB (``/proc/self/status``; peak RSS where that is missing)."""
    now = _proc_status_mb("VmRSS:")
    return now if now is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def peak_rss_mb() -> float:
    """Peak resident set size of this process in MiB.

    ``VmHWM`` of this address space where Linux has it: ``ru_maxrss`` survives ``execve``, so a process
    spawned from a big parent would report the parent's peak (every spawned replay showed the same 2180 MiB).
    """
    peak = _proc_status_mb("VmHWM:")
    return peak if peak is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _segment_dir(spec: Any) -> Path:
    key = json.dumps([FRAME_CACHE_VERSION, spec.scenario, spec.duration_s, spec.seed, spec.width, spec.height,
                      spec.config], sort_keys=True)
    return cache_dir() / "longrun" / f"{spec.scenario}_{spec.seed}_{hashlib.sha1(key.encode()).hexdigest()[:12]}"


def segment_frames(spec: Any, progress: bool = True) -> tuple[Path, int, Any]:
    """Simulate the segment once into one compressed file per frame; (folder, frame count, simulation)."""


    sim = make_simulation(spec)
    folder = _segment_dir(spec)
    done = folder / "complete"
    n = int(spec.duration_s * spec.rate_hz) + 1
    if not done.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        for k, f in enumerate(tqdm(sim.frames(), total=n, desc=f"simulate {spec.scenario} segment",
                                   disable=not progress, file=sys.stderr, leave=False)):
            np.savez_compressed(folder / f"{k:06d}.npz", stamp=f.stamp_ns, rgb=f.rgb, depth=f.depth_m)
        done.write_text("ok\n")
    n = len(list(folder.glob("*.npz")))
    return folder, n, sim


def ping_pong(n: int) -> Iterator[int]:
    """Frame indices 0..n-1, n-2..1, 0..n-1, ... for ever (continuous motion, reversed at the ends)."""
    period = max(1, 2 * (n - 1))
    k = 0
    while True:
        i = k % period
        yield i if i < n else period - i
        k += 1


def run_longrun(scenario: str = "trot", seed: int = 0, segment_s: float = 30.0, minutes: float = 10.0,
                config: str | None = None, overrides: dict[str, Any] | None = None, width: int | None = None,
                height: int | None = None, progress: bool = True) -> dict[str, Any]:
    """Drive the runtime for ``minutes`` of ping-pong playback; per-minute RSS, latency, map and statuses."""


    spec = SequenceSpec(scenario=scenario, duration_s=segment_s, seed=seed, config=config, width=width,
                        height=height)
    folder, n, sim = segment_frames(spec, progress)
    with np.load(folder / "000000.npz") as z:
        stamp0 = int(z["stamp"])
    with np.load(folder / "000001.npz") as z:
        dt_ns = int(z["stamp"]) - stamp0
    src_stamps = stamp0 + dt_ns * np.arange(n, dtype=np.int64)
    src_poses = sim.T_world_base(src_stamps)
    cfg = load_config(config or "synthetic", overrides={**(overrides or {}), "mode": "rgbd"})
    rt = OdometryRuntime(cfg, sim.rig.rgb_camera, use_events=False)
    total = int(minutes * MINUTE_NS // dt_ns)
    rows: list[dict[str, Any]] = []
    # the run's own record is allocated (and touched) up front, so that it does not show as growth
    stamps = np.full(total, -1, np.int64)
    poses = np.full((total, 4, 4), np.nan)
    src = np.full(total, -1, np.int64)
    statuses = np.full(total, -1, np.int8)
    status_names: list[str] = []
    n_out = 0
    minute_t: list[float] = []
    rss0 = None
    order = ping_pong(n)
    t_wall = time.perf_counter()
    for k in tqdm(range(total), desc="long run", disable=not progress, file=sys.stderr, unit="frame"):
        i = next(order)
        with np.load(folder / f"{i:06d}.npz") as z:
            rgb, depth = z["rgb"], z["depth"]
        stamp = stamp0 + k * dt_ns
        rt.add_rgb(stamp, rgb)
        rt.add_depth(stamp, depth)
        for o in rt.poll():
            r = o.result
            if r.status.value not in status_names:
                status_names.append(r.status.value)
            stamps[n_out], poses[n_out], src[n_out] = r.stamp_ns, r.T_odom_base, i
            statuses[n_out] = status_names.index(r.status.value)
            n_out += 1
            minute_t.append(r.tracking_time_s * 1e3)
        if rss0 is None and k == 30:  # after the kernels compiled and the first keyframes: the baseline
            rss0 = rss_mb()
        if (k + 1) * dt_ns % MINUTE_NS < dt_ns or k + 1 == total:
            core = rt.core
            snap = core.map if core is not None else None
            rows.append({"minute": round((k + 1) * dt_ns / MINUTE_NS, 2), "rss_mb": rss_mb(),
                         "peak_rss_mb": peak_rss_mb(),
                         "track_ms_p50": float(np.median(minute_t)) if minute_t else None,
                         "track_ms_p99": float(np.percentile(minute_t, 99)) if minute_t else None,
                         "map_points": None if snap is None else len(snap),
                         "keyframes": None if snap is None else len(snap.keyframes),
                         "statuses": {status_names[j]: c for j, c in
                                      Counter(statuses[n_out - len(minute_t):n_out].tolist()).items()}})
            minute_t = []
    wall = time.perf_counter() - t_wall
    st = stamps[:n_out]
    ok_index = status_names.index("ok") if "ok" in status_names else -2
    ev = evaluate(Trajectory(st, src_poses[src[:n_out]]), Trajectory(st, poses[:n_out]), EvalOptions(),
                  statuses[:n_out] == ok_index)
    return {"scenario": scenario, "seed": seed, "segment_s": segment_s, "minutes": minutes, "frames": n_out,
            "wall_s": wall, "rss_baseline_mb": rss0, "per_minute": rows, "ate_rmse_cm": ev.metrics["ate_rmse_m"] * 100,
            "statuses": {status_names[j]: c for j, c in Counter(statuses[:n_out].tolist()).items()}}


def add_longrun_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the long-run benchmark."""
    p.add_argument("--scenario", default="trot", help="simulator scenario of the segment (default trot)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--segment", type=float, default=30.0, help="seconds simulated and played back and forth")
    p.add_argument("--minutes", type=float, default=10.0, help="sequence time to run (default 10)")
    p.add_argument("--width", type=int, default=None)
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--json", default=None, help="write the figures to this file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    add_config_args(p, default="synthetic")


def main_longrun(args: argparse.Namespace) -> int:
    """Run it; print one line per minute and a summary."""
    r = run_longrun(args.scenario, args.seed, args.segment, args.minutes, args.config, parse_overrides(args.set),
                    args.width, args.height, progress=not args.quiet)
    print(f"{'minute':>6s} {'RSS [MiB]':>9s} {'peak':>7s} {'p50 [ms]':>8s} {'p99 [ms]':>8s} {'points':>7s} "
          f"{'kf':>4s}  statuses")
    for m in r["per_minute"]:
        print(f"{m['minute']:6.2f} {m['rss_mb']:9.1f} {m['peak_rss_mb']:7.1f} {m['track_ms_p50'] or 0:8.2f} "
              f"{m['track_ms_p99'] or 0:8.2f} {m['map_points'] or 0:7d} {m['keyframes'] or 0:4d}  {m['statuses']}")
    first, last = r["per_minute"][0], r["per_minute"][-1]
    print(f"summary: {r['frames']} frames in {r['wall_s']:.0f} s, RSS {r['rss_baseline_mb']:.1f} MiB after 1 s, "
          f"{first['rss_mb']:.1f} at minute {first['minute']:g}, {last['rss_mb']:.1f} at minute {last['minute']:g} "
          f"(peak {last['peak_rss_mb']:.1f}); ATE {r['ate_rmse_cm']:.2f} cm; {r['statuses']}")
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=2) + "\n")
    return 0
