"""Peer RGB-D odometries run on exactly our frames, for side-by-side scoring: Open3D's multi-scale RGB-D odometry.

Open3D (optional extra ``peers``) is run frame to frame through its tensor API
(``open3d.t.pipelines.odometry.rgbd_odometry_multi_scale``) with each of its three losses:
``point_to_plane`` (depth only, ICP on vertex/normal maps), ``intensity`` (photometric, Steinbruecker
et al.) and ``hybrid`` (both, Park et al.). The input is what our core tracks: the colour image
undistorted with :meth:`CameraModel.rectify_maps` (bilinear) and the depth remapped with the same maps
(nearest neighbour), as :class:`atsvo_ros.core.odometry.odometry.Odometry` does, with the pinhole K. Each frame
is registered to the previous one (identity initial guess, Open3D's default criteria and loss
parameters unless given) and the relative poses are chained into ``T_world_cam`` with the first
frame at the origin.

Open3D reports no tracking failure: a frame counts as ok when the result is finite and some pixels
were inliers (``fitness > 0``).
"""
from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import EvaluationError
from atsvo_ros.io.trajectory import Trajectory

#: our method names -> Open3D's ``Method`` members
OPEN3D_METHODS: dict[str, str] = {"point_to_plane": "PointToPlane", "hybrid": "Hybrid", "intensity": "Intensity"}


@dataclass
class PeerRun:
    """Trajectory and timing of one peer method over a sequence.

    ``time_s``: the odometry call per frame (0 for the first frame, which only becomes the reference);
    ``prep_time_s``: undistortion and conversion of the frame (shared by the methods of one run).
    """

    name: str
    stamps_ns: np.ndarray
    T_world_cam: np.ndarray
    ok: np.ndarray
    time_s: np.ndarray
    prep_time_s: np.ndarray
    fitness: np.ndarray
    inlier_rmse: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def trajectory(self):
        """The poses as a :class:`~atsvo_ros.io.trajectory.Trajectory`."""

        return Trajectory(self.stamps_ns, self.T_world_cam)


def import_open3d() -> Any:
    """``open3d`` or an EvaluationError saying how to get it."""
    try:
        import open3d
    except ImportError as exc:
        raise EvaluationError(f"the Open3D peer needs open3d: pip install 'atsvo_ros[peers]' ({exc})") from None
    return open3d


def undistorted_frames(frames: Iterable[tuple[int, np.ndarray, np.ndarray]],
                       camera: CameraModel) -> Iterator[tuple[int, np.ndarray, np.ndarray, float]]:
    """``(stamp_ns, rgb, depth_m)`` raw frames -> ``(stamp_ns, rgb float32 [0, 1], depth_m, seconds spent)``.

    The colour image is resampled bilinearly and the depth by nearest neighbour onto the pinhole
    grid of ``camera`` (no-op for an undistorted camera), as our odometry's preprocessing does.
    """

    maps = camera.rectify_maps() if camera.is_distorted else None
    for stamp, rgb, depth in frames:
        t0 = time.perf_counter()
        rgb = np.asarray(rgb)
        if rgb.ndim == 2:
            rgb = np.repeat(rgb[..., None], 3, axis=2)
        if rgb.shape[:2] != (camera.height, camera.width) or np.shape(depth) != rgb.shape[:2]:
            raise EvaluationError(f"frame at {stamp} ns is {rgb.shape[1]}x{rgb.shape[0]} (depth {np.shape(depth)}) "
                                  f"but the camera is {camera.width}x{camera.height}")
        img = rgb.astype(np.float32) * np.float32(1.0 / 255.0)
        d = np.asarray(depth, np.float32)
        if maps is not None:
            img = cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            d = cv2.remap(d, maps[0], maps[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        d = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
        yield int(stamp), np.ascontiguousarray(img), np.ascontiguousarray(d), time.perf_counter() - t0


def run_open3d(frames: Iterable[tuple[int, np.ndarray, np.ndarray]], camera: CameraModel,
               methods: Sequence[str] = tuple(OPEN3D_METHODS), *, depth_max_m: float = 5.0,
               criteria: Sequence[int] = (10, 5, 3), loss: dict[str, float] | None = None,
               progress: bool = False) -> dict[str, PeerRun]:
    """Open3D frame-to-frame RGB-D odometry over ``(stamp_ns, rgb, depth_m)`` frames, one run per method.

    Args:
        frames: raw frames in time order (RGB uint8 or grey, depth float32 metres, 0 = invalid),
            streamed: each frame is undistorted once and shared by all methods.
        camera: the raw colour camera (its pinhole model is passed to Open3D).
        methods: keys of :data:`OPEN3D_METHODS`.
        depth_max_m: Open3D's ``depth_max`` (depths beyond it are ignored).
        criteria: iterations per pyramid level, coarse to fine (Open3D's default 10, 5, 3).
        loss: ``OdometryLossParams`` keywords (``depth_outlier_trunc``, ``depth_huber_delta``,
            ``intensity_huber_delta``); Open3D's defaults when None.
        progress: show a progress bar on stderr.
    """
    o3d = import_open3d()

    unknown = [m for m in methods if m not in OPEN3D_METHODS]
    if unknown or not methods:
        raise EvaluationError(f"unknown Open3D method(s) {unknown} (choose from {', '.join(OPEN3D_METHODS)})")
    odo = o3d.t.pipelines.odometry
    K = o3d.core.Tensor(camera.pinhole().K, dtype=o3d.core.float64)
    crit = [odo.OdometryConvergenceCriteria(int(n)) for n in criteria]
    params = odo.OdometryLossParams(**(loss or {}))
    eye = o3d.core.Tensor(np.eye(4), dtype=o3d.core.float64)
    state = {m: {"prev": None, "T": np.eye(4), "poses": [], "ok": [], "t": [], "fit": [], "rmse": []} for m in methods}
    stamps: list[int] = []
    prep: list[float] = []
    for stamp, img, depth, t_prep in tqdm(undistorted_frames(frames, camera), disable=not progress, unit="frame",
                                          desc="open3d", leave=False):
        if stamps and stamp <= stamps[-1]:
            raise EvaluationError(f"frame stamps must increase: {stamp} ns after {stamps[-1]} ns")
        t0 = time.perf_counter()
        rgbd = o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3d.core.Tensor(img)),
                                        o3d.t.geometry.Image(o3d.core.Tensor(depth)))
        t_prep += time.perf_counter() - t0
        stamps.append(stamp)
        prep.append(t_prep)
        for m in methods:
            s = state[m]
            if s["prev"] is None:
                s["poses"].append(s["T"].copy())
                s["ok"].append(True)
                s["t"].append(0.0)
                s["fit"].append(np.nan)
                s["rmse"].append(np.nan)
            else:
                t0 = time.perf_counter()
                # source = this frame, target = the previous one: the result maps this camera into the previous.
                res = odo.rgbd_odometry_multi_scale(rgbd, s["prev"], K, eye, 1.0, float(depth_max_m), crit,
                                                    getattr(odo.Method, OPEN3D_METHODS[m]), params)
                dt = time.perf_counter() - t0
                T_prev_cur = res.transformation.numpy().astype(np.float64)
                ok = bool(np.all(np.isfinite(T_prev_cur)) and res.fitness > 0)
                if ok:
                    s["T"] = s["T"] @ T_prev_cur
                s["poses"].append(s["T"].copy())
                s["ok"].append(ok)
                s["t"].append(dt)
                s["fit"].append(float(res.fitness))
                s["rmse"].append(float(res.inlier_rmse))
            s["prev"] = rgbd
    if not stamps:
        raise EvaluationError("no frames given to the Open3D peer")
    info = {"open3d": o3d.__version__, "depth_max_m": float(depth_max_m), "criteria": list(criteria),
            "loss": {k: getattr(params, k) for k in ("depth_outlier_trunc", "depth_huber_delta",
                                                     "intensity_huber_delta")},
            "init": "identity", "undistorted": camera.is_distorted}
    return {m: PeerRun(f"open3d_{m}", np.asarray(stamps, np.int64), np.stack(s["poses"]), np.asarray(s["ok"]),
                       np.asarray(s["t"]), np.asarray(prep), np.asarray(s["fit"]), np.asarray(s["rmse"]),
                       dict(info, method=OPEN3D_METHODS[m]))
            for m, s in state.items()}


__all__ = ["OPEN3D_METHODS", "PeerRun", "import_open3d", "run_open3d", "undistorted_frames"]
