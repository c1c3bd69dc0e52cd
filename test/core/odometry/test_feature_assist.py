"""Which frames the feature matches check (:class:`~atsvo_ros.core.odometry.feature_assist.FeatureAssist`)."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.frame import RgbdFrame
from atsvo_ros.core.geometry import so3_exp
from atsvo_ros.core.image.frontend import RgbdFrontEnd
from atsvo_ros.core.odometry.feature_assist import FeatureAssist

CAM = CameraModel(320, 240, 270.0, 270.0, 159.5, 119.5)


def _assist(**overrides: float) -> FeatureAssist:
    """A feature assist with one trusted previous frame (a textured plane) to check against."""
    config = load_config("tum_fr1", overrides={f"tracker.{k}": v for k, v in overrides.items()})
    frontend = RgbdFrontEnd(CAM, 3, 0.3, 6.0, 0.05)
    u, v = np.meshgrid(np.arange(CAM.width), np.arange(CAM.height))
    rgb = np.repeat(((u * 7 + v * 3) % 255).astype(np.uint8)[..., None], 3, axis=2)
    frame = frontend.prepare(RgbdFrame(1_000, rgb, np.full(u.shape, 2.0, np.float32)))
    assist = FeatureAssist(config, frontend.cameras, frontend.at_colour_time)
    assist.end_frame(frame, np.eye(4), trusted=True)
    return assist


def _pose(turn_deg: float = 0.0, centre_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """``T_c_w`` of a camera turned about y by ``turn_deg`` with its centre at ``centre_m``."""
    T = np.eye(4)
    T[:3, :3] = so3_exp(np.array([0.0, np.radians(turn_deg), 0.0]))
    T[:3, 3] = -T[:3, :3] @ np.asarray(centre_m)
    return T


@pytest.mark.parametrize(("turn_deg", "centre_m", "checked"), [
    (5.0, (0.0, 0.0, 0.0), True),  # turned beyond feature_check_deg (4)
    (2.8, (0.01, 0.0, 0.0), False),  # a small turn where the motion said it would be
    (2.8, (0.074, 0.0, 0.0), True),  # a small turn 6 cm off the prediction: a turn taken for a slide
])
def test_a_frame_is_checked_when_it_turned_far_or_left_the_predicted_centre(turn_deg, centre_m, checked) -> None:
    assist = _assist()
    predicted = _pose(0.0, (0.012, 0.0, 0.0))
    assert assist.wants_check(_pose(turn_deg, centre_m), np.eye(4), predicted) is checked


def test_the_centre_check_is_off_at_zero_and_without_a_prediction() -> None:
    off_centre = _pose(2.8, (0.074, 0.0, 0.0))
    assert not _assist(feature_check_m=0.0).wants_check(off_centre, np.eye(4), _pose())
    assert not _assist().wants_check(off_centre, np.eye(4))
