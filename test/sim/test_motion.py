"""Gait trajectories: peak rates, the backflip's full turn, smoothness, determinism, clearance."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import so3_log
from atsvo_ros.errors import SimulationError
from atsvo_ros.sim.imu import imu_kinematics
from atsvo_ros.sim.motion import GRAVITY, PHASES, SCENARIOS, make_motion
from atsvo_ros.sim.sequence import SequenceSpec, Simulation

FREE = (2.0, 6.0, 1.9, 3.8)


def _rates(scenario: str, duration_s: float, seed: int = 1, step_ns: int = 1_000_000, t_from_s: float = 0.0,
           t_to_s: float | None = None):
    m = make_motion(scenario, duration_s, seed, FREE)
    t_to_s = duration_s if t_to_s is None else t_to_s
    ts = np.arange(int(t_from_s * 1e9), int(t_to_s * 1e9) + 1, step_ns, dtype=np.int64)
    T = m.T_world_base(ts)
    dt = step_ns * 1e-9
    w_body = so3_log(np.swapaxes(T[:-1, :3, :3], 1, 2) @ T[1:, :3, :3]) / dt
    v = np.diff(T[:, :3, 3], axis=0) / dt
    return T, w_body, v


def test_backflip_is_a_full_pitch_turn_with_fast_peaks():
    T, w, _ = _rates("backflip", 6.0)
    peak_pitch_rate = np.degrees(np.abs(w[:, 1]).max())
    assert peak_pitch_rate >= 510.0
    total_pitch = np.degrees(np.sum(w[:, 1]) * 1e-3)
    assert abs(abs(total_pitch) - 360.0) < 2.0
    # Aerial phase: the body rises well above its standing height.
    assert T[:, 2, 3].max() - T[0, 2, 3] > 0.2
    # Ends upright.
    assert abs(T[-1, 2, 2] - 1.0) < 0.01


def test_bound_pitches_at_about_260_deg_per_s():
    _, w, _ = _rates("bound", 4.0)
    peak = np.degrees(np.abs(w[:, 1]).max())
    assert 220.0 <= peak <= 300.0
    _, w_trot, _ = _rates("trot", 4.0)
    assert np.degrees(np.abs(w_trot[:, 1]).max()) < 60.0  # trot is gentle


def test_pronk_hops_vertically():
    T, _, v = _rates("pronk", 3.0)
    z = T[:, 2, 3]
    assert z.max() - z.min() > 0.06
    # Several hops: the vertical velocity changes sign repeatedly.
    assert np.count_nonzero(np.diff(np.sign(v[:, 2])) > 0) >= 5


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_velocities_are_continuous(scenario):
    """Halving the time step halves the largest velocity change: no jumps (finite acceleration)."""
    jumps = []
    for step in (40_000, 20_000):
        _, w, v = _rates(scenario, 4.0, step_ns=step, t_from_s=0.0, t_to_s=4.0)
        jumps.append((np.abs(np.diff(w, axis=0)).max(), np.abs(np.diff(v, axis=0)).max()))
    (dw1, dv1), (dw2, dv2) = jumps
    assert dw2 < 0.7 * dw1 + 1e-6 and dv2 < 0.7 * dv1 + 1e-6
    assert dv2 < 200.0 * 20e-6 * 2  # below ~400 m/s^2 even at landing impacts
    assert dw2 < 3000.0 * 20e-6 * 2


def test_running_mixes_gaits_and_flying_is_6dof():
    _, w, _ = _rates("running", 20.0, seed=2)
    pitch_rate = np.degrees(np.abs(w[:, 1]))
    assert pitch_rate.max() > 200.0  # bounding happens
    assert np.median(pitch_rate) < 100.0  # ... but not all the time
    T, w, v = _rates("flying", 20.0, seed=2)
    assert np.ptp(T[:, 2, 3]) > 0.1 and T[:, 2, 3].min() > 0.5
    assert np.all(np.degrees(np.abs(w).max(axis=0)) > 2.0)  # rotates about every axis
    assert np.all(np.abs(v).max(axis=0) > 0.05)


def test_motion_is_deterministic_and_seeded():
    ts = np.arange(0, 3_000_000_000, 10_000_000)
    a = make_motion("running", 3.0, 4, FREE).T_world_base(ts)
    b = make_motion("running", 3.0, 4, FREE).T_world_base(ts)
    c = make_motion("running", 3.0, 5, FREE).T_world_base(ts)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.01
    single = make_motion("running", 3.0, 4, FREE).T_world_base(np.int64(ts[7]))
    np.testing.assert_allclose(single, a[7])


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_cameras_stay_in_free_space(scenario):
    for seed in range(3):
        Simulation(SequenceSpec(scenario=scenario, duration_s=40.0, seed=seed, texture_size=16))  # checks itself


def test_bad_requests_raise():
    with pytest.raises(SimulationError, match="unknown scenario"):
        make_motion("moonwalk", 1.0, 0, FREE)
    with pytest.raises(SimulationError, match="backflip needs"):
        make_motion("backflip", 1.0, 0, FREE)


def test_default_free_area_is_the_seeded_scene_one():
    from atsvo_ros.sim.scene import make_scene

    for seed in (0, 3):
        assert make_motion("trot", 1.0, seed).free_xy == make_scene(seed, 16).free_xy


@pytest.mark.parametrize("scenario", ["trot", "bound", "pronk"])
def test_touchdowns_shake_the_trunk_as_the_imu_sees_it(scenario):
    """Every foot strike rings the camera mount: the specific force spikes past 1 g in the landing frames,
    well above what the same gait gives between strikes."""
    m = make_motion(scenario, 6.0, 2, FREE)
    ts = np.arange(m.t0_ns + 200_000_000, m.t_end_ns - 200_000_000, 2_000_000, dtype=np.int64)
    _, force = imu_kinematics(m.T_world_base, ts, GRAVITY)
    jolt = np.abs(np.linalg.norm(force, axis=1) - GRAVITY)
    phase = m.phase(ts)
    landing = np.percentile(jolt[phase == PHASES.index("landing")], 99)
    stance_or_flight = np.percentile(jolt[phase != PHASES.index("landing")], 99)
    assert landing > GRAVITY and landing > 1.3 * stance_or_flight  # measured (seed 2) trot 12.8 vs 7.8 m/s^2


def test_motion_phases_follow_the_gait():
    flip = make_motion("backflip", 6.0, 1, FREE)
    ts = flip.stamps_ns(1000)
    phase = flip.phase(ts)
    air_s = np.count_nonzero(phase == PHASES.index("flight")) * 1e-3
    assert abs(air_s - flip.params["flip_air_s"]) < 0.005
    t_land = ts[np.flatnonzero(phase == PHASES.index("flight"))[-1] + 1]
    assert phase[np.searchsorted(ts, t_land + 100_000_000)] == PHASES.index("landing")
    pronk = make_motion("pronk", 4.0, 1, FREE).phase(ts[:4000])
    assert 0.4 < np.mean(pronk == PHASES.index("flight")) < 0.7  # airborne ~0.25 s of every ~0.4 s hop
    assert set(make_motion("flying", 2.0, 1, FREE).phase(ts[:2000])) == {PHASES.index("flight")}
    trot = make_motion("trot", 4.0, 1, FREE).phase(ts[:4000])
    assert PHASES.index("flight") not in trot and 0.3 < np.mean(trot == PHASES.index("landing")) < 0.6
