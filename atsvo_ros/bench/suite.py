"""``atsvo-bench [--quick] --out DIR``: every benchmark in one run, side by side with the peers, on one machine.

Ratios measured in the same run hold on a noisy machine where absolute times do not. The run has
six parts, each a section of ``DIR/results.json`` and ``DIR/results.md``:

1. speed of the event front end (:mod:`atsvo_ros.bench.events`): decoding real packets against
   rosbags, ATS and speed-invariant surface updates and the ATS render against dv-processing;
2. accuracy on synthetic legged-robot sequences of every gait, on seeds nobody tuned on
   (:data:`HELD_OUT_SEEDS`), scenario x seed x mode (fused, RGB-D only, the fused run with the
   constant-tau surface, the speed-invariant surface and Eq. 2 as printed in place of the ATS, all on
   the D455 model's depth; and fused and RGB-D on the sharp depth of the simulator before it), per
   motion phase (stance, flight, landing) and in the format of the paper's Table III with the paper's
   real-robot figures beside;
3. tracking time per frame for each mode (median, p95, max), sequentially, on the first scenario;
4. end-to-end replays (``atsvo-replay``'s code) in a child process each: real-time factor and peak
   memory on a synthetic backflip and, in the full run, a 60 s running sequence; the backflip's
   trajectories of every mode in one figure;
5. real RGB-D data (TUM fr1_rpy in ``../shared/realdata``) against Open3D's odometry (``[peers]``);
6. any recording given with ``--recording`` (e.g. MVSEC indoor_flying), against the paper's figures.

Sequences are simulated once and cached (``$ATSVO_CACHE``); that generation runs first, in
parallel (``--jobs``), and its time is reported apart from the measurements. The accuracy runs are
deterministic and also run in parallel; timing runs never do.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import dataclasses
import datetime
import json
import multiprocessing as mp
import os
import platform
import shutil
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.bench.events import bench_decode, bench_real_decode, bench_time_surfaces
from atsvo_ros.bench.longrun import peak_rss_mb
from atsvo_ros.bench.paper import PAPER_MVSEC
from atsvo_ros.bench.real import DEFAULT_FOLDER, PAPER_VARIANT, bench_folder
from atsvo_ros.bench.report import README_BEGIN, README_END, markdown, readme_block
from atsvo_ros.bench.tracking import run_sequence, simulated_events, simulated_frames
from atsvo_ros.config import load_config
from atsvo_ros.errors import ConfigError
from atsvo_ros.eval.plots import plot_comparison
from atsvo_ros.sim.sequence import SequenceSpec
from atsvo_ros.tools._environment import library_versions
from atsvo_ros.tools.demo import cache_dir, ensure_sequence
from atsvo_ros.tools.replay import replay

#: Configuration overrides of each mode of the accuracy table (all replay the same event data).
MODES: dict[str, dict[str, Any]] = {
    "fused": {},
    "rgbd": {"mode": "rgbd"},
    "constant-tau": {"fusion.surface": "constant"},
    "speed-invariant": {"fusion.surface": "sits"},
    "eq2_printed": {"ats.tau_mode": "eq2_printed"},
    "fused, sharp depth": {},
    "rgbd, sharp depth": {"mode": "rgbd"},
    "fused + gyro": {},
    "rgbd + gyro": {"mode": "rgbd"},
}
#: The simulator's depth sensor of each mode: the D455 model, or the sharp depth of the simulator before it.
DEPTH = {m: ("sharp" if m.endswith("sharp depth") else "d455") for m in MODES}
#: Modes fed the IMU (the robot's D455 IMU): the gyro's rotation predicts, and turns each depth image to the
#: colour's time (``rig.depth_time_offset_s``).
IMU = {m: m.endswith("+ gyro") for m in MODES}
#: Seeds the parameters were tuned on (motion prior, fusion gates, thresholds): never reported as held out.
TUNING_SEEDS = (0, 1, 2, 3, 4)
#: Seeds no parameter was tuned on: the accuracy table's.
HELD_OUT_SEEDS = (100, 101, 102)
#: Every gait of the simulator.
GAITS = ("trot", "bound", "pronk", "backflip", "running", "flying")



@dataclasses.dataclass(frozen=True)
class Plan:
    """What one run measures."""

    scenarios: tuple[str, ...]
    seeds: tuple[int, ...]
    duration_s: float
    modes: tuple[str, ...]
    replay_running_60s: bool
    decode_events: int
    repeats: int
    open3d: tuple[str, ...]


QUICK = Plan(("backflip", "bound"), HELD_OUT_SEEDS[:1], 3.0, ("fused", "rgbd", "constant-tau", "rgbd, sharp depth"),
             False, 500_000, 1, ("point_to_plane",))
FULL = Plan(GAITS, HELD_OUT_SEEDS, 10.0, tuple(MODES), True, 2_000_000, 3, ("point_to_plane", "hybrid", "intensity"))


def machine() -> dict[str, Any]:
    """Where and when the run happened, and with what."""

    return {"date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "host": platform.node(), "platform": platform.platform(), "python": platform.python_version(),
            "cpus": os.cpu_count(), "load_avg_1min_at_start": os.getloadavg()[0], "versions": library_versions()}


# ----------------------------------------------------------------------------------------- workers
def _prepare(scenario: str, seed: int, duration_s: float, depths: tuple[str, ...]) -> float:
    """Simulate (or find cached) one sequence's frames (per depth sensor) and events; seconds spent."""

    t0 = time.perf_counter()
    for depth in depths:
        spec = SequenceSpec(scenario=scenario, duration_s=duration_s, seed=seed, depth=depth)
        simulated_frames(spec, progress=False)
    simulated_events(spec, progress=False)
    return time.perf_counter() - t0


def _prepare_bag(scenario: str, seed: int, duration_s: float) -> str:
    """Simulate (or find cached) one sequence as a bag, as ``atsvo-demo`` does; its path."""

    return str(ensure_sequence(cache_dir(), scenario, duration_s, seed, quiet=True))


def _accuracy_run(scenario: str, seed: int, duration_s: float, mode: str) -> dict[str, Any]:
    r = run_sequence(scenario, seed, duration_s, overrides=dict(MODES[mode]), progress=False, use_events=True,
                     depth=DEPTH[mode], use_imu=IMU[mode])
    return {"mode": mode, **r}


def _replay_child(bag: str, out: str, mode: str) -> dict[str, Any]:
    """One replay in a fresh process: its figures, its evaluation and the process's peak memory."""

    t0 = time.perf_counter()
    res = replay(Path(bag), Path(out), load_config("synthetic"), mode=mode, plots=False, progress=False)
    tt = res.tracking_time_s * 1e3
    return {"mode": res.mode, "bag": bag, "wall_s": time.perf_counter() - t0, "rtf": res.real_time_factor,
            "frames": len(res.stamps_ns), "peak_rss_mb": peak_rss_mb(),
            "track_ms_median": float(np.median(tt)), "track_ms_p95": float(np.percentile(tt, 95)),
            "metrics": res.metrics, "statuses": dict(Counter(res.statuses)), "evaluation": res.evaluation}


def _pool(jobs: int) -> cf.ProcessPoolExecutor:
    """Spawned workers (no fork of a process that runs threads)."""
    return cf.ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn"))


def _in_pools(fn: Any, tasks: list[tuple], jobs: int, per_worker: int) -> Iterator[Any]:
    """``fn(*task)`` for every task, in parallel, as they complete; a new pool every ``jobs * per_worker`` tasks.

    Fresh workers bound memory (a long-lived worker grows), but not by ``max_tasks_per_child``: on Python
    3.11-3.14 that deadlocks once a worker retires with tasks still queued (CPython gh-115634; it hung
    this benchmark after 9 of 126 runs).
    """
    step = max(1, jobs * per_worker)
    for i in range(0, len(tasks), step):
        with _pool(jobs) as pool:
            yield from (f.result() for f in cf.as_completed([pool.submit(fn, *t) for t in tasks[i:i + step]]))


# ----------------------------------------------------------------------------------------- sections
def speed_section(plan: Plan) -> dict[str, Any]:
    """Decoding, surface updates and render, ours against the peers (:mod:`bench_events`)."""

    return {"decode": bench_decode(plan.decode_events, 20_000, plan.repeats),
            "decode_real": bench_real_decode(plan.repeats), "time_surfaces": bench_time_surfaces(plan.repeats)}


def accuracy_section(plan: Plan, jobs: int, log: Any) -> list[dict[str, Any]]:
    """Every scenario x seed x mode, in parallel (each run is deterministic)."""
    runs = [(sc, seed, plan.duration_s, mode) for sc in plan.scenarios for seed in plan.seeds for mode in plan.modes]
    rows = []
    # fresh workers every few runs: two long-lived ones grew to 11-12 GB over ~70 10 s runs (OOM-killed on
    # 24 GB) while one run peaks at ~2 GB
    for row in _in_pools(_accuracy_run, runs, jobs, per_worker=4):
        rows.append(row)
        log(f"  accuracy {row['scenario']} seed {row['seed']} {row['mode']}: ATE {row['ate_rmse_cm']:.2f} cm, "
            f"{row['statuses']}")
    order = {(sc, s, m): i for i, (sc, s, _, m) in enumerate(runs)}
    return sorted(rows, key=lambda r: order[(r["scenario"], r["seed"], r["mode"])])


def timing_section(plan: Plan) -> list[dict[str, Any]]:
    """Tracking time per frame of each mode, one run at a time on the backflip (the highest event rate; else the
    first scenario), on the first seed of the plan."""

    scenario = "backflip" if "backflip" in plan.scenarios else plan.scenarios[0]
    rows = []
    for mode in ("fused", "rgbd", "fused + gyro"):
        r = run_sequence(scenario, plan.seeds[0], plan.duration_s, overrides=dict(MODES[mode]),
                         progress=False, use_events=True, use_imu=IMU[mode])
        rows.append({"mode": mode, "scenario": r["scenario"], "seed": r["seed"], "frames": r["frames"],
                     "ms_median": r["latency_ms_p50"], "ms_p95": r["latency_ms_p95"], "ms_max": r["latency_ms_max"],
                     "fused_ms_median": r["fused_ms_median"], "fused_ms_p95": r["fused_ms_p95"],
                     "event_map_ms_median": r["event_map_ms_median"], "modes": r["modes"], "events": r["events"]})
    return rows


def replay_section(plan: Plan, bags: dict[str, str], out: Path, log: Any) -> list[dict[str, Any]]:
    """End-to-end replays, each in a fresh process (peak memory is the process's own)."""
    rows = []
    for name, bag in bags.items():
        for mode in ("fused", "rgbd"):
            (r,) = _in_pools(_replay_child, [(bag, str(out / "replays" / f"{name}_{mode}"), mode)], 1, 1)
            r["sequence"] = name
            rows.append(r)
            m = r["metrics"] or {}
            log(f"  replay {name} {mode}: RTF {r['rtf']:.2f}, peak {r['peak_rss_mb']:.0f} MiB, "
                f"ATE {m.get('ate_rmse_m', float('nan')) * 100:.2f} cm")
    return rows


def real_section(plan: Plan, out: Path) -> dict[str, Any] | None:
    """TUM fr1_rpy (300 frames) against Open3D (when installed), as ``atsvo-bench real``."""

    if not DEFAULT_FOLDER.is_dir():
        return {"skipped": f"{DEFAULT_FOLDER} not found"}
    methods: tuple[str, ...] = plan.open3d
    note = None
    try:
        import open3d  # noqa: F401
    except ImportError as exc:
        methods, note = (), f"Open3D rows skipped: {exc} (pip install 'atsvo_ros[peers]')"
    seq = bench_folder(DEFAULT_FOLDER, None, {}, [PAPER_VARIANT], list(methods), out / "real", progress=False)
    seq["notes"] = [note] if note else []
    return seq


def recording_section(path: Path, out: Path, preset: str | None) -> dict[str, Any]:
    """Replay one recording with its preset and score it; the paper's figures beside when it names them."""

    cfg = load_config(preset) if preset else None
    res = replay(path, out / "recordings" / path.stem, cfg, plots=True, progress=False)
    key = next((k for k in PAPER_MVSEC if k in path.name), None)
    return {"recording": str(path), "mode": res.mode, "metrics": res.metrics, "rtf": res.real_time_factor,
            "statuses": dict(Counter(res.statuses)), "paper": None if key is None else dict(zip(
                ("rpe_deg_per_deg", "rpe_cm_per_deg", "ate_cm", "rpe_deg_per_frame", "rpe_cm_per_frame"),
                PAPER_MVSEC[key]))}


# ----------------------------------------------------------------------------------------- run
def run_all(out: Path, quick: bool = False, recordings: tuple[Path, ...] = (), preset: str | None = None,
            jobs: int = 2, log: Any = print) -> dict[str, Any]:
    """Run every part of the plan; returns what results.json holds (also written, with results.md)."""
    plan = QUICK if quick else FULL
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"plan": "quick" if quick else "full", "settings": dataclasses.asdict(plan),
                               "machine": machine()}
    t_start = time.perf_counter()
    log("generating (or finding cached) sequences ...")
    t0 = time.perf_counter()
    bag_specs = {f"backflip_{plan.duration_s:g}s": ("backflip", plan.seeds[0], plan.duration_s)}
    if plan.replay_running_60s:
        bag_specs["running_60s"] = ("running", plan.seeds[0], 60.0)
    with _pool(jobs) as pool:
        depths = tuple(sorted({DEPTH[m] for m in plan.modes}))
        prep = [pool.submit(_prepare, sc, seed, plan.duration_s, depths) for sc in plan.scenarios
                for seed in plan.seeds]
        bag_futs = {name: pool.submit(_prepare_bag, *spec) for name, spec in bag_specs.items()}
        for f in prep:
            f.result()
        bags = {name: f.result() for name, f in bag_futs.items()}
    results["generation_s"] = time.perf_counter() - t0
    log(f"  {results['generation_s']:.0f} s")
    t_measure = time.perf_counter()
    log("speed of the event front end ...")
    results["speed"] = speed_section(plan)
    log("accuracy (scenario x seed x mode) ...")
    results["accuracy"] = accuracy_section(plan, jobs, log)
    log("tracking time per mode ...")
    results["timing"] = timing_section(plan)
    log("end-to-end replays ...")
    replays = replay_section(plan, bags, out, log)
    evs = {r["mode"]: r["evaluation"] for r in replays
           if r["sequence"].startswith("backflip") and r["evaluation"] is not None}
    if evs:
        results["figure"] = str(plot_comparison(out / "backflip.png", evs, title=f"synthetic backflip, "
                                                f"{plan.duration_s:g} s, seed {plan.seeds[0]}: fused and RGB-D only"))
    for r in replays:
        r.pop("evaluation", None)
    results["replay"] = replays
    log("real RGB-D data against Open3D ...")
    results["real"] = real_section(plan, out)
    results["recordings"] = [recording_section(Path(p), out, preset) for p in recordings]
    results["measure_s"] = time.perf_counter() - t_measure
    results["total_s"] = time.perf_counter() - t_start
    (out / "results.json").write_text(json.dumps(results, indent=1, default=str) + "\n")

    (out / "results.md").write_text(markdown(results))
    return results


def update_readme(readme: Path, results: dict[str, Any], results_md: Path, figure: Path | None) -> Path:
    """Write ``docs/results.md`` (results.md) next to the README and fill the README's results block with the
    summary (:func:`~atsvo_ros.bench.report.readme_block`); the figure is copied to ``docs/``. The full page."""

    text = readme.read_text()
    if README_BEGIN not in text or README_END not in text:
        raise ConfigError(f"{readme} has no {README_BEGIN} ... {README_END} block to fill")
    docs = readme.parent / "docs"
    docs.mkdir(parents=True, exist_ok=True)
    fig_rel = None
    if figure is not None and figure.is_file():
        shutil.copyfile(figure, docs / "results_backflip.png")
        fig_rel = "docs/results_backflip.png"
    full = docs / "results.md"
    body = results_md.read_text()
    if fig_rel:
        figure_line = "![The synthetic backflip: fused and RGB-D-only trajectories](results_backflip.png)"
        body = body.replace("\n\n", f"\n\n{figure_line}\n\n", 1)
    full.write_text(f"<!-- generated by atsvo-bench --readme; do not edit by hand -->\n{body}")
    head, rest = text.split(README_BEGIN, 1)
    _, tail = rest.split(README_END, 1)
    readme.write_text(head + README_BEGIN + "\n" + readme_block(results, fig_rel, "docs/results.md") + README_END
                      + tail)
    return full


def add_all_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the whole run (the ``atsvo-bench`` command without a subcommand)."""
    p.add_argument("--quick", action="store_true", help="the short plan: under 5 minutes on 2 cores (warm cache)")
    p.add_argument("--out", default=None, help="write results.json, results.md and the figures here")
    p.add_argument("--recording", action="append", default=[], metavar="PATH",
                   help="also replay this recording (bag, MVSEC HDF5, TUM folder) and score it (repeatable)")
    p.add_argument("--preset", default=None, help="config preset for the --recording runs (default: detected)")
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                   help="processes for the simulation and the accuracy runs (timing runs are always alone)")
    p.add_argument("--readme", default=None, metavar="README.md",
                   help="after the run, fill the README's results block with results.md")


def main_all(args: argparse.Namespace) -> int:
    if not args.out:
        raise ConfigError("atsvo-bench needs --out DIR (or a subcommand: atsvo-bench --help)")
    out = Path(args.out)
    res = run_all(out, args.quick, tuple(Path(p) for p in args.recording), args.preset, max(1, args.jobs),
                  log=lambda s: print(s, flush=True))
    print((out / "results.md").read_text())
    print(f"wrote {out / 'results.json'} and {out / 'results.md'} ({res['total_s'] / 60:.1f} min, of which "
          f"{res['generation_s'] / 60:.1f} min generating sequences)", file=sys.stderr)
    if args.readme:
        fig = res.get("figure")
        full = update_readme(Path(args.readme), res, out / "results.md", Path(fig) if fig else None)
        print(f"updated {args.readme} and wrote {full}", file=sys.stderr)
    return 0
