"""Shifting serialized messages in time: the stamps and the decoded event times move, nothing else."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode import decode_raw
from atsvo_ros.io.encode import ENCODINGS, serialize_event_packet
from atsvo_ros.io.msgtypes import typestore
from atsvo_ros.io.restamp import cdr_stamp_ns, restamp_event_packet, restamp_header


def _batch(n: int = 500) -> EventBatch:
    rng = np.random.default_rng(3)
    t = 1_700_000_000_000_000_000 + np.sort(rng.integers(0, 20_000, n)) * 1000
    return EventBatch(rng.integers(0, 320, n), rng.integers(0, 240, n), t, rng.integers(0, 2, n), 320, 240)


@pytest.mark.parametrize("encoding", [e for e in ENCODINGS if e != "evt3"])
@pytest.mark.parametrize("frame_id", ["", "dv", "dvxplorer_optical_frame"])  # every alignment of what follows
def test_event_packet_times_move_by_the_shift(encoding, frame_id):
    b = _batch()
    raw = serialize_event_packet(b, encoding, frame_id=frame_id)
    shift = 61_000_000_123 * 1000  # whole microseconds, several minutes
    moved = restamp_event_packet(raw, shift, encoding)
    out = decode_raw(moved, "event_camera_msgs/msg/EventPacket")
    np.testing.assert_array_equal(out.t, b.t + shift)
    np.testing.assert_array_equal(out.x, b.x)
    np.testing.assert_array_equal(out.p, b.p)
    msg = typestore().deserialize_cdr(moved, "event_camera_msgs/msg/EventPacket")
    assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == b.t_first_ns + shift
    assert msg.header.frame_id == frame_id and msg.encoding == encoding


def test_evt3_is_refused():
    b = _batch()
    b = EventBatch(b.x, b.y, b.t - b.t_first_ns + 5_000_000, b.p, 320, 240)
    with pytest.raises(DecodeError, match="evt3"):
        restamp_event_packet(serialize_event_packet(b, "evt3"), 10**9, "evt3")


def test_header_stamp_carries_into_seconds():
    store = typestore()
    Image = store.types["sensor_msgs/msg/Image"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    img = Image(Header(Time(sec=100, nanosec=900_000_000), "camera_color_optical_frame"), 2, 3, "mono8", 0, 3,
                np.arange(6, dtype=np.uint8))
    raw = bytes(store.serialize_cdr(img, "sensor_msgs/msg/Image"))
    back = store.deserialize_cdr(restamp_header(raw, 250_000_000), "sensor_msgs/msg/Image")
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (101, 150_000_000)
    assert back.header.frame_id == img.header.frame_id
    np.testing.assert_array_equal(back.data, img.data)
    with pytest.raises(DecodeError, match="negative"):
        restamp_header(raw, -200 * 10**9)


def test_stamp_is_read_in_the_buffers_byte_order():
    little = b"\x00\x01\x00\x00" + (7).to_bytes(4, "little") + (5).to_bytes(4, "little")
    big = b"\x00\x00\x00\x00" + (7).to_bytes(4, "big") + (5).to_bytes(4, "big")
    assert cdr_stamp_ns(little) == cdr_stamp_ns(big) == 7_000_000_005
    assert cdr_stamp_ns(restamp_header(big, 10)) == 7_000_000_015
    assert cdr_stamp_ns(little[:10]) is None
