"""``atsvo-bench [--quick] --out DIR`` runs every benchmark (:mod:`atsvo_ros.bench.suite`); ``atsvo-bench
SUBCOMMAND`` runs one. Benchmarks, never timed tests. Subcommands live in their own modules and are
registered in :data:`SUBCOMMANDS` with one line each."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from atsvo_ros.bench import ats, ats_quality, events, longrun, nodes, real, tracking
from atsvo_ros.bench.suite import add_all_args, main_all
from atsvo_ros.tools._cli import prepare_out_dir, run

AddArgs = Callable[[argparse.ArgumentParser], None]
Main = Callable[[argparse.Namespace], "int | None"]

#: name -> (function adding the arguments, function running it, one-line help)
SUBCOMMANDS: dict[str, tuple[AddArgs, Main, str]] = {
    "events": (events.add_events_args, events.main_events,
               "event decoding and time-surface speed vs rosbags and dv-processing"),
    "tracking": (tracking.add_tracking_args, tracking.main_tracking,
                 "tracking time per frame and accuracy on synthetic legged-robot sequences (RGB-D, --events: fused)"),
    "longrun": (longrun.add_longrun_args, longrun.main_longrun,
                "memory (RSS per minute) and latency over a long synthetic run: is anything growing?"),
    "nodes": (nodes.add_nodes_args, nodes.main_nodes,
              "ROS nodes over loopback DDS: frame-stamp-to-odometry latency, drops and memory at 1x / 3x the "
              "sustainable frame rate"),
    "real": (real.add_real_args, real.main_real,
             "our RGB-D odometry vs Open3D's on real TUM RGB-D sequences (ATE, RPE, time, wrong-but-ok frames)"),
    "ats-basin": (ats.add_ats_basin_args, ats.main_ats_basin,
                  "convergence basin of the ATS term alone per decay rule (synthetic, simulated and real events)"),
    "ats-quality": (ats_quality.add_ats_quality_args, ats_quality.main_ats_quality,
                    "white-out and black-out of each time surface over dense and sparse texture, stand to flip"),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atsvo-bench", description="every benchmark in one run, side by side with the "
                                "peers (results.json, results.md), or one of them with a subcommand")
    add_all_args(p)
    sub = p.add_subparsers(dest="command", required=False)
    for name, (add_args, main_fn, help_text) in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        add_args(sp)
        sp.set_defaults(_target=main_fn)
    return p


def _dispatch(args: argparse.Namespace) -> int:
    if getattr(args, "out", None):  # an unusable --out fails now, not after the benchmark
        prepare_out_dir(args.out)
    if args.command is None:
        return main_all(args)
    return int(args._target(args) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    return run(_dispatch, build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
