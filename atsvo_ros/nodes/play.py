"""``atsvo-play``: publish a ROS 2 bag to running nodes and record what the odometry answers, without ``ros2``.

With only the pip wheels (no ``ros2 bag play``, no ``ros2 topic echo``), this feeds ``atsvo_node`` in
another shell (``source .ci/ros_env.sh`` in both: same ROS_DOMAIN_ID) and watches ``/atsvo/odometry``
like a controller::

    atsvo_node --ros-args --params-file config/synthetic.yaml      # shell 1
    atsvo-play BAG --tum odometry.tum                              # shell 2

It waits for the node to subscribe, plays the bag at ``--rate`` times its recorded timing (sensor-data
QoS, or ``--reliable`` like ``ros2 bag play``, for the node's loss-free mode), prints a line a second
while playing, then one summary line, and with ``--tum`` writes the odometry it received.
"""
from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import rclpy
from rclpy.executors import MultiThreadedExecutor

from atsvo_ros.config import load_config, parse_overrides
from atsvo_ros.errors import AtsvoError
from atsvo_ros.io.trajectory import Trajectory, write_tum
from atsvo_ros.nodes.player import BagPlayer, OdometryProbe, spin_in_background, stop_spinning


def _main(args: argparse.Namespace) -> int:
    if not args.rate > 0:
        raise AtsvoError(f"--rate must be positive, got {args.rate:g}")
    bag = Path(args.bag)
    if not (bag / "metadata.yaml").is_file() and bag.suffix not in (".mcap", ".db3"):
        raise AtsvoError(f"{bag} is not a ROS 2 bag (a folder with metadata.yaml, or an .mcap / .db3 file)")
    if args.tum:
        Path(args.tum).parent.mkdir(parents=True, exist_ok=True)
    config = load_config(args.config or "mini_cheetah", overrides=parse_overrides(args.set))
    t = config.topics
    rclpy.init()
    executor = spinner = node = None
    done = threading.Event()
    try:
        node = rclpy.create_node("atsvo_play")
        player = BagPlayer(node, bag, [t.rgb, t.depth, t.rgb_info, t.event_info, t.events, t.imu], t.rgb, t.depth,
                           t.events, reliable=args.reliable)
        probe = OdometryProbe(node, config)
        executor = MultiThreadedExecutor(num_threads=2)
        executor.add_node(node)
        spinner = spin_in_background(executor)
        print(f"atsvo-play: {bag.name}: {player.n_frames} frames; waiting for a subscriber on {t.rgb} "
              f"and {t.depth}", file=sys.stderr)
        if not player.wait_for_subscribers(args.wait_s, [t.rgb, t.depth]):
            raise AtsvoError(f"nothing subscribed to {t.rgb} within {args.wait_s:g} s: is atsvo_node running, "
                             "on this ROS_DOMAIN_ID, with the same topics (--config)?")
        time.sleep(0.5)  # a reader can match a moment after its writer

        def report() -> None:
            while not done.wait(1.0):
                stamps, poses = probe.poses()
                where = f", last at x={poses[-1][0, 3]:+.3f} y={poses[-1][1, 3]:+.3f} z={poses[-1][2, 3]:+.3f} m" \
                    if len(poses) else ""
                print(f"atsvo-play: {len(stamps)} odometry received{where}", file=sys.stderr)

        threading.Thread(target=report, daemon=True).start()
        played = player.play(rate=args.rate)
        n = probe.wait_idle(len(played.frame_stamps_ns), idle_s=3.0)
        done.set()
        stamps, poses = probe.poses()
        statuses = probe.statuses()
        counts = {s: statuses.count(s) for s in sorted(set(statuses))}
        print(f"atsvo-play: played {len(played.frame_stamps_ns)} frames at {args.rate:g}x; {n} odometry received "
              f"({', '.join(f'{k} {v}' for k, v in counts.items()) or 'no status'})")
        if args.tum:
            if len(stamps):
                write_tum(args.tum, Trajectory(stamps, poses), header=f"atsvo-play {bag.name}: {t.odometry}")
                print(f"wrote {args.tum}")
            else:
                print(f"atsvo-play: no odometry received: {args.tum} not written", file=sys.stderr)
        return 0 if n else 1
    finally:
        done.set()
        if executor is not None:
            stop_spinning(executor, spinner)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="atsvo-play", description="Publish a ROS 2 bag to the running odometry "
                                "nodes over DDS and record the odometry they publish (no ROS install needed).")
    p.add_argument("bag", help="a ROS 2 bag (folder with metadata.yaml, or .mcap), e.g. from atsvo-sim")
    p.add_argument("--rate", type=float, default=1.0, help="playback speed, times the recorded timing (default 1)")
    p.add_argument("--reliable", action="store_true",
                   help="publish reliable keep-all (like ros2 bag play; the node's loss-free mode wants it)")
    p.add_argument("--tum", help="write the odometry received to this TUM file")
    p.add_argument("--wait-s", type=float, default=60.0, help="how long to wait for the node to subscribe")
    p.add_argument("--config", default=None, help="the nodes' ROS-parameter YAML or a preset (its topics are "
                   "played and watched; default mini_cheetah)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one parameter")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-play``: errors are one line and exit code 1."""
    args = build_parser().parse_args(argv)
    try:
        return _main(args)
    except AtsvoError as exc:
        print(f"atsvo-play: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("atsvo-play: interrupted", file=sys.stderr)
        return 130


__all__ = ["build_parser", "main"]
