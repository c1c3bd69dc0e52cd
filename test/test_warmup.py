"""The nodes' warm-up: the odometry runs a few synthetic frames, through the fused path too, before subscribing."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.runtime.warmup import N_FRAMES, warm_decoders, warm_up


@pytest.mark.parametrize("preset", ["mini_cheetah", "synthetic"])
def test_the_warm_up_tracks_its_frames_through_both_paths(preset):
    cfg = load_config(preset)
    fused = warm_up(cfg)
    assert fused.statuses == ("initialising",) + ("ok",) * (N_FRAMES - 1), fused
    assert "fused" in fused.modes and "rgbd" in fused.modes, fused  # both paths' kernels ran
    rgbd = warm_up(cfg, use_events=False)
    assert set(rgbd.modes) == {"rgbd"} and rgbd.statuses[-1] == "ok", rgbd
    assert cfg.fusion.rate_threshold_deg_s > 0  # the node's own configuration is untouched


def test_the_event_decoders_of_the_configured_message_type_are_warmed():
    rng = np.random.default_rng(0)
    n = 500
    t_ns = 1_000_000_000 + np.sort(rng.integers(0, 30_000, n)) * 1000
    batch = EventBatch(rng.integers(0, 320, n).astype(np.uint16), rng.integers(0, 240, n).astype(np.uint16), t_ns,
                       rng.integers(0, 2, n).astype(np.uint8), 320, 240)
    assert warm_decoders("event_camera_msgs/msg/EventPacket", batch) == 4 * n  # libcaer_cmp, libcaer, mono, evt3
    assert warm_decoders("dvs_msgs/msg/EventArray", batch) == n
    assert warm_decoders("event_array_msgs/msg/EventArray", batch) == 0  # no encoder: not warmed
