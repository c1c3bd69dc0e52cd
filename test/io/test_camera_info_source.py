"""A bag whose camera_info holds NaN (reproduction r08 in ../shared/repro): the replay stops before the run
with one line naming the topic and the entry, not later blaming the depth or the focal length."""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.errors import CalibrationError
from atsvo_ros.io.msgtypes import register_event_types, typestore
from atsvo_ros.io.sources import open_source
from test.io.test_bags import TOPICS, write_bag


def _mutated_copy(src: Path, dst: Path, mutation: str) -> Path:
    """``src`` rewritten with its camera_info changed as r08's bag tool does (``info_nan_d``, ``info_nan_cx``)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    st = typestore(2)
    with AnyReader([src], default_typestore=st) as reader:
        register_event_types(reader.typestore, 2)
        with Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {}
            for c, t, raw in reader.messages():
                msg = reader.deserialize(raw, c.msgtype)
                if c.topic == TOPICS["rgb_info"]:
                    msg = copy.copy(msg)
                    if mutation == "info_nan_d":
                        msg.d = np.array([np.nan, 0, 0, 0, 0], np.float64)
                    else:
                        k = np.array(msg.k, np.float64)
                        k[2] = np.nan
                        msg.k = k
                if c.topic not in conns:
                    conns[c.topic] = writer.add_connection(c.topic, c.msgtype, typestore=st)
                writer.write(conns[c.topic], t, st.serialize_cdr(msg, c.msgtype))
    return dst


@pytest.mark.parametrize("mutation, message", [
    ("info_nan_d", "camera_info on /camera/camera/color/camera_info: D has non-finite values (D[0]=nan)"),
    ("info_nan_cx", "camera_info on /camera/camera/color/camera_info: K has non-finite values (cx=nan)"),
])
def test_nan_camera_info_names_topic_and_entry(tmp_path: Path, mutation, message):
    bag = _mutated_copy(write_bag(tmp_path / "good", "mcap", n_frames=3), tmp_path / mutation, mutation)
    cfg = load_config("mini_cheetah")
    source = open_source([bag], None, cfg)
    try:
        with pytest.raises(CalibrationError) as info:
            source.setup(cfg, [])
    finally:
        source.close()
    assert str(info.value) == message


def test_good_camera_info_still_gives_its_intrinsics(tmp_path: Path):
    bag = write_bag(tmp_path / "good", "mcap", n_frames=3)
    cfg = load_config("mini_cheetah")
    source = open_source([bag], None, cfg)
    try:
        notes: list[str] = []
        _, rgb_cam, _ = source.setup(cfg, notes)
    finally:
        source.close()
    assert (rgb_cam.width, rgb_cam.fx, rgb_cam.cx) == (32, 20.0, 16.0)
    assert "colour intrinsics from camera_info" in notes
