"""Unusable poses and text: NaN / zero-quaternion poses named by topic, frames and stamp; TUM lines
named by file:line; non-UTF-8 trajectory, config and metadata files as one-line errors."""
from __future__ import annotations

import math

import numpy as np
import pytest

from atsvo_ros.errors import ConfigError, TrajectoryError, TransformError
from atsvo_ros.io.bags import StaticTf, pose_from_msg
from atsvo_ros.io.msgtypes import typestore
from atsvo_ros.io.trajectory import read_tum

NAN = float("nan")


def _ts():
    return typestore(2)


def _header(stamp_ns: int, frame: str):
    ts = _ts()
    t = ts.types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return ts.types["std_msgs/msg/Header"](stamp=t, frame_id=frame)


def _transform(parent: str, child: str, t, q, stamp_ns: int = 1_700_000_000_250_000_000):
    ts = _ts()
    V3, Q = ts.types["geometry_msgs/msg/Vector3"], ts.types["geometry_msgs/msg/Quaternion"]
    tr = ts.types["geometry_msgs/msg/Transform"](translation=V3(x=t[0], y=t[1], z=t[2]),
                                                 rotation=Q(x=q[0], y=q[1], z=q[2], w=q[3]))
    return ts.types["geometry_msgs/msg/TransformStamped"](header=_header(stamp_ns, parent), child_frame_id=child,
                                                          transform=tr)


def _pose_stamped(t, q, stamp_ns: int = 1_700_000_000_500_000_000, frame: str = "world"):
    ts = _ts()
    P, Pt, Q = (ts.types[f"geometry_msgs/msg/{n}"] for n in ("Pose", "Point", "Quaternion"))
    pose = P(position=Pt(x=t[0], y=t[1], z=t[2]), orientation=Q(x=q[0], y=q[1], z=q[2], w=q[3]))
    return ts.types["geometry_msgs/msg/PoseStamped"](header=_header(stamp_ns, frame), pose=pose)


@pytest.mark.parametrize("t,q,problem", [
    ((0.0, NAN, 0.0), (0, 0, 0, 1.0), "translation is not finite"),
    ((0.0, 0.0, 0.0), (0, 0, NAN, 1.0), "quaternion (x, y, z, w) is not finite"),
    ((0.0, 0.0, 0.0), (0, 0, 0, 0.0), "zero norm"),
    ((math.inf, 0.0, 0.0), (0, 0, 0, 1.0), "translation is not finite"),
])
def test_ground_truth_pose_rejected_with_topic_frame_and_stamp(t, q, problem):
    with pytest.raises(TransformError) as info:
        pose_from_msg(_pose_stamped(t, q), "/ground_truth/pose")
    e = info.value
    assert problem in str(e) and "/ground_truth/pose" in str(e) and "world" in str(e)
    assert "1700000000.500000000 s" in str(e)
    assert (e.topic, e.parent, e.stamp_ns) == ("/ground_truth/pose", "world", 1_700_000_000_500_000_000)


def test_non_unit_quaternion_is_normalised():
    T = pose_from_msg(_pose_stamped((1.0, 2.0, 3.0), (0, 0, 0, 2.0)))
    np.testing.assert_allclose(T, np.array([[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1.0]]))


def test_tf_static_nan_is_rejected_when_read_naming_frames():
    ts = _ts()
    good = _transform("base_link", "camera_link", (0.2, 0, 0.08), (0, 0, 0, 1.0))
    bad = _transform("camera_link", "dvxplorer", (0.0, NAN, 0.0), (0, 0, 0, 1.0))
    msg = ts.types["tf2_msgs/msg/TFMessage"](transforms=[good, bad])
    tf = StaticTf()
    with pytest.raises(TransformError) as info:
        tf.add(msg)
    e = info.value
    assert "/tf_static" in str(e) and "camera_link -> dvxplorer" in str(e) and "translation is not finite" in str(e)
    assert (e.parent, e.child, e.stamp_ns) == ("camera_link", "dvxplorer", 1_700_000_000_250_000_000)
    # the good transform was kept; the bad one is not in the tree (so nothing NaN can come out later)
    assert tf.lookup("base_link", "camera_link") is not None
    assert tf.lookup("base_link", "dvxplorer") is None


@pytest.mark.parametrize("line,problem", [
    ("1.0 0 nan 0 0 0 0 1", "ty not finite"),
    ("1.0 0 0 0 0 0 0 0", "zero norm"),
    ("1.0 0 0 0 inf 0 0 1", "qx not finite"),
    ("1e400 0 0 0 0 0 0 1", "not finite"),
    ("99999999999999999999 0 0 0 0 0 0 1", "int64"),
    ("nan 0 0 0 0 0 0 1", "not a number"),
    ("1.0.0 0 0 0 0 0 0 1", "not a number"),
])
def test_tum_bad_line_named_by_file_and_line(tmp_path, line, problem):
    path = tmp_path / "gt.txt"
    path.write_text("# t tx ty tz qx qy qz qw\n0.5 0 0 0 0 0 0 1\n" + line + "\n")
    with pytest.raises(TrajectoryError) as info:
        read_tum(path)
    assert f"{path}:3" in str(info.value) and problem in str(info.value)


def test_tum_not_utf8(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_bytes(b"0.5 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 \xff\xfe 1\n")
    with pytest.raises(TrajectoryError, match=r"gt.txt:2: not UTF-8 text \(byte 0xff"):
        read_tum(path)


def test_eval_and_replay_cli_non_utf8_one_line(tmp_path, capsys):
    from atsvo_ros.tools.eval import main as eval_main

    ok = tmp_path / "ok.txt"
    ok.write_text("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")
    bad = tmp_path / "latin1.txt"
    bad.write_bytes("# r\xe9f\xe9rence\n1.0 0 0 0 0 0 0 1\n".encode("latin-1"))
    assert eval_main([str(bad), str(ok)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "latin1.txt:1" in err and "UTF-8" in err


def test_config_not_utf8_one_line(tmp_path, capsys):
    from atsvo_ros.config import load_config
    from atsvo_ros.tools.events import main as events_main

    path = tmp_path / "cfg.yaml"
    path.write_bytes(b"/**:\n  ros__parameters:\n    # caf\xe9\n    mode: rgbd\n")
    with pytest.raises(ConfigError, match=r"cfg.yaml:3: not UTF-8 text \(byte 0xe9"):
        load_config(path)
    assert events_main(["render", str(tmp_path / "x.aedat4"), "--out", str(tmp_path), "--config", str(path)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cfg.yaml" in err


def test_bag_metadata_not_utf8(realdata, tmp_path):
    from atsvo_ros.errors import BagError
    from atsvo_ros.io.event_files import open_events

    src = realdata / "event_camera_py_bags" / "test_events_2"
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "test_events_2_0.mcap").write_bytes((src / "test_events_2_0.mcap").read_bytes())
    (bag / "metadata.yaml").write_bytes((src / "metadata.yaml").read_bytes() + b"# \xff\n")
    with pytest.raises(BagError, match="metadata.yaml: not UTF-8"):
        open_events(bag)


def test_config_value_error_names_the_file(tmp_path):
    from atsvo_ros.config import load_config

    path = tmp_path / "cfg.yaml"
    path.write_text("/**:\n  ros__parameters:\n    ats:\n      tau_u_s: fast\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(path) in str(info.value) and "tau_u_s" in str(info.value)
