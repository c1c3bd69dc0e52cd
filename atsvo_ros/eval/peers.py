"""Peer RGB-D odometries run on exactly our frames, for side-by-side scoring: OpenCV's and Open3D's.

OpenCV's dense odometry (``cv2.Odometry``, the ``3d`` module of OpenCV 5, always installed) is run with
its three data types: ``rgb`` (photometric, Steinbruecker et al.), ``depth`` (ICP on the depth) and
``rgbd`` (both), accurate variant (``OdometryAlgoType_COMMON``), OpenCV's default settings but the
camera matrix and depth range.

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
were inliers (``fitness > 0``). OpenCV's ``compute`` says whether it succeeded; a failed frame keeps
the previous pose. Every peer runs frame to frame from an identity guess: none keeps a map.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator, Sequence
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
#: our method names -> OpenCV's ``OdometryType`` constants
OPENCV_METHODS: dict[str, str] = {"rgbd": "ODOMETRY_TYPE_RGB_DEPTH", "rgb": "ODOMETRY_TYPE_RGB",
                                  "depth": "ODOMETRY_TYPE_DEPTH"}


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


class _Chain:
    """One method's frame-to-frame results, chained into ``T_world_cam`` with the first frame at the origin."""

    def __init__(self) -> None:
        self.T = np.eye(4)
        self.poses: list[np.ndarray] = []
        self.ok: list[bool] = []
        self.t: list[float] = []
        self.fit: list[float] = []
        self.rmse: list[float] = []

    def first(self) -> None:
        """The first frame: the reference at the origin."""
        self.step(np.eye(4), True, 0.0, np.nan, np.nan)

    def step(self, T_prev_cur: np.ndarray, ok: bool, dt_s: float, fitness: float, rmse: float) -> None:
        """Chain one result (``T_prev_cur`` maps this camera into the previous one; ignored when not ok)."""
        if ok:
            self.T = self.T @ T_prev_cur
        self.poses.append(self.T.copy())
        self.ok.append(bool(ok))
        self.t.append(float(dt_s))
        self.fit.append(float(fitness))
        self.rmse.append(float(rmse))

    def run(self, name: str, stamps: list[int], prep: list[float], info: dict[str, Any]) -> PeerRun:
        return PeerRun(name, np.asarray(stamps, np.int64), np.stack(self.poses), np.asarray(self.ok),
                       np.asarray(self.t), np.asarray(prep), np.asarray(self.fit), np.asarray(self.rmse), info)


def _check_methods(kind: str, methods: Sequence[str], known: dict[str, str]) -> None:
    unknown = [m for m in methods if m not in known]
    if unknown or not methods:
        raise EvaluationError(f"unknown {kind} method(s) {unknown} (choose from {', '.join(known)})")


def _check_stamp(stamps: list[int], stamp: int) -> None:
    if stamps and stamp <= stamps[-1]:
        raise EvaluationError(f"frame stamps must increase: {stamp} ns after {stamps[-1]} ns")


def _run_chains(frames: Iterable[tuple[int, np.ndarray, np.ndarray]], camera: CameraModel, methods: Sequence[str],
                name: str, convert: Callable[[np.ndarray, np.ndarray], Any],
                register: Callable[[str, Any, Any], tuple[np.ndarray, bool, float, float]], progress: bool
                ) -> tuple[dict[str, _Chain], list[int], list[float]]:
    """The frame-to-frame loop every peer shares: undistort, ``convert`` (timed as preparation), ``register``
    each method's frame to the previous one (timed), chain the results."""
    chains = {m: _Chain() for m in methods}
    stamps: list[int] = []
    prep: list[float] = []
    prev = None
    for stamp, img, depth, t_prep in tqdm(undistorted_frames(frames, camera), disable=not progress, unit="frame",
                                          desc=name, leave=False):
        _check_stamp(stamps, stamp)
        t0 = time.perf_counter()
        cur = convert(img, depth)
        stamps.append(stamp)
        prep.append(t_prep + time.perf_counter() - t0)
        for m in methods:
            if prev is None:
                chains[m].first()
                continue
            t0 = time.perf_counter()
            T_prev_cur, ok, fitness, rmse = register(m, cur, prev)
            chains[m].step(T_prev_cur, ok, time.perf_counter() - t0, fitness, rmse)
        prev = cur
    if not stamps:
        raise EvaluationError(f"no frames given to the {name} peer")
    return chains, stamps, prep


def run_opencv(frames: Iterable[tuple[int, np.ndarray, np.ndarray]], camera: CameraModel,
               methods: Sequence[str] = tuple(OPENCV_METHODS), *, depth_min_m: float = 0.0,
               depth_max_m: float = 4.0, progress: bool = False) -> dict[str, PeerRun]:
    """OpenCV's frame-to-frame dense odometry over ``(stamp_ns, rgb, depth_m)`` frames, one run per method.

    Args:
        frames: raw frames in time order (RGB uint8 or grey, depth float32 metres, 0 = invalid),
            streamed: each frame is undistorted once and shared by all methods.
        camera: the raw colour camera (its pinhole K is passed to OpenCV).
        methods: keys of :data:`OPENCV_METHODS`.
        depth_min_m, depth_max_m: the depth range OpenCV uses (its defaults are 0 and 4 m).
        progress: show a progress bar on stderr.
    """
    _check_methods("OpenCV", methods, OPENCV_METHODS)
    odos = {}
    for m in methods:
        settings = cv2.OdometrySettings()
        settings.setCameraMatrix(camera.pinhole().K.astype(np.float32))
        settings.setMinDepth(float(depth_min_m))
        settings.setMaxDepth(float(depth_max_m))
        odos[m] = cv2.Odometry(getattr(cv2, OPENCV_METHODS[m]), settings, cv2.OdometryAlgoType_COMMON)
    def convert(img: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return depth, cv2.cvtColor(np.round(img * 255.0).astype(np.uint8), cv2.COLOR_RGB2GRAY)

    def register(m: str, cur: tuple, prev: tuple) -> tuple[np.ndarray, bool, float, float]:
        # OpenCV's Rt maps source points into the destination: source = this frame, destination = the previous.
        src, dst = cv2.OdometryFrame(*cur), cv2.OdometryFrame(*prev)
        odos[m].prepareFrames(src, dst)
        ok, Rt = odos[m].compute(src, dst)
        T_prev_cur = np.asarray(Rt, np.float64)
        ok = bool(ok) and T_prev_cur.shape == (4, 4) and bool(np.all(np.isfinite(T_prev_cur)))
        return T_prev_cur, ok, np.nan, np.nan

    chains, stamps, prep = _run_chains(frames, camera, methods, "opencv", convert, register, progress)
    info = {"opencv": cv2.__version__, "depth_range_m": [float(depth_min_m), float(depth_max_m)],
            "algo": "COMMON", "init": "identity", "undistorted": camera.is_distorted}
    return {m: c.run(f"opencv_{m}", stamps, prep, dict(info, method=OPENCV_METHODS[m])) for m, c in chains.items()}


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

    _check_methods("Open3D", methods, OPEN3D_METHODS)
    odo = o3d.t.pipelines.odometry
    K = o3d.core.Tensor(camera.pinhole().K, dtype=o3d.core.float64)
    crit = [odo.OdometryConvergenceCriteria(int(n)) for n in criteria]
    params = odo.OdometryLossParams(**(loss or {}))
    eye = o3d.core.Tensor(np.eye(4), dtype=o3d.core.float64)
    def convert(img: np.ndarray, depth: np.ndarray) -> Any:
        return o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3d.core.Tensor(img)),
                                        o3d.t.geometry.Image(o3d.core.Tensor(depth)))

    def register(m: str, cur: Any, prev: Any) -> tuple[np.ndarray, bool, float, float]:
        # source = this frame, target = the previous one: the result maps this camera into the previous.
        res = odo.rgbd_odometry_multi_scale(cur, prev, K, eye, 1.0, float(depth_max_m), crit,
                                            getattr(odo.Method, OPEN3D_METHODS[m]), params)
        T_prev_cur = res.transformation.numpy().astype(np.float64)
        ok = bool(np.all(np.isfinite(T_prev_cur)) and res.fitness > 0)
        return T_prev_cur, ok, float(res.fitness), float(res.inlier_rmse)

    chains, stamps, prep = _run_chains(frames, camera, methods, "open3d", convert, register, progress)
    info = {"open3d": o3d.__version__, "depth_max_m": float(depth_max_m), "criteria": list(criteria),
            "loss": {k: getattr(params, k) for k in ("depth_outlier_trunc", "depth_huber_delta",
                                                     "intensity_huber_delta")},
            "init": "identity", "undistorted": camera.is_distorted}
    return {m: c.run(f"open3d_{m}", stamps, prep, dict(info, method=OPEN3D_METHODS[m])) for m, c in chains.items()}


__all__ = ["OPEN3D_METHODS", "OPENCV_METHODS", "PeerRun", "import_open3d", "run_open3d", "run_opencv",
           "undistorted_frames"]
