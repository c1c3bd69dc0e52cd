"""TUM RGB-D folders: associate.py pairing, depth scale, preset detection, malformed files, replay wiring, real data."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import ConfigError, DatasetError, ImageError, TrajectoryError
from atsvo_ros.io.sync import FrameAssembler
from atsvo_ros.io.tum_rgbd import (
    TumRgbdReader,
    TumSource,
    associate_stamps,
    detect_tum_preset,
    is_tum_folder,
    read_file_list,
)
from test.io.tum_helpers import T0_NS, render_frames, write_tum_folder

MS = 1_000_000


def _associate_py(first, second, max_diff, offset=0):
    """TUM's associate.py, transcribed literally (all candidate pairs, closest first, each stamp once)."""
    potential = sorted((abs(a - (b + offset)), a, b) for a in first for b in second if abs(a - (b + offset)) < max_diff)
    used_a, used_b, matches = set(), set(), []
    for _, a, b in potential:
        if a not in used_a and b not in used_b:
            used_a.add(a)
            used_b.add(b)
            matches.append((a, b))
    return sorted(matches)


def test_association_is_associate_py_one_to_one_closest_first():
    # colour 1 takes the only depth (4 ms away), colour 0 (6 ms away) is left without one
    i, j = associate_stamps(np.array([0, 10]) * MS, np.array([6]) * MS, 20 * MS)
    assert (i.tolist(), j.tolist()) == ([1], [0])
    # exactly max_diff apart is not a pair (associate.py's strict <); the offset shifts the second list
    assert len(associate_stamps(np.array([0]), np.array([20 * MS]), 20 * MS)[0]) == 0
    assert associate_stamps(np.array([0]), np.array([20 * MS]), 20 * MS, offset_ns=-5 * MS)[1].tolist() == [0]
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = np.unique(rng.integers(0, 3000, rng.integers(1, 40)))
        b = np.unique(rng.integers(0, 3000, rng.integers(1, 40)))
        m, off = int(rng.integers(1, 200)), int(rng.integers(-50, 50))
        i, j = associate_stamps(a, b, m, off)
        assert list(zip(a[i].tolist(), b[j].tolist())) == _associate_py(a.tolist(), b.tolist(), m, off)
        assert np.all(np.diff(i) > 0)


@pytest.mark.parametrize("preset, k, d", [
    ("tum_fr1", (517.3, 516.5, 318.6, 255.3), (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    ("tum_fr2", (520.9, 521.0, 325.1, 249.7), (0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    ("tum_fr3", (535.4, 539.2, 320.1, 247.6), ()),
])
def test_presets_carry_tums_published_calibration(preset, k, d):
    """Full-precision values in the YAMLs; TUM's calibration table prints them rounded to 4 digits."""
    cfg = load_config(preset)
    cam = CameraModel.from_config(cfg.rgb_camera)
    assert (cam.width, cam.height) == (640, 480) and not cfg.rgb_camera.use_camera_info
    assert np.allclose([cam.fx, cam.fy, cam.cx, cam.cy], k, atol=0.05)
    assert np.allclose(cam.D, d, atol=5e-5) and cam.distortion_model == ("plumb_bob" if d else "none")
    assert cfg.mode == "rgbd" and cfg.rig.depth_scale_m == pytest.approx(1 / 5000)
    assert np.array_equal(cfg.rig.T_base_rgb_matrix(), np.eye(4))
    assert cfg.rig.depth_min_m <= 0.5 and 4.0 <= cfg.rig.depth_max_m <= 6.0


@pytest.fixture(scope="module")
def synth(tmp_path_factory):
    """A rendered fr1-like sequence (raw, distorted images) written as a TUM folder named like TUM's."""
    cam = CameraModel.from_config(load_config("tum_fr1").rgb_camera)
    frames = render_frames(cam, n=8)
    folder = write_tum_folder(tmp_path_factory.mktemp("tum") / "rgbd_dataset_freiburg1_synth", frames)
    return folder, frames


def test_reader_pairs_streams_and_scales_depth(synth):
    folder, frames = synth
    assert is_tum_folder(folder) and not is_tum_folder(folder / "rgb")
    with TumRgbdReader(folder) as r:
        assert len(r) == 8 and r.has("rgb") and r.has("ground_truth") and not r.has("events")
        assert r.stamps_ns.tolist() == [f[0] for f in frames]
        assert set(r.depth_offsets_ns.tolist()) == {8 * MS}
        loaded = list(r.frames(2, 4))
        gt = r.ground_truth()
    assert [f.index for f in loaded] == [2, 3] and loaded[0].depth_stamp_ns == frames[2][0] + 8 * MS
    f = loaded[0]
    assert f.rgb.dtype == np.uint8 and f.rgb.shape == (480, 640, 3) and np.array_equal(f.rgb, frames[2][1])
    assert f.depth_raw.dtype == np.uint16
    assert np.abs(f.depth_raw * (1 / 5000) - frames[2][2]).max() <= 1e-4 + 1e-6  # 0.2 mm units
    assert np.allclose(gt.T_w_b, np.stack([fr[3] for fr in frames]), atol=1e-7)
    # the replay source hands metres to the assembler, at the colour stamp, with the rig's range check
    cfg = load_config("tum_fr1", overrides={"rig.depth_max_m": 3.5})
    asm = FrameAssembler(cfg.rig, with_events=False)
    src = TumSource(folder)
    src.setup(cfg, [])
    gt_samples: list = []
    for _ in src.feed(asm, ("rgb", "depth"), gt_samples):
        pass
    pairs = asm.flush()
    assert len(pairs) == 8 and asm.stats.dropped_rgb == asm.stats.dropped_depth == 0
    fr, _ = pairs[0]
    assert fr.stamp_ns == frames[0][0] and fr.depth_m.dtype == np.float32
    d_true = frames[0][2]
    near = d_true < 3.49
    assert np.allclose(fr.depth_m[near], d_true[near], atol=1.1e-4)
    assert np.all(fr.depth_m[d_true > 3.51] == 0.0)  # beyond depth_max_m: invalid
    assert len(gt_samples) == 8


def test_zero_depth_stays_invalid(tmp_path):
    frames = render_frames(CameraModel.from_config(load_config("tum_fr3").rgb_camera), n=1)
    frames[0][2][:40] = 0.0
    folder = write_tum_folder(tmp_path / "fr3_holes", frames, gt=False)
    cfg = load_config("tum_fr3")
    asm = FrameAssembler(cfg.rig, with_events=False)
    src = TumSource(folder)
    src.setup(cfg, [])
    for _ in src.feed(asm, ("rgb", "depth"), None):
        pass
    (fr, _), = asm.flush()
    assert np.all(fr.depth_m[:40] == 0.0) and np.all(fr.depth_m[40:] > 3.0)


@pytest.mark.parametrize("name, readme, expected", [
    ("rgbd_dataset_freiburg2_xyz", None, ("tum_fr2", "the folder name")),
    ("tum_fr3_office", None, ("tum_fr3", "the folder name")),
    ("TUM-FR1-desk", None, ("tum_fr1", "the folder name")),
    ("frames_12", "TUM RGB-D rgbd_dataset_freiburg1_rpy ... Freiburg 2: ...", ("tum_fr1", "README.txt")),
    ("fr12", None, None),
])
def test_preset_from_folder_name_then_readme(tmp_path, name, readme, expected):
    folder = tmp_path / name
    folder.mkdir()
    if readme:
        (folder / "README.txt").write_text(readme)
    assert detect_tum_preset(folder) == expected


def test_preset_from_list_headers_and_a_clear_error_without_one(tmp_path):
    folder = tmp_path / "seq"
    folder.mkdir()
    (folder / "rgb.txt").write_text("# color images\n# file: 'rgbd_dataset_freiburg3_long_office.bag'\n1.0 rgb/a.png\n")
    (folder / "depth.txt").write_text("1.0 depth/a.png\n")
    assert TumSource(folder).preset == "tum_fr3"
    (folder / "rgb.txt").write_text("# color images\n1.0 rgb/a.png\n")
    with pytest.raises(ConfigError, match="--preset tum_fr1"):
        _ = TumSource(folder).preset


@pytest.mark.parametrize("text, words", [
    ("# c\n1.0 rgb/a.png\n1.1 rgb/b.png extra\n", ["rgb.txt:3", "timestamp filename"]),
    ("1.0 rgb/a.png\nabc rgb/b.png\n", ["rgb.txt:2", "'abc'"]),
    ("1.0 rgb/a.png\n-2.0 rgb/b.png\n", ["rgb.txt:2", "'-2.0'"]),
    ("\n1.0 rgb/a.png\n1.0 rgb/b.png\n", ["rgb.txt:3", "not after", "line 2"]),
])
def test_malformed_list_lines_name_file_and_line(tmp_path, text, words):
    (tmp_path / "rgb.txt").write_text(text)
    with pytest.raises(DatasetError) as exc:
        read_file_list(tmp_path / "rgb.txt")
    for w in words:
        assert w in str(exc.value)


def test_missing_and_broken_files_are_reported(tmp_path, synth):
    with pytest.raises(DatasetError, match="does not exist"):
        TumRgbdReader(tmp_path / "nothing")
    (tmp_path / "rgb.txt").write_text("1.0 rgb/a.png\n")
    with pytest.raises(DatasetError, match="no depth.txt"):
        TumRgbdReader(tmp_path)
    (tmp_path / "depth.txt").write_text("# d\n1.5 depth/a.png\n")
    with pytest.raises(DatasetError, match="no colour/depth pair within 20 ms"):
        TumRgbdReader(tmp_path)
    (tmp_path / "depth.txt").write_text("# d\n1.01 depth/a.png\n")
    r = TumRgbdReader(tmp_path)
    with pytest.raises(DatasetError, match=r"rgb\.txt:1: image .*a\.png does not exist"):
        next(r.frames())
    (tmp_path / "rgb").mkdir()
    (tmp_path / "depth").mkdir()
    (tmp_path / "rgb" / "a.png").write_bytes(b"not a png")
    with pytest.raises(ImageError, match=r"cannot decode .*a\.png \(listed in .*rgb\.txt:1\)"):
        next(r.frames())
    cv2.imwrite(str(tmp_path / "rgb" / "a.png"), np.zeros((4, 6, 3), np.uint8))
    cv2.imwrite(str(tmp_path / "depth" / "a.png"), np.zeros((4, 6), np.uint8))  # 8-bit: not TUM depth
    with pytest.raises(ImageError, match="16-bit"):
        next(r.frames())
    (tmp_path / "groundtruth.txt").write_text("# gt\n1.0 0 0 0 0 0 0 1\n1.1 0 0 0 0 0 1\n")
    with pytest.raises(TrajectoryError, match=r"groundtruth\.txt:3"):
        TumRgbdReader(tmp_path).ground_truth()


def test_replay_reads_a_tum_folder_with_its_preset_and_camera_frame(synth, tmp_path):
    from atsvo_ros.config import load_config
    from atsvo_ros.eval.metrics import EvalOptions
    from atsvo_ros.io.trajectory import read_tum
    from atsvo_ros.tools.replay import replay

    folder, frames = synth
    # both trajectories start at the identity: scored as they are
    res = replay(folder, tmp_path / "out", plots=False, progress=False, eval_options=EvalOptions(align="none"))
    assert "config preset tum_fr1 (from the folder name)" in res.notes
    assert any("8 colour/depth pairs" in n for n in res.notes)
    # published at the exposure: the stamp minus the preset's 10 ms host-stamping latency
    offset_ns = int(round(load_config("tum_fr1").rgb_camera.time_offset_s * 1e9))
    assert offset_ns == -10_000_000
    assert res.mode == "rgbd" and res.stamps_ns.tolist() == [f[0] + offset_ns for f in frames]
    assert "frame=colour optical" in (tmp_path / "out" / "trajectory.tum").read_text().splitlines()[0]
    assert len(read_tum(tmp_path / "out" / "groundtruth.tum")) == 8
    # distortion, depth scale and the camera-frame ground truth all right: the motion is recovered
    # (measured 0.6 cm; 1.5 cm without undistortion, 1.4 cm with the fr2 intrinsics, 10 cm with a
    # 1/1000 depth scale: walls 3-4 m away leave rotation and translation hard to tell apart). These
    # frames are rendered with a global shutter and stamped at their exposure, so the preset's Kinect
    # rolling-shutter readout (left on, the model misplaces the rows: ~3 cm) and latency are turned off.
    cfg = load_config("tum_fr1", overrides={"rgb_camera.readout_time_s": 0.0, "rgb_camera.time_offset_s": 0.0})
    res = replay(folder, tmp_path / "out_gs", cfg, plots=False, progress=False, eval_options=EvalOptions(align="none"))
    assert res.statuses.count("ok") >= 6
    assert res.metrics["ate_rmse_m"] < 0.015, res.metrics


def test_tum_folder_user_errors_are_one_line(synth, tmp_path, capsys):
    """Topic flags do not apply, a folder without depth.txt is named as such, a non-TUM depth scale is a warning."""
    import shutil

    from atsvo_ros.errors import BagError
    from atsvo_ros.io.sources import open_source
    from atsvo_ros.io.tum_rgbd import TumSource

    folder, _ = synth
    with pytest.raises(BagError, match="--rgb-topic does not apply to a TUM RGB-D folder"):
        open_source([folder], {"rgb": "/foo", "depth": None}, None)
    only_rgb = tmp_path / "only_rgb"
    only_rgb.mkdir()
    shutil.copy(folder / "rgb.txt", only_rgb / "rgb.txt")
    with pytest.raises(BagError, match="has rgb.txt but no depth.txt"):
        open_source([only_rgb], None, None)
    notes: list[str] = []
    TumSource(folder).setup(load_config("mini_cheetah"), notes)
    assert any(n.startswith("warning: rig.depth_scale_m = 0.001 differs from TUM's 1/5000 m, so depths are read 5x")
               for n in notes), notes


def test_replay_cli_preset_choice_overrides_the_folder_name(synth, tmp_path):
    from atsvo_ros.tools.replay import build_parser

    args = build_parser().parse_args([str(synth[0]), "--out", str(tmp_path), "--preset", "tum_fr3"])
    assert args.preset == "tum_fr3" and args.frame is None


# ---------------------------------------------------------------------------- real data


def test_real_fr1_rpy_first_frames(realdata):
    folder = realdata / "tum_rgbd_fr1_rpy_300"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    r = TumRgbdReader(folder)
    assert len(r) == 300 and r.n_rgb == r.n_depth == 300
    assert detect_tum_preset(folder) == ("tum_fr1", "the folder name")
    assert r.pairs[0].stamp_ns == T0_NS and r.pairs[0].depth.stamp_ns == 1_305_031_229_528_784_000
    off_ms = r.depth_offsets_ns * 1e-6
    assert -0.5 < off_ms.min() and off_ms.max() < 17.5 and 5 < np.median(off_ms) < 10  # not simultaneous
    f0, f1 = list(r.frames(0, 2))
    assert f0.rgb.shape == (480, 640, 3) and f0.depth_raw.shape == (480, 640) and f0.depth_raw.dtype == np.uint16
    d = f0.depth_raw[f0.depth_raw > 0] / 5000.0
    assert len(d) > 0.5 * f0.depth_raw.size and 0.5 < np.median(d) < 4.0
    assert f1.stamp_ns - f0.stamp_ns == 35_677_000
    gt = r.ground_truth()
    assert len(gt) == 1097 and gt.stamps_ns[0] < r.pairs[0].stamp_ns and gt.stamps_ns[-1] > r.pairs[-1].stamp_ns
