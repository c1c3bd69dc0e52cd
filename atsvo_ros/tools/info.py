"""``atsvo-info``: the environment (library versions, numba kernel cache) and the rig a configuration describes.

Useful to check a parameter file before a run (every value is validated exactly as the nodes do) and to see
why a run is slow: kernels missing from numba's cache compile on first use.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Sequence

import numpy as np

from atsvo_ros.config import flatten, load_config, parse_overrides
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import rotation_angle_rad
from atsvo_ros.tools._cli import add_config_args, run
from atsvo_ros.tools._environment import describe
from atsvo_ros.tools._help import description


def _main(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, overrides=parse_overrides(args.set))
    if args.json:
        print(json.dumps(flatten(cfg), indent=2))
        return 0
    print("\n".join(describe()))
    print()
    for name in ("rgb_camera", "event_camera"):
        cam = CameraModel.from_config(getattr(cfg, name))
        hfov = np.degrees(2 * np.arctan(cam.width / (2 * cam.fx)))
        print(f"{name:13s} {cam.width}x{cam.height}  fx={cam.fx:.2f} fy={cam.fy:.2f} "
              f"cx={cam.cx:.2f} cy={cam.cy:.2f}  {cam.distortion_model}  HFOV {hfov:.1f} deg")
    for name in ("T_base_rgb", "T_rgb_event", "T_rgb_imu"):
        T = np.asarray(getattr(cfg.rig, name)).reshape(4, 4)
        print(f"{name:13s} t = {np.round(T[:3, 3], 4).tolist()} m, "
              f"rotation {np.degrees(rotation_angle_rad(T[:3, :3])):.2f} deg")
    print(f"depth         {cfg.rig.depth_min_m}-{cfg.rig.depth_max_m} m, scale {cfg.rig.depth_scale_m} m/unit")
    print(f"mode          {cfg.mode}")
    print("topics        " + ", ".join(f"{k}={v}" for k, v in vars(cfg.topics).items()))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-info``."""
    parser = argparse.ArgumentParser(prog="atsvo-info", description=description(__doc__))
    add_config_args(parser, default="mini_cheetah")
    parser.add_argument("--json", action="store_true", help="print every parameter as JSON")
    return run(_main, parser, argv)


if __name__ == "__main__":
    raise SystemExit(main())
