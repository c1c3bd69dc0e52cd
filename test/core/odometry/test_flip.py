"""The event term earns its place: a backflip's take-off to landing on honest sensors, fused against RGB-D alone.

A 2.4 s backflip (seed 1: stand, crouch, push-off at 1.1 s, 0.53 s of flight at up to ~590 deg/s, landing),
320x240 colour, the D455 model's depth (active stereo under motion, exposed at its own time) and the
DVXplorer model's events. What this test guards, measured on this sequence (ATE over the frames reported
ok, cm): fused with the ATS 11.0; RGB-D alone 91.7; fused with a constant-tau surface 20.2; fused with the
event term weighed ~0 (``tracker.w_event`` 1e-9) 45.7. It fails when the event term is switched off or
weighed to nothing, and when the surface is swapped for constant tau (the default surface is the ATS by
this and ``atsvo-bench ats-quality``; see docs/events.md).
"""
from __future__ import annotations

import pytest

from atsvo_ros.bench.tracking import run_sequence

SEED, DURATION_S, FUSED_BOUND_CM = 1, 2.4, 15.0


@pytest.fixture(scope="module")
def flip_runs(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("ATSVO_CACHE", str(tmp_path_factory.mktemp("flip_cache")))
    try:
        common = dict(scenario="backflip", seed=SEED, duration_s=DURATION_S, width=320, height=240, progress=False)
        fused = run_sequence(use_events=True, **common)
        rgbd = run_sequence(overrides={"mode": "rgbd"}, **common)
    finally:
        mp.undo()
    return fused, rgbd


def test_fused_holds_the_flip_where_rgbd_alone_does_not(flip_runs):
    fused, rgbd = flip_runs
    assert fused["modes"].get("fused", 0) >= 15  # the event term joined through the flight
    assert fused["ate_rmse_cm"] < FUSED_BOUND_CM, fused["ate_rmse_cm"]
    assert rgbd["ate_rmse_cm"] > 2 * FUSED_BOUND_CM, rgbd["ate_rmse_cm"]
    # and in the flight itself, where RGB-D has the least to go on
    assert fused["phases"]["flight"]["ate_rmse_cm"] < rgbd["phases"]["flight"]["ate_rmse_cm"] / 3
