"""``atsvo-events stats|render`` on real recordings and on bags written here."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.io.encode import serialize_dvs_event_array, serialize_event_packet
from atsvo_ros.io.msgtypes import typestore
from atsvo_ros.tools.events import STATS_KEYS, main

PACKET = "event_camera_msgs/msg/EventPacket"
DVS = "dvs_msgs/msg/EventArray"
T0 = 1_700_000_000_000_000_000


def _bars(t_start_ns: int, duration_s: float, speed_px_s: float, w: int = 64, h: int = 48) -> EventBatch:
    """Vertical bars every 16 px moving right; one column event per bar and pixel crossing."""
    n_steps = max(1, int(duration_s * speed_px_s))
    xs, ys, ts = [], [], []
    for k in range(n_steps):
        t = t_start_ns + int(k / speed_px_s * 1e9) // 1000 * 1000
        for bar in range(0, w, 16):
            xs.append(np.full(h, (bar + k) % w))
            ys.append(np.arange(h))
            ts.append(np.full(h, t))
    return EventBatch(np.concatenate(xs), np.concatenate(ys), np.concatenate(ts), np.ones(n_steps * (w // 16) * h),
                      w, h)


def _write_bag(path, batches, encoding="libcaer_cmp", ros_version=2, extra_dvs=False, packet_ms=5):
    store = typestore(ros_version)
    b = EventBatch.concatenate(batches)
    edges = np.arange(b.t_first_ns, b.t_last_ns + packet_ms * 1_000_000, packet_ms * 1_000_000)
    writer = Writer2(path, version=9) if ros_version == 2 else Writer1(path)
    with writer:
        conn = writer.add_connection("/event_camera/events", PACKET, typestore=store)
        dconn = writer.add_connection("/dvs/events", DVS, typestore=store) if extra_dvs else None
        for a, z in zip(edges[:-1], edges[1:]):
            part = b.time_slice(int(a), int(z))
            if len(part) == 0:
                continue
            writer.write(conn, int(z), serialize_event_packet(part, encoding, ros_version=ros_version))
            if dconn is not None:
                writer.write(dconn, int(z), serialize_dvs_event_array(part, ros_version=ros_version))
    return b


def _stats_json(capsys, *argv):
    assert main(["stats", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("encoding,ros_version", [("libcaer_cmp", 2), ("mono", 2), ("libcaer", 1)])
def test_stats_json_on_a_written_bag(tmp_path, capsys, encoding, ros_version):
    path = tmp_path / ("bag.bag" if ros_version == 1 else "bag")
    b = _write_bag(path, [_bars(T0, 0.2, 300.0)], encoding, ros_version)
    s = _stats_json(capsys, path)
    assert tuple(s) == STATS_KEYS
    assert (s["width"], s["height"], s["encoding"]) == (64, 48, encoding)
    assert (s["n_events"], s["n_on"], s["n_off"]) == (len(b), int(b.p.sum()), len(b) - int(b.p.sum()))
    assert (s["t_first_ns"], s["t_last_ns"]) == (b.t_first_ns, b.t_last_ns)
    assert s["sum_t"] == int(b.t.view(np.uint64).sum(dtype=np.uint64))
    assert (s["sum_x"], s["sum_y"], s["sum_p"]) == (int(b.x.sum(dtype=np.int64)), int(b.y.sum(dtype=np.int64)),
                                                    int(b.p.sum()))
    assert s["duration"] == pytest.approx((b.t_last_ns - b.t_first_ns) * 1e-9)
    assert s["rate"] == pytest.approx(len(b) / s["duration"])


def test_stats_needs_topic_when_a_bag_has_several(tmp_path, capsys):
    path = tmp_path / "two"
    b = _write_bag(path, [_bars(T0, 0.05, 300.0)], extra_dvs=True)
    assert main(["stats", str(path), "--json"]) == 1
    err = capsys.readouterr().err
    assert "several event topics" in err and "--topic" in err and len(err.strip().splitlines()) == 1
    s = _stats_json(capsys, path, "--topic", "/dvs/events")
    assert s["encoding"] == "dvs" and s["n_events"] == len(b)


def test_stats_real_libcaer_rollover_matches_published_checksums(realdata, capsys):
    s = _stats_json(capsys, realdata / "event_camera_codecs_bags" / "test_data_libcaer_rollover")
    assert (s["sum_t"], s["sum_x"], s["sum_y"], s["sum_p"]) == (15762826572202229126, 111651612, 82801007, 181908)
    assert (s["width"], s["height"], s["encoding"]) == (640, 480, "libcaer")


def test_stats_text_and_errors(realdata, tmp_path, capsys):
    assert main(["stats", str(realdata / "tonic_samples" / "sample.aedat4")]) == 0
    out = capsys.readouterr().out
    assert "320x240" in out and "111,954" in out
    bad = tmp_path / "x.txt"
    bad.write_text("hello")
    assert main(["stats", str(bad)]) == 1
    assert "unsupported event file type" in capsys.readouterr().err
    assert main(["stats", str(tmp_path / "missing.bag")]) == 1
    assert "not found" in capsys.readouterr().err


def test_render_picks_slow_and_fast_moments(tmp_path, capsys):
    slow = _bars(T0, 0.3, 100.0)
    fast = _bars(T0 + 300_000_000, 0.1, 1500.0)
    path = tmp_path / "bag"
    _write_bag(path, [slow, fast])
    out = tmp_path / "fig"
    assert main(["render", str(path), "--out", str(out), "--set", "ats.tau_u_s=0.02"]) == 0
    fig4 = cv2.imread(str(out / "fig4_ts_vs_ats.png"))
    assert fig4 is not None and fig4.shape[0] == 2 * 48 * 10 and fig4.shape[1] == 2 * 64 * 10
    for name in ("slow", "fast"):
        img = cv2.imread(str(out / f"fig5_selection_{name}.png"))
        assert img is not None and img.shape[:2] == (2 * 480, 2 * 640)
    # in the rendered panels the fast moment's constant-tau TS is brighter (more overlap) than the slow one's
    top, bottom = fig4[: 48 * 10, : 64 * 10], fig4[48 * 10:, : 64 * 10]
    assert bottom.mean() > top.mean()
    from atsvo_ros.tools.events_render import event_rate_bins, pick_moments

    t0, counts, _ = event_rate_bins(path, 20_000_000)
    slow_m, fast_m = pick_moments(t0, counts, 20_000_000)
    assert slow_m.t_ns <= T0 + 300_000_000 < fast_m.t_ns
