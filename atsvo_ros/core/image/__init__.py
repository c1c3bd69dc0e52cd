"""Images for direct alignment: pyramids with gradients, residual patterns, sampling, the RGB-D front end."""
from __future__ import annotations

from atsvo_ros.core.image.frontend import ImageFrontEnd, PreparedFrame, RgbdFrontEnd, to_grey, usable_levels
from atsvo_ros.core.image.photometric import (
    ATS_PATTERN,
    RGB_PATTERN,
    bilinear,
    extract_patches,
    huber_energy,
    huber_weight,
    level_position,
    sample_patches,
)
from atsvo_ros.core.image.pyramid import (
    build_pyramid,
    depth_pyramid,
    image_gradients,
    image_pyramid_with_gradients,
    pyramid_cameras,
)

__all__ = ["ATS_PATTERN", "RGB_PATTERN", "ImageFrontEnd", "PreparedFrame", "RgbdFrontEnd", "bilinear", "build_pyramid",
           "depth_pyramid", "extract_patches", "huber_energy", "huber_weight", "image_gradients",
           "image_pyramid_with_gradients", "level_position", "pyramid_cameras", "sample_patches", "to_grey",
           "usable_levels"]
