"""Every decoder against the counts and checksums published with the real recordings.

The expected numbers are those of ../shared/realdata/README.md and the README.txt files of its
folders (computed there by the reference C++/pybind decoders of ros-event-camera, by the `aedat`
package and by expelliarmus); the tests skip when ../shared/realdata is absent.
"""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.decode.packet import Evt3State, decode_packet
from atsvo_ros.io.decode.packet_msg import parse_packet_raw
from atsvo_ros.io.event_files import open_events

U64 = np.uint64


def _u64sum(a: np.ndarray) -> int:
    """Sum modulo 2**64, as the C++ checksum processors accumulate."""
    return int(a.astype(np.int64).view(U64).sum(dtype=U64))


def _read(path, **opts):
    src = open_events(path, drop_backwards=False, strict=True, **opts)
    return src, src.read_all()


def test_libcaer_cmp_davis346_mcap_with_empty_storage_identifier(realdata):
    src, b = _read(realdata / "event_camera_py_bags" / "test_events_2")
    assert (src.encoding, src.width, src.height, src.stats.n_messages) == ("libcaer_cmp", 346, 260, 100)
    assert int(np.count_nonzero(b.p == 0)) == 360_223
    assert int(np.count_nonzero(b.p == 1)) == 211_043
    # event_camera_py reports microseconds relative to the first event (test_2.py's sum_time)
    t_us = b.t // 1000
    assert int((t_us - t_us[0]).sum()) == 335_555_680_277
    assert b.t_first_ns == 1_744_227_144_732_712_000  # test_2.py: first sensor time 1744227144732712 us
    assert b.is_sorted()


def test_libcaer_rollover_checksums(realdata):
    src, b = _read(realdata / "event_camera_codecs_bags" / "test_data_libcaer_rollover")
    assert (src.encoding, src.width, src.height) == ("libcaer", 640, 480)
    assert _u64sum(b.t) == 15_762_826_572_202_229_126
    assert (int(b.x.sum(dtype=np.int64)), int(b.y.sum(dtype=np.int64)), int(b.p.sum(dtype=np.int64))) == \
        (111_651_612, 82_801_007, 181_908)
    assert len(b) == 334_331 and b.is_sorted()
    # README's "first ts" 1702309120772229018 is the first event of the *second* packet
    assert 1_702_309_120_772_229_018 in set(b.t[:5000].tolist())


def test_mono_checksums(realdata):
    src, b = _read(realdata / "event_camera_codecs_bags" / "test_data_mono_cd")
    assert (src.encoding, src.msgtype) == ("mono", "event_array_msgs/msg/EventArray")
    # event_camera_codecs decoder_test.cpp: (t, x, y, p) = 4950000, 34450, 26450, 50 -- 2 packets x 50 events
    assert (_u64sum(b.t), int(b.x.sum(dtype=np.int64)), int(b.y.sum(dtype=np.int64)),
            int(b.p.sum(dtype=np.int64))) == (4_950_000, 34_450, 26_450, 50)
    assert len(b) == 100


def test_evt3_trigger_checksums_and_triggers(realdata):
    from rosbags.rosbag2 import Reader

    path = realdata / "event_camera_codecs_bags" / "test_data_evt3_trigger"
    src, b = _read(path)
    assert (src.encoding, src.width, src.height) == ("evt3", 1280, 720)
    assert (_u64sum(b.t), int(b.x.sum(dtype=np.int64)), int(b.y.sum(dtype=np.int64)),
            int(b.p.sum(dtype=np.int64))) == (1_222_326_831_810_000, 42_078_718, 31_656_267, 41_439)
    # trigger checksum of decoder_test.cpp: (t, edge, id) = 29096982000, 1, 0
    state, trig_t, trig_edge, trig_id = Evt3State(), [], [], []
    with Reader(path) as reader:
        for _, _, raw in reader.messages():
            f = parse_packet_raw(raw, 2)
            r = decode_packet(f.encoding, f.events, f.time_base, f.width, f.height, evt3_state=state)
            trig_t.append(r.trigger_t)
            trig_edge.append(r.trigger_edge)
            trig_id.append(r.trigger_id)
    assert (int(np.concatenate(trig_t).sum()), int(np.concatenate(trig_edge).sum()),
            int(np.concatenate(trig_id).sum())) == (29_096_982_000, 1, 0)


@pytest.mark.parametrize("name", ["test_events_1.bag", "test_events_1"])
def test_evt3_ros1_and_ros2_bags(realdata, name):
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag2 import Reader as Reader2

    path = realdata / "event_camera_py_bags" / name
    ros_version = 1 if name.endswith(".bag") else 2
    dec = EventDecoder("event_camera_msgs/msg/EventPacket", ros_version, drop_backwards=False, strict=True)
    cd_sum_us = 0
    off = on = 0
    state, trig_t, trig_edge = Evt3State(), [], []
    with (Reader1 if ros_version == 1 else Reader2)(path) as reader:
        for _, _, raw in reader.messages():
            b = dec.decode_raw(raw)
            off += int(np.count_nonzero(b.p == 0))
            on += int(np.count_nonzero(b.p == 1))
            cd_sum_us += int((b.t // 1000).sum())
            f = parse_packet_raw(raw, ros_version)
            r = decode_packet(f.encoding, f.events, f.time_base, f.width, f.height, evt3_state=state)
            trig_t.append(r.trigger_t)
            trig_edge.append(r.trigger_edge)
    edges = np.concatenate(trig_edge)
    assert (off, on) == (218_291, 125_183)
    assert dec.stats.n_trigger == len(edges) == 4157
    # test_1.py counts p == 0 as rising (2,078); its check compares only that count, there are 2,079 falling
    assert int(np.count_nonzero(edges == 0)) == 2078
    # test_1.py's sum_time adds CD and trigger times in microseconds
    assert cd_sum_us + int((np.concatenate(trig_t) // 1000).sum()) == 2_885_601_049_874
    assert dec.stats.width == 640 and dec.stats.height == 480


def test_aedat4_dvxplorer(realdata):
    pytest.importorskip("aedat", reason="the aedat package is not installed (pip install 'atsvo_ros[aedat]')")
    src, b = _read(realdata / "tonic_samples" / "sample.aedat4")
    assert (src.width, src.height) == (320, 240)
    assert len(b) == 111_954
    assert 0.58e9 < b.t_last_ns - b.t_first_ns < 0.60e9  # 0.590 s
    assert int(b.x.max()) < 320 and int(b.y.max()) < 240


def test_prophesee_evt2_raw(realdata):
    src, b = _read(realdata / "expelliarmus_prophesee" / "evt2_sample.raw")
    assert (src.width, src.height, src.encoding) == (640, 480, "evt2")
    assert len(b) == 539_481
    assert (int(np.count_nonzero(b.p == 0)), int(np.count_nonzero(b.p == 1))) == (171_626, 367_855)
    assert b.is_sorted()


def test_prophesee_evt3_raw_against_reference_decode(realdata):
    folder = realdata / "expelliarmus_prophesee"
    src, b = _read(folder / "evt3_sample.raw")
    ref = np.load(folder / "evt3_sample.npy")
    assert (src.width, src.height) == (1280, 720)
    assert len(b) == len(ref) == 219_596
    np.testing.assert_array_equal(b.x, ref["x"])
    np.testing.assert_array_equal(b.y, ref["y"])
    np.testing.assert_array_equal(b.p, ref["p"])
    # Times follow the evt3 spec as event_camera_codecs reads it (TIME_LOW replaces the low 12 bits).
    # expelliarmus bumps TIME_HIGH whenever TIME_LOW steps back a little, so its times run ahead by
    # multiples of 4096 us; both agree on the first events and on the order.
    assert b.is_sorted()
    assert int(b.t[0] // 1000) == int(ref["t"][0])
    lag_us = ref["t"] - b.t // 1000
    assert np.all(lag_us % 4096 == 0) and np.all(lag_us >= 0)


def test_aedat4_agrees_with_dv_processing(realdata):
    dv = pytest.importorskip("dv_processing", reason="dv-processing is not installed (pip install 'atsvo_ros[bench]')")
    _, b = _read(realdata / "tonic_samples" / "sample.aedat4")
    rec = dv.io.MonoCameraRecording(str(realdata / "tonic_samples" / "sample.aedat4"))
    parts = []
    while rec.isRunning():
        store = rec.getNextEventBatch()
        if store is not None:
            parts.append(store.numpy())
    ref = np.concatenate(parts)
    np.testing.assert_array_equal(b.t, ref["timestamp"] * 1000)
    np.testing.assert_array_equal(b.x, ref["x"])
    np.testing.assert_array_equal(b.y, ref["y"])
    np.testing.assert_array_equal(b.p, ref["polarity"])


@pytest.mark.parametrize("ros_version", [1, 2])
def test_registered_message_types_match_the_published_definitions(realdata, ros_version):
    from rosbags.typesys import get_types_from_msg

    from atsvo_ros.io.msgtypes import DEFINITIONS, typestore

    store = typestore(ros_version)
    checked = 0
    for path in sorted((realdata / "cear_dvxlite_d455_calib" / "msgs").glob("*.msg")):
        parts = path.name[: -len(".msg")].split(".")
        if len(parts) == 2 and parts[1] != f"ros{ros_version}":
            continue  # the other ROS version's definition
        pkg, name = parts[0].split("__")
        full = f"{pkg}/msg/{name}"
        if full not in DEFINITIONS:
            continue  # e.g. dv_ros_msgs/Trigger: not an event stream
        assert store.fielddefs[full] == get_types_from_msg(path.read_text(), full)[full], full
        checked += 1
    assert checked == 7
