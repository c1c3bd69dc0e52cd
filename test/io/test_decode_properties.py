"""Property-based tests of the event decoders (hypothesis, derandomized so runs are repeatable).

* encode -> serialize -> decode gives the events back, for every EventPacket encoding, both
  serializations, one packet at a time and many at once (``decode_raw_many``);
* the stateful decoder's output is time-ordered and drops exactly the events older than the
  newest one kept (the reference filter), whatever the packets;
* evt3 and libcaer clocks rolling over any number of times are unwrapped exactly, and a clock
  stepping back is counted as a step back.
"""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.io.decode import EventDecoder, decode_raw
from atsvo_ros.io.decode._kernels import _keep_forward
from atsvo_ros.io.encode import serialize_dvs_event_array, serialize_event_packet

PACKET = "event_camera_msgs/msg/EventPacket"
T0 = 1_700_000_000_000_000_000
PROPS = settings(max_examples=60, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

#: largest time span of one packet (ns) and coordinate per encoding
LIMITS = {"libcaer_cmp": ((1 << 24) * 1000 - 1000, 0x7FF), "libcaer": (10**12, 0x7FFF),
          "mono": ((1 << 32) - 1, 0x7FFF), "evt3": (10**10, 0x7FF)}


@st.composite
def batches(draw, encoding: str, max_events: int = 300):
    """Time-sorted events that the encoding can carry (microsecond grid except mono)."""
    span, cmax = LIMITS[encoding]
    n = draw(st.integers(0, max_events))
    w = draw(st.integers(1, min(cmax, 2047) + 1))
    h = draw(st.integers(1, min(cmax, 2047) + 1))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    unit = 1 if encoding == "mono" else 1000
    dt = np.sort(rng.integers(0, span // unit + 1, n)) * unit
    if draw(st.booleans()):  # bursts: many events sharing a time
        dt = np.repeat(dt[: (n + 3) // 4], 4)[:n]
    base = 5 * 10**9 if encoding == "evt3" else T0  # evt3: camera clock, inside its first 16.7 s epoch
    t = base + dt
    return EventBatch(rng.integers(0, w, n), rng.integers(0, h, n), t, rng.integers(0, 2, n), w, h)


def _same(a: EventBatch, b: EventBatch) -> None:
    for f in "xytp":
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def _roundtrip(encoding: str, b: EventBatch, ros_version: int) -> None:
    raw = serialize_event_packet(b, encoding, stamp_ns=T0, ros_version=ros_version)
    _same(decode_raw(raw, PACKET, ros_version), b)
    dec = EventDecoder(PACKET, ros_version, drop_backwards=False, strict=True)
    _same(dec.decode_raw(raw), b)
    assert (dec.stats.n_events, dec.stats.dropped_messages, dec.stats.time_backsteps) == (len(b), 0, 0)


@PROPS
@given(batches("libcaer_cmp"), st.sampled_from([1, 2]))
def test_libcaer_cmp_roundtrip(b, ros_version):
    _roundtrip("libcaer_cmp", b, ros_version)


@PROPS
@given(batches("libcaer"), st.sampled_from([1, 2]))
def test_libcaer_roundtrip(b, ros_version):
    _roundtrip("libcaer", b, ros_version)


@PROPS
@given(batches("mono"), st.sampled_from([1, 2]))
def test_mono_roundtrip(b, ros_version):
    _roundtrip("mono", b, ros_version)


@PROPS
@given(batches("evt3"), st.sampled_from([1, 2]))
def test_evt3_roundtrip(b, ros_version):
    _roundtrip("evt3", b, ros_version)


@PROPS
@given(st.data(), st.sampled_from(["libcaer_cmp", "libcaer", "mono", "evt3"]), st.sampled_from([1, 2]))
def test_many_packets_one_at_a_time_or_at_once(data, encoding, ros_version):
    parts = [data.draw(batches(encoding, 120)) for _ in range(data.draw(st.integers(1, 6)))]
    if encoding == "evt3":  # one camera clock: shift the packets one after the other
        shifted, t_next = [], 5 * 10**9
        for p in parts:
            d = p.t - (p.t[0] if len(p) else 0) + t_next
            shifted.append(EventBatch(p.x, p.y, d, p.p, p.width, p.height))
            t_next = int(d[-1]) + 1000 if len(p) else t_next
        parts = shifted
    raws = [serialize_event_packet(p, encoding, stamp_ns=T0, ros_version=ros_version) for p in parts]
    one = EventDecoder(PACKET, ros_version, drop_backwards=False)
    singles = [one.decode_raw(r) for r in raws]
    many = EventDecoder(PACKET, ros_version, drop_backwards=False)
    split = data.draw(st.integers(0, len(raws)))
    joined = [many.decode_raw_many(raws[:split]), many.decode_raw_many(raws[split:])]
    for f in "xytp":
        np.testing.assert_array_equal(np.concatenate([getattr(b, f) for b in singles]),
                                      np.concatenate([getattr(b, f) for b in joined]))
    assert one.stats == many.stats
    if encoding != "evt3":
        _same(EventBatch.concatenate(singles), EventBatch.concatenate(parts))


@PROPS
@given(st.data(), st.sampled_from(["libcaer_cmp", "mono", "libcaer"]))
def test_stream_is_time_ordered_and_drops_exactly_the_older_events(data, encoding):
    parts = [data.draw(batches(encoding, 80)) for _ in range(data.draw(st.integers(1, 5)))]
    parts = [EventBatch(p.x, p.y, p.t - data.draw(st.integers(0, 50)) * 1000, p.p, p.width, p.height) for p in parts]
    raws = [serialize_event_packet(p, encoding, ros_version=2) for p in parts]
    dec = EventDecoder(PACKET)
    out = EventBatch.concatenate([dec.decode_raw(r) for r in raws])
    assert out.is_sorted()
    allt = np.concatenate([p.t for p in parts]) if parts else np.zeros(0, np.int64)
    keep = _keep_forward(allt, np.iinfo(np.int64).min)
    np.testing.assert_array_equal(out.t, allt[keep])
    assert dec.stats.dropped_backwards == int(len(allt) - keep.sum())
    assert dec.stats.n_events == len(out)


def _libcaer_raw(stamps_us: np.ndarray, time_base: int) -> bytes:
    n = len(stamps_us)
    head = serialize_event_packet(EventBatch(np.zeros(n), np.zeros(n), np.full(n, time_base), np.zeros(n), 64, 48),
                                  "libcaer", time_base_ns=time_base)
    rec = np.zeros(n, np.dtype([("d", "<u4"), ("ts", "<i4")]))
    rec["d"] = 1
    rec["ts"] = (stamps_us & 0x7FFFFFFF).astype(np.int64).astype(np.int32)
    return head[: len(head) - 8 * n] + rec.tobytes()


@PROPS
@given(st.lists(st.integers(0, (1 << 30) - 1), min_size=1, max_size=200), st.integers(1, 6))
def test_libcaer_counter_rolling_over_many_times_is_unwrapped(steps_us, n_packets):
    t_us = np.cumsum(np.asarray(steps_us, np.int64))  # true microseconds, any number of 2**31 roll-overs
    dec = EventDecoder(PACKET, drop_backwards=False)
    got = np.concatenate([dec.decode_raw(_libcaer_raw(part, T0)).t for part in np.array_split(t_us, n_packets)])
    np.testing.assert_array_equal(got, T0 + (t_us - 0) * 1000)
    assert dec.stats.time_backsteps == 0


@PROPS
@given(st.lists(st.integers(0, 8_000_000), min_size=1, max_size=150), st.integers(1, 6))
def test_evt3_clock_rolling_over_many_times_is_unwrapped(steps_us, n_packets):
    t_us = 1000 + np.cumsum(np.asarray(steps_us, np.int64))  # gaps below 8.4 s, any number of 16.8 s roll-overs
    t = t_us * 1000
    b = EventBatch(np.arange(len(t)) % 640, np.arange(len(t)) % 480, t, np.ones(len(t)), 640, 480)
    dec = EventDecoder(PACKET, drop_backwards=False)
    raws = [serialize_event_packet(b.select(slice(int(ix[0]), int(ix[-1]) + 1)), "evt3", stamp_ns=T0)
            for ix in np.array_split(np.arange(len(t)), n_packets) if len(ix)]
    got = np.concatenate([dec.decode_raw(r).t for r in raws])
    np.testing.assert_array_equal(got, t)
    assert dec.stats.time_backsteps == 0


@PROPS
@given(st.lists(st.tuples(st.integers(1, 2000), st.booleans()), min_size=2, max_size=40))
def test_evt3_steps_back_are_counted_not_rolled_over(moves):
    """Packets whose clock moves forward or back by up to 2000 TIME_HIGH ticks (8.2 s)."""
    t_us, times = 6_000_000, []
    n_back = 0
    for ticks, back in moves:
        t_us = t_us - ticks * 4096 if back and t_us - ticks * 4096 > 0 else t_us + ticks * 4096
        n_back += back and times != [] and times[-1] > t_us
        times.append(t_us)
    dec = EventDecoder(PACKET, drop_backwards=False)
    for t in times:
        b = EventBatch([1], [1], [t * 1000], [1], 64, 48)
        got = dec.decode_raw(serialize_event_packet(b, "evt3", stamp_ns=T0)).t
        assert int(got[0]) == t * 1000
    assert dec.stats.time_backsteps == n_back


@PROPS
@given(st.integers(0, 300), st.sampled_from([1, 2]), st.integers(0, 2**32 - 1))
def test_dvs_event_array_roundtrip(n, ros_version, seed):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, 10**10, n)) + T0
    b = EventBatch(rng.integers(0, 346, n), rng.integers(0, 260, n), t, rng.integers(0, 2, n), 346, 260)
    _same(decode_raw(serialize_dvs_event_array(b, ros_version=ros_version), "dvs_msgs/msg/EventArray", ros_version), b)
