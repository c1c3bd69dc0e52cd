"""The simulator's parameter dataclasses refuse NaN, infinities and values out of their stated ranges (the API's
side of atsvo-sim's argument checks, reproduction r12_sim_argument_gaps.sh)."""
from __future__ import annotations

import pytest

from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.events import EventModel
from atsvo_ros.sim.sequence import MAX_DURATION_S, MAX_SEED, SequenceSpec
from atsvo_ros.sim.stereo import StereoModel

NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize("changes", [
    {"duration_s": NAN}, {"duration_s": INF}, {"duration_s": MAX_DURATION_S * 1.001}, {"seed": -1},
    {"seed": MAX_SEED + 1}, {"seed": 1.5}, {"rate_hz": INF}, {"gt_rate_hz": NAN}, {"event_packet_s": 1e-9},
    {"texture_size": 8192}, {"texture_size": 24},
])
def test_sequence_spec_refuses(changes):
    with pytest.raises(SimulationError):
        SequenceSpec(**changes)


@pytest.mark.parametrize("changes", [
    {"contrast_pos": NAN}, {"contrast_neg": NAN}, {"contrast_pos": 2.5}, {"contrast_min": NAN},
    {"contrast_sigma": NAN}, {"refractory_s": NAN}, {"refractory_s": INF}, {"noise_rate_hz": NAN},
    {"noise_rate_hz": 1e6}, {"scan_period_s": NAN}, {"scan_period_s": 1.0, "scan_sweep_s": 0.5},
    {"max_render_interval_s": NAN},
])
def test_event_model_refuses(changes):
    with pytest.raises(SimulationError):
        EventModel(**changes)


@pytest.mark.parametrize("changes", [{"ambient_ir": NAN}, {"ambient_ir": -0.1}, {"ambient_ir": INF},
                                     {"projector_power": NAN}, {"max_blur_step_px": NAN}])
def test_stereo_model_refuses(changes):
    with pytest.raises(SimulationError):
        StereoModel(**changes)


def test_the_limits_themselves_are_accepted():
    SequenceSpec(duration_s=MAX_DURATION_S, seed=MAX_SEED, rate_hz=1000.0, exposure_s=0.001, gt_rate_hz=1000.0,
                 event_packet_s=1e-6, texture_size=4096)
    EventModel(contrast_pos=2.0, contrast_neg=2.0, refractory_s=0.1, noise_rate_hz=100.0, scan_period_s=0.01)
    EventModel(scan_period_s=0.0, refractory_s=0.0, noise_rate_hz=0.0)
    StereoModel(ambient_ir=0.0, projector_power=100.0)
