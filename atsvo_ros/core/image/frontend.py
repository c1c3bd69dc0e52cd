"""Per-camera front end: rectify, build the image pyramid with gradients (and the depth pyramid).

Everything downstream works on pinhole models and their pyramids: a distorted camera is rectified
once per image (``cv2.remap``; depth with nearest neighbour, so no depth is invented across edges).
The colour camera uses :class:`RgbdFrontEnd`; the event camera's ATS image goes through the same
:class:`ImageFrontEnd` (rectification maps, pyramid, gradients).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.geometry import se3_inv
from atsvo_ros.core.image.depth_warp import warp_depth
from atsvo_ros.core.image.pyramid import build_pyramid, depth_pyramid, image_pyramid_with_gradients, pyramid_cameras
from atsvo_ros.errors import ImageError

#: The coarsest pyramid level keeps at least this many pixels along its shorter side.
MIN_LEVEL_SIZE_PX = 16


def usable_levels(camera: CameraModel, requested: int) -> int:
    """``requested`` pyramid levels, fewer if the coarsest would be smaller than :data:`MIN_LEVEL_SIZE_PX`."""
    levels = max(1, int(requested))
    while levels > 1 and min(camera.width, camera.height) >> (levels - 1) < MIN_LEVEL_SIZE_PX:
        levels -= 1
    return levels


def to_grey(image: np.ndarray, width: int, height: int, what: str = "colour image") -> np.ndarray:
    """HxWx3 RGB uint8 or HxW grey (uint8, or float in 0-255) -> float32 grey, checked against the camera size.

    Raises :class:`ImageError` for anything else (other dtypes, channels, empty or mis-sized images), so a
    wrong encoding is named instead of surfacing as an OpenCV error or a silently rescaled image.
    """
    img = np.asarray(image)
    if img.size == 0:
        raise ImageError(f"{what} is empty (shape {img.shape})")
    if img.ndim == 3 and img.shape[2] == 3:
        if img.dtype != np.uint8:
            raise ImageError(f"{what}: a 3-channel image must be uint8 RGB, got {img.dtype} (16-bit or float "
                             "colour is not supported: convert to rgb8)")
        grey = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY).astype(np.float32)
    elif img.ndim == 2:
        if img.dtype == np.uint8:
            grey = img.astype(np.float32)
        elif img.dtype in (np.float32, np.float64):
            grey = img.astype(np.float32)
            if not np.all(np.isfinite(grey)):
                raise ImageError(f"{what} contains NaN or infinite values")
        else:
            raise ImageError(f"{what}: a grey image must be uint8 (or float 0-255), got {img.dtype}")
    else:
        raise ImageError(f"{what} must be HxWx3 RGB or HxW grey, got shape {img.shape}")
    if grey.shape != (height, width):
        raise ImageError(f"{what} is {grey.shape[1]}x{grey.shape[0]} but the camera model is {width}x{height}; "
                         "check the camera_info / config")
    return grey


class ImageFrontEnd:
    """Rectification and pyramid of one camera's images (colour or ATS)."""

    def __init__(self, raw_camera: CameraModel, levels: int) -> None:
        self.raw_camera = raw_camera
        self.camera = raw_camera.pinhole()
        self.n_levels = usable_levels(self.camera, levels)
        self.cameras = pyramid_cameras(self.camera, self.n_levels)
        self._maps = raw_camera.rectify_maps() if raw_camera.is_distorted else None

    def rectify(self, image: np.ndarray, nearest: bool = False) -> np.ndarray:
        """An image of the raw camera resampled onto the pinhole grid (identity for an undistorted camera)."""
        if self._maps is None:
            return image
        mx, my = self._maps
        if nearest:
            return cv2.remap(image, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def pyramid(self, image: np.ndarray) -> list[np.ndarray]:
        """``[I, Ix, Iy]`` per level of an already rectified float32 image."""
        return image_pyramid_with_gradients(build_pyramid(image, self.n_levels))


@dataclass(frozen=True)
class PreparedFrame:
    """A colour + depth pair ready for tracking and mapping (all on the pinhole grid)."""

    stamp_ns: int
    pyramid: list[np.ndarray]  # per level (H, W, 3) float32 [I, Ix, Iy]
    depth_m: np.ndarray  # float32 metres, NaN/out of range kept as given (the mapper validates)
    depth_pyramid: list[np.ndarray]  # float32 per level, 0 = invalid
    n_valid_depth: int
    contrast: float = 255.0  # standard deviation of the grey image (0-255) at 1/4 resolution
    # The camera at the depth's exposure relative to the colour's (``X_depth = T_depth_rgb X_rgb``); None when the
    # depth is at the colour's time. Tracking reads the depth where it was exposed; mapping moves it first.
    T_depth_rgb: np.ndarray | None = None

    @property
    def grey(self) -> np.ndarray:
        return self.pyramid[0][..., 0]


class RgbdFrontEnd(ImageFrontEnd):
    """The colour camera's front end; the aligned depth follows the colour image."""

    def __init__(self, raw_camera: CameraModel, levels: int, depth_min_m: float, depth_max_m: float,
                 depth_edge_ratio: float) -> None:
        super().__init__(raw_camera, levels)
        self.depth_min_m = float(depth_min_m)
        self.depth_max_m = float(depth_max_m)
        self.depth_edge_ratio = float(depth_edge_ratio)

    def prepare(self, frame: RgbdFrame) -> PreparedFrame:
        """Check, rectify and build the pyramids of one frame."""
        cam = self.raw_camera
        grey = to_grey(frame.rgb, cam.width, cam.height)
        depth = np.asarray(frame.depth_m)
        if depth.shape != grey.shape:
            raise ImageError(f"depth image shape {depth.shape} differs from the colour image {grey.shape}: "
                             "the depth must be aligned to colour (on a RealSense: aligned_depth_to_color/image_raw, "
                             "not depth/image_rect_raw)")
        if depth.dtype.kind != "f":
            raise ImageError(f"depth must be float metres, got {depth.dtype} (convert 16UC1 millimetres first)")
        depth = depth.astype(np.float32, copy=False)
        grey = self.rectify(grey)
        if not frame.depth_rectified:
            depth = self.rectify(depth, nearest=True)
        pyr = self.pyramid(grey)
        return self.with_depth(PreparedFrame(int(frame.stamp_ns), pyr, depth, [], 0,
                                             float(np.std(pyr[min(2, len(pyr) - 1)][..., 0]))), depth)

    def with_depth(self, prepared: PreparedFrame, depth_m: np.ndarray) -> PreparedFrame:
        """``prepared`` with another depth image on the rectified grid (e.g. moved to the colour's time)."""
        dpyr = depth_pyramid(depth_m, self.n_levels, self.depth_edge_ratio, self.depth_min_m, self.depth_max_m)
        return dataclasses.replace(prepared, depth_m=depth_m, depth_pyramid=dpyr,
                                   n_valid_depth=int(np.count_nonzero(dpyr[0])), T_depth_rgb=None)

    def at_colour_time(self, prepared: PreparedFrame) -> PreparedFrame:
        """``prepared`` with its depth image moved to the colour's time (itself when the depth is there already).

        Tracking does not need this (its depth term reads the depth at its own exposure, ``T_depth_rgb``); a
        keyframe or an event map does, as its points sit on colour pixels: the warp (1.8-2.5 ms at 640x480) and a
        second depth pyramid are paid only then.
        """
        if prepared.T_depth_rgb is None:
            return prepared
        T_rgb_depth = se3_inv(prepared.T_depth_rgb)
        return self.with_depth(prepared, warp_depth(prepared.depth_m, self.camera, T_rgb_depth[:3, :3],
                                                    T_rgb_depth[:3, 3]))


__all__ = ["ImageFrontEnd", "PreparedFrame", "RgbdFrontEnd", "to_grey", "usable_levels"]
