"""Tracking and mapping exchanging bytes (what the two nodes do over topics), without ROS."""
from __future__ import annotations

import queue
import threading
import time

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.frame import TrackingStatus
from atsvo_ros.core.odometry.odometry import Odometry, RgbdFrame
from atsvo_ros.errors import WireError
from atsvo_ros.runtime.mapping_remote import MappingServer, RemoteMapping, mapping_digest
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation, sequence_rig


@pytest.fixture(scope="module")
def frames():
    # sharp depth: these tests are of the mapping process's protocol, not of the depth (the D455 model's drift is
    # measured in test_odometry.py and the benchmark)
    spec = SequenceSpec(scenario="trot", duration_s=1.5, seed=0, width=160, height=120, event_scale=0.25,
                        depth="sharp")
    items = [RgbdFrame(i.stamp_ns, i.rgb, i.depth_m) for i in make_simulation(spec).frames()]  # no events
    return load_config("synthetic", overrides={"mode": "rgbd"}), sequence_rig(spec).rgb_camera, items


class _Link:
    """A mapping process on a thread: requests go in a queue, answers come back through ``on_message``."""

    def __init__(self, cfg, drop_answers: bool = False, delay_s: float = 0.0) -> None:
        self.server = MappingServer(cfg)
        self.delay_s = delay_s  # a slow mapping process
        self.requests: queue.Queue[bytes | None] = queue.Queue()
        self.port: RemoteMapping | None = None
        self.drop_answers = drop_answers
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while (payload := self.requests.get()) is not None:
            time.sleep(self.delay_s)
            served = self.server.handle(payload)
            if not self.drop_answers:
                self.port.on_message(served.answer)

    def factory(self, synchronous: bool, timeout_s: float = 5.0, connected=lambda: True):
        def make(mapper):
            self.port = RemoteMapping(mapper, self.requests.put, connected, synchronous=synchronous,
                                      timeout_s=timeout_s)
            return self.port
        return make

    def close(self) -> None:
        self.requests.put(None)
        self.thread.join(5)


def _track(cfg, cam, frames, mapping=None):
    odo = Odometry(cfg, cam, mapping=mapping)
    try:
        return [odo.process_frame(f) for f in frames], odo
    finally:
        odo.close()


def test_synchronous_remote_mapping_gives_the_inline_poses_exactly(frames):
    cfg, cam, items = frames
    inline, _ = _track(cfg, cam, items)
    link = _Link(cfg)
    try:
        remote, odo = _track(cfg, cam, items, link.factory(synchronous=True))
    finally:
        link.close()
    assert [r.status for r in remote] == [r.status for r in inline]
    for a, b in zip(remote, inline):
        assert np.array_equal(a.T_odom_base, b.T_odom_base)
    assert odo.n_keyframes == link.server.mapper.n_keyframes > 2
    assert link.port.stats["answers"] == link.port.stats["sent"] == link.server.n_requests


@pytest.mark.parametrize("delay_s", [0.0, 0.15], ids=["prompt", "slow_mapper"])
def test_asynchronous_remote_mapping_keeps_tracking_while_mapping_works(frames, delay_s):
    """A frame the old map cannot hold waits for the keyframe on its way (a slow mapper costs latency, not the map)."""
    cfg, cam, items = frames
    link = _Link(cfg, delay_s=delay_s)
    try:
        remote, odo = _track(cfg, cam, items, link.factory(synchronous=False))
    finally:
        link.close()
    assert all(r.status in (TrackingStatus.OK, TrackingStatus.INITIALISING) for r in remote), \
        [(i, r.status.name, odo.last_loss_reason) for i, r in enumerate(remote) if r.status is not TrackingStatus.OK]
    assert odo.n_keyframes > 2 and link.port.stats["timeouts"] == 0


def test_without_a_mapper_nothing_is_sent_and_tracking_reports_no_map(frames):
    cfg, cam, items = frames
    link = _Link(cfg)
    try:
        results, _ = _track(cfg, cam, items[:3], link.factory(synchronous=True, connected=lambda: False))
    finally:
        link.close()
    assert [r.status for r in results] == [TrackingStatus.INITIALISING] * 3
    assert link.port.stats["unavailable"] == 3 and link.port.stats["sent"] == 0


def test_an_unanswered_request_times_out_and_is_counted(frames):
    cfg, cam, items = frames
    link = _Link(cfg, drop_answers=True)
    try:
        results, _ = _track(cfg, cam, items[:2], link.factory(synchronous=True, timeout_s=0.05))
    finally:
        link.close()
    assert link.port.stats["timeouts"] == 2 and results[0].status is TrackingStatus.INITIALISING


def test_answers_of_other_sessions_are_ignored_and_garbage_raises(frames):
    cfg, cam, items = frames
    link = _Link(cfg)
    try:
        _track(cfg, cam, items[:2], link.factory(synchronous=True))
        first = link.port
        _track(cfg, cam, items[:2], link.factory(synchronous=True))
    finally:
        link.close()
    assert first.session != link.port.session and link.server.n_sessions == 2
    served = MappingServer(cfg)
    from atsvo_ros.core.tracking.tracking import Tracking
    from atsvo_ros.io.wire import PinholeLevels, encode_keyframe_request

    odo = Odometry(cfg, cam)
    req = Tracking.reset_request(odo.frontend.prepare(items[0]), np.eye(4))
    c = odo.camera
    answer = served.handle(encode_keyframe_request(link.port.session, 99, req, PinholeLevels(
        c.width, c.height, c.fx, c.fy, c.cx, c.cy, odo.n_levels))).answer
    assert first.on_message(answer) is False and first.stats["ignored"] == 1
    with pytest.raises(WireError):
        first.on_message(b"garbage")


def test_mapping_digest_covers_what_the_mapper_reads():
    cfg = load_config("synthetic")
    assert mapping_digest(cfg) == mapping_digest(load_config("synthetic", overrides={"mapping.synchronous": True,
                                                                                     "ats.tau_u_s": 0.05}))
    assert mapping_digest(cfg) != mapping_digest(load_config("synthetic", overrides={"mapping.max_points": 5000}))
