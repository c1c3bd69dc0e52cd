"""FrameAssembler: RGB/depth pairing by stamp and event cutting at frame stamps, fed incrementally."""
from __future__ import annotations

import numpy as np

from atsvo_ros.config import RigConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.io.sync import FrameAssembler, _percentile_25

MS = 1_000_000


def _img(v: int) -> np.ndarray:
    return np.full((2, 2), v, np.uint8)


def _dep(v: float) -> np.ndarray:
    return np.full((2, 2), v, np.float32)


def _events(t0_ms: float, t1_ms: float, n: int = 10) -> EventBatch:
    t = np.linspace(t0_ms * MS, t1_ms * MS, n, endpoint=False).astype(np.int64)
    return EventBatch(np.zeros(n), np.zeros(n), t, np.ones(n))


def test_pairs_nearest_depth_within_tolerance_and_drops_unmatched():
    fa = FrameAssembler(RigConfig(sync_tolerance_s=0.005), with_events=False)
    fa.add_rgb(100 * MS, _img(1))
    fa.add_depth(98 * MS, _dep(1.0))
    fa.add_depth(101 * MS, _dep(2.0))  # nearer, arrives later: must win
    fa.add_rgb(133 * MS, _img(2))  # depth for it never comes
    fa.add_rgb(166 * MS, _img(3))
    fa.add_depth(166 * MS, _dep(3.0))
    out = fa.pop_ready() + fa.flush()
    assert [f.stamp_ns for f, _ in out] == [100 * MS, 166 * MS]
    assert [float(f.depth_m[0, 0]) for f, _ in out] == [2.0, 3.0]
    assert fa.stats.dropped_rgb == 1 and fa.stats.dropped_depth == 1


def test_depth_arriving_before_or_after_colour_gives_same_pairs():
    def run(depth_first: bool) -> list[tuple[int, float]]:
        fa = FrameAssembler(RigConfig(), with_events=False)
        out = []
        for k in range(5):
            t = k * 33 * MS
            items = [lambda t=t, k=k: fa.add_rgb(t, _img(k)), lambda t=t, k=k: fa.add_depth(t + MS, _dep(k))]
            for f in (items[::-1] if depth_first else items):
                f()
            out += fa.pop_ready()
        out += fa.flush()
        return [(f.stamp_ns, float(f.depth_m[0, 0])) for f, _ in out]

    assert run(True) == run(False) == [(k * 33 * MS, float(k)) for k in range(5)]


def test_events_cut_at_frame_stamps_and_frames_wait_for_events():
    fa = FrameAssembler(RigConfig(), with_events=True)
    all_t = np.concatenate([_events(0, 20).t, _events(20, 40).t, _events(40, 70).t])
    fa.add_events(_events(0, 20))
    fa.add_rgb(30 * MS, _img(0))
    fa.add_depth(30 * MS, _dep(1))
    assert fa.pop_ready() == []  # events only known up to ~20 ms
    fa.add_events(_events(20, 40))
    (f0, ev0), = fa.pop_ready()
    assert f0.stamp_ns == 30 * MS and np.array_equal(ev0.t, all_t[all_t <= 30 * MS])
    fa.add_rgb(60 * MS, _img(1))
    fa.add_depth(60 * MS, _dep(1))
    fa.add_events(_events(40, 70))
    (f1, ev1), = fa.pop_ready()
    assert np.array_equal(ev1.t, all_t[(all_t > 30 * MS) & (all_t <= 60 * MS)])
    # every event is delivered once
    rest = fa.flush()
    assert rest == []


def test_silent_event_camera_does_not_block():
    fa = FrameAssembler(RigConfig(), with_events=True, max_event_wait_s=0.1)
    for k in range(6):
        fa.add_rgb(k * 33 * MS, _img(k))
        fa.add_depth(k * 33 * MS, _dep(1))
    got = fa.pop_ready()
    assert 0 < len(got) < 6  # the older frames waited long enough
    assert fa.stats.released_without_events == len(got)
    assert len(got) + len(fa.flush()) == 6


def test_complete_to_marks_progress_without_events():
    fa = FrameAssembler(RigConfig(), with_events=True)
    fa.add_rgb(10 * MS, _img(0))
    fa.add_depth(10 * MS, _dep(1))
    fa.add_events(EventBatch.empty(), complete_to_ns=12 * MS)  # an empty packet stamped after the frame
    (f, ev), = fa.pop_ready()
    assert len(ev) == 0 and fa.stats.released_without_events == 0


def test_memory_is_bounded_when_depth_never_comes():
    fa = FrameAssembler(RigConfig(), with_events=False, max_pending=10)
    for k in range(100):
        fa.add_rgb(k * 33 * MS, _img(0))
    assert fa.pending <= 11 and fa.stats.dropped_rgb >= 89


def test_a_clock_jumping_back_starts_the_assembler_over():
    """``ros2 bag play --loop`` or a simulator restart: the stamps jump back; frames and events carry on."""
    asm = FrameAssembler(RigConfig(), with_events=True)
    for k in range(3):  # frames at 3 s, 3.033 s, ...; events up to each frame
        t = 3000 + 33 * k
        asm.add_events(_events(t - 33, t))
        asm.add_rgb(t * MS, _img(k))
        asm.add_depth(t * MS, _dep(1.0))
    asm.add_events(_events(3066, 3100))
    first = asm.pop_ready()
    assert len(first) == 3
    for k in range(3):  # the clock restarts at 0.2 s
        t = 200 + 33 * k
        asm.add_events(_events(t - 33, t))
        asm.add_rgb(t * MS, _img(10 + k))
        asm.add_depth(t * MS, _dep(2.0))
    asm.add_events(_events(266, 300))
    again = asm.pop_ready()
    assert [f.stamp_ns for f, _ in again] == [200 * MS, 233 * MS, 266 * MS]
    assert all(len(ev) == 10 for _, ev in again[1:])  # the new timeline's events are not dropped as late
    assert asm.stats.clock_jumps == 1 and asm.stats.late_events == 0


def test_events_waiting_for_frames_are_bounded_oldest_first():
    """No colour for a while (or a flood): the event buffer keeps the newest events only, and counts the rest."""
    asm = FrameAssembler(RigConfig(), with_events=True, max_buffered_events=25)
    for k in range(10):
        asm.add_events(_events(10 * k, 10 * k + 10))  # 10 events per 10 ms, no frame
    assert asm.stats.dropped_events == 75
    asm.add_rgb(100 * MS, _img(1))
    asm.add_depth(100 * MS, _dep(1.0))
    asm.add_events(EventBatch.empty(), complete_to_ns=100 * MS)
    [(frame, ev)] = asm.pop_ready()
    assert len(ev) == 25 and ev.t[0] == 75 * MS and ev.t[-1] == 99 * MS  # the newest 25


def test_stamp_gaps_count_the_images_a_lossy_transport_dropped():
    """30 Hz with 3 of every 10 images lost (what best-effort DDS delivered of 640x480 frames): all counted."""
    from atsvo_ros.io.sync import StampGaps

    period = 33_333_333
    gaps = StampGaps()
    kept = [k for k in range(300) if k < 10 or k % 10 not in (3, 4, 8)]
    for k in kept:
        gaps.add(1_700_000_000_000_000_000 + k * period + (k * 7919 % 2_000_000))  # 0-2 ms stamp jitter
    assert gaps.missing == 300 - len(kept) == 87
    assert abs(gaps.period_ns - period) < 2_000_000


def test_stamp_gaps_take_back_a_late_image_and_start_over_after_a_clock_jump():
    from atsvo_ros.io.sync import StampGaps

    p, t0 = 33_000_000, 10_000_000_000
    gaps = StampGaps()
    for k in (0, 1, 2, 3, 5, 6):
        gaps.add(t0 + k * p)
    assert gaps.missing == 1
    gaps.add(t0 + 4 * p)  # late, into the gap
    gaps.add(t0 + 6 * p)  # a duplicate is not a late image
    assert gaps.missing == 0
    for k in (7, 8, 9, 12):
        gaps.add(t0 + k * p)
    assert gaps.missing == 2
    for k in (0, 1, 2, 3):  # the bag loops (10 s back): a new timeline, nothing missing or late
        gaps.add(k * p)
    assert gaps.missing == 2 and gaps.period_ns == p  # measured anew on the new timeline


def test_the_assembler_reports_images_missing_from_either_stream():
    asm = FrameAssembler(RigConfig(sync_tolerance_s=0.005), with_events=False)
    for k in range(10):
        if k != 4:
            asm.add_rgb(k * 33 * MS, _img(k))
        if k not in (6, 7):
            asm.add_depth(k * 33 * MS, _dep(1.0))
    assert (asm.stats.missing_rgb, asm.stats.missing_depth) == (1, 2)


def test_the_stream_period_is_numpys_25th_percentile_exactly():
    """StampGaps' plain-Python percentile (kept off numpy for speed) equals ``int(np.percentile(x, 25))``."""
    rng = np.random.default_rng(3)
    for n in range(3, 33):
        for _ in range(200):
            x = rng.choice([33_333_333, 33_366_667, 66_666_667], n) + rng.integers(-50_000, 50_000, n)
            if rng.random() < 0.3:
                x = rng.integers(1, 2_000_000_000, n)
            assert _percentile_25(x.tolist()) == int(np.percentile(x, 25)), x
