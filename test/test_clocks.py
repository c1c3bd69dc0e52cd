"""Streams on other clocks: event times put on the colour images' clock, or one clear line naming the offset.

On the robot the event camera and the D455 run on different clocks. A 0.6 s synthetic trot is fed to
the runtime message by message (as the node's subscriptions do) with its event times or its IMU
stamps moved, and what reaches the frames is checked.
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.io.sync import FrameAssembler
from atsvo_ros.runtime.clock_check import ClockCheck, EventClock
from atsvo_ros.runtime.problems import ProblemLog
from atsvo_ros.runtime.runtime import OdometryRuntime
from test.test_runtime import SIM_ARGS, _dispatch, _messages

S = 1_000_000_000


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    from atsvo_ros.tools.sim import main as sim_main

    out = tmp_path_factory.mktemp("clocks") / "bag"
    assert sim_main([*SIM_ARGS, "--out", str(out)]) == 0
    return out


def _restamped(msg, shift_ns: int):
    """A copy of a message with its header stamp moved by ``shift_ns``."""
    t = msg.header.stamp.sec * S + msg.header.stamp.nanosec + shift_ns
    stamp = dataclasses.replace(msg.header.stamp, sec=t // S, nanosec=t % S)
    out = copy.copy(msg)
    out.header = dataclasses.replace(msg.header, stamp=stamp)
    return out


def _run(bag, overrides=None, events_ns: int = 0, event_headers_ns: int = 0, imu_ns: int = 0):
    """The trot through the runtime with the event times (time_base), their headers or the IMU stamps moved."""
    cfg = load_config("synthetic", overrides=overrides or {})
    rt = OdometryRuntime(cfg)
    outs = []
    for topic, msgtype, msg in _messages(bag):
        if topic == cfg.topics.events:
            msg = _restamped(msg, event_headers_ns)
            msg.time_base = int(msg.time_base) + events_ns
        elif topic == cfg.topics.imu and imu_ns:
            msg = _restamped(msg, imu_ns)
        _dispatch(rt, cfg, topic, msgtype, msg)
        outs += rt.poll()
    outs += rt.flush()
    return rt, outs


def test_in_sync_streams_reach_every_frame_and_nothing_is_said(bag):
    rt, outs = _run(bag)
    assert sum(o.n_events > 0 for o in outs) >= len(outs) - 1 and rt.assembler.stats.clock_jumps == 0
    assert not {"events_on_camera_clock", "clock_events", "clock_imu"} & set(rt.counters)


@pytest.mark.parametrize("apart_s", [-1.5, 5.0, -1.7e9 + 3])  # 1.5 s behind, 5 s ahead, evt3's power-on clock
def test_event_times_on_the_camera_clock_are_moved_onto_the_header_clock(bag, apart_s):
    rt, outs = _run(bag, events_ns=int(apart_s * S))
    assert rt.counters["events_on_camera_clock"] == 1, rt.counters  # said once
    assert sum(o.n_events > 0 for o in outs) >= len(outs) - 1 and rt.assembler.stats.clock_jumps == 0
    assert "clock_events" not in rt.counters


def test_events_whose_headers_are_on_another_clock_too_get_one_line_naming_the_offset(bag):
    rt, outs = _run(bag, events_ns=5 * S, event_headers_ns=5 * S)
    assert rt.counters["clock_events"] == 1 and sum(o.n_events for o in outs) == 0
    assert "event_camera.time_offset_s: -5.00 " in rt.first_problem["clock_events"]
    assert rt.assembler.stats.clock_jumps == 0 and len(outs) >= 17  # the frames still go (RGB-D), none dropped
    # the offset it names puts them right
    rt, outs = _run(bag, {"event_camera.time_offset_s": -5.0}, events_ns=5 * S, event_headers_ns=5 * S)
    assert "clock_events" not in rt.counters and sum(o.n_events > 0 for o in outs) >= len(outs) - 1


def test_an_imu_on_another_clock_gets_one_line_and_the_offset_it_names_works(bag):
    rt, outs = _run(bag, imu_ns=100 * S)
    assert rt.counters["clock_imu"] == 1 and "rig.imu_time_offset_s: -100.00 " in rt.first_problem["clock_imu"]
    rt, outs = _run(bag, {"rig.imu_time_offset_s": -100.0}, imu_ns=100 * S)
    assert "clock_imu" not in rt.counters and rt.counters["imu_samples"] > 0
    assert rt.counters.get("frames_without_imu", 0) == 0


def test_event_clock_and_clock_check_units():
    log = ProblemLog()
    clock = EventClock(-2.0, log)
    batch = EventBatch(np.zeros(3, np.uint16), np.zeros(3, np.uint16), np.array([10, 11, 12]) * S, np.ones(3, np.uint8))
    moved, header = clock.place(batch, 10 * S)  # on the header clock: only the configured offset
    assert moved.t.tolist() == [8 * S, 9 * S, 10 * S] and header == 8 * S and not log.counters
    check = ClockCheck(log)
    for k in range(10):
        check.stream("imu", 1000 * S + k)
        check.image(k)
    assert check.offsets_s == {"imu": pytest.approx(-1000.0)} and log.counters["clock_imu"] == 1


def test_two_streams_apart_are_not_a_clock_jump():
    """Only a stream's own stamps going back restart the assembler (a bag loop); two clocks do not."""
    cfg = load_config("synthetic")
    asm = FrameAssembler(cfg.rig)
    img, depth = np.zeros((4, 4, 3), np.uint8), np.ones((4, 4), np.float32)
    ev = EventBatch(np.zeros(2, np.uint16), np.zeros(2, np.uint16), np.array([1, 2]) * S, np.ones(2, np.uint8))
    asm.add_events(ev)
    for k in range(5):
        asm.add_rgb(10 * S + k, img)
        asm.add_depth(10 * S + k, depth)
    asm.add_events(ev.shifted(S))  # 8 s behind the images: another clock, not a jump
    assert asm.stats.clock_jumps == 0
    asm.add_rgb(5 * S, img)  # the images' own stamps jump back: a jump
    assert asm.stats.clock_jumps == 1


@pytest.mark.parametrize("apart_s", [0.05, -0.03])  # events (stamps and headers) 50 ms late / 30 ms early
def test_a_small_event_clock_offset_is_estimated_at_start_up(trot_3s_bag, apart_s):
    """event_camera.time_offset_search_s: the offset is found from motion (2-3 ms off on this trot), said once,
    and the events follow it; the same run without the search keeps them where they were stamped."""
    moved = {"events_ns": int(apart_s * S), "event_headers_ns": int(apart_s * S)}
    rt, outs = _run(trot_3s_bag, {"event_camera.time_offset_search_s": 0.1}, **moved)
    assert rt.counters["event_offset_estimated"] == 1, rt.counters
    assert rt.event_time_offset_s == pytest.approx(-apart_s, abs=0.005)
    assert "event clock offset estimated" in rt.first_problem["event_offset_estimated"]
    assert sum(o.n_events > 0 for o in outs) >= len(outs) - 2 and rt.assembler.stats.clock_jumps == 0
    rt, _ = _run(trot_3s_bag, **moved)
    assert rt.event_time_offset_s == 0.0 and "event_offset_estimated" not in rt.counters


def test_an_estimated_offset_back_in_time_keeps_the_event_stream_in_order():
    clock = EventClock(0.0, ProblemLog())
    xy = np.zeros(3, np.uint16)
    clock.place(EventBatch(xy, xy, np.array([10, 20, 30]) * 1_000_000, np.ones(3, np.uint8)), None)
    clock.adjust(-15_000_000)  # events were 15 ms late
    moved, _ = clock.place(EventBatch(xy, xy, np.array([40, 50, 60]) * 1_000_000, np.ones(3, np.uint8)), None)
    assert moved.t.tolist() == [35_000_000, 45_000_000]  # 25 ms would go before the 30 ms already placed: dropped
    assert clock.offset_s == pytest.approx(-0.015)
    moved, _ = clock.place(EventBatch(xy, xy, np.array([61, 62, 63]) * 1_000_000, np.ones(3, np.uint8)), None)
    assert len(moved) == 3
