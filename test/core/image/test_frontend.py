"""The colour front end: a depth image exposed off the colour, kept where it was exposed until mapping needs it."""
from __future__ import annotations

import dataclasses

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.geometry import se3_exp, se3_inv
from atsvo_ros.core.image.depth_warp import warp_depth
from atsvo_ros.core.image.frontend import RgbdFrontEnd

CAM = CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5)


def _frame() -> RgbdFrame:
    u, v = np.meshgrid(np.arange(CAM.width), np.arange(CAM.height))
    rgb = np.repeat(((u * 7 + v * 3) % 255).astype(np.uint8)[..., None], 3, axis=2)
    depth = (1.0 / (1.0 - 0.3 * (u - CAM.cx) / CAM.fx)).astype(np.float32)  # a tilted plane
    return RgbdFrame(1_000, rgb, depth)


def test_depth_at_the_colour_time_is_the_frame_itself():
    fe = RgbdFrontEnd(CAM, 3, 0.3, 6.0, 0.05)
    prepared = fe.prepare(_frame())
    assert prepared.T_depth_rgb is None and fe.at_colour_time(prepared) is prepared


def test_depth_exposed_elsewhere_is_warped_once_asked_for_with_its_pyramid():
    fe = RgbdFrontEnd(CAM, 3, 0.3, 6.0, 0.05)
    prepared = fe.prepare(_frame())
    T_depth_rgb = se3_exp(np.array([0.01, 0.0, -0.02, 0.0, np.radians(3.0), 0.0]))
    placed = fe.at_colour_time(dataclasses.replace(prepared, T_depth_rgb=T_depth_rgb))
    T_rgb_depth = se3_inv(T_depth_rgb)
    want = warp_depth(prepared.depth_m, CAM, T_rgb_depth[:3, :3], T_rgb_depth[:3, 3])
    assert placed.T_depth_rgb is None
    np.testing.assert_array_equal(placed.depth_m, want)
    assert len(placed.depth_pyramid) == 3 and not np.array_equal(placed.depth_pyramid[0], prepared.depth_pyramid[0])
    assert placed.pyramid is prepared.pyramid  # the colour is untouched
