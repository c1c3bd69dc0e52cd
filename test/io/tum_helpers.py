"""Small TUM RGB-D folders for the tests: rendered box-room frames with exact poses, written in TUM's layout."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.geometry import se3_exp, tq_from_pose
from atsvo_ros.io.trajectory import format_stamp
from test.core.render_helpers import BoxRoom

T0_NS = 1_305_031_229_528_748_000
PERIOD_NS = 33_333_000  # whole microseconds: the list files hold 6 decimals


def render_frames(camera: CameraModel, n: int = 8, seed: int = 3, step: tuple[float, ...] = (0.02, -0.01, 0.01,
                  0.004, 0.012, -0.006), room: BoxRoom | None = None) -> list[tuple[int, np.ndarray, np.ndarray,
                                                                                np.ndarray]]:
    """``(stamp_ns, rgb uint8 raw, depth_m raw, T_w_c)`` of a constant-twist camera motion in a box room."""
    room = room or BoxRoom(seed=seed)
    dT = se3_exp(np.asarray(step, float))
    T = np.eye(4)
    out = []
    for k in range(n):
        img, depth = room.render(camera, T, supersample=1)
        rgb = np.repeat(np.clip(img + 0.5, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
        out.append((T0_NS + k * PERIOD_NS, rgb, depth.astype(np.float32), T.copy()))
        T = T @ dT
    return out


def _line(stamp_ns: int, name: str) -> str:
    return f"{format_stamp(stamp_ns)[:-3]} {name}\n"  # microseconds, as TUM writes them


def write_tum_folder(folder: Path, frames: list, depth_offset_ns: int = 8_000_000, gt: bool = True) -> Path:
    """rgb/, depth/ (uint16, 5000 per metre), rgb.txt, depth.txt (+ groundtruth.txt at 100 Hz, exact poses)."""
    (folder / "rgb").mkdir(parents=True, exist_ok=True)
    (folder / "depth").mkdir(exist_ok=True)
    rgb_lines = ["# color images\n", "# file: 'synthetic'\n", "# timestamp filename\n"]
    depth_lines = ["# depth maps\n", "# file: 'synthetic'\n", "# timestamp filename\n"]
    for stamp, rgb, depth_m, _ in frames:
        t_rgb = format_stamp(stamp)[:-3]
        t_d = format_stamp(stamp + depth_offset_ns)[:-3]
        cv2.imwrite(str(folder / "rgb" / f"{t_rgb}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        raw = np.clip(np.round(np.nan_to_num(depth_m) * 5000.0), 0, 65535).astype(np.uint16)
        cv2.imwrite(str(folder / "depth" / f"{t_d}.png"), raw)
        rgb_lines.append(_line(stamp, f"rgb/{t_rgb}.png"))
        depth_lines.append(_line(stamp + depth_offset_ns, f"depth/{t_d}.png"))
    (folder / "rgb.txt").write_text("".join(rgb_lines))
    (folder / "depth.txt").write_text("".join(depth_lines))
    if gt:
        lines = ["# ground truth trajectory\n", "# timestamp tx ty tz qx qy qz qw\n"]
        for stamp, _, _, T in frames:
            t, q = tq_from_pose(T[None])
            lines.append(f"{format_stamp(stamp)} " + " ".join(f"{v:.9f}" for v in [*t[0], *q[0]]) + "\n")
        (folder / "groundtruth.txt").write_text("".join(lines))
    return folder
