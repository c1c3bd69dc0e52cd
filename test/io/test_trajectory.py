from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.core.geometry import se3_exp
from atsvo_ros.errors import TrajectoryError
from atsvo_ros.io.trajectory import Trajectory, format_stamp, read_tum, write_tum


def test_write_read_round_trip_keeps_nanoseconds(tmp_path):
    rng = np.random.default_rng(0)
    stamps = np.array([1504645177500200033, 1504645177509701490, 1504645177516887188], dtype=np.int64)
    poses = np.stack([se3_exp(rng.normal(size=6)) for _ in stamps])
    write_tum(tmp_path / "t.tum", Trajectory(stamps, poses), header="test")
    back = read_tum(tmp_path / "t.tum")
    assert np.array_equal(back.stamps_ns, stamps)
    assert np.allclose(back.T_w_b, poses, atol=1e-8)
    assert format_stamp(-1_500_000_000) == "-1.500000000"


def test_read_real_tum_ground_truth(realdata):
    traj = read_tum(realdata / "tum_rgbd_trajectories_evo/freiburg1_xyz-groundtruth.txt")
    assert len(traj) == 3000 and 29 < traj.duration_s < 31
    mvsec = read_tum(realdata / "mvsec_calib_gt/gt_esvo2/indoor_flying1_stamped_groundtruth.txt")
    assert mvsec.stamps_ns[0] == 1504645177500200033 and np.allclose(mvsec.T_w_b[0], np.eye(4))


def test_malformed_files_name_the_line(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("# c\n0 1 2 3 0 0 0 1\n1 2 3\n")
    with pytest.raises(TrajectoryError, match="bad.txt:3"):
        read_tum(p)
    p.write_text("")
    with pytest.raises(TrajectoryError, match="no poses"):
        read_tum(p)
    with pytest.raises(TrajectoryError, match="cannot read"):
        read_tum(tmp_path / "missing.txt")
