"""ORB-SLAM3 as a peer: its bindings load our vocabulary and track real frames (TUM fr1_rpy's first 90)."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.bench.real import score
from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import EvaluationError
from atsvo_ros.eval.metrics import EvalOptions, evaluate
from atsvo_ros.eval.orb_vocabulary import orb_descriptors, train, write_text
from atsvo_ros.eval.orbslam3 import run_orbslam3, settings_text
from atsvo_ros.io.tum_rgbd import TumRgbdReader

pytestmark = pytest.mark.realdata
FR1 = load_config("tum_fr1")


def test_settings_carry_the_calibration():
    cam = CameraModel.from_config(FR1.rgb_camera)
    text = settings_text(cam)
    assert "Camera.fx: 517.306408" in text and "Camera.k3: 1.163314" in text and "DepthMapFactor: 1.0" in text
    with pytest.raises(EvaluationError, match="plumb_bob"):
        settings_text(CameraModel(640, 480, 500.0, 500.0, 320.0, 240.0, D=(0.1, 0.0, 0.0, 0.0),
                                  distortion_model="equidistant"))


def test_orbslam3_tracks_real_frames_with_a_vocabulary_trained_here(realdata, tmp_path):
    pytest.importorskip("pyorbslam3")
    folder = realdata / "tum_rgbd_fr1_rpy_300"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    reader = TumRgbdReader(folder)
    frames = list(reader.frames())
    # the vocabulary from frames the run does not track (200-299), the run on frames 0-89
    tree = train(orb_descriptors([f.rgb for f in frames[200::4]]), k=10, levels=3)
    vocabulary = tmp_path / "voc.txt"
    write_text(tree, vocabulary)
    cam = CameraModel.from_config(FR1.rgb_camera)
    raw = ((f.stamp_ns, f.rgb, f.depth_raw.astype(np.float32) * np.float32(FR1.rig.depth_scale_m))
           for f in frames[:90])
    run = run_orbslam3(raw, cam, vocabulary, progress=False)
    assert len(run.ok) == 90 and run.ok.sum() >= 88
    s = score(reader.ground_truth(), run.stamps_ns, run.T_world_cam, run.ok)
    print(f"ORB-SLAM3 on fr1_rpy frames 0-89: ATE {s['ate_cm']:.2f} cm, RPE {s['rpe_deg_per_frame']:.3f} deg/f")
    # ORB-SLAM3 is not deterministic (its mapping thread races tracking): 38 runs here gave 2.46-4.34 cm and
    # 0.59-0.71 deg/f (idle, beside one and two busy cores), one CI run 5.96 cm. The camera turns 2.3 deg/f (RMS)
    # over a 26 cm path. The depth in the wrong unit by 2x gave 11.06 cm and 20.3 deg/f, a run without motion does
    # not align at all. (A focal length 15% off is not caught here, 2.40 cm: the settings test above covers that.)
    assert s["ate_cm"] < 8.0 and s["rpe_deg_per_frame"] < 1.0
    # metric: the depth reached it in metres. A Sim(3) fit's scale, measured 0.59-0.63 (biased low by the error
    # on this short, mostly rotating path); depth in the wrong unit (DepthMapFactor 5000) gave 1569
    scale = evaluate(reader.ground_truth(), run.trajectory(), EvalOptions(align="sim3")).extra["alignment"]["scale"]
    print(f"Sim(3) scale {scale:.3f}")
    assert 0.4 < scale < 2.5
