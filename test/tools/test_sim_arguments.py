"""``atsvo-sim``'s numeric arguments and ``--out``: every bad value gives one line and exit code 1 before any work
(reproductions r12_sim_argument_gaps.sh and r01_out_not_writable.sh)."""
from __future__ import annotations

import pytest

import atsvo_ros.sim.writer as writer
from atsvo_ros.tools.sim import main
from test.tools._unwritable import unwritable_dir  # noqa: F401  (a fixture)

# the reproduction's arguments
R12 = ["--scenario", "trot", "--width", "64", "--height", "48", "--event-scale", "0.1", "--quiet", "--force"]


@pytest.fixture()
def no_generation(monkeypatch):
    """Fail the test if the generation starts: every case here must be refused before it."""

    def must_not_run(*_a, **_k):
        raise AssertionError("the generation started")

    monkeypatch.setattr(writer, "_generate", must_not_run)


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("atsvo-sim: error: ") and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("args,message", [
    # r12 cases 1-5
    (["--duration", "inf"], "duration must be in (0, 3600] s, got inf"),
    (["--duration", "1e12"], "duration must be in (0, 3600] s"),
    (["--duration", "0.2", "--seed", "-1"], "seed must be an integer in [0, 4294967295]"),
    (["--duration", "0.2", "--refractory-us", "nan"], "refractory period must be in [0, 0.1] s"),
    (["--duration", "0.2", "--contrast", "nan"], "contrast threshold contrast_pos must be in (0, 2]"),
])
def test_r12_sim_arguments_are_refused_in_one_line(tmp_path, capsys, no_generation, args, message):
    assert main([*R12, *args, "--out", str(tmp_path / "s")]) == 1
    assert message in _one_error_line(capsys)
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("option,value,message", [
    ("--duration", "nan", "duration must be in"),
    ("--duration", "0", "duration must be in"),
    ("--seed", str(2**32), "seed must be an integer"),
    ("--rate", "inf", "frame rate must be in (0, 1000] Hz"),
    ("--rate", "nan", "frame rate must be in"),
    ("--gt-rate", "1e9", "ground-truth rate must be in (0, 1000] Hz"),
    ("--gt-rate", "nan", "ground-truth rate must be in"),
    ("--exposure", "nan", "exposure nan s must be positive"),
    ("--rgb-readout", "nan", "readout_time_s must be in [0, 0.1] s"),
    ("--rgb-stamp-jitter", "inf", "stamp_jitter_s must be in [0, 0.005] s"),
    ("--rgb-stamp-latency", "nan", "stamp_latency_s must be in [0, 0.1] s"),
    ("--packet-ms", "nan", "event packet length must be in [1e-06, 1] s"),
    ("--packet-ms", "1e-9", "event packet length must be in [1e-06, 1] s"),
    ("--event-scale", "nan", "event_scale must be in [0.05, 4]"),
    ("--texture-size", "65536", "texture size must be a power of two in [8, 4096]"),
    ("--texture-size", "100", "texture size must be a power of two"),
    ("--contrast", "inf", "contrast threshold contrast_pos must be in (0, 2]"),
    ("--noise-rate", "nan", "noise rate must be in [0, 100]"),
    ("--noise-rate", "inf", "noise rate must be in [0, 100]"),
    ("--scan-period-us", "nan", "must be in [0, 0.01] s"),
    ("--scan-period-us", "1e9", "must be in [0, 0.01] s"),
    ("--refractory-us", "inf", "refractory period must be in [0, 0.1] s"),
    ("--ir-exposure", "nan", "IR exposure must lie in"),
    ("--ir-ambient", "nan", "ambient_ir must be in [0, 100]"),
    ("--ir-ambient", "-1", "ambient_ir must be in [0, 100]"),
    ("--depth-phase", "nan", "phase_s must be within +-0.1 s"),
    ("--width", "100000", "image size must be in [8, 4096] px"),
])
def test_every_numeric_sim_argument_is_checked(tmp_path, capsys, no_generation, option, value, message):
    assert main([*R12, "--duration", "0.2", option, value, "--out", str(tmp_path / "s")]) == 1
    assert message in _one_error_line(capsys)


def test_r01_sim_out_under_a_file_is_refused_before_the_work(tmp_path, capsys, no_generation):
    (tmp_path / "existing_file").touch()
    for out in (tmp_path / "existing_file" / "sub", tmp_path / "existing_file" / "a" / "b"):
        assert main([*R12, "--duration", "0.2", "--out", str(out)]) == 1
        assert f"--out {out} is under {tmp_path / 'existing_file'}, which is not a folder" in _one_error_line(capsys)
    assert main([*R12, "--duration", "0.2", "--out", str(tmp_path / "existing_file")]) == 1
    assert "exists and is not a directory" in _one_error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing_file"]


def test_r01_sim_out_in_an_unwritable_folder_is_refused_before_the_work(unwritable_dir, capsys,  # noqa: F811
                                                                         no_generation):
    for out in (unwritable_dir / "sim", unwritable_dir / "a" / "b"):
        assert main([*R12, "--duration", "0.2", "--out", str(out)]) == 1
        assert f"--out {out}: cannot write in {unwritable_dir}: " in _one_error_line(capsys)


def test_sim_force_still_refuses_foreign_files_and_needs_force(tmp_path, capsys, no_generation):
    out = tmp_path / "s"
    out.mkdir()
    (out / "groundtruth.tum").touch()
    assert main([*R12[:-1], "--duration", "0.2", "--out", str(out)]) == 1
    assert "is not empty (use --force" in _one_error_line(capsys)
    (out / "notes.txt").touch()
    assert main([*R12, "--duration", "0.2", "--out", str(out)]) == 1
    assert "holds notes.txt, which atsvo-sim did not write" in _one_error_line(capsys)


def test_a_resized_mvsec_layout_is_refused_as_it_would_not_replay(tmp_path, capsys, no_generation):
    """The mvsec preset a replay takes for the bag fixes the DAVIS346: 160x120 colour gave 'no frame could be used'."""
    assert main([*R12, "--duration", "0.2", "--layout", "mvsec", "--out", str(tmp_path / "s")]) == 1
    assert ("--width and --height and --event-scale with --layout mvsec: the bag would not replay"
            in _one_error_line(capsys))
