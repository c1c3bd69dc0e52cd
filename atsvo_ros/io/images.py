"""Image / CompressedImage / CameraInfo messages -> numpy (duck-typed: rclpy or rosbags classes).

Supported raw encodings: rgb8, bgr8, rgba8, bgra8, mono8, mono16, 16UC1, 32FC1 (``step`` padding
and ``is_bigendian`` honoured). Anything else raises :class:`ImageError` naming the encoding.
Colour output is RGB uint8 (or grey uint8 for mono); depth output is float32 metres with invalid
pixels (0, NaN, outside the valid range) set to 0.
"""
from __future__ import annotations

import functools
from typing import Any

import cv2
import numpy as np

from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import ImageError
from atsvo_ros.io.ros_out import time_to_ns

#: encoding -> (numpy dtype, channels)
ENCODINGS: dict[str, tuple[str, int]] = {
    "rgb8": ("u1", 3), "bgr8": ("u1", 3), "rgba8": ("u1", 4), "bgra8": ("u1", 4),
    "mono8": ("u1", 1), "8UC1": ("u1", 1), "mono16": ("u2", 1), "16UC1": ("u2", 1), "32FC1": ("f4", 1),
}
COLOUR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8UC1", "mono16")
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


def _encoding(msg: Any) -> str:
    enc = str(getattr(msg, "encoding", "") or "")
    if enc not in ENCODINGS:
        raise ImageError(f"unsupported image encoding {enc!r} (supported: {', '.join(ENCODINGS)})")
    return enc


def image_to_numpy(msg: Any) -> np.ndarray:
    """The pixel array of a sensor_msgs/Image: (H, W) or (H, W, C), native byte order, no copy if possible."""
    enc = _encoding(msg)
    kind, channels = ENCODINGS[enc]
    h, w = int(msg.height), int(msg.width)
    dtype = np.dtype(kind).newbyteorder(">" if getattr(msg, "is_bigendian", False) else "<")
    row_bytes = w * channels * dtype.itemsize
    step = int(getattr(msg, "step", 0) or row_bytes)
    data = msg.data
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.view(np.uint8)
    if h <= 0 or w <= 0:
        raise ImageError(f"image has an empty size {w}x{h}")
    if step < row_bytes or len(buf) < step * (h - 1) + row_bytes:
        raise ImageError(f"{enc} image {w}x{h} needs {row_bytes} bytes per row and {step * h} bytes, "
                         f"got step {step} and {len(buf)} bytes")
    rows = np.lib.stride_tricks.as_strided(buf, shape=(h, row_bytes), strides=(step, 1))
    arr = np.ascontiguousarray(rows).view(dtype).reshape((h, w, channels) if channels > 1 else (h, w))
    if dtype.byteorder == ">":
        arr = arr.astype(dtype.newbyteorder("="))
    return arr


def compressed_to_numpy(msg: Any) -> np.ndarray:
    """Decode a sensor_msgs/CompressedImage (jpeg/png; ``compressedDepth`` png) with OpenCV.

    Colour images come back as RGB, 16-bit depth as uint16, 32-bit compressedDepth is not supported.
    """

    fmt = str(getattr(msg, "format", "") or "").lower()
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8) if not isinstance(msg.data, np.ndarray) else msg.data
    if "compresseddepth" in fmt:
        if "32fc1" in fmt:
            raise ImageError(f"compressedDepth with 32FC1 (quantised inverse depth) is not supported: {fmt!r}")
        data = data[12:]  # ConfigHeader of compressed_depth_image_transport
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"cannot decode compressed image (format {fmt!r}, {len(data)} bytes)")
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return img


def is_compressed(msg: Any) -> bool:
    """True for sensor_msgs/CompressedImage-shaped messages."""
    return hasattr(msg, "format") and not hasattr(msg, "encoding")


def colour_from_msg(msg: Any) -> np.ndarray:
    """RGB (H, W, 3) uint8 or grey (H, W) uint8 from an Image or CompressedImage."""
    if is_compressed(msg):
        img = compressed_to_numpy(msg)
        return (img >> 8).astype(np.uint8) if img.dtype == np.uint16 else img
    enc = _encoding(msg)
    if enc not in COLOUR_ENCODINGS:
        raise ImageError(f"encoding {enc!r} is not a colour/grey image (expected one of {', '.join(COLOUR_ENCODINGS)})")
    arr = image_to_numpy(msg)
    if enc == "rgb8":
        return arr
    if enc == "bgr8":
        return np.ascontiguousarray(arr[..., ::-1])
    if enc == "rgba8":
        return np.ascontiguousarray(arr[..., :3])
    if enc == "bgra8":
        return np.ascontiguousarray(arr[..., 2::-1])
    if enc == "mono16":
        return (arr >> 8).astype(np.uint8)
    return arr


def depth_to_metres(raw: np.ndarray, depth_scale_m: float, depth_min_m: float, depth_max_m: float) -> np.ndarray:
    """float32 metres from a uint16 (scaled by ``depth_scale_m``) or float (metres) depth array.

    Zero, NaN, inf and values outside ``[depth_min_m, depth_max_m]`` become 0 (invalid). uint16 goes
    through a 65,536-entry table (one gather instead of four passes over the image; same values).
    """
    raw = np.asarray(raw)
    if raw.ndim != 2:
        raise ImageError(f"depth image must be single channel, got shape {raw.shape}")
    if raw.dtype == np.uint16:
        return _depth_table(float(depth_scale_m), float(depth_min_m), float(depth_max_m))[raw]
    if raw.dtype.kind in "ui":
        depth = raw * float(depth_scale_m)  # float64: the range check is exact at the limits
    elif raw.dtype.kind == "f":
        depth = raw.astype(np.float64)
    else:
        raise ImageError(f"depth image has unsupported dtype {raw.dtype}")
    bad = ~np.isfinite(depth) | (depth < depth_min_m) | (depth > depth_max_m)
    depth[bad] = 0.0
    return depth.astype(np.float32)


@functools.lru_cache(maxsize=8)
def _depth_table(depth_scale_m: float, depth_min_m: float, depth_max_m: float) -> np.ndarray:
    """float32 metres of every uint16 value (the general path of :func:`depth_to_metres` on all of them)."""
    table = depth_to_metres(np.arange(65536, dtype=np.int32).reshape(1, -1), depth_scale_m, depth_min_m,
                            depth_max_m)[0]
    table.flags.writeable = False
    return table


def depth_from_msg(msg: Any, depth_scale_m: float = 0.001, depth_min_m: float = 0.0,
                   depth_max_m: float = np.inf) -> np.ndarray:
    """Depth in float32 metres from an Image (16UC1/mono16 scaled by ``depth_scale_m``, 32FC1 metres)."""
    if is_compressed(msg):
        return depth_to_metres(compressed_to_numpy(msg), depth_scale_m, depth_min_m, depth_max_m)
    enc = _encoding(msg)
    if enc not in DEPTH_ENCODINGS:
        raise ImageError(f"encoding {enc!r} is not a depth image (expected one of {', '.join(DEPTH_ENCODINGS)})")
    return depth_to_metres(image_to_numpy(msg), depth_scale_m, depth_min_m, depth_max_m)


def camera_from_info(msg: Any):
    """:class:`~atsvo_ros.core.camera.CameraModel` from a sensor_msgs/CameraInfo."""

    return CameraModel.from_camera_info(msg)


def stamp_ns(msg: Any) -> int:
    """Header stamp in int64 nanoseconds (ROS 2 ``sec/nanosec`` or ROS 1 ``secs/nsecs``)."""

    return time_to_ns(msg.header.stamp)


__all__ = ["COLOUR_ENCODINGS", "DEPTH_ENCODINGS", "ENCODINGS", "camera_from_info", "colour_from_msg",
           "compressed_to_numpy", "depth_from_msg", "depth_to_metres", "image_to_numpy", "is_compressed",
           "stamp_ns"]
