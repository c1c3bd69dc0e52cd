"""The atsvo wire format: keyframe requests and map snapshots as bytes, between tracking and mapping processes.

Pure numpy (no ROS): the nodes carry these bytes in a ``std_msgs/UInt8MultiArray`` whose CDR they
write and parse here too (:func:`uint8_multiarray_cdr`, :func:`uint8_multiarray_payload`), so
neither side converts megabytes through Python message objects. Every array travels bit for bit, so
a mapper in another process builds exactly the snapshot an in-process one would.

Layout of one message (all integers little-endian)::

    0   4 bytes  magic b"ATSW"
    4   u16      format version (1)
    6   u16      kind (1 keyframe request, 2 map snapshot)
    8   u32      header length H
    12  H bytes  UTF-8 JSON header: {"fields": {...}, "arrays": [{"name", "dtype", "shape", "offset"}]}
        padding to a multiple of 16
    D   arrays, each at D + offset, offsets multiples of 16, dtypes explicit ("<f4", "<f8", "<i4", "<i8", "|u1")

Scalars (stamps, ids, affine parameters, the camera, flags) are JSON fields: Python writes floats with
the shortest representation that reads back to the same double, so they round-trip exactly too.

A keyframe request carries the frame's rectified level-0 intensity and its depth, not the pyramid:
the receiver rebuilds the pyramid with the same code (identical arrays, a third of the bytes). The
rebuilt frame has no depth pyramid, which the mapper does not read.
"""
from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.image.frontend import PreparedFrame
from atsvo_ros.core.image.pyramid import build_pyramid, image_pyramid_with_gradients, pyramid_cameras
from atsvo_ros.core.mapping.map import Keyframe, MapSnapshot
from atsvo_ros.core.mapping.mapper import KeyframeRequest
from atsvo_ros.core.rolling_shutter import RollingShutter
from atsvo_ros.errors import WireError

MAGIC = b"ATSW"
VERSION = 1
KIND_KEYFRAME_REQUEST = 1
KIND_MAP_SNAPSHOT = 2
_KIND_NAMES = {KIND_KEYFRAME_REQUEST: "keyframe request", KIND_MAP_SNAPSHOT: "map snapshot"}
_PREFIX = struct.Struct("<4sHHI")
_ALIGN = 16
_DTYPES = {"<f4", "<f8", "<i4", "<i8", "|u1", "|b1"}


def _pad(n: int) -> int:
    return (-n) % _ALIGN


def _encode(kind: int, fields: dict[str, Any], arrays: dict[str, np.ndarray]) -> bytes:
    descs, chunks, offset = [], [], 0
    for name, arr in arrays.items():
        a = np.asarray(arr)
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder not in ("|", "<", "=") else a.dtype
        a = np.ascontiguousarray(a, dtype=dt)
        if a.dtype.str not in _DTYPES:
            raise WireError(f"array {name} has dtype {a.dtype.str}, which the wire format does not carry")
        raw = a.tobytes()
        descs.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset})
        chunks.append(raw + b"\0" * _pad(len(raw)))
        offset += len(raw) + _pad(len(raw))
    header = json.dumps({"fields": fields, "arrays": descs}, separators=(",", ":"), allow_nan=True).encode()
    head = _PREFIX.pack(MAGIC, VERSION, kind, len(header)) + header
    return b"".join([head, b"\0" * _pad(len(head)), *chunks])


def _decode(data: bytes | bytearray | memoryview, kind: int) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    buf = memoryview(data).cast("B")
    what = _KIND_NAMES[kind]
    if len(buf) < _PREFIX.size:
        raise WireError(f"{what}: {len(buf)} bytes is too short for the atsvo wire format")
    magic, version, got_kind, hlen = _PREFIX.unpack_from(buf, 0)
    if magic != MAGIC:
        raise WireError(f"{what}: not an atsvo wire message (magic {bytes(magic)!r})")
    if version != VERSION:
        raise WireError(f"{what}: wire format version {version}, this build reads version {VERSION} "
                        "(run the same atsvo_ros version in both processes)")
    if got_kind != kind:
        raise WireError(f"expected a {what}, got a {_KIND_NAMES.get(got_kind, f'message of kind {got_kind}')}")
    start = _PREFIX.size
    if start + hlen > len(buf):
        raise WireError(f"{what}: header of {hlen} bytes runs past the end of the {len(buf)}-byte message")
    try:
        header = json.loads(bytes(buf[start:start + hlen]).decode("utf-8"))
        fields, descs = header["fields"], header["arrays"]
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise WireError(f"{what}: unreadable header ({exc})") from None
    base = start + hlen + _pad(start + hlen)
    arrays: dict[str, np.ndarray] = {}
    for d in descs:
        try:
            name, dtype, shape, offset = str(d["name"]), str(d["dtype"]), tuple(int(n) for n in d["shape"]), \
                int(d["offset"])
        except (KeyError, TypeError, ValueError) as exc:
            raise WireError(f"{what}: bad array description {d!r} ({exc})") from None
        if dtype not in _DTYPES or any(n < 0 for n in shape) or offset < 0:
            raise WireError(f"{what}: array {name} has an unsupported dtype {dtype!r} or a negative size")
        count = int(np.prod(shape, dtype=np.int64)) if shape else 1
        nbytes = count * np.dtype(dtype).itemsize
        if base + offset + nbytes > len(buf):
            raise WireError(f"{what}: array {name} ({nbytes} bytes at {offset}) runs past the end of the message")
        # a copy: aligned, writeable, independent of the received buffer
        arrays[name] = np.frombuffer(buf, dtype=dtype, count=count, offset=base + offset).reshape(shape).copy()
    return fields, arrays


def _need(arrays: dict[str, np.ndarray], what: str, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    a = arrays.get(name)
    if a is None:
        raise WireError(f"{what}: array {name} is missing")
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        raise WireError(f"{what}: array {name} has shape {a.shape}, expected {shape}")
    return a


def _field(fields: dict[str, Any], what: str, name: str, typ: type | tuple[type, ...]) -> Any:
    if name not in fields:
        raise WireError(f"{what}: field {name} is missing")
    v = fields[name]
    if not isinstance(v, typ) or (typ in (int, float) and isinstance(v, bool)):
        raise WireError(f"{what}: field {name} = {v!r} has the wrong type")
    return v


def _optional(fields: dict[str, Any], what: str, name: str, default: bool) -> bool:
    return default if name not in fields else _field(fields, what, name, bool)


# ---------------------------------------------------------------------------- keyframe requests


@dataclass(frozen=True)
class PinholeLevels:
    """The colour camera as the mapper needs it: the level-0 pinhole model and the pyramid depth."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    n_levels: int

    def cameras(self) -> list:
        """The pyramid cameras, as the tracking side has them."""

        cam = CameraModel(self.width, self.height, self.fx, self.fy, self.cx, self.cy, "none", ())
        return pyramid_cameras(cam, self.n_levels)


@dataclass(frozen=True)
class WireRequest:
    """A keyframe request with its routing: which tracking session sent it, its sequence number and camera."""

    session: str
    seq: int
    request: KeyframeRequest
    camera: PinholeLevels
    config_digest: str = ""


def encode_keyframe_request(session: str, seq: int, request: KeyframeRequest, camera: PinholeLevels,
                            config_digest: str = "") -> bytes:
    """Bytes of a keyframe request (see the module docstring)."""
    rs = request.rolling_shutter
    fields = {"session": str(session), "seq": int(seq), "snapshot_id": int(request.snapshot_id),
              "stamp_ns": int(request.frame.stamp_ns), "affine": [float(request.affine[0]), float(request.affine[1])],
              "reset": bool(request.reset), "keep_memory": bool(request.keep_memory),
              "geometry_only": bool(request.geometry_only),
              "refine": bool(request.refine), "n_valid_depth": int(request.frame.n_valid_depth),
              "camera": {"width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy,
                         "cx": camera.cx, "cy": camera.cy, "n_levels": camera.n_levels},
              "rolling_shutter": None if rs is None else {"t0_s": float(rs.t0_s), "line_s": float(rs.line_s),
                                                          "dt_s": float(rs.dt_s)},
              "config_digest": str(config_digest)}
    arrays = {"grey": np.asarray(request.frame.grey, dtype=np.float32),
              "depth_m": np.asarray(request.frame.depth_m, dtype=np.float32),
              "T_c_w": np.asarray(request.T_c_w, dtype=np.float64),
              "tracked_uv": np.asarray(request.tracked_uv, dtype=np.float64).reshape(-1, 2),
              "outlier_runs": np.asarray(request.outlier_runs)}
    if arrays["outlier_runs"].dtype.kind not in "iu":
        raise WireError(f"outlier_runs must be integers, got {arrays['outlier_runs'].dtype}")
    arrays["outlier_runs"] = arrays["outlier_runs"].astype(np.int64 if arrays["outlier_runs"].dtype.itemsize > 4
                                                           else np.int32)
    if rs is not None:
        arrays["rs_T_prev_c_w"] = np.asarray(rs.T_prev_c_w, dtype=np.float64)
    return _encode(KIND_KEYFRAME_REQUEST, fields, arrays)


def decode_keyframe_request(data: bytes | bytearray | memoryview) -> WireRequest:
    """The request (with a frame whose pyramid is rebuilt from the intensity image) and its routing."""

    what = "keyframe request"
    fields, arrays = _decode(data, KIND_KEYFRAME_REQUEST)
    cam = _field(fields, what, "camera", dict)
    try:
        camera = PinholeLevels(int(cam["width"]), int(cam["height"]), float(cam["fx"]), float(cam["fy"]),
                               float(cam["cx"]), float(cam["cy"]), int(cam["n_levels"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise WireError(f"{what}: bad camera {cam!r} ({exc})") from None
    if camera.n_levels < 1 or camera.width < 1 or camera.height < 1:
        raise WireError(f"{what}: bad camera {cam!r}")
    hw = (camera.height, camera.width)
    grey = _need(arrays, what, "grey", hw)
    depth = _need(arrays, what, "depth_m", hw)
    T_c_w = _need(arrays, what, "T_c_w", (4, 4))
    tracked_uv = _need(arrays, what, "tracked_uv", (None, 2))
    runs = _need(arrays, what, "outlier_runs", (None,))
    affine = _field(fields, what, "affine", list)
    if len(affine) != 2:
        raise WireError(f"{what}: affine = {affine!r} must hold two numbers")
    rs_fields = fields.get("rolling_shutter")
    rs = None
    if rs_fields is not None:
        try:
            rs = RollingShutter(float(rs_fields["t0_s"]), float(rs_fields["line_s"]),
                                _need(arrays, what, "rs_T_prev_c_w", (4, 4)), float(rs_fields["dt_s"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise WireError(f"{what}: bad rolling_shutter {rs_fields!r} ({exc})") from None
    stamp = _field(fields, what, "stamp_ns", int)
    pyramid = image_pyramid_with_gradients(build_pyramid(grey, camera.n_levels))
    frame = PreparedFrame(stamp, pyramid, depth, [], _field(fields, what, "n_valid_depth", int))
    req = KeyframeRequest(_field(fields, what, "snapshot_id", int), frame, T_c_w,
                          (float(affine[0]), float(affine[1])), tracked_uv, runs,
                          reset=_field(fields, what, "reset", bool), rolling_shutter=rs,
                          # absent from an older sender: a full keyframe, refined (what it asked for then)
                          geometry_only=_optional(fields, what, "geometry_only", False),
                          refine=_optional(fields, what, "refine", True),
                          keep_memory=_optional(fields, what, "keep_memory", False))
    return WireRequest(_field(fields, what, "session", str), _field(fields, what, "seq", int), req, camera,
                       str(fields.get("config_digest", "")))


# ---------------------------------------------------------------------------- map snapshots


@dataclass(frozen=True)
class WireSnapshot:
    """A map snapshot with its routing: the session and request it answers, and the mapper's keyframe count."""

    session: str
    seq: int
    snapshot: MapSnapshot
    n_keyframes: int


def encode_map_snapshot(session: str, seq: int, snapshot: MapSnapshot, n_keyframes: int) -> bytes:
    """Bytes of a map snapshot answering request ``seq`` of ``session``."""
    kfs = snapshot.keyframes
    fields = {"session": str(session), "seq": int(seq), "snapshot_id": int(snapshot.snapshot_id),
              "n_reference": int(snapshot.n_reference), "healthy_reference": int(snapshot.healthy_reference),
              "n_keyframes": int(n_keyframes),
              "keyframes": [{"kf_id": int(k.kf_id), "stamp_ns": int(k.stamp_ns),
                             "affine": [float(k.affine[0]), float(k.affine[1])]} for k in kfs]}
    arrays = {"points_w": np.asarray(snapshot.points_w, dtype=np.float64).reshape(-1, 3),
              "patches": np.asarray(snapshot.patches, dtype=np.float32),
              "host_depth": np.asarray(snapshot.host_depth, dtype=np.float64),
              "host": np.asarray(snapshot.host, dtype=np.int32),
              "geo_points_w": np.asarray(snapshot.geo_points_w, dtype=np.float64).reshape(-1, 3),
              "kf_T_w_c": np.stack([np.asarray(k.T_w_c, dtype=np.float64) for k in kfs]) if kfs
              else np.zeros((0, 4, 4))}
    return _encode(KIND_MAP_SNAPSHOT, fields, arrays)


def decode_map_snapshot(data: bytes | bytearray | memoryview) -> WireSnapshot:
    """The snapshot (arrays frozen as :class:`MapSnapshot` keeps them) and its routing."""
    what = "map snapshot"
    fields, arrays = _decode(data, KIND_MAP_SNAPSHOT)
    points = _need(arrays, what, "points_w", (None, 3))
    n = len(points)
    patches = _need(arrays, what, "patches", (None, n, None))
    host_depth = _need(arrays, what, "host_depth", (n,))
    host = _need(arrays, what, "host", (n,))
    geo = _need(arrays, what, "geo_points_w", (None, 3))
    kf_fields = _field(fields, what, "keyframes", list)
    kf_T = _need(arrays, what, "kf_T_w_c", (len(kf_fields), 4, 4))
    try:
        kfs = tuple(Keyframe(int(k["kf_id"]), int(k["stamp_ns"]), kf_T[i],
                             (float(k["affine"][0]), float(k["affine"][1]))) for i, k in enumerate(kf_fields))
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise WireError(f"{what}: bad keyframe list ({exc})") from None
    snap = MapSnapshot(_field(fields, what, "snapshot_id", int), points, patches, host_depth, host, geo, kfs,
                       _field(fields, what, "n_reference", int), _field(fields, what, "healthy_reference", int))
    return WireSnapshot(_field(fields, what, "session", str), _field(fields, what, "seq", int), snap,
                        _field(fields, what, "n_keyframes", int))


# ---------------------------------------------------------------------------- std_msgs/UInt8MultiArray CDR

_CDR_LE = b"\x00\x01\x00\x00"


def uint8_multiarray_cdr(payload: bytes) -> bytes:
    """Serialized ROS 2 ``std_msgs/msg/UInt8MultiArray`` (little-endian CDR, no dimensions) carrying ``payload``.

    What ``rclpy.serialization.serialize_message`` makes of the same message; a publisher sends it
    with ``publish(bytes)``, no Python message object in between.
    """
    return b"".join([_CDR_LE, struct.pack("<III", 0, 0, len(payload)), payload])


def uint8_multiarray_payload(raw: bytes | bytearray | memoryview) -> memoryview:
    """The ``data`` of a serialized ``std_msgs/msg/UInt8MultiArray`` (any layout), as a view of ``raw``."""
    buf = memoryview(raw).cast("B")
    if len(buf) < 16 or bytes(buf[0:2]) not in (b"\x00\x01", b"\x00\x00"):
        raise WireError("not a serialized UInt8MultiArray (too short or an unknown CDR representation)")
    order = "<" if buf[1] == 1 else ">"
    pos = 4

    def u32() -> int:
        nonlocal pos
        pos += (-(pos - 4)) % 4
        if pos + 4 > len(buf):
            raise WireError("serialized UInt8MultiArray is truncated")
        (v,) = struct.unpack_from(order + "I", buf, pos)
        pos += 4
        return v

    for _ in range(u32()):  # layout.dim[]: label (string), size, stride
        n = u32()
        pos += n
        u32()
        u32()
    u32()  # layout.data_offset
    n = u32()
    if pos + n > len(buf):
        raise WireError(f"serialized UInt8MultiArray says {n} data bytes but only {len(buf) - pos} follow")
    return buf[pos:pos + n]


__all__ = ["PinholeLevels", "WireRequest", "WireSnapshot", "decode_keyframe_request",
           "decode_map_snapshot", "encode_keyframe_request", "encode_map_snapshot", "uint8_multiarray_cdr",
           "uint8_multiarray_payload"]
