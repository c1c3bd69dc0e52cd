"""RealSense-D455-like colour and depth models applied to rendered irradiance and depth.

Colour: sub-frames rendered across the exposure are averaged (motion blur), then the sensor
response: exposure time x gain x vignetting, shot noise (Poisson-like, variance proportional to
the signal) plus read noise, clipping, an sRGB-like gamma and 8-bit quantisation. The gain follows
an auto-exposure loop with a time constant, so bright/dark views change the brightness slowly as
on the real camera. Depth: z in millimetres (16UC1), Gaussian noise with sigma growing with z^2,
holes at depth discontinuities, random dropout blobs, 0 outside the valid range.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.errors import SimulationError


@dataclass(frozen=True)
class RgbModel:
    """Colour sensor parameters (irradiance in the renderer's linear unit, signal in [0, 1] before gamma).

    Attributes:
        max_blur_step_px: largest apparent motion between two motion-blur sub-frames.
        max_subframes: cap on sub-frames per exposure (bounds the cost of very fast motion).
        sensitivity: signal per unit irradiance and second at gain 1.
        full_well: signal-to-electrons scale of the shot noise (variance = signal / full_well).
        read_noise: standard deviation of the additive read noise (signal units).
        gamma: output encoding exponent (sRGB-like).
        ae_target / ae_time_constant_s / gain_limits: auto-gain set point, speed and range.
        vignetting: share of the cos^4 falloff applied at the image corners.
        readout_time_s: rolling-shutter readout, first to last row (0 = global shutter, as the D455's
            OV9782 colour imager; a Kinect v1's colour camera reads out over ~28 ms). Row ``r`` is exposed
            around ``stamp + readout (r / (H - 1) - 1/2)``: the stamp is the middle row's time.
        stamp_jitter_s: scale of the delay between exposure and the reported stamp (half-normal): a driver
            without hardware timestamps stamps each image when it reaches the host (OpenNI's Kinect in
            TUM RGB-D: 1.8 ms rms off its frame clock); the D455 with global time stamps on the sensor (0).
        stamp_latency_s: constant delay of every stamp after the middle row's exposure, on top of the jitter
            (OpenNI's Kinect: ~10 ms against TUM's motion capture; the D455 with global time: 0).
    """

    max_blur_step_px: float = 1.0
    max_subframes: int = 25
    sensitivity: float = 60.0
    full_well: float = 2000.0
    read_noise: float = 0.004
    gamma: float = 1.0 / 2.2
    ae_target: float = 0.22
    ae_time_constant_s: float = 0.3
    gain_limits: tuple[float, float] = (0.25, 8.0)
    vignetting: float = 0.35
    readout_time_s: float = 0.0
    stamp_jitter_s: float = 0.0
    stamp_latency_s: float = 0.0

    def __post_init__(self) -> None:
        if self.max_blur_step_px <= 0 or self.max_subframes < 1:
            raise SimulationError("max_blur_step_px must be > 0 and max_subframes >= 1")
        if not 0.0 <= self.readout_time_s <= 0.1:
            raise SimulationError(f"readout_time_s must be in [0, 0.1] s, got {self.readout_time_s}")
        if not 0.0 <= self.stamp_jitter_s <= 0.005:
            raise SimulationError(f"stamp_jitter_s must be in [0, 0.005] s, got {self.stamp_jitter_s}")
        if not 0.0 <= self.stamp_latency_s <= 0.1:
            raise SimulationError(f"stamp_latency_s must be in [0, 0.1] s, got {self.stamp_latency_s}")


@dataclass(frozen=True)
class DepthModel:
    """Depth sensor parameters.

    Attributes:
        min_m / max_m: valid range (the config's ``rig.depth_min_m``/``depth_max_m`` override them).
        sigma_at_1m_m: noise standard deviation at 1 m; it grows with z^2 as for stereo.
        edge_hole_ratio: relative depth jump within 3x3 pixels that leaves a hole.
        dropout_fraction / dropout_blob_px: share of pixels lost in random blobs of this size.
    """

    min_m: float = 0.3
    max_m: float = 6.0
    sigma_at_1m_m: float = 0.002
    edge_hole_ratio: float = 0.06
    dropout_fraction: float = 0.004
    dropout_blob_px: int = 5


class ColorSensor:
    """Stateful colour pipeline: averages sub-frames, applies noise and the auto-gain loop."""

    def __init__(self, model: RgbModel, exposure_s: float, rays: np.ndarray, shape: tuple[int, int],
                 rng: np.random.Generator) -> None:
        if not 0.0 < exposure_s <= 0.1:
            raise SimulationError(f"exposure must be in (0, 0.1] s, got {exposure_s}")
        self.model = model
        self.exposure_s = float(exposure_s)
        self.rng = rng
        r2 = (rays[:, 0] ** 2 + rays[:, 1] ** 2).reshape(shape)
        cos4 = 1.0 / (1.0 + r2) ** 2
        self.vignette = ((1.0 - model.vignetting) + model.vignetting * cos4).astype(np.float32)[..., None]
        self.gain = 1.0
        self._last_t_ns: int | None = None

    def expose(self, subframes: list[np.ndarray], stamp_ns: int) -> np.ndarray:
        """rgb8 image from the linear colour sub-frames of one exposure (HxWx3 float32 each)."""
        m = self.model
        irr = np.mean(subframes, axis=0) if len(subframes) > 1 else subframes[0]
        x = irr * self.vignette * (self.exposure_s * m.sensitivity * self.gain)
        noisy = x + self.rng.standard_normal(x.shape).astype(np.float32) * np.sqrt(
            np.maximum(x, 0.0) / m.full_well + m.read_noise**2).astype(np.float32)
        img = np.clip(noisy, 0.0, 1.0) ** m.gamma
        out = np.clip(img * 255.0 + self.rng.random(x.shape, dtype=np.float32), 0, 255).astype(np.uint8)
        self._update_gain(float(np.mean(x)), stamp_ns)
        return out

    def _update_gain(self, mean_linear: float, stamp_ns: int) -> None:
        m = self.model
        dt = 1.0 / 30.0 if self._last_t_ns is None else max((stamp_ns - self._last_t_ns) * 1e-9, 0.0)
        self._last_t_ns = stamp_ns
        wanted = self.gain * m.ae_target / max(mean_linear, 1e-6)
        a = 1.0 - np.exp(-dt / m.ae_time_constant_s)
        gain = self.gain * (wanted / self.gain) ** a  # first-order loop in log-gain
        self.gain = float(np.clip(gain, *m.gain_limits))


def row_weights(sub_times_s: np.ndarray, height: int, exposure_s: float, readout_time_s: float) -> np.ndarray:
    """(n_sub, height) weights of each sub-frame in each row's exposure (rows sum to 1).

    Sub-frame ``j`` stands for the time bin around ``sub_times_s[j]`` (relative to the stamp, half-way to
    its neighbours); row ``r`` integrates ``[t_r - exposure/2, t_r + exposure/2]`` with
    ``t_r = readout (r / (H - 1) - 1/2)``. The weight is the overlap of the two intervals; a row whose
    window falls between sub-frames takes the nearest one.
    """
    t = np.asarray(sub_times_s, dtype=np.float64)
    mid = 0.5 * (t[1:] + t[:-1])
    lo = np.concatenate([[-np.inf], mid])
    hi = np.concatenate([mid, [np.inf]])
    rows = readout_time_s * (np.arange(height) / max(height - 1, 1) - 0.5)
    a = rows[None, :] - 0.5 * exposure_s
    b = rows[None, :] + 0.5 * exposure_s
    w = np.clip(np.minimum(hi[:, None], b) - np.maximum(lo[:, None], a), 0.0, None)
    empty = w.sum(axis=0) <= 0
    if np.any(empty):
        w[np.argmin(np.abs(t[:, None] - rows[None, empty]), axis=0), np.flatnonzero(empty)] = 1.0
    return w / w.sum(axis=0, keepdims=True)


def depth_to_mm(depth_m: np.ndarray, model: DepthModel, rng: np.random.Generator) -> np.ndarray:
    """16UC1 millimetres from rendered z-depth: noise ~ z^2, holes, validity range (0 = no depth)."""
    z = np.asarray(depth_m, np.float32)
    noisy = z + rng.standard_normal(z.shape).astype(np.float32) * (model.sigma_at_1m_m * z * z)
    invalid = (noisy < model.min_m) | (noisy > model.max_m) | ~np.isfinite(noisy)
    # Depth discontinuities: stereo matching fails on the occluded side of an edge.
    zmax = cv2.dilate(z, np.ones((3, 3), np.uint8))
    zmin = cv2.erode(z, np.ones((3, 3), np.uint8))
    invalid |= (zmax - zmin) > model.edge_hole_ratio * zmin
    if model.dropout_fraction > 0:
        seeds = (rng.random(z.shape) < model.dropout_fraction / max(model.dropout_blob_px, 1) ** 2 * 4).astype(np.uint8)
        k = max(int(model.dropout_blob_px), 1)
        invalid |= cv2.dilate(seeds, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    mm = np.round(noisy * 1000.0)
    mm[invalid] = 0
    return np.clip(mm, 0, 65535).astype(np.uint16)
