"""EventOffsetSearch: the runtime's start-up estimate of the event clock offset (runtime/offset_search.py)."""
from __future__ import annotations

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.runtime.offset_search import MAX_FRAMES, EventOffsetSearch
from atsvo_ros.runtime.problems import ProblemLog

FRAME_NS = 33_333_333


def _feed(search: EventOffsetSearch, offset_s: float, n_frames: int, moving: bool = True, seed: int = 0):
    """Flat grey images whose brightness steps by a random amount each frame; events at the same rate, stamped
    ``-offset_s`` off. Returns the first non-None answer of :meth:`add_image` and the frame it came at."""
    rng = np.random.default_rng(seed)
    steps = rng.gamma(0.5, 1.0, n_frames) if moving else np.zeros(n_frames)
    level = 60.0
    t0 = 1_000_000_000
    for k in range(n_frames):
        stamp = t0 + k * FRAME_NS
        n = int(rng.poisson(400 * steps[k])) + 5  # events during the frame's interval, at true times
        t = np.sort(rng.integers(stamp - FRAME_NS, stamp, n)) - int(offset_s * 1e9)
        search.add_events(EventBatch(np.zeros(n, np.uint16), np.zeros(n, np.uint16), t.astype(np.int64),
                                     np.ones(n, np.uint8), 8, 8))
        level = level * np.exp(0.05 * steps[k] * (1 if k % 2 else -1))
        answer = search.add_image(stamp, np.full((8, 8), level, np.float32))
        if k == 50:
            assert search.add_image(stamp - FRAME_NS // 2, np.zeros((8, 8), np.float32)) is None  # out of order
        if answer is not None:
            return answer, k
    return None, n_frames


def test_the_offset_is_taken_once_two_estimates_agree():
    log = ProblemLog()
    search = EventOffsetSearch(0.1, log)
    answer, frame = _feed(search, 0.04, 200)
    assert answer is not None and abs(answer - 40_000_000) < 3_000_000, (answer, search.estimates)
    assert frame < 100 and not search.active and log.counters["event_offset_estimated"] == 1


def test_without_motion_the_search_ends_and_says_so_once():
    log = ProblemLog()
    search = EventOffsetSearch(0.1, log)
    answer, _ = _feed(search, 0.04, MAX_FRAMES + 5, moving=False)
    assert answer is None and not search.active and search.offset_s is None
    assert log.counters["event_offset_not_estimated"] == 1 and "event_offset_estimated" not in log.counters


def test_off_by_default():
    search = EventOffsetSearch(0.0, ProblemLog())
    assert not search.active and _feed(search, 0.04, 60)[0] is None
