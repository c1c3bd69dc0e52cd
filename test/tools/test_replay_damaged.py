"""atsvo-replay on a damaged mcap: what rosbags silently drops is counted per topic and reported.

Reproduces the probe "1000 bytes overwritten in the middle of an mcap replay with rc 0, a lost
ground-truth message and changed metrics, and nothing said".
"""
from __future__ import annotations

import json

import numpy as np

from atsvo_ros.config import load_config
from atsvo_ros.io.bags import Bag
from atsvo_ros.tools.replay import replay
from test.io.test_bags import write_bag
from test.tools.test_replay import FakeOdometry


def _damage_losing_ground_truth(bag_dir) -> dict[str, int]:
    """Overwrite 1000 bytes in the middle of the mcap where rosbags then silently loses pose messages."""
    from rosbags.highlevel import AnyReader

    f = next(bag_dir.glob("*.mcap"))
    data = f.read_bytes()
    for off in range(len(data) // 2, len(data) * 3 // 4, 97):
        raw = bytearray(data)
        raw[off:off + 1000] = b"\xa5" * 1000
        f.write_bytes(bytes(raw))
        counts: dict[str, int] = {}
        try:
            with AnyReader([bag_dir]) as r:
                for c, _, _ in r.messages():
                    counts[c.topic] = counts.get(c.topic, 0) + 1
                lost = {c.topic: c.msgcount - counts.get(c.topic, 0) for c in r.connections}
        except Exception:  # searching for damage that rosbags does *not* report: skip the loud kinds
            continue
        if lost.get("/ground_truth/pose"):
            return lost
    raise AssertionError("no silent loss found")


def test_damaged_mcap_replay_reports_lost_records(tmp_path):
    FakeOdometry.instances = []
    bag = write_bag(tmp_path / "seq", "mcap", n_frames=30)
    lost = _damage_losing_ground_truth(bag)
    res = replay(bag, tmp_path / "out", load_config("synthetic"), odometry_factory=FakeOdometry, plots=False,
                 progress=False)
    timing = json.loads((tmp_path / "out" / "timing.json").read_text())
    topics = timing["bag_read"]["topics"]
    assert topics["/ground_truth/pose"]["skipped"] == lost["/ground_truth/pose"]
    assert topics["/ground_truth/pose"]["role"] == "ground_truth"
    assert topics["/dvxplorer/events"]["skipped"] == lost["/dvxplorer/events"]
    assert timing["bag_read"]["clean"] is False
    assert any("bag damaged" in n and "/ground_truth/pose (ground_truth)" in n for n in res.notes)
    with Bag(bag) as b:
        list(b.messages(["ground_truth"]))
        assert b.read_stats.topics["/ground_truth/pose"].skipped == lost["/ground_truth/pose"]


def test_undamaged_replay_reads_clean(tmp_path):
    bag = write_bag(tmp_path / "seq", "mcap", n_frames=6)
    res = replay(bag, tmp_path / "out", load_config("synthetic"), odometry_factory=FakeOdometry, plots=False,
                 progress=False)
    timing = json.loads((tmp_path / "out" / "timing.json").read_text())
    assert timing["bag_read"]["clean"] is True and not any("damaged" in n for n in res.notes)
    assert all(t["skipped"] == 0 for t in timing["bag_read"]["topics"].values())


def test_nan_ground_truth_pose_is_skipped_and_noted(tmp_path, monkeypatch):
    import test.io.test_bags as tb

    real = tb.gt_pose

    def poisoned(t_s: float) -> np.ndarray:
        T = real(t_s)
        if 0.045 < t_s < 0.055:  # one of the 100 Hz samples
            T = T.copy()
            T[0, 3] = np.nan
        return T

    monkeypatch.setattr(tb, "gt_pose", poisoned)
    bag = write_bag(tmp_path / "seq", "mcap", n_frames=8)
    monkeypatch.setattr(tb, "gt_pose", real)
    res = replay(bag, tmp_path / "out", load_config("synthetic"), odometry_factory=FakeOdometry, plots=False,
                 progress=False)
    note = next(n for n in res.notes if "ground-truth" in n)
    assert "skipped 1 unusable" in note and "/ground_truth/pose" in note and "translation is not finite" in note
    assert res.metrics is not None
