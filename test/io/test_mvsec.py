"""MVSEC HDF5 reading on a small file with the dataset's layout, built here with h5py."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.errors import BagError
from atsvo_ros.io.mvsec import MvsecReader

h5py = pytest.importorskip("h5py")

T0_S = 1506117000.0


def write_mvsec(folder, n_img: int = 5, n_ev: int = 1000, hz: float = 20.0, split: bool = True):
    """``name_data.hdf5`` (+ ``name_gt.hdf5``) like MVSEC indoor_flying; returns the data path."""
    rng = np.random.default_rng(3)
    data = folder / "seq_data.hdf5"
    gt = folder / "seq_gt.hdf5" if split else data
    t_img = T0_S + np.arange(n_img) / hz
    with h5py.File(data, "w") as f:
        g = f.create_group("davis/left")
        t_ev = np.sort(rng.uniform(T0_S - 0.01, t_img[-1] + 0.01, n_ev))
        ev = np.stack([rng.integers(0, 346, n_ev), rng.integers(0, 260, n_ev), t_ev,
                       rng.choice([-1.0, 1.0], n_ev)], 1)
        g.create_dataset("events", data=ev)
        g.create_dataset("image_raw", data=rng.integers(0, 255, (n_img, 260, 346), dtype=np.uint8))
        g.create_dataset("image_raw_ts", data=t_img)
    with h5py.File(gt, "a") as f:
        g = f.require_group("davis/left")
        depth = np.full((n_img, 260, 346), 2.0, np.float32)
        depth[:, :10] = np.nan
        g.create_dataset("depth_image_raw", data=depth)
        g.create_dataset("depth_image_raw_ts", data=t_img + 0.002)
        n_pose = n_img * 5
        pose = np.repeat(np.eye(4)[None], n_pose, 0)
        pose[:, 0, 3] = np.linspace(0, 1, n_pose)
        g.create_dataset("pose", data=pose)
        g.create_dataset("pose_ts", data=T0_S + np.arange(n_pose) / (hz * 5))
    return data


def test_stream_is_time_ordered_and_complete(tmp_path):
    path = write_mvsec(tmp_path)
    with MvsecReader(path, tmp_path / "seq_gt.hdf5", events_per_chunk=128) as r:
        items = list(r.stream())
        assert r.has("depth") and r.has("ground_truth")
        gt = r.ground_truth()
    roles = [i.role for i in items]
    assert roles.count("rgb") == 5 and roles.count("depth") == 5
    ev = [i.data for i in items if i.role == "events"]
    assert sum(len(b) for b in ev) == 1000 and len(ev) == 8
    t = [i.stamp_ns for i in items]
    assert t == sorted(t)
    b = ev[0]
    assert (b.width, b.height) == (346, 260) and set(np.unique(b.p)) <= {0, 1}
    assert items[0].stamp_ns == pytest.approx(T0_S * 1e9 - 1e7, abs=2e7)
    assert len(gt) == 25 and gt.T_w_b[-1, 0, 3] == pytest.approx(1.0)


def test_single_file_and_missing(tmp_path):
    path = write_mvsec(tmp_path, split=False)
    with MvsecReader(path) as r:
        assert r.has("depth") and len(r.ground_truth()) == 25
    with pytest.raises(BagError, match="does not exist"):
        MvsecReader(tmp_path / "nope.hdf5")
    bad = tmp_path / "bad.hdf5"
    bad.write_bytes(b"not hdf5")
    with pytest.raises(BagError, match="bad.hdf5"):
        MvsecReader(bad)


def test_replay_reads_mvsec(tmp_path):
    from atsvo_ros.config import load_config
    from atsvo_ros.io.trajectory import read_tum
    from atsvo_ros.tools.replay import replay
    from test.tools.test_replay import FakeOdometry

    path = write_mvsec(tmp_path)
    FakeOdometry.instances = []
    res = replay(path, tmp_path / "out", load_config("mvsec"), odometry_factory=FakeOdometry, plots=False,
                 progress=False)
    assert len(read_tum(tmp_path / "out" / "trajectory.tum")) == 5 and res.mode == "fused"
    odo = FakeOdometry.instances[0]
    d = odo.frames[0].depth_m
    assert d.dtype == np.float32 and d[0, 0] == 0 and d[20, 20] == 2.0  # NaN -> invalid
    assert res.metrics is not None and res.metrics["n_matched"] == 5
