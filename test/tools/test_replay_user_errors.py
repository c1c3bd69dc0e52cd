"""atsvo-replay as a user gets it wrong: one clear line before the work, the real reason, a skipped frame.

Each case is a reproduction from ../shared/repro (r01 unusable --out, r03 every frame rejected for its
size, r05 one bad image in a TUM folder, r09 --record naming the input).
"""
from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest

from atsvo_ros.config import load_config
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.errors import BagError, OutputError, RecordError
from atsvo_ros.tools.replay import main, replay
from test.io.tum_helpers import render_frames, write_tum_folder

FR1 = CameraModel.from_config(load_config("tum_fr1").rgb_camera)


@pytest.fixture(scope="module")
def frames():
    return render_frames(FR1, n=8)


def _folder(tmp_path, frames, name="rgbd_dataset_freiburg1_synth"):
    return write_tum_folder(tmp_path / name, frames)


class _MustNotRun:
    """An odometry factory that fails the test if the replay gets as far as building the core."""

    def __init__(self, *_a, **_k) -> None:
        raise AssertionError("the replay started before checking --out")


@pytest.mark.parametrize("case", ["file", "under_file", "read_only"])
def test_unusable_out_is_one_line_before_the_run(tmp_path, frames, capsys, case):
    folder = _folder(tmp_path, frames)
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    out = {"file": blocker, "under_file": blocker / "sub", "read_only": tmp_path / "ro" / "out"}[case]
    if case == "read_only":
        (tmp_path / "ro").mkdir()
        os.chmod(tmp_path / "ro", 0o555)
        probe = tmp_path / "ro" / "probe"
        try:  # root ignores the mode bits: nothing to test then
            probe.mkdir()
            probe.rmdir()
            pytest.skip("running as a user that may write into a read-only folder")
        except PermissionError:
            pass
    with pytest.raises(OutputError, match="file, not a folder|not writable"):
        replay(folder, out, plots=False, progress=False, odometry_factory=_MustNotRun)
    assert main([str(folder), "--out", str(out), "--no-plots", "--no-progress"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("atsvo-replay: error: --out") and "Traceback" not in err[0]


def test_every_frame_rejected_for_its_size_says_why(tmp_path, frames):
    small = [(s, cv2.resize(rgb, (320, 240), interpolation=cv2.INTER_AREA),
              cv2.resize(d, (320, 240), interpolation=cv2.INTER_NEAREST), T) for s, rgb, d, T in frames]
    folder = _folder(tmp_path, small)
    with pytest.raises(BagError) as err:  # the folder's preset is fr1: 640x480
        replay(folder, tmp_path / "out", plots=False, progress=False)
    msg = str(err.value)
    assert "colour image is 320x240 but the camera model is 640x480" in msg and "frames the core rejected" in msg
    assert "no colour/depth pair could be formed" not in msg
    assert not (tmp_path / "out").exists()  # made for the run, nothing written: removed again


@pytest.mark.parametrize("damage", ["missing", "truncated", "smaller"])
def test_one_bad_tum_image_costs_its_frame_not_the_run(tmp_path, frames, damage):
    folder = _folder(tmp_path, frames)
    victim = sorted((folder / "depth").glob("*.png"))[4]
    if damage == "missing":
        victim.unlink()
    elif damage == "truncated":
        victim.write_bytes(victim.read_bytes()[:100])
    else:
        cv2.imwrite(str(victim), np.zeros((240, 320), np.uint16))
    res = replay(folder, tmp_path / "out", plots=False, progress=False)
    assert len(res.statuses) == len(frames) - 1
    timing = json.loads((tmp_path / "out" / "timing.json").read_text())
    assert timing["counters"]["images_rejected"] == 1
    assert any("1 unreadable images skipped" in n and "TUM pair 4" in n for n in res.notes), res.notes
    assert (tmp_path / "out" / "metrics.json").is_file()


def test_record_over_the_input_is_refused_even_with_force(tmp_path, frames):
    folder = _folder(tmp_path, frames)
    before = {p.name: p.read_bytes() for p in folder.glob("*.txt")}
    for target in (folder / "rgb.mcap", folder / "rgb" / "x.mcap"):
        with pytest.raises(RecordError, match="would overwrite the input"):
            replay(folder, tmp_path / "out", plots=False, progress=False, record=target, force=True)
    assert {p.name: p.read_bytes() for p in folder.glob("*.txt")} == before


def test_event_drops_are_reported_with_their_totals():
    """r11: the log shows the first message's drop count (5); the summary must give the totals."""
    from atsvo_ros.tools.replay import _decoder_notes

    stats = {"/dvxplorer/events": {"n_events": 205_966, "dropped_out_of_range": 490_352, "dropped_backwards": 0,
                                   "dropped_messages": 0, "dropped_by_kind": {}, "width": 80, "height": 60},
             "/clean/events": {"n_events": 10, "dropped_out_of_range": 0, "dropped_backwards": 0,
                               "dropped_messages": 0, "dropped_by_kind": {}}}
    notes = _decoder_notes(stats)
    assert notes == ["warning: /dvxplorer/events: 490,352 of 696,318 events dropped in decoding (sensor 80x60): "
                     "outside the sensor 490,352"]
