"""Encoders round-trip through the decoders and serialize exactly as rosbags does."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import EventDecoder, decode_message, decode_raw
from atsvo_ros.io.decode.packet import decode_packet
from atsvo_ros.io.encode import ENCODINGS, encode_events, serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.io.msgtypes import typestore


def _random_batch(n: int, seed: int = 0, width: int = 346, height: int = 260, t0_ns: int = 1_700_000_000_000_000_000,
                  span_us: int = 50_000) -> EventBatch:
    rng = np.random.default_rng(seed)
    t_us = np.sort(rng.integers(0, span_us, n))  # repeated stamps exercise the "same time" paths
    return EventBatch(rng.integers(0, width, n), rng.integers(0, height, n), t0_ns + t_us * 1000,
                      rng.integers(0, 2, n), width, height)


def _same(a: EventBatch, b: EventBatch) -> None:
    assert len(a) == len(b)
    for f in "xytp":
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("n", [0, 1, 2, 3000])
def test_payload_round_trip(encoding, n):
    b = _random_batch(n, seed=n)
    if encoding == "evt3":  # evt3 carries the camera clock: start near zero, like a real sensor
        b = EventBatch(b.x, b.y, b.t - b.t_first_ns + 5_000_000 if n else b.t, b.p, b.width, b.height)
    tb, payload = encode_events(b, encoding)
    assert payload.dtype == np.uint8
    r = decode_packet(encoding, payload, tb, b.width, b.height)
    _same(EventBatch(r.x, r.y, r.t, r.p), b)
    assert r.n_out_of_range == r.n_unknown_words == r.n_trailing_bytes == 0


def test_libcaer_cmp_payload_is_compact_and_packet_local():
    b = _random_batch(2000, seed=3)
    _, payload = encode_events(b, "libcaer_cmp")
    # at most 4 words per event, usually fewer (shared time words)
    assert len(payload) <= 8 * len(b)
    # a packet split on a word boundary after a time word decodes on its own
    words = payload.view("<u2")
    assert words[0] >> 12 == 0 and words[1] >> 12 == 1


def test_evt3_round_trip_across_the_24_bit_rollover():
    t_us = np.arange(0, 40_000_000, 7919)  # 40 s of camera clock: two wraps of 2**24 us
    n = len(t_us)
    b = EventBatch(np.arange(n) % 640, np.arange(n) % 480, t_us * 1000, np.arange(n) % 2, 640, 480)
    dec = EventDecoder("event_camera_msgs/msg/EventPacket", strict=True)
    out = []
    for chunk in np.array_split(np.arange(n), 40):
        raw = serialize_event_packet(b.select(chunk), "evt3", stamp_ns=0)
        out.append(dec.decode_raw(raw))
    _same(EventBatch.concatenate(out), b)


def test_libcaer_round_trip_across_packets_with_rollover():
    tb = 1_000_000_000_000
    t_us = np.arange(2**31 - 50_000, 2**31 + 50_000, 997)  # the 31-bit us counter wraps in the middle
    n = len(t_us)
    b = EventBatch(np.arange(n) % 320, np.arange(n) % 240, tb + t_us * 1000, np.arange(n) % 2, 320, 240)
    dec = EventDecoder("event_camera_msgs/msg/EventPacket", strict=True)
    out = []
    for chunk in np.array_split(np.arange(n), 9):
        # the driver keeps time_base fixed while the sensor counter wraps
        raw = serialize_event_packet(b.select(chunk), "libcaer", time_base_ns=tb)
        out.append(dec.decode_raw(raw))
    _same(EventBatch.concatenate(out), b)
    # without state a packet that starts after the wrap would jump back by 2**31 us
    late = serialize_event_packet(b.select(slice(n - 10, n)), "libcaer", time_base_ns=tb)
    assert decode_raw(late, "event_camera_msgs/msg/EventPacket").t[0] < b.t[n - 10]


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("n", [0, 1, 2, 7, 500])
def test_dvs_event_array_bytes_match_rosbags_and_round_trip(ros_version, n):
    b = _random_batch(n, seed=10 + n)
    store = typestore(ros_version)
    for msgtype in ("dvs_msgs/msg/EventArray", "dv_ros2_msgs/msg/EventArray"):
        raw = serialize_dvs_event_array(b, stamp_ns=123_456_789_012, frame_id="dvs", ros_version=ros_version)
        if ros_version == 2:
            msg = store.deserialize_cdr(raw, msgtype)
            again = bytes(store.serialize_cdr(msg, msgtype))
        else:
            msg = store.deserialize_ros1(raw, msgtype)
            again = bytes(store.serialize_ros1(msg, msgtype))
        assert again == raw
        assert msg.header.frame_id == "dvs" and msg.width == b.width and msg.height == b.height
        _same(decode_raw(raw, msgtype, ros_version), b)
        _same(decode_message(msg, msgtype), b)


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_event_packet_bytes_match_rosbags(ros_version, encoding):
    b = _random_batch(300, seed=5)
    if encoding == "evt3":
        b = EventBatch(b.x, b.y, b.t - b.t_first_ns, b.p, b.width, b.height)
    raw = serialize_event_packet(b, encoding, frame_id="event_camera", seq=42, ros_version=ros_version)
    store = typestore(ros_version)
    t = "event_camera_msgs/msg/EventPacket"
    msg = store.deserialize_cdr(raw, t) if ros_version == 2 else store.deserialize_ros1(raw, t)
    again = store.serialize_cdr(msg, t) if ros_version == 2 else store.serialize_ros1(msg, t)
    assert bytes(again) == raw
    assert (msg.encoding, msg.seq, msg.width, msg.height) == (encoding, 42, b.width, b.height)
    _same(decode_raw(raw, t, ros_version), b)
    _same(decode_message(msg, t), b)


def test_encoders_refuse_what_does_not_fit():
    b = _random_batch(10)
    with pytest.raises(DecodeError, match="unknown event encoding"):
        encode_events(b, "evt4")
    long = EventBatch([0, 1], [0, 1], [0, 20_000_000_000], [0, 1])
    with pytest.raises(DecodeError, match="2\\*\\*24"):
        encode_events(long, "libcaer_cmp")
    with pytest.raises(DecodeError, match="2\\*\\*32"):
        encode_events(long, "mono")
    unsorted = EventBatch([0, 1], [0, 1], [5000, 1000], [0, 1])
    with pytest.raises(DecodeError, match="not sorted"):
        encode_events(unsorted, "libcaer")
