"""The bag player loops a recording with time running on: every pass later by the recording's length."""
from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="rclpy is not installed (pip install -e '.[ros]'; docs/ros_env.md)")
pytest.importorskip("event_camera_msgs.msg", reason="event_camera_msgs not built: source .ci/ros_env.sh")

from atsvo_ros.config import load_config
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.msgtypes import typestore
from atsvo_ros.nodes.player import BagPlayer


class _Recorder:
    """Stands in for an rclpy node: its publishers keep what they are given."""

    def __init__(self) -> None:
        self.sent: dict[str, list[bytes]] = defaultdict(list)

    def create_publisher(self, _cls, topic, _qos):
        sent = self.sent[topic]

        class _Pub:
            def publish(self, raw):
                sent.append(raw)

        return _Pub()


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    from atsvo_ros.tools.sim import main as sim_main

    out = tmp_path_factory.mktemp("player") / "trot"
    assert sim_main(["--scenario", "trot", "--duration", "0.5", "--seed", "1", "--width", "80", "--height", "60",
                     "--event-scale", "0.25", "--quiet", "--out", str(out)]) == 0
    return out


def _stamps(raws: list[bytes], msgtype: str) -> np.ndarray:
    store = typestore()
    return np.array([(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
                     for m in (store.deserialize_cdr(r, msgtype) for r in raws)], np.int64)


def test_repeat_moves_every_pass_on_by_the_recording_length(bag):
    t = load_config("synthetic").topics
    rec = _Recorder()
    player = BagPlayer(rec, bag, [t.rgb, t.depth, t.rgb_info, t.event_info, t.events, t.imu], t.rgb, t.depth, t.events)
    played = player.play(rate=20.0, repeat=3)
    n = player.n_frames
    frames = np.array(played.frame_stamps_ns)
    assert len(frames) == 3 * n
    loop = frames[n] - frames[0]
    period = np.diff(frames[:n]).mean()
    assert loop == pytest.approx(n * period, abs=1)  # one frame period between the passes
    np.testing.assert_array_equal(frames[n:2 * n] - frames[:n], loop)
    np.testing.assert_array_equal(frames[2 * n:] - frames[:n], 2 * loop)
    assert np.all(np.diff(frames) > 0)
    for topic, msgtype in ((t.rgb, "sensor_msgs/msg/Image"), (t.depth, "sensor_msgs/msg/Image"),
                           (t.imu, "sensor_msgs/msg/Imu"), (t.rgb_info, "sensor_msgs/msg/CameraInfo")):
        s = _stamps(rec.sent[topic], msgtype)
        k = len(s) // 3
        np.testing.assert_array_equal(s[k:2 * k] - s[:k], loop, err_msg=topic)
        assert rec.sent[topic][k][-64:] == rec.sent[topic][0][-64:]  # the payload itself is untouched
    # the event stream decodes as one stream, time running on with no step back
    dec = EventDecoder(player._events_msgtype, 2)
    batches = [dec.decode_raw(r) for r in rec.sent[t.events]]
    ts = np.concatenate([b.t for b in batches])
    assert dec.stats.dropped_backwards == 0 and np.all(np.diff(ts) >= 0)
    k = len(batches) // 3
    first = np.concatenate([b.t for b in batches[:k]])
    np.testing.assert_array_equal(np.concatenate([b.t for b in batches[k:2 * k]]), first + loop)
