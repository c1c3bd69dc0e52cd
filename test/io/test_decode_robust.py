"""EventDecoder on hostile input: out-of-range time bases, time steps back, roll-overs, noisy warnings.

Each test reproduces a reported probe: a uint64 ``time_base`` beyond int64 ns, an evt3 / libcaer
stream whose clock steps back (a step back must be counted, never read as a roll-over), and a
stream of differently broken packets (warnings per kind and rate-limited, counted per kind).
"""
from __future__ import annotations

import logging
import struct

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import EventDecoder, decode_raw
from atsvo_ros.io.encode import encode_events, serialize_event_packet

PACKET = "event_camera_msgs/msg/EventPacket"
T0 = 1_700_000_000_000_000_000
INT64_MAX = (1 << 63) - 1


def _batch(t_ns, w: int = 64, h: int = 48, seed: int = 0) -> EventBatch:
    t_ns = np.asarray(t_ns, np.int64)
    rng = np.random.default_rng(seed)
    n = len(t_ns)
    return EventBatch(rng.integers(0, w, n), rng.integers(0, h, n), t_ns, rng.integers(0, 2, n), w, h)


def _with_time_base(raw: bytes, old: int, new: int) -> bytes:
    """The serialized packet with its uint64 time_base field replaced."""
    i = raw.find(struct.pack("<Q", old))
    assert i > 0
    return raw[:i] + struct.pack("<Q", new) + raw[i + 8:]


@pytest.mark.parametrize("encoding", ["libcaer_cmp", "libcaer", "mono"])
@pytest.mark.parametrize("first", [True, False])
@pytest.mark.parametrize("time_base", [1 << 63, (1 << 64) - 1, INT64_MAX - 10])
def test_time_base_beyond_int64_ns_drops_the_message_and_counts_it(encoding, first, time_base):
    b = _batch(T0 + np.arange(20) * 1000)
    raw = serialize_event_packet(b, encoding, time_base_ns=T0)
    bad = _with_time_base(raw, T0, time_base)
    dec = EventDecoder(PACKET)
    if not first:
        assert len(dec.decode_raw(raw)) == 20
    out = dec.decode_raw(bad)  # no OverflowError, no wrapped negative times
    assert len(out) == 0
    assert dec.stats.dropped_messages == 1 and dec.stats.dropped_by_kind == {"time_range": 1}
    after = dec.decode_raw(serialize_event_packet(_batch(T0 + 10**6 + np.arange(5) * 1000), encoding))
    assert len(after) == 5 and after.t_first_ns == T0 + 10**6
    with pytest.raises(DecodeError, match="time_base") as info:
        decode_raw(bad, PACKET)
    assert info.value.kind == "time_range"


def _evt3_packets(parts: list[np.ndarray]) -> list[bytes]:
    return [serialize_event_packet(_batch(t, seed=i), "evt3", stamp_ns=T0) for i, t in enumerate(parts)]


def test_evt3_time_stepping_back_is_counted_not_read_as_a_rollover():
    # 10.0-10.5 s, then a packet whose camera clock is 1 s earlier, then the clock resumes
    a = 10_000_000_000 + np.arange(0, 500_000_000, 1_000_000)
    back = 9_000_000_000 + np.arange(0, 100_000_000, 1_000_000)
    resume = 10_600_000_000 + np.arange(0, 100_000_000, 1_000_000)
    dec = EventDecoder(PACKET, drop_backwards=False)
    out = [dec.decode_raw(r) for r in _evt3_packets([a, back, resume])]
    np.testing.assert_array_equal(out[0].t, a)
    np.testing.assert_array_equal(out[1].t, back)  # read as it is: 1 s back, not 16.78 - 1 s forward
    np.testing.assert_array_equal(out[2].t, resume)
    assert dec.stats.time_backsteps == 1
    # the default decoder keeps the stream ordered: the stepped-back events are dropped and counted
    dec = EventDecoder(PACKET)
    out = [dec.decode_raw(r) for r in _evt3_packets([a, back, resume])]
    assert len(out[1]) == 0 and dec.stats.dropped_backwards == len(back)
    np.testing.assert_array_equal(out[2].t, resume)
    assert dec.stats.time_backsteps == 1


def test_evt3_real_rollover_of_the_24_bit_clock_is_unwrapped():
    wrap_ns = (1 << 24) * 1000  # 16.777216 s
    t = wrap_ns - 300_000_000 + np.arange(0, 600_000_000, 250_000)  # 0.3 s before to 0.3 s after
    parts = np.array_split(t, 12)
    dec = EventDecoder(PACKET, drop_backwards=False)
    got = np.concatenate([dec.decode_raw(r).t for r in _evt3_packets(parts)])
    np.testing.assert_array_equal(got, t)
    assert dec.stats.time_backsteps == 0


def test_evt3_rollover_after_a_gap_between_packets():
    wrap_ns = (1 << 24) * 1000
    parts = [wrap_ns - 2_000_000_000 + np.arange(10) * 1000, wrap_ns + 3_000_000_000 + np.arange(10) * 1000]
    dec = EventDecoder(PACKET, drop_backwards=False)
    got = np.concatenate([dec.decode_raw(r).t for r in _evt3_packets(parts)])
    np.testing.assert_array_equal(got, np.concatenate(parts))


def _libcaer_packet(stamps_us: np.ndarray, time_base: int = T0) -> bytes:
    n = len(stamps_us)
    b = _batch(np.full(n, time_base, np.int64))
    rec = np.empty(n, np.dtype([("d", "<u4"), ("ts", "<i4")]))
    rec["d"] = (b.x.astype(np.uint32) << 17) | (b.y.astype(np.uint32) << 2) | 1
    rec["ts"] = stamps_us
    raw = serialize_event_packet(b, "libcaer", time_base_ns=time_base)
    head = raw[: len(raw) - 8 * n]
    return head + rec.tobytes()


def test_libcaer_stamp_stepping_back_is_not_a_rollover():
    dec = EventDecoder(PACKET, drop_backwards=False)
    t1 = dec.decode_raw(_libcaer_packet(np.arange(5_000_000, 5_000_100, 10))).t
    t2 = dec.decode_raw(_libcaer_packet(np.arange(4_000_000, 4_000_100, 10))).t  # 1 s back
    assert t2[0] == T0 + 4_000_000_000  # not + 2**31 us (35.8 min) ahead
    assert dec.stats.time_backsteps == 1
    assert t1[-1] > t2[0]


def test_libcaer_rollover_of_the_31_bit_counter_inside_and_across_packets():
    top = (1 << 31) - 50
    dec = EventDecoder(PACKET, drop_backwards=False)
    t1 = dec.decode_raw(_libcaer_packet(np.array([top, top + 20, 3, 10]))).t
    t2 = dec.decode_raw(_libcaer_packet(np.array([20, 30]))).t
    wrap = (1 << 31) * 1000
    np.testing.assert_array_equal(t1, T0 + np.array([top * 1000, (top + 20) * 1000, wrap + 3000, wrap + 10_000]))
    np.testing.assert_array_equal(t2, T0 + wrap + np.array([20_000, 30_000]))
    assert dec.stats.time_backsteps == 0


def _truncated(k: int) -> bytes:
    raw = serialize_event_packet(_batch(T0 + np.arange(100) * 1000), "libcaer_cmp")
    return raw[: len(raw) - 1 - k]


def test_warnings_are_per_kind_not_per_message_text(caplog):
    dec = EventDecoder(PACKET)
    with caplog.at_level(logging.WARNING, logger="atsvo_ros.io.decode"):
        for k in range(50):  # 50 differently truncated packets (each error text differs)
            dec.decode_raw(_truncated(k))
    assert dec.stats.dropped_messages == 50
    assert dec.stats.dropped_by_kind == {"truncated": 50}
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "truncated" in warnings[0].getMessage()


def test_each_kind_warns_once_then_is_rate_limited(caplog, monkeypatch):
    import atsvo_ros.io.decode as mod

    now = [1000.0]
    monkeypatch.setattr(mod, "_monotonic", lambda: now[0])
    dec = EventDecoder(PACKET, warn_interval_s=10.0)
    good = serialize_event_packet(_batch(T0 + np.arange(10) * 1000), "libcaer_cmp")
    unknown = good.replace(b"libcaer_cmp", b"libcaer_xyz")
    with caplog.at_level(logging.WARNING, logger="atsvo_ros.io.decode"):
        for k in range(5):
            dec.decode_raw(_truncated(k))
            dec.decode_raw(unknown)
        assert len(caplog.records) == 2  # one per kind
        now[0] += 11.0
        dec.decode_raw(_truncated(7))
        assert len(caplog.records) == 3
        assert "5 more" in caplog.records[-1].getMessage() or "5 since" in caplog.records[-1].getMessage()
    assert dec.stats.dropped_by_kind == {"truncated": 6, "unknown_encoding": 5}


def test_one_shot_decoders_reject_time_base_beyond_int64():
    b = _batch(T0 + np.arange(3) * 1000)
    from atsvo_ros.io.decode.packet import decode_packet

    tb, payload = encode_events(b, "mono")
    with pytest.raises(DecodeError, match="time_base"):
        decode_packet("mono", payload, 1 << 63)
