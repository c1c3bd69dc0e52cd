"""``atsvo-bench SUBCOMMAND``: benchmarks (never timed tests). Subcommands live in their own modules
and are registered in :data:`SUBCOMMANDS` with one line each."""
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
                 "RGB-D tracking time per frame and accuracy on synthetic trot/flying sequences"),
    "nodes": ("atsvo_ros.tools.bench_nodes", "add_nodes_args", "main_nodes",
              "ROS nodes over loopback DDS: frame-stamp-to-odometry latency, drops and memory at 1x / 3x the "
              "sustainable frame rate"),
    "real": ("atsvo_ros.tools.bench_real", "add_real_args", "main_real",
             "our RGB-D odometry vs Open3D's on real TUM RGB-D sequences (ATE, RPE, time, wrong-but-ok frames)"),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atsvo-bench", description=__doc__.split("\n")[0].strip("`: "))
    sub = p.add_subparsers(dest="command", required=True)
    for name, (module, add_args, main_fn, help_text) in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        getattr(importlib.import_module(module), add_args)(sp)
        sp.set_defaults(_target=(module, main_fn))
    return p


def _dispatch(args: argparse.Namespace) -> int:
    module, main_fn = args._target
    return int(getattr(importlib.import_module(module), main_fn)(args) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    return run(_dispatch, build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
