"""``atsvo-sim``: generate a synthetic legged-robot sequence (RGB-D, events, ground truth) as a bag.

Example: ``atsvo-sim --scenario backflip --duration 10 --seed 1 --out out/backflip`` writes a ROS 2
mcap bag directory with the robot's topics (cameras, events, IMU, ground truth), ``groundtruth.tum``
and ``sequence.yaml``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from atsvo_ros.errors import ConfigError, OutputError
from atsvo_ros.sim.events import MAX_CONTRAST, MAX_NOISE_RATE_HZ, MAX_REFRACTORY_S, MAX_SCAN_PERIOD_S, EventModel
from atsvo_ros.sim.motion import SCENARIOS
from atsvo_ros.sim.sequence import (
    DEPTH_MODELS,
    LAYOUTS,
    MAX_DURATION_S,
    MAX_RATE_HZ,
    MAX_SEED,
    MAX_TEXTURE_SIZE,
    MIN_EVENT_PACKET_S,
    SequenceSpec,
    with_sensors,
)
from atsvo_ros.sim.stereo import MAX_IR_LIGHT, StereoModel
from atsvo_ros.sim.writer import EVENT_ENCODINGS, EVENT_MSGS, FORMATS, write_sequence
from atsvo_ros.tools._cli import run
from atsvo_ros.tools._help import description


def check_out_parent(out: str | Path) -> None:
    """Fail now, before the generation, when ``out`` cannot be written.

    The simulator writes into a temporary folder next to ``out`` (creating missing parent folders) and renames
    it when complete, so the nearest existing parent must be a writable folder; with ``--force`` an existing
    ``out`` is emptied too. What ``out`` may already hold is the writer's check (it refuses foreign files).

    Raises:
        OutputError: one line naming the file in the way or the folder that cannot be written.
    """
    out = Path(out)
    parent = out.parent
    existing = next(p for p in (parent, *parent.parents) if p.exists() or p.is_symlink())
    if not existing.is_dir():
        raise OutputError(f"--out {out} is under {existing}, which is not a folder")
    folders = [existing] + ([out] if out.is_dir() and any(out.iterdir()) else [])
    for folder in folders:
        try:
            with tempfile.TemporaryFile(dir=folder):
                pass
        except OSError as exc:
            raise OutputError(f"--out {out}: cannot write in {folder}: {exc.strerror or exc}") from None


def _main(args: argparse.Namespace) -> int:
    resized = [f for f, on in (("--width", args.width is not None), ("--height", args.height is not None),
                               ("--event-scale", args.event_scale != 1.0)) if on]
    if args.layout == "mvsec" and resized and args.config is None:
        # the mvsec preset a replay takes for this bag fixes the DAVIS346's 346x260 (camera_info is not used)
        raise ConfigError(f"{' and '.join(resized)} with --layout mvsec: the bag would not replay with the mvsec "
                          "preset (the DAVIS346, 346x260); give --config with a rig of that size, or leave them out")
    check_out_parent(args.out)
    spec = SequenceSpec(scenario=args.scenario, duration_s=args.duration, seed=args.seed, layout=args.layout,
                        config=args.config, width=args.width, height=args.height, rate_hz=args.rate,
                        exposure_s=args.exposure, gt_rate_hz=args.gt_rate, event_packet_s=args.packet_ms * 1e-3,
                        event_scale=args.event_scale, texture_size=args.texture_size, imu=not args.no_imu)
    spec = with_sensors(spec, contrast=args.contrast, noise_rate_hz=args.noise_rate, ambient_ir=args.ir_ambient)
    spec = dataclasses.replace(spec, event_model=_event_model(spec.event_model, args))
    if args.rgb_readout or args.rgb_stamp_jitter or args.rgb_stamp_latency:
        spec = dataclasses.replace(spec, rgb_model=dataclasses.replace(
            spec.rgb_model, readout_time_s=args.rgb_readout, stamp_jitter_s=args.rgb_stamp_jitter,
            stamp_latency_s=args.rgb_stamp_latency))
    stereo: dict = {}
    if args.ir_exposure is not None:
        stereo["exposure_s"] = args.ir_exposure
    if args.depth_phase is not None:
        stereo["phase_s"] = args.depth_phase
    spec = dataclasses.replace(spec, depth=args.depth,
                               stereo_model=dataclasses.replace(spec.stereo_model, **stereo))
    summary = write_sequence(spec, args.out, fmt=args.format, event_msg=args.event_msg, encoding=args.encoding,
                             force=args.force, progress=not args.quiet)
    print(f"{args.scenario} {args.duration:g} s seed {args.seed}: {summary['frames']} RGB-D frames, "
          f"{summary['events']} events in {summary['event_packets']} packets "
          f"({summary['event_renders']} event renders, {summary['rgb_renders']} colour sub-frames), "
          f"{summary['poses']} poses, {summary['imu_samples']} IMU samples; "
          f"{summary['wall_s']:.1f} s wall -> {summary['bag']}", file=sys.stderr)
    print(f"what the sensors gave (depth: {summary['depth_sensor']}):\n{summary['phase_table']}", file=sys.stderr)
    return 0


def _event_model(em: EventModel, args: argparse.Namespace) -> EventModel:
    """The event model with the command line's readout overrides (a new scan period keeps the column sweep's
    share of it; contrast and noise go through :func:`~atsvo_ros.sim.sequence.with_sensors`)."""
    changes: dict = {}
    if args.refractory_us is not None:
        changes["refractory_s"] = args.refractory_us * 1e-6
    if args.scan_period_us is not None:
        changes.update(scan_period_s=args.scan_period_us * 1e-6,
                       scan_sweep_s=args.scan_period_us * 1e-6 * em.scan_sweep_s / em.scan_period_s)
    return dataclasses.replace(em, **changes)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-sim``."""
    p = argparse.ArgumentParser(prog="atsvo-sim", description=description(__doc__))
    p.add_argument("--scenario", required=True, choices=SCENARIOS)
    p.add_argument("--duration", type=float, default=10.0,
                   help=f"seconds, at most {MAX_DURATION_S:g} (default 10; the bag grows by ~20 MB per simulated "
                        "second at 320x240)")
    p.add_argument("--seed", type=int, default=0,
                   help=f"scene, motion and noise seed, 0 to {MAX_SEED} (default 0)")
    p.add_argument("--out", required=True, help="output directory (ROS 2 bag directory, or holds sequence.bag)")
    p.add_argument("--format", default="mcap", choices=FORMATS, help="bag container (default mcap)")
    p.add_argument("--layout", default="robot", choices=LAYOUTS,
                   help="topics/types: the robot's drivers or MVSEC's (default robot)")
    p.add_argument("--config", default=None,
                   help="rig preset or YAML (default: synthetic, or mvsec for --layout mvsec)")
    p.add_argument("--width", type=int, default=None,
                   help="colour image width, 8 to 4096 px (intrinsics scale with it; the D455's IR images keep "
                        "their size)")
    p.add_argument("--height", type=int, default=None, help="colour image height, 8 to 4096 px")
    p.add_argument("--rate", type=float, default=30.0,
                   help=f"RGB-D frame rate in Hz, at most {MAX_RATE_HZ:g} (default 30)")
    p.add_argument("--exposure", type=float, default=0.008,
                   help="colour exposure time in s, up to 0.1 and one frame period (motion blur; 0.008)")
    p.add_argument("--rgb-readout", type=float, default=0.0,
                   help="colour rolling-shutter readout in s, 0 to 0.1 (default 0: global shutter as the D455; "
                        "~0.028 for a Kinect v1)")
    p.add_argument("--rgb-stamp-jitter", type=float, default=0.0,
                   help="scale in s of the delay between a colour/depth image's exposure and its stamp, 0 to 0.005 "
                        "(default 0: hardware stamps as the D455's; ~0.002 for a host-stamped Kinect v1)")
    p.add_argument("--rgb-stamp-latency", type=float, default=0.0,
                   help="constant delay in s of every colour/depth stamp after the exposure, on top of the jitter, "
                        "0 to 0.1 (default 0; ~0.010 for TUM's Kinect v1 against its motion capture)")
    p.add_argument("--gt-rate", type=float, default=200.0,
                   help=f"ground-truth pose rate in Hz, at most {MAX_RATE_HZ:g} (default 200)")
    p.add_argument("--event-msg", default="packet", choices=EVENT_MSGS,
                   help="layout robot: event_camera_msgs/EventPacket (packet) or dvs_msgs/EventArray (dvs)")
    p.add_argument("--encoding", default="libcaer_cmp", choices=EVENT_ENCODINGS, help="EventPacket encoding")
    p.add_argument("--packet-ms", type=float, default=1.0,
                   help=f"event packet length in ms, {MIN_EVENT_PACKET_S * 1e3:g} (one event clock tick) to 1000 "
                        "(default 1)")
    p.add_argument("--event-scale", type=float, default=1.0, help="scale the event sensor size, 0.05 to 4 (tests)")
    p.add_argument("--texture-size", type=int, default=512,
                   help=f"texture side in texels, a power of two from 8 to {MAX_TEXTURE_SIZE} (default 512)")
    em = EventModel()
    p.add_argument("--contrast", type=float, default=None,
                   help=f"event contrast threshold C+ = C- in log units, up to {MAX_CONTRAST:g} (default "
                        f"{em.contrast_pos:g})")
    p.add_argument("--noise-rate", type=float, default=None,
                   help=f"background events per pixel per s, 0 to {MAX_NOISE_RATE_HZ:g} (default "
                        f"{em.noise_rate_hz:g})")
    p.add_argument("--scan-period-us", type=float, default=None,
                   help=f"event readout scan period in us, 0 to {MAX_SCAN_PERIOD_S * 1e6:g} (default "
                        f"{em.scan_period_s * 1e6:g}: the DVXplorer's ~5 kHz scans, events stamped when their column "
                        "is read); 0 = asynchronous (DAVIS)")
    p.add_argument("--refractory-us", type=float, default=None,
                   help=f"pixel reset after an event in us, 0 to {MAX_REFRACTORY_S * 1e6:g}; change during it is "
                        f"lost (default {em.refractory_s * 1e6:g}, between one and two scans as measured)")
    sm = StereoModel()
    p.add_argument("--depth", default=None, choices=DEPTH_MODELS,
                   help="depth sensor: d455 (active IR stereo exposed at its own time, registered to colour; the "
                        "robot layout's default) or sharp (rendered at the colour stamp: the too kind model before, "
                        "MVSEC's default)")
    lo, hi = sm.exposure_limits_s
    p.add_argument("--ir-exposure", type=float, default=None,
                   help=f"d455: fixed IR exposure in s, {lo:g} to {hi:g} (default: auto-exposure, up to the frame "
                        "period)")
    p.add_argument("--ir-ambient", type=float, default=None,
                   help=f"d455: the room's IR light against the projector's, 0 to {MAX_IR_LIGHT:g} (default "
                        f"{sm.ambient_ir:g}; lower = a dimmer room, longer auto-exposures, more blur)")
    p.add_argument("--depth-phase", type=float, default=None,
                   help="d455: depth exposure centre minus colour exposure centre in s, -0.1 to 0.1 (default: drawn "
                        "from the seed within half a frame period; the D455 cannot synchronise them)"),
    p.add_argument("--no-imu", action="store_true", help="layout robot: no IMU topic (default: the D455's "
                   "BMI055 on /camera/camera/imu at ~200 Hz)")
    p.add_argument("--force", action="store_true", help="replace an existing atsvo-sim output in --out")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return run(_main, p, argv)


if __name__ == "__main__":
    raise SystemExit(main())
