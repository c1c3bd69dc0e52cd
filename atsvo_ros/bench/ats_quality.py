"""``atsvo-bench ats-quality``: does a time surface white out or black out, per texture and speed?

The paper's case for the ATS (Section II-A): a constant decay whites out under fast motion or dense
texture and blacks out under slow motion or sparse texture. This benchmark puts exactly that in one
view: a 320x240 window over a canvas whose left half is densely textured (2500 small discs) and whose
right half is sparse (80 shapes), moving across the split (so each half keeps its texture) at the
image speeds of the robot's motions (event camera, f = 270 px):

========  =========  =============================================
name      px/s       source
========  =========  =============================================
stand     30         body sway while standing (~6 deg/s)
trot      235        simulated trot, ~50 deg/s pitch/roll
bound     1225       simulated bound, 260 deg/s peaks
flip      2640       simulated backflip, 560 deg/s (the paper's Fig. 8)
========  =========  =============================================

Events come from the simulator's DVS model (threshold mismatch, refractory period, noise). For every
surface rule it measures, per half, at a frame time:

* ``saturated``: share of pixels at >= 90 % of full scale (white-out: no gradient left to align);
* ``empty``: share of 20x20 blocks with no pixel above Eq. 3's ``h`` (black-out: nothing to select);
* ``selected`` and ``spread``: Eq. 3's selected pixels, and the share of 20x20 blocks holding one;
* ``track_px``: the event term alone (one :class:`~atsvo_ros.core.tracking.residuals.photometric.PhotometricBlock`,
  the tracker's default pyramid) from a guess 2 px off the true 33 ms motion in eight directions: the
  median image error after tracking, over scenes and directions (``ok``: share under 0.5 px).

The fused tracker's error on the simulator's flips is :mod:`atsvo_ros.bench.tracking`'s (``atsvo-bench
tracking --modes fused,fused_constant``); this part isolates the surface.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from atsvo_ros.bench.ats import (
    FRAME_NS,
    RULES,
    Pair,
    _translation,
    point_errors,
    scene_canvas,
    select,
    surfaces_at,
    translating_events,
)
from atsvo_ros.config import EventSelectionConfig, TrackerConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.image.frontend import usable_levels
from atsvo_ros.errors import ConfigError

SPEEDS_PX_S = {"stand": 30.0, "trot": 235.0, "bound": 1225.0, "flip": 2640.0}
BLOCK_PX = 20
SATURATED = 0.9 * 255.0
CAMERA = CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5)


def mixed_canvas(size: int = 1024, seed: int = 0) -> np.ndarray:
    """Left half dense texture, right half sparse: one view with both."""
    canvas = scene_canvas("sparse", size, seed)
    canvas[:, : size // 2] = scene_canvas("dense", size, seed)[:, : size // 2]
    return canvas


def _blocks(mask: np.ndarray) -> np.ndarray:
    """Whether each BLOCK_PX x BLOCK_PX block of ``mask`` holds a True pixel."""
    h, w = (mask.shape[0] // BLOCK_PX) * BLOCK_PX, (mask.shape[1] // BLOCK_PX) * BLOCK_PX
    return mask[:h, :w].reshape(h // BLOCK_PX, BLOCK_PX, w // BLOCK_PX, BLOCK_PX).any(axis=(1, 3))


def surface_quality(surface: np.ndarray, uv: np.ndarray, h: float) -> dict[str, dict[str, float]]:
    """Saturated share, empty blocks, selected pixels and their spread, for the dense and the sparse half."""
    half = surface.shape[1] // 2
    out = {}
    for name, cols in (("dense", slice(0, half)), ("sparse", slice(half, None))):
        s = surface[:, cols]
        sel = np.zeros(s.shape, bool)
        x0 = 0 if name == "dense" else half
        inside = (uv[:, 0] >= x0) & (uv[:, 0] < x0 + s.shape[1])
        u = np.clip(uv[inside, 0].astype(int) - x0, 0, s.shape[1] - 1)
        v = np.clip(uv[inside, 1].astype(int), 0, s.shape[0] - 1)
        sel[v, u] = True
        out[name] = {"saturated": float((s >= SATURATED).mean()), "empty": float(1.0 - _blocks(s > h).mean()),
                     "selected": int(inside.sum()), "spread": float(_blocks(sel).mean())}
    return out


def bench_quality(rules: list[str], speeds: dict[str, float], reps: int, offset_px: float,
                  progress: bool) -> list[dict[str, Any]]:
    """One row per (speed, rule): surface quality per half and the event term's tracking error."""
    tcfg = TrackerConfig()
    levels = usable_levels(CAMERA, tcfg.pyramid_levels)
    h = EventSelectionConfig().h
    duration_s = 0.3
    t_ref = int((duration_s - 0.06) * 1e9)
    rows = []
    for name, speed in speeds.items():
        acc: dict[str, list] = {r: [] for r in rules}
        for rep in range(reps):
            angle = np.pi / 2 if rep % 2 == 0 else -np.pi / 2  # across the split: each half keeps its texture
            events, vel = translating_events("mixed", speed, angle, duration_s, seed=rep, canvas=mixed_canvas(seed=rep))
            ref, recent, cur = surfaces_at(events, rules, t_ref)
            shift = vel * FRAME_NS * 1e-9
            for r in rules:
                uv = select(ref[r], recent, t_ref)
                q = surface_quality(ref[r], uv, h)
                errs = []
                if len(uv) >= 20:
                    pair = Pair(ref[r], cur[r], uv, CAMERA.backproject(uv, np.ones(len(uv))),
                                _translation(shift, CAMERA))
                    for a in np.arange(8) * np.pi / 4:
                        d = offset_px * np.array([np.cos(a), np.sin(a)])
                        errs.append(point_errors(pair, CAMERA, levels, _translation(shift + d, CAMERA), tcfg))
                else:
                    errs = [float("inf")] * 8
                acc[r].append((q, errs))
        for r in rules:
            row: dict[str, Any] = {"speed": name, "speed_px_s": speed, "rule": r}
            for part in ("dense", "sparse"):
                for key in ("saturated", "empty", "selected", "spread"):
                    row[f"{part}_{key}"] = float(np.mean([q[part][key] for q, _ in acc[r]]))
            errs = np.concatenate([e for _, e in acc[r]])
            row["track_px"] = float(np.median(errs))
            row["track_ok"] = float((errs < 0.5).mean())
            rows.append(row)
            if progress:
                print(f"  {name:5s} {r:11s} dense sat {row['dense_saturated']:.2f} empty {row['dense_empty']:.2f} "
                      f"sel {row['dense_selected']:4.0f} | sparse sat {row['sparse_saturated']:.2f} empty "
                      f"{row['sparse_empty']:.2f} sel {row['sparse_selected']:4.0f} | track {row['track_px']:.2f} px "
                      f"ok {row['track_ok']:.2f}", flush=True)
    return rows


def print_table(rows: list[dict[str, Any]], rules: list[str]) -> None:
    """Rules as columns, one line per (speed, figure)."""
    print("\nsurface quality (columns: rules); dense | sparse half")
    print(f"{'':28s}" + "".join(f"{r:>16s}" for r in rules))
    for name in dict.fromkeys(r["speed"] for r in rows):
        for key, fmt in (("saturated", "{:.2f}"), ("empty", "{:.2f}"), ("selected", "{:.0f}"), ("spread", "{:.2f}")):
            cells = []
            for rule in rules:
                r = next(x for x in rows if x["speed"] == name and x["rule"] == rule)
                cells.append(f"{fmt.format(r['dense_' + key])}|{fmt.format(r['sparse_' + key])}")
            print(f"  {name:5s} {key:20s}" + "".join(f"{c:>16s}" for c in cells))
        cells = [next(f"{x['track_px']:.2f} ({x['track_ok']:.2f})" for x in rows if x["speed"] == name
                      and x["rule"] == rule) for rule in rules]
        print(f"  {name:5s} {'track px (ok share)':20s}" + "".join(f"{c:>16s}" for c in cells))


def add_ats_quality_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the surface-quality benchmark."""
    p.add_argument("--rules", default=",".join(RULES), help=f"comma list of {', '.join(RULES)}")
    p.add_argument("--reps", type=int, default=4, help="scenes (half moving up, half down) per speed")
    p.add_argument("--offset-px", type=float, default=2.0, help="initial guess error of the tracking figure")
    p.add_argument("--json", default=None, help="also write every figure to this JSON file")


def main_ats_quality(args: argparse.Namespace) -> int:
    """Run the benchmark and print the table."""
    rules = [r.strip() for r in args.rules.split(",") if r.strip()]
    unknown = sorted(set(rules) - set(RULES))
    if unknown:
        raise ConfigError(f"unknown rule(s) {unknown}; choose from {', '.join(RULES)}")
    if args.reps < 1:
        raise ConfigError(f"--reps must be at least 1, got {args.reps}")
    print("one view, dense texture left and sparse right, moving at the robot's image speeds", flush=True)
    rows = bench_quality(rules, SPEEDS_PX_S, args.reps, args.offset_px, True)
    print_table(rows, rules)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
        print(f"wrote {args.json}")
    return 0
