"""The wire format between tracking and mapping processes: exact round trips, clear errors, the CDR carrier."""
from __future__ import annotations

import dataclasses
import struct

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.mapping.map import MapSnapshot
from atsvo_ros.core.mapping.mapper import KeyframeRequest, Mapper
from atsvo_ros.core.mapping.ports import InlineMapping
from atsvo_ros.core.odometry.odometry import Odometry, RgbdFrame
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.errors import WireError
from atsvo_ros.io.wire import (
    PinholeLevels,
    decode_keyframe_request,
    decode_map_snapshot,
    encode_keyframe_request,
    encode_map_snapshot,
    uint8_multiarray_cdr,
    uint8_multiarray_payload,
)
from atsvo_ros.sim.sequence import SequenceSpec, make_simulation, sequence_rig


class _Recording(InlineMapping):
    """Inline mapping that keeps every request and the snapshot it produced."""

    def __init__(self, mapper: Mapper) -> None:
        super().__init__(mapper)
        self.log: list[tuple[KeyframeRequest, MapSnapshot]] = []

    def insert(self, request, wait=False):
        snap = super().insert(request, wait)
        self.log.append((request, snap))
        return snap


@pytest.fixture(scope="module")
def session():
    """Keyframe requests and snapshots of a short simulated trot (RGB-D, 160x120; sharp depth: these tests are of
    the wire format, and the D455 model's stereo at 848x480 would be most of their time)."""
    spec = SequenceSpec(scenario="trot", duration_s=1.5, seed=0, width=160, height=120, event_scale=0.25,
                        depth="sharp")
    cfg = load_config("synthetic", overrides={"mode": "rgbd"})
    rig = sequence_rig(spec)
    ports: list[_Recording] = []

    def port(mapper):
        ports.append(_Recording(mapper))
        return ports[-1]

    odo = Odometry(cfg, rig.rgb_camera, mapping=port)
    for item in make_simulation(spec).frames():  # RGB-D only: the events are not simulated
        odo.process_frame(RgbdFrame(item.stamp_ns, item.rgb, item.depth_m))
    assert len(ports[0].log) >= 3, "the sequence should insert several keyframes"
    return cfg, odo, ports[0].log


def _assert_snapshots_equal(a: MapSnapshot, b: MapSnapshot) -> None:
    assert a.snapshot_id == b.snapshot_id and a.n_reference == b.n_reference
    assert a.healthy_reference == b.healthy_reference
    for name in ("points_w", "patches", "host_depth", "host", "geo_points_w"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert len(a.keyframes) == len(b.keyframes)
    for ka, kb in zip(a.keyframes, b.keyframes):
        assert (ka.kf_id, ka.stamp_ns, ka.affine) == (kb.kf_id, kb.stamp_ns, kb.affine)
        assert ka.T_w_c.tobytes() == kb.T_w_c.tobytes()


def test_snapshots_round_trip_bit_for_bit(session):
    _, _, log = session
    for _, snap in log:
        got = decode_map_snapshot(encode_map_snapshot("s1", 7, snap, 12))
        assert (got.session, got.seq, got.n_keyframes) == ("s1", 7, 12)
        _assert_snapshots_equal(got.snapshot, snap)
        assert not got.snapshot.points_w.flags.writeable  # frozen like every snapshot


def test_a_mapper_fed_decoded_requests_builds_the_same_snapshots(session):
    """What a mapping process does: decode each request, insert it; every snapshot equals the in-process one."""
    cfg, odo, log = session
    camera = PinholeLevels(odo.camera.width, odo.camera.height, odo.camera.fx, odo.camera.fy, odo.camera.cx,
                           odo.camera.cy, odo.n_levels)
    remote = None
    for k, (req, snap) in enumerate(log):
        wire = decode_keyframe_request(encode_keyframe_request("sess", k, req, camera, "abc"))
        assert (wire.session, wire.seq, wire.camera, wire.config_digest) == ("sess", k, camera, "abc")
        r = wire.request
        assert r.frame.grey.tobytes() == req.frame.grey.tobytes()
        assert all(x.tobytes() == y.tobytes() for x, y in zip(r.frame.pyramid, req.frame.pyramid))
        assert r.frame.depth_m.tobytes() == req.frame.depth_m.tobytes() and r.reset == req.reset
        assert r.outlier_runs.tobytes() == np.asarray(req.outlier_runs).tobytes()
        if remote is None:
            remote = Mapper(cfg, camera.cameras())
        _assert_snapshots_equal(remote.insert(r), snap)


def test_rolling_shutter_and_affine_travel_exactly(session):
    _, odo, log = session
    req = log[1][0]
    rs = RollingShutter(-0.0123456789, 3.3e-5, np.eye(4) + 1e-9, 1 / 30)
    req = dataclasses.replace(req, rolling_shutter=rs, affine=(0.1 + 0.2, -1 / 3))
    cam = PinholeLevels(odo.camera.width, odo.camera.height, 1.0, 2.0, 3.0, 4.0, odo.n_levels)
    got = decode_keyframe_request(encode_keyframe_request("x", 1, req, cam)).request
    assert got.affine == (0.1 + 0.2, -1 / 3)
    assert (got.rolling_shutter.t0_s, got.rolling_shutter.line_s, got.rolling_shutter.dt_s) == (rs.t0_s, rs.line_s,
                                                                                                 rs.dt_s)
    assert got.rolling_shutter.T_prev_c_w.tobytes() == rs.T_prev_c_w.tobytes()
    assert got.T_c_w.tobytes() == np.asarray(req.T_c_w, dtype=np.float64).tobytes()


@pytest.mark.parametrize("geometry_only, refine, keep_memory",
                         [(True, False, False), (False, False, False), (False, True, False), (False, True, True)])
def test_what_mapping_is_asked_to_do_with_a_keyframe_travels(session, geometry_only, refine, keep_memory):
    _, odo, log = session
    req = dataclasses.replace(log[1][0], geometry_only=geometry_only, refine=refine, keep_memory=keep_memory)
    cam = PinholeLevels(odo.camera.width, odo.camera.height, 1.0, 2.0, 3.0, 4.0, odo.n_levels)
    got = decode_keyframe_request(encode_keyframe_request("x", 1, req, cam)).request
    assert (got.geometry_only, got.refine, got.keep_memory) == (geometry_only, refine, keep_memory)


def test_bad_bytes_raise_wire_errors_that_say_what(session):
    _, _, log = session
    good = encode_map_snapshot("s", 1, log[0][1], 1)
    with pytest.raises(WireError, match="too short"):
        decode_map_snapshot(good[:5])
    with pytest.raises(WireError, match="not an atsvo wire message"):
        decode_map_snapshot(b"XXXX" + good[4:])
    with pytest.raises(WireError, match="version 9"):
        decode_map_snapshot(good[:4] + struct.pack("<H", 9) + good[6:])
    with pytest.raises(WireError, match="expected a keyframe request, got a map snapshot"):
        decode_keyframe_request(good)
    with pytest.raises(WireError, match="runs past the end"):
        decode_map_snapshot(good[:-64])
    (hlen,) = struct.unpack_from("<I", good, 8)
    with pytest.raises(WireError, match="unreadable header"):
        decode_map_snapshot(good[:12] + b"{" * hlen + good[12 + hlen:])
    # every truncation fails cleanly (WireError only)
    for n in range(0, len(good), max(1, len(good) // 97)):
        with pytest.raises(WireError):
            decode_map_snapshot(good[:n])


def test_uint8_multiarray_cdr_matches_the_ros_serializer_both_ways():
    from atsvo_ros.io.msgtypes import typestore

    store = typestore(2)
    U8 = store.types["std_msgs/msg/UInt8MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    Dim = store.types["std_msgs/msg/MultiArrayDimension"]
    payload = bytes(range(256)) * 3 + b"xyz"
    ours = uint8_multiarray_cdr(payload)
    ref = store.serialize_cdr(U8(layout=Layout(dim=[], data_offset=0), data=np.frombuffer(payload, np.uint8)),
                              U8.__msgtype__)
    assert bytes(ref) == ours
    assert bytes(uint8_multiarray_payload(ours)) == payload
    # a message with a labelled dimension (another publisher's layout) is read too
    other = store.serialize_cdr(U8(layout=Layout(dim=[Dim(label="abc", size=5, stride=5)], data_offset=0),
                                   data=np.frombuffer(b"hello", np.uint8)), U8.__msgtype__)
    assert bytes(uint8_multiarray_payload(other)) == b"hello"
    with pytest.raises(WireError, match="truncated|follow"):
        uint8_multiarray_payload(ours[:-1])
