"""``atsvo-bench [--quick] --out DIR`` runs every benchmark (:mod:`atsvo_ros.tools.bench_all`); ``atsvo-bench
SUBCOMMAND`` runs one. Benchmarks, never timed tests. Subcommands live in their own modules and are
registered in :data:`SUBCOMMANDS` with one line each."""
from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from atsvo_ros.tools._cli import run

#: name -> (module, function adding the arguments, function running it, one-line help)
SUBCOMMANDS: dict[str, tuple[str, str, str, str]] = {
    "events": ("atsvo_ros.tools.bench_events", "add_events_args", "main_events",
               "event decoding and time-surface speed vs rosbags and dv-processing"),
    "tracking": ("atsvo_ros.tools.bench_tracking", "add_tracking_args", "main_tracking",
                 "tracking time per frame and accuracy on synthetic legged-robot sequences (RGB-D, --events: fused)"),
    "longrun": ("atsvo_ros.tools.bench_longrun", "add_longrun_args", "main_longrun",
                "memory (RSS per minute) and latency over a long synthetic run: is anything growing?"),
    "nodes": ("atsvo_ros.nodes.bench_nodes", "add_nodes_args", "main_nodes",
              "ROS nodes over loopback DDS: frame-stamp-to-odometry latency, drops and memory at 1x / 3x the "
              "sustainable frame rate"),
    "real": ("atsvo_ros.tools.bench_real", "add_real_args", "main_real",
             "our RGB-D odometry vs Open3D's on real TUM RGB-D sequences (ATE, RPE, time, wrong-but-ok frames)"),
    "ats-basin": ("atsvo_ros.tools.bench_ats", "add_ats_basin_args", "main_ats_basin",
                  "convergence basin of the ATS term alone per decay rule (synthetic, simulated and real events)"),
}


def build_parser() -> argparse.ArgumentParser:
    from atsvo_ros.tools.bench_all import add_all_args

    p = argparse.ArgumentParser(prog="atsvo-bench", description="every benchmark in one run, side by side with the "
                                "peers (results.json, results.md), or one of them with a subcommand")
    add_all_args(p)
    sub = p.add_subparsers(dest="command", required=False)
    for name, (module, add_args, main_fn, help_text) in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        getattr(importlib.import_module(module), add_args)(sp)
        sp.set_defaults(_target=(module, main_fn))
    return p


def _dispatch(args: argparse.Namespace) -> int:
    if args.command is None:
        from atsvo_ros.tools.bench_all import main_all

        return main_all(args)
    module, main_fn = args._target
    return int(getattr(importlib.import_module(module), main_fn)(args) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    return run(_dispatch, build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
