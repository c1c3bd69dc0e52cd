"""The RealSense D455's depth as the robot gets it: active IR stereo, exposed while the robot moves.

The D455 does not measure depth at an instant. Its two global-shutter IR imagers (95 mm apart) see the
scene's IR texture with the projector's dot pattern over it, each integrated over the IR exposure;
its vision processor matches them along the rows (semi-global block matching with a left-right check,
a uniqueness ("second peak") test and a texture test that leave holes where matching is unsure), turns
disparity into depth, and the driver registers that depth to the colour camera (realsense2_camera's
``aligned_depth_to_color``) without any motion compensation. This module simulates that chain:

1. IR images of both imagers: albedo x (room IR + the projector's dots with inverse-square falloff),
   averaged over sub-frames spread across the IR exposure (motion blur: the scene's texture smears with
   the motion; the dots move with the projector, i.e. with the camera, and smear only where the depth
   along their ray changes), then shot and read noise and 8-bit quantisation;
2. an auto-exposure loop that sets the IR exposure from the last frames' brightness (long exposures in a
   room with little IR light: more blur);
3. OpenCV's semi-global matcher with the left-right consistency and uniqueness checks, a texture test,
   speckle removal; the left-most band where no match can exist stays invalid, as on the real camera;
4. depth = f B / disparity in the left imager, registered to the colour camera pixel by pixel
   (nearest surface wins), 0 where nothing maps (occlusion shadow, holes).

The depth frame is exposed at its own time: the D455 cannot synchronise the exposures of its colour and
depth imagers (librealsense issue #11609), and realsense2_camera stamps a frameset's images alike, so
the aligned depth carries the colour stamp while it shows the scene ``phase_s`` away from it.

Sources of the defaults: D455 datasheet (Intel RealSense D400 Series Product Family Datasheet, rev. 2020
with the D455: 95 mm baseline, depth field of view 87 x 58 deg, global-shutter OV9782 imagers, depth up
to 848x480 at 30 fps by default in realsense2_camera); librealsense's D4 defaults (auto-exposure on, up to
the frame period, 33 ms at 30 fps; 8.5 ms is the stereo module's default manual exposure, our indoor
operating point); the D4 vision processor's 128-disparity search. Not from a datasheet, stated as our
choice and open to a fit on the robot's recordings: the dot count and size, the projector's brightness
against the room's IR, the matcher's thresholds and the colour camera's 59 mm offset from the left imager.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim import _stereo_kernels as kern
from atsvo_ros.sim.render import MotionProbe, Renderer
from atsvo_ros.sim.scene import Scene

#: Brightest IR light (room or projector) in the model's unit (on a white surface at 1 m): 400 times the default
#: room's 0.25 and 25 times the projector's dots (4); there the auto-exposure is down at its shortest (20 us).
MAX_IR_LIGHT = 100.0


@dataclass(frozen=True)
class StereoModel:
    """Parameters of the D455's depth pipeline (lengths in m, times in s, IR signal in [0, 1] of full scale).

    Attributes:
        width / height: depth (IR) image size; 848x480 is realsense2_camera's default D455 depth profile.
        hfov_deg: horizontal field of view of the IR imagers (datasheet: 87 deg).
        baseline_m: distance between the imagers (datasheet: 95 mm).
        rgb_offset_m: the colour camera's position along the left imager's x axis (a typical factory
            extrinsic; read yours with ``rs-enumerate-devices -c``).
        projector_offset_m: the dot projector's position along the left imager's x axis (between the imagers).
        n_dots / dot_sigma_px: dots of the projector's pseudo-random pattern and their Gaussian size (in IR
            pixels at 1 m); our choice, of the order of the D400 projectors' few thousand dots.
        projector_power: a dot's peak irradiance on a white surface at 1 m, in units of the room's IR on it.
        ambient_ir: the room's IR light on a white surface (relative to ``projector_power``'s unit): indoor
            LED light carries little IR, so the dots dominate within ~2 m and fade beyond ~4-5 m.
        exposure_s: fixed IR exposure, or None for the auto-exposure loop.
        ae_target / ae_time_constant_s / exposure_limits_s: the loop's mean-signal set point, speed and
            range (up to the frame period at 30 fps, as librealsense allows).
        sensitivity: signal per unit irradiance and second; sets where the loop settles in the default
            room (about 8.5 ms, the D4 stereo module's default manual exposure).
        full_well / read_noise: shot noise (variance = signal / full_well) and read noise of the imagers.
        num_disparities / block_size: search range (D4: 128 disparities) and matching window.
        uniqueness_ratio: % by which the best match must beat the second best (the D4's second-peak test).
        lr_max_diff_px: left-right consistency tolerance.
        texture_threshold: minimum local standard deviation (grey levels) of the left IR image for a match.
        speckle_window_px / speckle_range_px: small disparity islands removed as speckle.
        max_blur_step_px / max_subframes: sub-frame spacing over the exposure (apparent motion) and its cap.
        phase_s: depth exposure centre minus colour exposure centre; None draws it from the sequence's
            seed, uniform within half a frame period (the exposures are not synchronised).
    """

    width: int = 848
    height: int = 480
    hfov_deg: float = 87.0
    baseline_m: float = 0.095
    rgb_offset_m: float = 0.059
    projector_offset_m: float = 0.0475
    n_dots: int = 5000
    dot_sigma_px: float = 0.8
    projector_power: float = 4.0
    ambient_ir: float = 0.25
    exposure_s: float | None = None
    ae_target: float = 0.25
    ae_time_constant_s: float = 0.15
    exposure_limits_s: tuple[float, float] = (20e-6, 0.033)
    sensitivity: float = 110.0
    full_well: float = 3000.0
    read_noise: float = 0.004
    num_disparities: int = 128
    block_size: int = 7
    uniqueness_ratio: int = 10
    lr_max_diff_px: int = 1
    texture_threshold: float = 3.0
    speckle_window_px: int = 60
    speckle_range_px: int = 2
    max_blur_step_px: float = 1.5
    max_subframes: int = 15
    phase_s: float | None = None

    def __post_init__(self) -> None:
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise SimulationError(f"IR image size must be in [16, 4096] px, got {self.width}x{self.height}")
        if not 10.0 <= self.hfov_deg <= 150.0 or not self.baseline_m > 0:
            raise SimulationError("hfov_deg must be in [10, 150] and baseline_m > 0")
        lo, hi = self.exposure_limits_s
        if not 0 < lo <= hi <= 0.1 or (self.exposure_s is not None and not lo <= self.exposure_s <= hi):
            raise SimulationError(f"IR exposure must lie in (0, 0.1] s within its limits {self.exposure_limits_s}, "
                                  f"got {self.exposure_s}")
        if self.num_disparities % 16 or self.num_disparities < 16 or self.block_size % 2 == 0:
            raise SimulationError("num_disparities must be a positive multiple of 16 and block_size odd")
        if not self.max_blur_step_px > 0 or self.max_subframes < 1 or self.n_dots < 0:
            raise SimulationError("max_blur_step_px must be > 0, max_subframes >= 1 and n_dots >= 0")
        for name in ("projector_power", "ambient_ir"):  # NaN fails these tests
            if not 0 <= getattr(self, name) <= MAX_IR_LIGHT:
                raise SimulationError(f"{name} must be in [0, {MAX_IR_LIGHT:g}] (the room's default IR light is "
                                      f"0.25, the projector's dots 4), got {getattr(self, name)}")
        if self.phase_s is not None and not abs(self.phase_s) <= 0.1:
            raise SimulationError(f"phase_s must be within +-0.1 s, got {self.phase_s}")

    @property
    def focal_px(self) -> float:
        return 0.5 * self.width / np.tan(np.radians(0.5 * self.hfov_deg))

    def camera(self) -> CameraModel:
        """The (rectified, undistorted) IR imagers' camera model."""
        f = self.focal_px
        return CameraModel(self.width, self.height, f, f, 0.5 * self.width - 0.5, 0.5 * self.height - 0.5,
                           "none", ())

    def T_rgb_left(self) -> np.ndarray:
        """The left imager's pose in the colour optical frame (same orientation, offset along x)."""
        T = np.eye(4)
        T[0, 3] = -self.rgb_offset_m
        return T


def dot_pattern(model: StereoModel, rng: np.random.Generator) -> np.ndarray:
    """The projector's pattern on its image plane (same intrinsics as the imagers): Gaussian dots, peak 1."""
    img = np.zeros((model.height, model.width), np.float32)
    if model.n_dots == 0:
        return img
    xy = rng.random((model.n_dots, 2)) * [model.width, model.height]
    r = int(np.ceil(3 * model.dot_sigma_px))
    offs = np.arange(-r, r + 1)
    for dx in offs:
        for dy in offs:
            u = np.floor(xy[:, 0]).astype(int) + dx
            v = np.floor(xy[:, 1]).astype(int) + dy
            ok = (u >= 0) & (v >= 0) & (u < model.width) & (v < model.height)
            d2 = (u + 0.5 - xy[:, 0]) ** 2 + (v + 0.5 - xy[:, 1]) ** 2
            np.maximum.at(img, (v[ok], u[ok]), np.exp(-0.5 * d2[ok] / model.dot_sigma_px ** 2).astype(np.float32))
    return img


@dataclass(frozen=True)
class DepthCapture:
    """One depth frame: depth in metres on the colour grid (0 = no depth) and how it was made."""

    depth_m: np.ndarray
    exposure_s: float
    n_subframes: int
    ir_blur_px: float  # largest apparent motion of the scene in the left imager over the exposure
    centre_ns: int  # when the depth frame's exposure was centred


class StereoDepthSensor:
    """The D455's depth pipeline over a scene, frame by frame (stateful: its auto-exposure loop).

    ``T_world_rgb(t_ns)`` gives the colour camera's pose at any time (stacked for several times);
    ``rgb_camera`` is the colour camera the depth is registered to.
    """

    def __init__(self, model: StereoModel, scene: Scene, rgb_camera: CameraModel, T_world_rgb,
                 rng: np.random.Generator) -> None:
        self.model = model
        self.ir_camera = model.camera()
        self.rgb_camera = rgb_camera
        self._T_world_rgb = T_world_rgb
        self._rng = rng
        self._albedo = Renderer(dataclasses.replace(scene, ambient=1.0), self.ir_camera)
        self._probe = MotionProbe(self.ir_camera, self._albedo.rays)
        self._dots = dot_pattern(model, rng)
        self._T_rgb_left = model.T_rgb_left()
        self._T_left_right = np.eye(4)
        self._T_left_right[0, 3] = model.baseline_m
        self._R_left_rgb = np.ascontiguousarray(self._T_rgb_left[:3, :3])  # left imager -> colour
        self._t_left_rgb = np.ascontiguousarray(self._T_rgb_left[:3, 3])
        self._matcher = cv2.StereoSGBM_create(
            minDisparity=0, numDisparities=model.num_disparities, blockSize=model.block_size,
            P1=8 * model.block_size ** 2, P2=32 * model.block_size ** 2, disp12MaxDiff=model.lr_max_diff_px,
            uniquenessRatio=model.uniqueness_ratio, speckleWindowSize=model.speckle_window_px,
            speckleRange=model.speckle_range_px, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
        self.exposure_s: float | None = model.exposure_s
        self._last_ns: int | None = None
        self._depth_prev: np.ndarray | None = None

    # ------------------------------------------------------------------ poses
    def T_world_left(self, t_ns) -> np.ndarray:
        return self._T_world_rgb(t_ns) @ self._T_rgb_left

    # ------------------------------------------------------------------ capture
    def capture(self, centre_ns: int) -> DepthCapture:
        """The depth frame exposed around ``centre_ns``, registered to the colour camera."""
        m = self.model
        if self._depth_prev is None:
            self._depth_prev = self._albedo.render(self.T_world_left(centre_ns))[1]
        if self.exposure_s is None:
            self.exposure_s = self._settled_exposure(centre_ns)
        exposure = float(self.exposure_s)
        half = int(round(0.5 * exposure * 1e9))
        moved = float(self._probe.max_motion_px(self._depth_prev, self.T_world_left(centre_ns - half),
                                                self.T_world_left(centre_ns + half)))
        n_sub = 1 if not moved > m.max_blur_step_px else min(int(np.ceil(moved / m.max_blur_step_px)) + 1,
                                                             m.max_subframes)
        n_sub += 1 - n_sub % 2
        times = centre_ns + (np.linspace(-half, half, n_sub) if n_sub > 1 else np.zeros(1)).round().astype(np.int64)
        irr_left, irr_right = self._irradiance(times)
        left = self._expose(irr_left, exposure)
        right = self._expose(irr_right, exposure)
        self._auto_expose(left, centre_ns)
        z_left = self._match(left, right)
        return DepthCapture(self._align(z_left), exposure, n_sub, moved, int(centre_ns))

    def _irradiance(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both imagers' IR irradiance averaged over the sub-frames at ``times`` (flat float32 arrays)."""
        m, cam = self.model, self.ir_camera
        n = cam.width * cam.height
        left = np.zeros(n, np.float32)
        right = np.zeros(n, np.float32)
        w = 1.0 / len(times)
        rays = self._albedo.rays
        for j, T_w_l in enumerate(self.T_world_left(times)):
            for T_w_c, out, proj_dx in ((T_w_l, left, -m.projector_offset_m),
                                        (T_w_l @ self._T_left_right, right, m.baseline_m - m.projector_offset_m)):
                def lit(band: slice, albedo: np.ndarray, depth: np.ndarray, out=out, proj_dx=proj_dx) -> None:
                    kern._ir_irradiance(rays[band], depth[band], albedo[band], self._dots, cam.fx, cam.fy, cam.cx,
                                        cam.cy, proj_dx, m.projector_power, m.ambient_ir, w, out[band])

                _, depth = self._albedo.render(T_w_c, then=lit)  # the projector's light in the cast's threads
                if out is left and j == len(times) // 2:
                    self._depth_prev = depth
        shape = (cam.height, cam.width)
        return left.reshape(shape), right.reshape(shape)

    def _expose(self, irradiance: np.ndarray, exposure_s: float) -> np.ndarray:
        """8-bit IR image: signal, shot and read noise, clipping."""
        m = self.model
        x = irradiance * np.float32(exposure_s * m.sensitivity)
        sigma = np.sqrt(np.maximum(x, 0.0) / m.full_well + m.read_noise ** 2).astype(np.float32)
        noisy = x + self._rng.standard_normal(x.shape, dtype=np.float32) * sigma
        return np.clip(np.round(noisy * 255.0), 0, 255).astype(np.uint8)

    def _settled_exposure(self, t_ns: int) -> float:
        """The exposure the loop has settled on before the sequence starts (a sharp view at ``t_ns``)."""
        m = self.model
        irr_left, _ = self._irradiance(np.array([t_ns], np.int64))
        mean = float(np.mean(irr_left)) * m.sensitivity
        return float(np.clip(m.ae_target / max(mean, 1e-9), *m.exposure_limits_s))

    def _auto_expose(self, image: np.ndarray, t_ns: int) -> None:
        """First-order loop in log-exposure towards the set point (fixed exposure: nothing to do)."""
        m = self.model
        if m.exposure_s is not None:
            return
        dt = 1.0 / 30.0 if self._last_ns is None else max((t_ns - self._last_ns) * 1e-9, 0.0)
        self._last_ns = t_ns
        mean = max(float(np.mean(image)) / 255.0, 1e-4)
        a = 1.0 - np.exp(-dt / m.ae_time_constant_s)
        self.exposure_s = float(np.clip(self.exposure_s * (m.ae_target / mean) ** a, *m.exposure_limits_s))

    def _match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Depth (m) in the left imager from semi-global matching; 0 where the checks leave a hole."""
        m, cam = self.model, self.ir_camera
        # OpenCV leaves the first num_disparities columns unmatched; the D4 searches them too (what the right
        # imager does not see there then fails the checks: the real camera's invalid band on the left).
        pad = m.num_disparities
        disp = self._matcher.compute(cv2.copyMakeBorder(left, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0),
                                     cv2.copyMakeBorder(right, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0))
        disp = disp[:, pad:].astype(np.float32) / 16.0
        k = (m.block_size, m.block_size)
        f = left.astype(np.float32)
        var = cv2.blur(f * f, k) - cv2.blur(f, k) ** 2
        # a match in the padding is a column the right imager does not see: no depth (the left invalid band)
        seen = disp <= np.arange(disp.shape[1], dtype=np.float32)[None, :]
        valid = (disp > 0.5) & seen & (var >= m.texture_threshold ** 2)
        z = np.zeros_like(disp)
        z[valid] = cam.fx * m.baseline_m / disp[valid]
        return z

    def _align(self, z_left: np.ndarray) -> np.ndarray:
        """The left imager's depth registered to the colour camera (0 where no depth lands)."""
        ir, rgb = self.ir_camera, self.rgb_camera
        out = np.full((rgb.height, rgb.width), np.inf, np.float32)
        kern._align_to_colour(z_left, ir.fx, ir.fy, ir.cx, ir.cy, self._R_left_rgb, self._t_left_rgb,
                              rgb.fx, rgb.fy, rgb.cx, rgb.cy, out)
        out[~np.isfinite(out)] = 0.0
        return out


def depth_phase_s(model: StereoModel, rate_hz: float, rng: np.random.Generator) -> float:
    """The depth frame's exposure centre minus the colour frame's: the model's, or drawn within half a period."""
    if model.phase_s is not None:
        return float(model.phase_s)
    return float(rng.uniform(-0.5, 0.5) / rate_hz)


def stereo_depth_to_mm(depth_m: np.ndarray, min_m: float, max_m: float) -> np.ndarray:
    """16UC1 millimetres (the D455's depth unit) within the valid range, 0 elsewhere."""
    z = np.asarray(depth_m, np.float32)
    ok = (z >= min_m) & (z <= max_m)
    return np.where(ok, np.round(z * 1000.0), 0).astype(np.uint16)


__all__ = ["DepthCapture", "StereoDepthSensor", "StereoModel", "depth_phase_s", "dot_pattern", "stereo_depth_to_mm"]
