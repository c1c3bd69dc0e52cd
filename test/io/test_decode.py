"""Decoder robustness: broken input gives a clear DecodeError or a counted drop, never a crash."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import EventDecoder, decode_message, decode_raw, normalize_msgtype
from atsvo_ros.io.decode.packet import decode_packet
from atsvo_ros.io.encode import encode_events, serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.io.msgtypes import typestore

PACKET = "event_camera_msgs/msg/EventPacket"
DVS = "dvs_msgs/msg/EventArray"


def _batch(n=50, width=64, height=48, t0=10**15, step_ns=1000):
    i = np.arange(n)
    return EventBatch(i % width, (i * 7) % height, t0 + i * step_ns, i % 2, width, height)


@pytest.mark.parametrize("ros_version", [1, 2])
@pytest.mark.parametrize("kind", ["libcaer_cmp", "libcaer", "mono", "evt3", "dvs"])
def test_truncated_messages_raise_a_clear_error(kind, ros_version):
    b = _batch(t0=0 if kind == "evt3" else 10**15)
    if kind == "dvs":
        raw, typ = serialize_dvs_event_array(b, ros_version=ros_version), DVS
    else:
        raw, typ = serialize_event_packet(b, kind, ros_version=ros_version), PACKET
    for cut in (3, 20, len(raw) // 2, len(raw) - 1):
        with pytest.raises(DecodeError, match="truncated"):
            decode_raw(raw[:cut], typ, ros_version)


def test_event_decoder_counts_broken_messages_and_keeps_going(caplog):
    b = _batch()
    good = serialize_event_packet(b, "libcaer_cmp")
    dec = EventDecoder(PACKET)
    with caplog.at_level(logging.WARNING):
        assert len(dec.decode_raw(good[:-7])) == 0
        assert len(dec.decode_raw(good)) == len(b)
    assert dec.stats.dropped_messages == 1 and dec.stats.n_events == len(b)
    assert "truncated" in caplog.text
    with pytest.raises(DecodeError):
        EventDecoder(PACKET, strict=True).decode_raw(good[:-7])


def test_unknown_encoding_and_message_type():
    msg_cls = typestore(2).types[PACKET]
    hdr = typestore(2).types["std_msgs/msg/Header"]
    stamp = typestore(2).types["builtin_interfaces/msg/Time"](sec=1, nanosec=0)
    msg = msg_cls(header=hdr(stamp=stamp, frame_id="c"), height=4, width=4, seq=0, time_base=0, encoding="evt4",
                  is_bigendian=False, events=np.zeros(8, np.uint8))
    with pytest.raises(DecodeError, match="unknown event encoding 'evt4'"):
        decode_message(msg, PACKET)
    dec = EventDecoder(PACKET)
    assert len(dec.decode_message(msg)) == 0 and dec.stats.dropped_messages == 1
    with pytest.raises(DecodeError, match="not an event message type"):
        decode_raw(b"", "sensor_msgs/msg/Image", 2)
    assert normalize_msgtype("dvs_msgs/EventArray") == DVS


@pytest.mark.parametrize("encoding", ["libcaer_cmp", "libcaer", "mono", "evt3"])
def test_out_of_range_coordinates_are_dropped_and_counted(encoding):
    b = _batch(n=40, width=64, height=48, t0=0 if encoding == "evt3" else 10**15)
    tb, payload = encode_events(b, encoding)
    r = decode_packet(encoding, payload, tb, 32, 48)  # claim a narrower sensor
    expected = b.x < 32
    assert r.n_out_of_range == int(np.count_nonzero(~expected))
    np.testing.assert_array_equal(r.x, b.x[expected])
    np.testing.assert_array_equal(r.t, b.t[expected])


def test_dvs_out_of_range_and_backwards_time_are_dropped_by_the_stream_decoder(caplog):
    b = _batch(n=10, width=64, height=48)
    x = b.x.copy()
    x[3] = 500
    t = b.t.copy()
    t[6] = t[0] - 1  # older than what was already emitted
    bad = EventBatch(x, b.y, t, b.p, 64, 48)
    raw = serialize_dvs_event_array(bad)
    dec = EventDecoder(DVS)
    with caplog.at_level(logging.WARNING):
        out = dec.decode_raw(raw)
    assert dec.stats.dropped_out_of_range == 1 and dec.stats.dropped_backwards == 1
    assert len(out) == 8 and out.is_sorted()
    assert "outside" in caplog.text and "backwards" in caplog.text
    # a later message that starts before the end of the previous one loses its old events only
    older = serialize_dvs_event_array(_batch(n=10, t0=int(b.t[5])))
    out2 = dec.decode_raw(older)
    assert out2.t_first_ns >= out.t_last_ns
    assert dec.stats.dropped_backwards == 1 + int(np.count_nonzero(_batch(n=10, t0=int(b.t[5])).t < out.t_last_ns))
    # one-shot functions keep everything (they have no history)
    assert len(decode_raw(raw, DVS, 2)) == 10


def test_unknown_words_are_counted_not_fatal():
    b = _batch(n=5)
    tb, payload = encode_events(b, "libcaer_cmp")
    words = np.concatenate([payload.view("<u2"), np.array([0xF123, 0x9000], "<u2")])
    r = decode_packet("libcaer_cmp", words.view(np.uint8), tb, 64, 48)
    assert len(r.x) == 5 and r.n_unknown_words == 2
    r = decode_packet("libcaer", payload[:-3], tb)  # not a multiple of 8 bytes
    assert r.n_trailing_bytes == (len(payload) - 3) % 8


def test_evt3_aligned_to_header_clock():
    b = _batch(n=20, t0=3_000_000)
    raw = serialize_event_packet(b, "evt3", stamp_ns=1_700_000_000_000_000_000)
    dec = EventDecoder(PACKET, align_to_header=True)
    out = dec.decode_raw(raw)
    assert out.t_first_ns == 1_700_000_000_000_000_000
    np.testing.assert_array_equal(np.diff(out.t), np.diff(b.t))


def test_packet_message_with_rclpy_style_payloads():
    """rclpy hands uint8[] over as array('B') (or bytes / a list); all decode the same."""
    import array
    from types import SimpleNamespace

    b = _batch(n=30)
    tb, payload = encode_events(b, "libcaer_cmp")
    stamp = SimpleNamespace(sec=1, nanosec=2)
    for events in (array.array("B", payload.tobytes()), payload.tobytes(), payload.tolist()):
        msg = SimpleNamespace(header=SimpleNamespace(stamp=stamp, frame_id="ev"), height=b.height, width=b.width,
                              seq=3, time_base=tb, encoding="libcaer_cmp", is_bigendian=False, events=events)
        out = decode_message(msg, "event_camera_msgs/EventPacket")
        np.testing.assert_array_equal(out.t, b.t)
        np.testing.assert_array_equal(out.x, b.x)


@pytest.mark.parametrize("encoding,word", [("libcaer_cmp", "u2"), ("evt3", "u2"), ("mono", "u8"), ("libcaer", "u4")])
def test_big_endian_payloads(encoding, word):
    b = _batch(n=25, t0=0 if encoding == "evt3" else 10**15)
    tb, payload = encode_events(b, encoding)
    swapped = payload.view(f"<{word}").byteswap().view(np.uint8)  # libcaer: both 32-bit fields swap alike
    r = decode_packet(encoding, swapped, tb, b.width, b.height, big_endian=True)
    np.testing.assert_array_equal(r.t, b.t)
    np.testing.assert_array_equal(r.x, b.x)
    np.testing.assert_array_equal(r.y, b.y)
    np.testing.assert_array_equal(r.p, b.p)


@pytest.mark.parametrize("typ", [DVS, PACKET])
def test_big_endian_cdr_messages(typ):
    store = typestore(2)
    b = _batch(n=9)
    raw = serialize_dvs_event_array(b) if typ == DVS else serialize_event_packet(b, "mono")
    msg = store.deserialize_cdr(raw, typ)
    big = bytes(store.serialize_cdr(msg, typ, little_endian=False))
    assert big[1] == 0  # CDR_BE
    out = decode_raw(big, typ, 2)
    np.testing.assert_array_equal(out.t, b.t)
    np.testing.assert_array_equal(out.x, b.x)
