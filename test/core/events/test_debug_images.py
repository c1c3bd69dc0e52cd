"""The debug images (ATS and selected pixels) the tracking node publishes and atsvo-replay --record writes."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.debug_images import SELECTED_RGB, render_debug_images
from atsvo_ros.core.events.frontend import EventFrontEnd
from atsvo_ros.core.geometry import se3_exp
from test.core.event_helpers import simulate_events
from test.core.render_helpers import BoxRoom

EV = CameraModel(160, 120, 120.0, 120.0, 79.5, 59.5)
MS = 1_000_000


@pytest.fixture(scope="module")
def frontend():
    """An event front end after 40 ms of a turning camera in a textured box room."""
    room = BoxRoom(seed=4)
    fe = EventFrontEnd(EV, load_config("synthetic", overrides={"mode": "fused"}), 4)
    fe.add_events(simulate_events(room, EV, lambda t: se3_exp(np.array([0.2, 0.1, 0.3, 1.2, 2.4, 0.6]) * t * 1e-9),
                                  -40 * MS, 0))
    return fe


def test_ats_image_is_the_rendered_surface_as_mono8(frontend):
    images = render_debug_images(frontend, 0, selection=False)
    expected = np.clip(frontend.render(0).surface, 0, 255).astype(np.uint8)
    assert images.ats.dtype == np.uint8 and images.ats.shape == (EV.height, EV.width)
    np.testing.assert_array_equal(images.ats, expected)
    assert images.selection is None and images.ats.max() > 100  # the moving edges are bright


def test_selection_image_paints_exactly_the_selected_pixels_on_the_grey_surface(frontend):
    images = render_debug_images(frontend, 0)
    sel = frontend.select(frontend.render(0)).selected
    assert len(sel) > 50
    rgb = images.selection
    assert rgb.shape == (EV.height, EV.width, 3) and rgb.dtype == np.uint8
    painted = np.zeros((EV.height, EV.width), bool)
    painted[sel[:, 1], sel[:, 0]] = True
    assert np.all(rgb[painted] == SELECTED_RGB)
    np.testing.assert_array_equal(rgb[~painted], np.repeat(images.ats[~painted][:, None], 3, axis=1))


def test_rendering_does_not_change_the_front_end(frontend):
    """The recorder renders after every frame: the odometry must see the same surface either way."""
    before = frontend.surface.t_last.copy()
    first = render_debug_images(frontend, 0)
    again = render_debug_images(frontend, 0)
    np.testing.assert_array_equal(frontend.surface.t_last, before)
    np.testing.assert_array_equal(first.ats, again.ats)
    np.testing.assert_array_equal(first.selection, again.selection)
