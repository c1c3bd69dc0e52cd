"""``atsvo-demo``'s output and cache folders are checked before the sequence is generated: one line naming the
option or ``ATSVO_CACHE``, exit code 1 (reproductions r12_sim_argument_gaps.sh case 7, r01_out_not_writable.sh)."""
from __future__ import annotations

import pytest

from atsvo_ros.tools import demo as demo_mod
from test.tools._unwritable import unwritable_dir  # noqa: F401  (a fixture)

R12 = ["--scenario", "trot", "--duration", "0.3", "--width", "64", "--height", "48", "--event-scale", "0.1",
       "--no-progress"]


@pytest.fixture()
def no_generation(monkeypatch):
    """Fail the test if the simulator is started: the folders must be checked before it."""

    def must_not_run(*_a, **_k):
        raise AssertionError("the generation started")

    monkeypatch.setattr(demo_mod, "simulate", must_not_run)


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("atsvo-demo: error: ") and "Traceback" not in err, err
    return err


def test_r12_atsvo_cache_set_to_a_file_names_the_variable(tmp_path, capsys, monkeypatch, no_generation):
    existing = tmp_path / "existing_file"
    existing.touch()
    monkeypatch.setenv("ATSVO_CACHE", str(existing))
    assert demo_mod.main([*R12, "--out", str(tmp_path / "demo")]) == 1
    assert f"ATSVO_CACHE {existing} is a file, not a folder" in _one_error_line(capsys)
    monkeypatch.setenv("ATSVO_CACHE", str(existing / "sub"))
    assert demo_mod.main([*R12, "--out", str(tmp_path / "demo")]) == 1
    assert f"ATSVO_CACHE {existing / 'sub'} is under {existing}, which is a file" in _one_error_line(capsys)


def test_cache_option_and_unwritable_cache_are_named(tmp_path, capsys, monkeypatch, unwritable_dir,  # noqa: F811
                                                     no_generation):
    (tmp_path / "existing_file").touch()
    assert demo_mod.main([*R12, "--cache", str(tmp_path / "existing_file"), "--out", str(tmp_path / "demo")]) == 1
    assert f"--cache {tmp_path / 'existing_file'} is a file, not a folder" in _one_error_line(capsys)
    monkeypatch.setenv("ATSVO_CACHE", str(unwritable_dir / "cache"))
    assert demo_mod.main([*R12, "--out", str(tmp_path / "demo")]) == 1
    assert f"ATSVO_CACHE {unwritable_dir / 'cache'} is not writable: " in _one_error_line(capsys)


def test_r01_demo_out_not_writable_is_refused_before_the_generation(tmp_path, capsys, monkeypatch,
                                                                    unwritable_dir, no_generation):  # noqa: F811
    monkeypatch.setenv("ATSVO_CACHE", str(tmp_path / "cache"))
    existing = tmp_path / "existing_file"
    existing.touch()
    assert demo_mod.main([*R12, "--out", str(existing)]) == 1
    assert f"--out {existing} is a file, not a folder" in _one_error_line(capsys)
    assert demo_mod.main([*R12, "--out", str(existing / "sub")]) == 1
    assert f"--out {existing / 'sub'} is under {existing}, which is a file, not a folder" in _one_error_line(capsys)
    assert demo_mod.main([*R12, "--out", str(unwritable_dir / "demo")]) == 1
    assert f"--out {unwritable_dir / 'demo'} is not writable: " in _one_error_line(capsys)
    assert not (tmp_path / "cache").exists()


@pytest.mark.parametrize("limit", ["-1", "0", "nan"])
def test_an_impossible_accuracy_limit_is_refused_before_the_generation(tmp_path, capsys, limit, no_generation):
    assert demo_mod.main([*R12, "--out", str(tmp_path / "demo"), "--max-ate-cm", limit]) == 1
    assert "--max-ate-cm must be a positive number of centimetres" in _one_error_line(capsys)
