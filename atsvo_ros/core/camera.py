"""Pinhole camera with plumb_bob / rational_polynomial / equidistant distortion.

Built from a sensor_msgs/CameraInfo-shaped object (ROS 2 ``k``/``d`` or ROS 1 ``K``/``D``), from a
ROS camera_calibration YAML, or from a plain dict. Projection maps camera-frame points to *raw*
(distorted) pixels; undistortion is a Gauss-Newton inversion accurate far below 1e-6 px.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from atsvo_ros.config import CameraConfig
from atsvo_ros.errors import CalibrationError

_N_COEFFS = {"none": 0, "plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}
_K_NAMES = {0: "fx", 2: "cx", 4: "fy", 5: "cy"}  # row-major K entries by name, for messages
_ALIASES = {"": "none", "pinhole": "none", "radtan": "plumb_bob", "fisheye": "equidistant",
            "kannala_brandt": "equidistant", "equi": "equidistant"}


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of one camera. ``D`` holds the ROS-ordered distortion coefficients."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    D: tuple[float, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        model = _ALIASES.get(self.distortion_model.lower(), self.distortion_model.lower())
        if model not in _N_COEFFS:
            raise CalibrationError(
                f"distortion_model {self.distortion_model!r} is not supported "
                f"(allowed: {', '.join(sorted(_N_COEFFS))})")
        d = tuple(float(v) for v in self.D)
        bad = [f"{name}={v}" for name, v in (("fx", self.fx), ("fy", self.fy), ("cx", self.cx), ("cy", self.cy))
               + tuple((f"D[{i}]", v) for i, v in enumerate(d)) if not math.isfinite(v)]
        if bad:  # first: a NaN passes some of the checks below and fails others, blaming the wrong value
            raise CalibrationError(f"intrinsics and distortion must be finite, got {', '.join(bad)}")
        n = _N_COEFFS[model]
        if len(d) > n and any(abs(v) > 0 for v in d[n:]):
            raise CalibrationError(f"{model} takes {n} coefficients, got {len(d)}: {d}")
        d = (d + (0.0,) * n)[:n]
        if model != "none" and not any(d):
            model, d = "none", ()
        object.__setattr__(self, "distortion_model", model)
        object.__setattr__(self, "D", d)
        if self.width <= 0 or self.height <= 0:
            raise CalibrationError(f"image size must be positive, got {self.width}x{self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise CalibrationError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_config(cls, cfg: CameraConfig) -> CameraModel:
        """The camera a :class:`~atsvo_ros.config.CameraConfig` describes (fallback intrinsics of a preset)."""
        return cls(cfg.width, cfg.height, cfg.fx, cfg.fy, cfg.cx, cfg.cy, cfg.distortion_model, cfg.D)

    @classmethod
    def from_camera_info(cls, msg: Any) -> CameraModel:
        """Build from a sensor_msgs/CameraInfo (rclpy, rosbags ROS 1 or ROS 2 classes).

        Raises:
            CalibrationError: K is missing or fx is not positive, or K or D hold NaN/inf (the message names the entries;
                callers prefix the topic).
        """
        K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64).reshape(-1)
        D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64).reshape(-1)
        if K.size != 9 or K[0] <= 0:
            raise CalibrationError("CameraInfo has no valid K matrix (uncalibrated camera?)")
        for name, values, labels in (("K", K, _K_NAMES), ("D", D, {})):
            bad = [f"{labels.get(i, f'{name}[{i}]')}={v}" for i, v in enumerate(values.tolist())
                   if not math.isfinite(v)]
            if bad:
                raise CalibrationError(f"{name} has non-finite values ({', '.join(bad)})")
        return cls(int(msg.width), int(msg.height), float(K[0]), float(K[4]), float(K[2]),
                   float(K[5]), str(msg.distortion_model or "none"), tuple(D.tolist()))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CameraModel:
        """Build from a ROS camera_calibration dict or a flat ``fx/fy/cx/cy`` dict."""
        try:
            w = int(d.get("image_width", d.get("width")))
            h = int(d.get("image_height", d.get("height")))
            if "camera_matrix" in d:
                K = np.asarray(d["camera_matrix"]["data"], dtype=np.float64).reshape(-1)
                fx, fy, cx, cy = K[0], K[4], K[2], K[5]
            elif "intrinsics" in d:
                fx, fy, cx, cy = (float(v) for v in d["intrinsics"])
            else:
                fx, fy, cx, cy = (float(d[k]) for k in ("fx", "fy", "cx", "cy"))
            dist = d.get("distortion_coefficients", d.get("D", d.get("distortion", ())))
            if isinstance(dist, dict):
                dist = dist["data"]
            model = str(d.get("distortion_model", "plumb_bob" if len(dist) else "none"))
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"incomplete camera calibration: {exc!r}") from exc
        return cls(w, h, float(fx), float(fy), float(cx), float(cy), model,
                   tuple(float(v) for v in dist))

    @classmethod
    def from_yaml(cls, path: str | Path) -> CameraModel:
        """Load a ROS camera_calibration YAML file."""

        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise CalibrationError(f"cannot read calibration {path}: {exc}") from exc
        if not isinstance(data, dict):
            raise CalibrationError(f"calibration {path} is not a mapping")
        for key in ("event_camera", "camera"):
            if isinstance(data.get(key), dict):
                data = data[key]
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        """Flat dict, the inverse of :meth:`from_dict` (used by config files and the simulator)."""
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy, "distortion_model": self.distortion_model,
                "D": list(self.D)}

    # ------------------------------------------------------------------ derived models
    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def is_distorted(self) -> bool:
        return self.distortion_model != "none"

    def pinhole(self) -> CameraModel:
        """Same intrinsics without distortion: the model of an image rectified with :meth:`rectify_maps`."""
        return dataclasses.replace(self, distortion_model="none", D=())

    def scaled(self, factor: float) -> CameraModel:
        """Model of the image resized by ``factor`` (pyramid levels), pixel-centre convention."""
        if self.is_distorted:
            raise CalibrationError("scale a rectified (pinhole) model, not a distorted one")
        return CameraModel(max(1, int(self.width * factor)), max(1, int(self.height * factor)),
                           self.fx * factor, self.fy * factor,
                           (self.cx + 0.5) * factor - 0.5, (self.cy + 0.5) * factor - 0.5)

    # ------------------------------------------------------------------ distortion
    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Normalised undistorted coordinates (N, 2) -> normalised distorted coordinates."""
        xy = np.asarray(xy, dtype=np.float64)
        return _distort(self.distortion_model, self.D, xy)[0]

    def undistort(self, xy_d: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Normalised distorted coordinates (N, 2) -> undistorted, by Gauss-Newton on :meth:`distort`."""
        xy_d = np.asarray(xy_d, dtype=np.float64)
        if not self.is_distorted:
            return xy_d.copy()
        xy = xy_d.copy()
        for _ in range(iterations):
            f, J = _distort(self.distortion_model, self.D, xy, jacobian=True)
            r = f - xy_d
            if np.abs(r).max(initial=0.0) < 1e-14:
                break
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            dx = (J[:, 1, 1] * r[:, 0] - J[:, 0, 1] * r[:, 1]) / det
            dy = (-J[:, 1, 0] * r[:, 0] + J[:, 0, 0] * r[:, 1]) / det
            xy = xy - np.stack([dx, dy], axis=1)
        return xy

    # ------------------------------------------------------------------ projection
    def project(self, p_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points (N, 3) -> raw pixels (N, 2) and a mask of points in front (z > 0)."""
        p_c = np.asarray(p_c, dtype=np.float64).reshape(-1, 3)
        z = p_c[:, 2]
        valid = z > 1e-9
        zs = np.where(valid, z, 1.0)
        xy = p_c[:, :2] / zs[:, None]
        if self.is_distorted:
            xy = self.distort(xy)
        uv = np.empty_like(xy)
        uv[:, 0] = self.fx * xy[:, 0] + self.cx
        uv[:, 1] = self.fy * xy[:, 1] + self.cy
        return uv, valid

    def backproject(self, uv: np.ndarray, depth_m: np.ndarray | float) -> np.ndarray:
        """Raw pixels (N, 2) and z-depths (N,) in metres -> camera-frame points (N, 3)."""
        xy = self.pixel_to_normalized(uv)
        z = np.broadcast_to(np.asarray(depth_m, dtype=np.float64), (len(xy),))
        return np.column_stack([xy * z[:, None], z])

    def pixel_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (N, 2) -> undistorted normalised image coordinates (N, 2)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        xy_d = np.column_stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy])
        return self.undistort(xy_d)

    def in_image(self, uv: np.ndarray, border_px: float = 0.0) -> np.ndarray:
        """Mask of pixels at least ``border_px`` inside the image."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        return ((uv[:, 0] >= border_px) & (uv[:, 0] <= self.width - 1 - border_px)
                & (uv[:, 1] >= border_px) & (uv[:, 1] <= self.height - 1 - border_px))

    def rectify_maps(self, target: CameraModel | None = None) -> tuple[np.ndarray, np.ndarray]:
        """float32 ``(map_x, map_y)`` for ``cv2.remap`` from this raw camera to ``target`` (pinhole).

        Computed with this module's own distortion so that maps and :meth:`project` agree exactly.
        """
        target = target or self.pinhole()
        u, v = np.meshgrid(np.arange(target.width, dtype=np.float64),
                           np.arange(target.height, dtype=np.float64))
        xy = np.column_stack([((u - target.cx) / target.fx).ravel(), ((v - target.cy) / target.fy).ravel()])
        xy_d = self.distort(xy) if self.is_distorted else xy
        map_x = (self.fx * xy_d[:, 0] + self.cx).reshape(u.shape).astype(np.float32)
        map_y = (self.fy * xy_d[:, 1] + self.cy).reshape(u.shape).astype(np.float32)
        return map_x, map_y


def _distort(model: str, D: tuple[float, ...], xy: np.ndarray,
             jacobian: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Apply a distortion model to normalised points; optionally return d(out)/d(xy), (N, 2, 2)."""
    x, y = xy[:, 0], xy[:, 1]
    if model == "none":
        J = np.broadcast_to(np.eye(2), (len(xy), 2, 2)).copy() if jacobian else None
        return xy.copy(), J
    if model == "equidistant":
        k1, k2, k3, k4 = D
        r = np.hypot(x, y)
        th = np.arctan(r)
        th2 = th * th
        poly = 1 + th2 * (k1 + th2 * (k2 + th2 * (k3 + th2 * k4)))
        thd = th * poly
        small = r < 1e-12
        rs = np.where(small, 1.0, r)
        s = np.where(small, 1.0, thd / rs)
        out = np.column_stack([x * s, y * s])
        if not jacobian:
            return out, None
        dthd_dth = 1 + th2 * (3 * k1 + th2 * (5 * k2 + th2 * (7 * k3 + th2 * 9 * k4)))
        dth_dr = 1.0 / (1.0 + r * r)
        ds_dr = np.where(small, 0.0, (dthd_dth * dth_dr * rs - thd) / (rs * rs))
        drdx, drdy = np.where(small, 0.0, x / rs), np.where(small, 0.0, y / rs)
        J = np.empty((len(xy), 2, 2))
        J[:, 0, 0] = s + x * ds_dr * drdx
        J[:, 0, 1] = x * ds_dr * drdy
        J[:, 1, 0] = y * ds_dr * drdx
        J[:, 1, 1] = s + y * ds_dr * drdy
        return out, J
    if model == "plumb_bob":
        k1, k2, p1, p2, k3 = D
        k4 = k5 = k6 = 0.0
    else:  # rational_polynomial
        k1, k2, p1, p2, k3, k4, k5, k6 = D
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    out = np.column_stack([xd, yd])
    if not jacobian:
        return out, None
    dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    drad_dr2 = (dnum * den - num * dden) / (den * den)
    J = np.empty((len(xy), 2, 2))
    J[:, 0, 0] = rad + x * drad_dr2 * 2 * x + 2 * p1 * y + 6 * p2 * x
    J[:, 0, 1] = x * drad_dr2 * 2 * y + 2 * p1 * x + 2 * p2 * y
    J[:, 1, 0] = y * drad_dr2 * 2 * x + 2 * p1 * x + 2 * p2 * y
    J[:, 1, 1] = rad + y * drad_dr2 * 2 * y + 6 * p1 * y + 2 * p2 * x
    return out, J
