"""``atsvo-bench tracking --orbslam3``: ORB-SLAM3 RGB-D on a simulated sequence's frames, scored as ours."""
from __future__ import annotations

import pytest

from atsvo_ros.bench.tracking import orbslam3_line, orbslam3_sequence, sequence_spec, simulated_frames
from atsvo_ros.eval.orb_vocabulary import orb_descriptors, train, write_text


def test_orbslam3_tracks_a_simulated_trot(tmp_path):
    pytest.importorskip("pyorbslam3")
    spec = sequence_spec("trot", 0, 1.5, width=320, height=240)
    frames, _, _ = simulated_frames(spec, progress=False)
    vocabulary = tmp_path / "voc.txt"
    write_text(train(orb_descriptors([f[1] for f in frames[::5]], n_features=500), k=10, levels=3), vocabulary)
    o = orbslam3_sequence(spec, vocabulary, progress=False)
    print(orbslam3_line(o))
    assert o["frames"] == len(frames) and o["ok"] >= len(frames) - 1
    # measured 0.71-1.51 cm (SE(3)) and 1.42-2.27 (anchored) over this 0.73 m path; a run that lost it is tens of cm off
    assert o["ate_se3_cm"] < 3.0 and o["ate_origin_cm"] < 5.0
    assert "ORB-SLAM3 RGB-D, same frames, no IMU: ATE RMSE" in orbslam3_line(o)
