"""``atsvo-bench real``: our RGB-D odometry against OpenCV's and Open3D's on real TUM RGB-D sequences, one table.

For each TUM folder (default: ``../shared/realdata/tum_rgbd_fr1_rpy_300`` next to the repository) it
replays our pipeline (:func:`atsvo_ros.tools.replay.replay`, mode rgbd, the folder's TUM preset),
then each ``--variant NAME:key=value,...`` (the same with those config overrides, e.g. the paper's
formulation against the default), then OpenCV's frame-to-frame dense odometry (rgbd, rgb, depth) and
Open3D's with its three losses (:mod:`atsvo_ros.eval.peers`) on the same undistorted frames, Open3D
when it is installed, and ORB-SLAM3 RGB-D (:mod:`atsvo_ros.eval.orbslam3`, the raw frames, a vocabulary trained
on the simulator's rooms: :mod:`atsvo_ros.bench.peer_vocabulary`) when its bindings are installed.

Columns (every method scored alike, :func:`atsvo_ros.eval.metrics.evaluate`):

* ATE: RMSE of the position error after one SE(3) Umeyama alignment over all poses (``evo_ape -a``).
* RPE deg/f, cm/f: RMSE over consecutive frame pairs of the rotation angle / translation norm of
  ``(Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` (``evo_rpe --delta 1 --delta_unit f``, rmse); the means are in the JSON.
  Q is the ground-truth sample nearest each stamp, as evo associates: up to half a sample period (5 ms at
  TUM's 100 Hz) off, which alone scores a perfect estimate 0.16-0.28 deg/f on fr1_rpy depending on where
  the stamps fall between the samples. *interp*: the same with Q interpolated at the stamps.
* ms/frame median and p95: one frame from raw images to pose (ours: the whole ``process_frame``, i.e.
  undistortion, tracking and keyframe insertion; Open3D: undistortion + conversion + the odometry
  call). Image decoding is excluded for both.
* window ms/kf: mean wall time of the local window optimisation per keyframe (``mapping.window_iterations``;
  mapping's time, inside ours' ms/frame here where mapping runs in line; n/a when off and for the peers).
* ok: frames whose reported status is ok (ours: ``ok``; Open3D reports no failure: a finite result
  with inliers, the first frame being the reference).
* wrong-but-ok: ok frames whose rotation over one frame (the RPE of the pair ending at that frame)
  is wrong by more than max(1.5 deg, 25 % of the true rotation over that frame): a wrong pose
  reported as good. The 25 % keeps a fast turn's proportional error from counting as a failure.
* ok & rel>1.5: the same with a flat 1.5 deg. (The JSON also has ``ok_abs_rot_gt_1_5``, ok frames
  whose orientation error after the alignment exceeds 1.5 deg: it adds up drift, and on fr1_rpy,
  where the position-only alignment hardly constrains the world rotation, it counts nearly every
  frame of every method.)
"""
from __future__ import annotations

import argparse
import json
import os
import re
import tempfile
import time
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from atsvo_ros.bench.peer_vocabulary import vocabulary_file
from atsvo_ros.config import load_config, parse_overrides
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.odometry.odometry import Odometry
from atsvo_ros.errors import ConfigError
from atsvo_ros.eval.metrics import EvalOptions, evaluate, rotation_angle_deg
from atsvo_ros.eval.orbslam3 import run_orbslam3
from atsvo_ros.eval.peers import OPENCV_METHODS, run_open3d, run_opencv
from atsvo_ros.io.images import depth_to_metres
from atsvo_ros.io.trajectory import Trajectory, write_tum
from atsvo_ros.io.tum_rgbd import TumRgbdReader, TumSource
from atsvo_ros.tools.demo import cache_dir
from atsvo_ros.tools.replay import replay

DEFAULT_FOLDER = Path(__file__).resolve().parents[2].parent / "shared" / "realdata" / "tum_rgbd_fr1_rpy_300"
#: orientation error (deg) above which an ok frame is counted as wrong
BAD_ROT_DEG = 1.5
#: ... or this share of the true rotation over the frame, when that is larger (a fast turn)
BAD_ROT_SHARE = 0.25

COLUMNS = [("method", "method", "{}"), ("ate_cm", "ATE cm", "{:.2f}"), ("rpe_deg_per_frame", "RPE deg/f", "{:.3f}"),
           ("rpe_deg_per_frame_interp", "RPE deg/f interp", "{:.3f}"), ("rpe_cm_per_frame", "RPE cm/f", "{:.3f}"),
           ("tracking_ms_median", "track ms med", "{:.1f}"), ("ms_median", "ms/f med", "{:.1f}"),
           ("ms_p95", "ms/f p95", "{:.1f}"), ("window_ms", "window ms/kf", "{:.1f}"), ("ok", "ok", "{}"),
           ("wrong_but_ok", "wrong-but-ok", "{}"), ("ok_rel_rot_gt_1_5", "ok & rel>1.5", "{}")]


def parse_variant(text: str) -> tuple[str, dict[str, Any]]:
    """``'paper:tracker.w_rgb=1,ats.tau_u_s=0.05'`` -> ``('paper', {...})`` (values as YAML scalars)."""
    name, sep, body = text.partition(":")
    name = name.strip()
    if not sep or not re.fullmatch(r"[A-Za-z0-9_.+-]+", name) or not body.strip():
        raise ConfigError(f"--variant expects NAME:key=value[,key=value...], got {text!r}")
    pairs = [p for p in re.split(r",(?=\s*[A-Za-z_][\w.]*\s*=)", body) if p.strip()]
    return name, parse_overrides(pairs)


def score(gt: Any, stamps_ns: np.ndarray, T_w_c: np.ndarray, ok: np.ndarray) -> dict[str, Any]:
    """The table's accuracy figures for one trajectory (see the module docstring)."""

    ok = np.asarray(ok, bool)
    ev = evaluate(gt, Trajectory(stamps_ns, T_w_c), EvalOptions(align="se3"), est_ok=ok)
    ev_interp = evaluate(gt, Trajectory(stamps_ns, T_w_c), EvalOptions(align="se3", interpolate_gt=True))
    order = np.argsort(stamps_ns, kind="stable")
    ok_m = ok[order][np.searchsorted(np.asarray(stamps_ns)[order], ev.stamps_ns)]
    abs_rot = rotation_angle_deg(np.swapaxes(ev.T_w_gt[:, :3, :3], -1, -2) @ ev.T_w_est[:, :3, :3])
    R_gt = ev.T_w_gt[:, :3, :3]
    true_rot = rotation_angle_deg(np.swapaxes(R_gt[:-1], -1, -2) @ R_gt[1:])
    wrong = ok_m[1:] & (ev.rpe_rot_deg > np.maximum(BAD_ROT_DEG, BAD_ROT_SHARE * true_rot))
    m, x = ev.metrics, ev.extra
    return {
        "ate_cm": m["ate_rmse_m"] * 100.0,
        "rpe_deg_per_frame": x["rpe_rot_deg_per_frame_rmse"],
        "rpe_deg_per_frame_interp": ev_interp.extra["rpe_rot_deg_per_frame_rmse"],
        "rpe_cm_per_frame": x["rpe_trans_cm_per_frame_rmse"],
        "rpe_deg_per_frame_mean": m["rpe_rot_deg_per_frame"],
        "rpe_cm_per_frame_mean": m["rpe_trans_cm_per_frame"],
        "n_matched": m["n_matched"],
        "abs_rot_err_deg_median": float(np.median(abs_rot)),
        "ok_abs_rot_gt_1_5": int(np.count_nonzero(ok_m & (abs_rot > BAD_ROT_DEG))),
        "ok_rel_rot_gt_1_5": int(np.count_nonzero(ok_m[1:] & (ev.rpe_rot_deg > BAD_ROT_DEG))),
        "wrong_but_ok": int(np.count_nonzero(wrong)),
        "wrong_but_ok_share": float(np.count_nonzero(wrong) / max(1, len(wrong))),
        "wrong_but_ok_frames": [int(i) + 1 for i in np.flatnonzero(wrong)],
    }


def _timing(times_s: np.ndarray) -> dict[str, float]:
    t = np.asarray(times_s, float) * 1e3
    return {"ms_median": float(np.median(t)), "ms_p95": float(np.percentile(t, 95)), "ms_mean": float(np.mean(t))}


def _window_ms(mapper: Any) -> float | None:
    """Mean wall time (ms) of the mapper's local window optimisations, None when it ran none."""
    return mapper.window_time_s / mapper.n_windows * 1e3 if mapper.n_windows else None


def run_ours(folder: Path, out_dir: Path, config: Any, progress: bool) -> dict[str, Any]:
    """Replay a TUM folder through our pipeline (rgbd) with ``config``; figures plus the raw outputs."""

    instances: list[Any] = []

    class _Timed:
        """Our odometry with the whole process_frame call timed."""

        def __init__(self, cfg: Any, rgb_cam: Any, ev_cam: Any = None) -> None:
            self.odo = Odometry(cfg, rgb_cam, ev_cam)
            self.times_s: list[float] = []
            instances.append(self)

        def add_events(self, batch: Any) -> None:
            self.odo.add_events(batch)

        def add_imu(self, batch: Any) -> None:
            self.odo.add_imu(batch)

        def process_frame(self, frame: Any) -> Any:
            t0 = time.perf_counter()
            res = self.odo.process_frame(frame)
            self.times_s.append(time.perf_counter() - t0)
            return res

    res = replay(folder, out_dir, config, mode="rgbd", frame="camera", plots=False, progress=progress,
                 odometry_factory=_Timed)
    statuses = res.statuses
    counts = {s: statuses.count(s) for s in sorted(set(statuses))}
    return {"stamps_ns": res.stamps_ns, "T_w_c": res.T_odom_x, "ok": np.array([s == "ok" for s in statuses]),
            "times_s": np.asarray(instances[-1].times_s), "tracking_s": res.tracking_time_s,
            "statuses": counts, "notes": res.notes,
            "keyframes": instances[-1].odo.n_keyframes, "mapper": instances[-1].odo.mapper}


def bench_folder(folder: Path, preset: str | None, base_overrides: dict[str, Any],
                 variants: list[tuple[str, dict[str, Any]]], open3d_methods: Sequence[str], out: Path,
                 progress: bool, opencv_methods: Sequence[str] = tuple(OPENCV_METHODS),
                 orbslam3_vocabulary: Path | None = None) -> dict[str, Any]:
    """All rows of one sequence (ORB-SLAM3's when a vocabulary is given)."""

    reader = TumRgbdReader(folder)
    preset = preset or TumSource(folder).preset
    gt = reader.ground_truth()
    seq: dict[str, Any] = {"folder": str(folder), "preset": preset, "frames": len(reader),
                           "pairing": reader.summary(), "rows": [], "notes": []}
    base = load_config(preset, overrides=base_overrides or None)
    for name, extra in [("atsvo_ros", {})] + [(f"atsvo_ros:{n}", o) for n, o in variants]:
        cfg = load_config(preset, overrides={**base_overrides, **extra}) if extra else base
        r = run_ours(folder, out / name.replace(":", "_"), cfg, progress)
        row = {"method": name, "overrides": {**base_overrides, **extra},
               **score(gt, r["stamps_ns"], r["T_w_c"], r["ok"]), **_timing(r["times_s"]),
               "tracking_ms_median": float(np.median(r["tracking_s"][1:]) * 1e3), "ok": int(r["ok"].sum()),
               "frames": len(r["ok"]), "statuses": r["statuses"], "keyframes": r["keyframes"],
               "window_ms": _window_ms(r["mapper"])}
        seq["rows"].append(row)
        _print_row(row)
    rig = base.rig

    def frames():
        return ((f.stamp_ns, f.rgb, depth_to_metres(f.depth_raw, rig.depth_scale_m, rig.depth_min_m, rig.depth_max_m))
                for f in reader.frames())

    camera = CameraModel.from_config(base.rgb_camera)
    runs = {}
    if opencv_methods:
        runs.update(run_opencv(frames(), camera, opencv_methods, depth_min_m=rig.depth_min_m,
                               depth_max_m=rig.depth_max_m, progress=progress))
    if open3d_methods:
        runs.update(run_open3d(frames(), camera, open3d_methods, depth_max_m=rig.depth_max_m, progress=progress))
    if orbslam3_vocabulary is not None:  # the frames as the files hold them: its own undistortion and depth range
        raw = ((f.stamp_ns, f.rgb, f.depth_raw.astype(np.float32) * np.float32(rig.depth_scale_m))
               for f in reader.frames())
        run = run_orbslam3(raw, camera, orbslam3_vocabulary, progress=progress)
        runs[run.name] = run
    for run in runs.values():
        write_tum(out / f"{run.name}.tum", run.trajectory(), header=f"{run.name} on {folder.name} (T_world_cam)")
        row = {"method": run.name, **score(gt, run.stamps_ns, run.T_world_cam, run.ok),
               **_timing((run.time_s + run.prep_time_s)[1:]), "ok": int(run.ok.sum()), "frames": len(run.ok),
               "odometry_call_ms_median": float(np.median(run.time_s[1:]) * 1e3), "info": run.info}
        seq["rows"].append(row)
        _print_row(row)
    return seq


def row_cells(row: dict[str, Any]) -> list[str]:
    out = []
    for key, _, fmt in COLUMNS:
        v = row.get(key)
        if key == "ok":
            out.append(f"{row['ok']}/{row['frames']}")
        else:
            out.append("n/a" if v is None else fmt.format(v))
    return out


def _print_row(row: dict[str, Any]) -> None:
    print("  " + "  ".join(f"{c:>{max(len(h), 12) if i else 28}}" for i, (c, (_, h, _)) in
                           enumerate(zip(row_cells(row), COLUMNS))), flush=True)


def markdown(results: dict[str, Any]) -> str:
    """results.md: one table per sequence plus the definitions."""
    lines = ["# atsvo-bench real", ""]
    for seq in results["sequences"]:
        lines += [f"## {Path(seq['folder']).name} ({seq['frames']} frames, preset {seq['preset']})", "",
                  f"Pairing: {seq['pairing']}.", "",
                  "| " + " | ".join(h for _, h, _ in COLUMNS) + " |",
                  "|" + "|".join("---" if i == 0 else "---:" for i in range(len(COLUMNS))) + "|"]
        lines += ["| " + " | ".join(row_cells(r)) + " |" for r in seq["rows"]]
        overrides = [f"`{r['method']}`: " + ", ".join(f"{k}={v}" for k, v in r["overrides"].items())
                     for r in seq["rows"] if r.get("overrides")]
        lines += [""] + [f"- {o}" for o in overrides] + ([""] if overrides else [])
        lines += [f"- note: {n}" for n in seq["notes"]] + ([""] if seq["notes"] else [])
    lines += ["## Definitions", ""] + [line.strip() for line in __doc__.split("Columns", 1)[1].splitlines()[2:]
                                       if line.strip()]
    env = results["environment"]
    lines += ["", f"Environment: {env['cpus']} CPUs (load average {env['load_avg_1min_before']:.1f} before the run: "
                  f"other processes inflate the times), numpy {env['numpy']}, "
                  f"opencv {env.get('opencv')}, open3d {env['open3d'] or 'not installed'}, "
                  f"pyorbslam3 {env.get('pyorbslam3') or 'not installed'}."]
    return "\n".join(lines) + "\n"


#: The paper's formulation of the tracking (Eq. 4 with the RGB term only, global-shutter camera model), run
#: beside the default unless --no-paper: the depth term, the rolling-shutter model, the frame clock and the
#: stamp latency are ours.
PAPER_VARIANT = ("paper", {"tracker.w_depth": 0.0, "rgb_camera.readout_time_s": 0.0,
                           "rgb_camera.frame_clock_frames": 0, "rgb_camera.time_offset_s": 0.0})


def add_real_args(p: argparse.ArgumentParser) -> None:
    """Arguments of the real-data benchmark (used by the ``atsvo-bench`` front end)."""
    p.add_argument("folders", nargs="*", help=f"TUM RGB-D folders (default: {DEFAULT_FOLDER} when it exists)")
    p.add_argument("--preset", choices=("tum_fr1", "tum_fr2", "tum_fr3"),
                   help="camera preset for every folder (default: from each folder's name / README.txt)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override for all our runs (YAML value syntax)")
    p.add_argument("--variant", action="append", default=[], metavar="NAME:KEY=VALUE[,KEY=VALUE...]",
                   help="one more named run of ours with these overrides (repeatable)")
    p.add_argument("--no-paper", action="store_true",
                   help="skip the run of the paper's formulation (photometric term only, global shutter, "
                        "stamps as given)")
    p.add_argument("--opencv", nargs="*", default=list(OPENCV_METHODS), choices=list(OPENCV_METHODS),
                   metavar="METHOD", help="OpenCV odometry types to run: rgbd, rgb, depth (none: skip OpenCV)")
    p.add_argument("--open3d", nargs="*", default=["point_to_plane", "hybrid", "intensity"],
                   metavar="METHOD", help="Open3D losses to run (none: skip Open3D)")
    p.add_argument("--orbslam3", action=argparse.BooleanOptionalAction, default=True,
                   help="run ORB-SLAM3 RGB-D when its bindings are installed (pip install 'atsvo_ros[orbslam3]'; "
                        "its vocabulary is trained on simulated rooms and cached on first use)")
    p.add_argument("--out", default=None, help="write results.json, results.md and the trajectories here")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def main_real(args: argparse.Namespace) -> int:
    """Run the benchmark for parsed arguments; prints the table as it goes."""

    folders = [Path(f) for f in args.folders] or ([DEFAULT_FOLDER] if DEFAULT_FOLDER.is_dir() else [])
    if not folders:
        raise ConfigError(f"no TUM folder given and the default {DEFAULT_FOLDER} does not exist")
    base = parse_overrides(args.set)
    variants = ([] if args.no_paper else [PAPER_VARIANT]) + [parse_variant(v) for v in args.variant]
    names = [n for n, _ in variants]
    if len(set(names)) != len(names):
        raise ConfigError(f"variant names must be unique, got {names}")
    methods = list(args.open3d)
    o3d_version = None
    notes = []
    if methods:
        try:
            import open3d

            o3d_version = open3d.__version__
        except ImportError as exc:
            notes.append(f"Open3D rows skipped: open3d is not importable ({exc}); pip install 'atsvo_ros[peers]'")
            print(f"note: {notes[-1]}")
            methods = []
    vocabulary, orb_version = None, None
    if args.orbslam3:
        try:
            orb_version = version("pyorbslam3")
        except PackageNotFoundError:
            notes.append("ORB-SLAM3 row skipped: pyorbslam3 is not installed; pip install 'atsvo_ros[orbslam3]'")
            print(f"note: {notes[-1]}")
        else:
            vocabulary = vocabulary_file(cache_dir(), progress=not args.quiet)
    tmp = None
    if args.out:
        out = Path(args.out)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="atsvo-bench-real-")
        out = Path(tmp.name)
    results: dict[str, Any] = {"sequences": [], "bad_rot_deg": BAD_ROT_DEG, "bad_rot_share": BAD_ROT_SHARE,
                               "environment": {"cpus": os.cpu_count(), "numpy": np.__version__, "open3d": o3d_version,
                                               "opencv": cv2.__version__, "pyorbslam3": orb_version,
                                               "load_avg_1min_before": os.getloadavg()[0]}}
    try:
        for folder in folders:
            print(f"{folder.name}")
            print("  " + "  ".join(f"{h:>{max(len(h), 12) if i else 28}}" for i, (_, h, _) in enumerate(COLUMNS)))
            seq = bench_folder(folder, args.preset, base, variants, methods, out / folder.name, progress=not args.quiet,
                               opencv_methods=args.opencv, orbslam3_vocabulary=vocabulary)
            seq["notes"] = notes
            results["sequences"].append(seq)
    finally:
        if tmp is not None:
            tmp.cleanup()
    if args.out:
        out.mkdir(parents=True, exist_ok=True)
        (out / "results.json").write_text(json.dumps(results, indent=1, default=str) + "\n")
        (out / "results.md").write_text(markdown(results))
        print(f"wrote {out / 'results.json'} and {out / 'results.md'}")
    return 0


__all__ = ["BAD_ROT_DEG", "BAD_ROT_SHARE", "COLUMNS", "DEFAULT_FOLDER", "PAPER_VARIANT", "add_real_args",
           "bench_folder", "main_real", "markdown", "parse_variant", "row_cells", "score"]
