"""The bounded drop-oldest queue and its worker (what keeps the tracking node's callbacks short)."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.imu import ImuBatch
from atsvo_ros.core.odometry.odometry import RgbdFrame
from atsvo_ros.runtime.frame_queue import DropOldestQueue, Worker
from atsvo_ros.runtime.types import FrameInput


def test_full_queue_drops_the_oldest_and_counts():
    q: DropOldestQueue[int] = DropOldestQueue(2)
    assert [q.put(i) for i in range(5)] == [0, 0, 1, 1, 1]
    assert (q.n_put, q.n_dropped, q.high_water, len(q)) == (5, 3, 2, 2)
    assert [q.get(0), q.get(0), q.get(0)] == [3, 4, None]
    q.close()
    assert q.put(9) == 0 and q.get() is None  # closed: nothing waits forever
    with pytest.raises(ValueError):
        DropOldestQueue(0)


def test_dropped_frames_hand_their_events_and_imu_to_the_next():
    def inp(k: int) -> FrameInput:
        ev = EventBatch(np.full(k + 1, k, np.uint16), np.zeros(k + 1, np.uint16),
                        np.arange(k + 1, dtype=np.int64) + 100 * k, np.ones(k + 1, np.uint8))
        imu = ImuBatch(np.array([100 * k]), np.zeros((1, 3)), np.zeros((1, 3)))
        return FrameInput(RgbdFrame(100 * k + 50, np.zeros((2, 2, 3), np.uint8), np.zeros((2, 2), np.float32)),
                          ev, imu, 0.0)

    q: DropOldestQueue[FrameInput] = DropOldestQueue(1, merge=lambda old, new: new.after(old))
    for k in range(3):
        q.put(inp(k))
    last = q.get(0)
    assert last.stamp_ns == 250 and q.n_dropped == 2
    assert last.events.x.tolist() == [0, 1, 1, 2, 2, 2]  # every event, in order
    assert last.imu.stamps_ns.tolist() == [0, 100, 200]


def test_worker_processes_in_order_runs_calls_between_items_and_stops():
    q: DropOldestQueue[int] = DropOldestQueue(100)
    seen: list[object] = []
    started, gate = threading.Event(), threading.Event()

    def handle(i: int) -> None:
        started.set()
        gate.wait(5)
        seen.append(i)

    w = Worker(q, handle)
    w.start()
    for i in range(3):
        q.put(i)
    assert started.wait(5)  # item 0 is being processed
    done = w.call(lambda: seen.append("reset"))
    gate.set()
    assert done.wait(5)
    for _ in range(500):
        if len(seen) == 4:
            break
        threading.Event().wait(0.01)
    w.stop()
    assert not w.alive and seen == [0, "reset", 1, 2]


def test_a_bug_in_the_handler_ends_the_worker_and_is_reported():
    q: DropOldestQueue[int] = DropOldestQueue(4)
    errors: list[BaseException] = []
    w = Worker(q, lambda i: 1 / i, on_error=errors.append)
    w.start()
    q.put(1)
    q.put(0)
    w._thread.join(5)
    assert not w.alive and isinstance(w.error, ZeroDivisionError) and errors == [w.error]
    assert w.call(lambda: None).wait(1)  # a call after the worker died does not hang
