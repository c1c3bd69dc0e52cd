"""Image conversion with rosbags' real sensor_msgs classes (ROS 1 and ROS 2 stores)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from atsvo_ros.errors import ImageError
from atsvo_ros.io.images import (
    camera_from_info,
    colour_from_msg,
    depth_from_msg,
    depth_to_metres,
    image_to_numpy,
    stamp_ns,
)
from atsvo_ros.io.msgtypes import typestore


def _image(ros: int, arr: np.ndarray, encoding: str, pad: int = 0, bigendian: bool = False):
    ts = typestore(ros)
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    header = Header(seq=0, stamp=Time(sec=12, nanosec=345), frame_id="cam") if ros == 1 else \
        Header(stamp=Time(sec=12, nanosec=345), frame_id="cam")
    a = arr.astype(arr.dtype.newbyteorder(">" if bigendian else "<"))
    h = a.shape[0]
    rows = a.reshape(h, -1).view(np.uint8)
    step = rows.shape[1] + pad
    data = np.zeros((h, step), np.uint8)
    data[:, :rows.shape[1]] = rows
    return ts.types["sensor_msgs/msg/Image"](header=header, height=h, width=arr.shape[1], encoding=encoding,
                                             is_bigendian=bigendian, step=step, data=data.reshape(-1))


@pytest.mark.parametrize("ros", [1, 2])
def test_colour_encodings(ros):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 255, (5, 7, 3), dtype=np.uint8)
    assert np.array_equal(colour_from_msg(_image(ros, rgb, "rgb8", pad=3)), rgb)
    assert np.array_equal(colour_from_msg(_image(ros, rgb[..., ::-1].copy(), "bgr8")), rgb)
    grey = rgb[..., 0].copy()
    assert np.array_equal(colour_from_msg(_image(ros, grey, "mono8", pad=1)), grey)
    g16 = grey.astype(np.uint16) * 256 + 7
    assert np.array_equal(colour_from_msg(_image(ros, g16, "mono16")), grey)
    assert stamp_ns(_image(ros, grey, "mono8")) == 12_000_000_345


@pytest.mark.parametrize("bigendian", [False, True])
def test_depth_16uc1_scaled_and_range_checked(bigendian):
    mm = np.array([[0, 250, 1000], [2500, 6000, 9000]], np.uint16)
    d = depth_from_msg(_image(2, mm, "16UC1", pad=2, bigendian=bigendian), 0.001, 0.3, 6.0)
    assert d.dtype == np.float32
    np.testing.assert_allclose(d, [[0, 0, 1.0], [2.5, 6.0, 0]], rtol=1e-6)


def test_depth_32fc1_metres_nan_invalid():
    m = np.array([[np.nan, 1.5], [np.inf, 0.1]], np.float32)
    d = depth_from_msg(_image(1, m, "32FC1"), 1.0, 0.3, 15.0)
    np.testing.assert_array_equal(d, [[0, 1.5], [0, 0]])
    assert np.array_equal(image_to_numpy(_image(2, m, "32FC1", bigendian=True))[0, 1:], [1.5])


def test_unknown_encoding_named():
    msg = _image(2, np.zeros((2, 2), np.uint8), "bayer_rggb8")
    with pytest.raises(ImageError, match="bayer_rggb8"):
        colour_from_msg(msg)
    with pytest.raises(ImageError, match="not a depth"):
        depth_from_msg(_image(2, np.zeros((2, 2, 3), np.uint8), "rgb8"))


def test_truncated_data_is_an_error():
    msg = _image(2, np.zeros((4, 4), np.uint8), "mono8")
    msg.data = msg.data[:5]
    with pytest.raises(ImageError, match="bytes"):
        image_to_numpy(msg)


def test_compressed_png_and_jpeg():
    ts = typestore(2)
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    rgb = np.zeros((8, 8, 3), np.uint8)
    rgb[..., 0] = 200
    ok, png = cv2.imencode(".png", rgb[..., ::-1])
    msg = ts.types["sensor_msgs/msg/CompressedImage"](header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""),
                                                      format="rgb8; png compressed bgr8", data=png.reshape(-1))
    assert np.array_equal(colour_from_msg(msg), rgb)
    msg.data = np.frombuffer(b"garbage", np.uint8)
    with pytest.raises(ImageError, match="cannot decode"):
        colour_from_msg(msg)


def test_depth_to_metres_rejects_colour():
    with pytest.raises(ImageError):
        depth_to_metres(np.zeros((2, 2, 3)), 1.0, 0.1, 5.0)


@pytest.mark.parametrize("ros", [1, 2])
def test_camera_info(ros):
    ts = typestore(ros)
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    hdr = Header(seq=0, stamp=Time(sec=0, nanosec=0), frame_id="c") if ros == 1 else \
        Header(stamp=Time(sec=0, nanosec=0), frame_id="c")
    K = np.array([300.0, 0, 160, 0, 301, 120, 0, 0, 1])
    names = ("D", "K", "R", "P") if ros == 1 else ("d", "k", "r", "p")
    Roi = ts.types["sensor_msgs/msg/RegionOfInterest"]
    info = ts.types["sensor_msgs/msg/CameraInfo"](
        header=hdr, height=240, width=320, distortion_model="plumb_bob", binning_x=0, binning_y=0,
        roi=Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        **dict(zip(names, (np.array([0.1, 0.0, 0, 0, 0]), K, np.eye(3).reshape(-1), np.zeros(12)))))
    cam = camera_from_info(info)
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (320, 240, 300.0, 301.0, 160.0, 120.0)


@pytest.mark.parametrize("scale,lo,hi", [(0.001, 0.0, np.inf), (0.0002, 0.3, 6.0), (1 / 5000, 0.1, 4.0),
                                         (0.001, 1.0, 1.0)])
def test_uint16_depth_table_equals_the_general_path(scale, lo, hi):
    """The uint16 look-up table gives the float64 range check and float32 values of the general path, bit for bit
    (every value, including the limits themselves, zero and 65535)."""
    every = np.arange(65536, dtype=np.uint16).reshape(256, 256)
    fast = depth_to_metres(every, scale, lo, hi)
    general = depth_to_metres(every.astype(np.int32), scale, lo, hi)
    assert fast.dtype == np.float32 and fast.shape == every.shape
    np.testing.assert_array_equal(fast.view(np.uint32), general.view(np.uint32))
    fast[0, 0] = 7.0  # the caller owns its image: the shared table is not written through it
    assert depth_to_metres(every, scale, lo, hi)[0, 0] == 0.0
