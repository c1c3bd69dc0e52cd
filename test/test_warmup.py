"""The nodes' warm-up: the odometry runs a few synthetic frames, through the fused path too, before subscribing."""
from __future__ import annotations

import pytest

from atsvo_ros.config import load_config
from atsvo_ros.runtime.warmup import N_FRAMES, warm_up


@pytest.mark.parametrize("preset", ["mini_cheetah", "synthetic"])
def test_the_warm_up_tracks_its_frames_through_both_paths(preset):
    cfg = load_config(preset)
    fused = warm_up(cfg)
    assert fused.statuses == ("initialising",) + ("ok",) * (N_FRAMES - 1), fused
    assert "fused" in fused.modes and "rgbd" in fused.modes, fused  # both paths' kernels ran
    rgbd = warm_up(cfg, use_events=False)
    assert set(rgbd.modes) == {"rgbd"} and rgbd.statuses[-1] == "ok", rgbd
    assert cfg.fusion.rate_threshold_deg_s > 0  # the node's own configuration is untouched
