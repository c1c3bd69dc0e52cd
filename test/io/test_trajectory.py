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


def _lines(stamps: list[str]) -> str:
    return "".join(f"{s} {i} 0 0 0 0 0 1\n" for i, s in enumerate(stamps))


def test_stamp_order_repeats_and_going_back_name_the_lines(tmp_path):
    """r06: a repeated or backwards stamp is an error naming file:line, where the caller asks for an order."""
    rep = tmp_path / "rep.txt"
    rep.write_text("# header\n" + _lines(["1.0", "1.5", "1.5", "2.0"]))
    with pytest.raises(TrajectoryError, match=r"rep\.txt:4: stamp 1\.500000000 repeats the stamp of line 3 "):
        read_tum(rep, order="increasing")
    assert len(read_tum(rep, order="nondecreasing")) == 4  # motion capture repeats a sample now and then
    back = tmp_path / "back.txt"
    back.write_text(_lines(["1.0", "2.0", "1.5"]))
    for order in ("increasing", "nondecreasing"):
        with pytest.raises(TrajectoryError, match=r"back\.txt:3: stamp 1\.500000000 goes back in time from line 2"):
            read_tum(back, order=order)
    assert len(read_tum(rep)) == 4 and len(read_tum(back)) == 3  # the default reads the lines as they are
    with pytest.raises(TrajectoryError, match="unknown stamp order"):
        read_tum(rep, order="sorted")


def test_utf8_byte_order_mark_is_skipped(tmp_path):
    """r09 f: a file saved with a BOM (Notepad) reads like the same file without it."""
    text = "# saved on Windows\n" + _lines(["1700000000.0", "1700000000.5"])
    plain, bom = tmp_path / "plain.txt", tmp_path / "bom.txt"
    plain.write_text(text)
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    a, b = read_tum(plain), read_tum(bom)
    assert np.array_equal(a.stamps_ns, b.stamps_ns) and np.array_equal(a.T_w_b, b.T_w_b)
    bom.write_bytes(b"\xef\xbb\xbf" + _lines(["1.0"]).encode())  # no comment: the BOM sits before the stamp
    assert read_tum(bom).stamps_ns.tolist() == [1_000_000_000]
    bom.write_bytes(b"\xef\xbb\xbf1.0 0 0 0 0 0 0 1\n\xff\n")  # offsets still count the BOM's 3 bytes
    with pytest.raises(TrajectoryError, match=r"bom\.txt:2: not UTF-8 text \(byte 0xff at offset 21\)"):
        read_tum(bom)
