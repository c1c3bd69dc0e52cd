"""Test helper: counts how many camera-sized images cross between two processes over DDS.

Not a benchmark of ours and not collected by pytest: it measures the middleware set-up (Fast DDS
profile, QoS), which decides whether 640x480 frames at 30 Hz survive at all. Run it in a venv with
the ``ros`` extra::

    python test/nodes/dds_image_probe.py                       # matrix: default/ours x best_effort/reliable
    python test/nodes/dds_image_probe.py --profile none --reliability best_effort --streams rgb8

Each case starts a subscriber process, then a publisher process that sends ``--frames`` images per
stream at ``--rate_hz`` once it has matched the subscriber, and prints the subscriber's counts.
Discovery is kept on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) on a random domain id, unless
``--discovery_range SUBNET`` (the robot's default) is asked for inside a loopback-only network namespace.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUR_PROFILE = ROOT / "config" / "fastdds_shm.xml"
PROFILE_VARS = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
STREAMS = {"rgb8": 3, "16UC1": 2}  # encoding -> bytes per pixel
WIDTH, HEIGHT = 640, 480


def _qos(reliability: str, depth: int):
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    policy = ReliabilityPolicy.RELIABLE if reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=policy)


def _publish(args: argparse.Namespace) -> None:
    import numpy as np
    import rclpy
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("probe_pub")
    pubs, msgs = [], []
    for enc in args.streams:
        qos = _qos(args.pub_reliability, args.depth)
        pubs.append(node.create_publisher(Image, f"probe/image_{enc.lower()}", qos))
        msg = Image(height=HEIGHT, width=WIDTH, encoding=enc, step=WIDTH * STREAMS[enc])
        msg.data = np.random.default_rng(0).integers(0, 255, HEIGHT * WIDTH * STREAMS[enc], np.uint8).tobytes()
        msgs.append(msg)
    deadline = time.monotonic() + 20.0
    while any(p.get_subscription_count() == 0 for p in pubs):
        if time.monotonic() > deadline:
            raise SystemExit("publisher: no subscriber matched within 20 s")
        time.sleep(0.05)
    time.sleep(0.5)  # let the reader side finish matching the writers too
    period_s = 1.0 / args.rate_hz
    t0 = time.monotonic()
    for i in range(args.frames):
        stamp = node.get_clock().now().to_msg()
        for pub, msg in zip(pubs, msgs):
            msg.header.stamp = stamp
            msg.header.frame_id = str(i)
            pub.publish(msg)
        time.sleep(max(0.0, t0 + (i + 1) * period_s - time.monotonic()))
    time.sleep(1.0)  # keep the writer alive while reliable repairs finish
    node.destroy_node()
    rclpy.try_shutdown()


def _subscribe(args: argparse.Namespace) -> None:
    import rclpy
    from rclpy.time import Time
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("probe_sub")
    counts = {enc: 0 for enc in args.streams}
    latency_s = {enc: [] for enc in args.streams}
    last = [time.monotonic()]

    def callback(enc: str):
        def on_image(msg: Image) -> None:
            counts[enc] += 1
            latency_s[enc].append((node.get_clock().now() - Time.from_msg(msg.header.stamp)).nanoseconds * 1e-9)
            last[0] = time.monotonic()
        return on_image

    for enc in args.streams:
        qos = _qos(args.sub_reliability, args.depth)
        node.create_subscription(Image, f"probe/image_{enc.lower()}", callback(enc), qos)
    print("ready", flush=True)
    start = time.monotonic()
    while time.monotonic() - start < args.timeout_s:
        rclpy.spin_once(node, timeout_sec=0.1)
        if all(c >= args.frames for c in counts.values()):
            break
        if any(counts.values()) and time.monotonic() - last[0] > 2.0:
            break
    lat = {enc: round(1e3 * sorted(v)[len(v) // 2], 2) if v else None for enc, v in latency_s.items()}
    print(json.dumps({"counts": counts, "median_latency_ms": lat}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def _child_env(profile: str, profile_var: str, discovery_range: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in PROFILE_VARS}
    env["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range
    if profile != "none":
        env[profile_var] = str(OUR_PROFILE if profile == "ours" else Path(profile).resolve())
    return env


def run_case(args: argparse.Namespace, profile: str, reliability: str) -> dict:
    """Runs one subscriber + one publisher process and returns the subscriber's report."""
    common = ["--frames", str(args.frames), "--rate_hz", str(args.rate_hz), "--depth", str(args.depth),
              "--streams", *args.streams]
    pub_rel = args.pub_reliability or reliability
    sub_rel = args.sub_reliability or reliability
    env = _child_env(profile, args.profile_var, args.discovery_range)
    sub = subprocess.Popen([sys.executable, __file__, "sub", *common, "--sub_reliability", sub_rel],
                           env=env, stdout=subprocess.PIPE, text=True)
    try:
        assert sub.stdout is not None
        if sub.stdout.readline().strip() != "ready":
            raise SystemExit("subscriber did not start")
        subprocess.run([sys.executable, __file__, "pub", *common, "--pub_reliability", pub_rel],
                       env=env, check=True, timeout=120)
        out, _ = sub.communicate(timeout=60)
    finally:
        if sub.poll() is None:
            sub.kill()
    report = json.loads(out.strip().splitlines()[-1])
    report.update(profile=profile, pub=pub_rel, sub=sub_rel)
    return report


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", nargs="?", default="matrix", choices=["matrix", "pub", "sub"])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--rate_hz", type=float, default=30.0)
    ap.add_argument("--depth", type=int, default=10, help="KEEP_LAST history depth on both ends")
    ap.add_argument("--streams", nargs="+", default=["rgb8"], choices=sorted(STREAMS))
    ap.add_argument("--profile", nargs="+", default=["none", "ours"],
                    help="'none' (Fast DDS defaults), 'ours' (config/fastdds_shm.xml) or an XML path")
    ap.add_argument("--profile_var", default=PROFILE_VARS[0], choices=PROFILE_VARS,
                    help="environment variable that names the profile to the children")
    ap.add_argument("--discovery_range", default="LOCALHOST", choices=["LOCALHOST", "SUBNET"],
                    help="SUBNET multicasts discovery out of every interface: use it only inside a network "
                         "namespace that has nothing but loopback")
    ap.add_argument("--reliability", nargs="+", default=["best_effort", "reliable"])
    ap.add_argument("--pub_reliability", default=None, help="override the publisher's reliability")
    ap.add_argument("--sub_reliability", default=None, help="override the subscriber's reliability")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--timeout_s", type=float, default=60.0)
    args = ap.parse_args(argv)
    if args.mode == "pub":
        _publish(args)
    elif args.mode == "sub":
        _subscribe(args)
    else:
        for profile in args.profile:
            for reliability in args.reliability:
                for _ in range(args.repeat):
                    print(json.dumps(run_case(args, profile, reliability)), flush=True)


if __name__ == "__main__":
    main()
