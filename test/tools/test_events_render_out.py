"""``atsvo-events render --out``: a file, a path under a file or an unwritable folder gives one line and exit code
1 before the recording is read (reproduction r01_out_not_writable.sh); a bad ``--bin`` is a usage error."""
from __future__ import annotations

import pytest

import atsvo_ros.tools.events_render as events_render
from atsvo_ros.tools.events import main
from test.tools._unwritable import unwritable_dir  # noqa: F401  (a fixture)
from test.tools.test_events_cli import T0, _bars, _write_bag


@pytest.fixture()
def bag(tmp_path, monkeypatch):
    """A small event bag; reading it fails the test (the output must be checked first)."""
    path = tmp_path / "bag"
    _write_bag(path, [_bars(T0, 0.2, 200.0)])

    def must_not_read(*_a, **_k):
        raise AssertionError("the recording was read")

    monkeypatch.setattr(events_render, "open_events", must_not_read)
    return path


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("atsvo-events: error: ") and "Traceback" not in err, err
    return err


def test_r01_render_out_is_checked_before_the_recording_is_read(tmp_path, capsys, bag,
                                                                unwritable_dir):  # noqa: F811
    existing = tmp_path / "existing_file"
    existing.touch()
    assert main(["render", str(bag), "--out", str(existing)]) == 1
    assert f"--out {existing} is a file, not a folder" in _one_error_line(capsys)
    assert main(["render", str(bag), "--out", str(existing / "sub")]) == 1
    assert f"--out {existing / 'sub'} is under {existing}, which is a file, not a folder" in _one_error_line(capsys)
    assert main(["render", str(bag), "--out", str(unwritable_dir / "fig")]) == 1
    assert f"--out {unwritable_dir / 'fig'} is not writable: " in _one_error_line(capsys)


def test_render_reports_a_figure_that_could_not_be_written(tmp_path, capsys, monkeypatch):
    path = tmp_path / "bag"
    _write_bag(path, [_bars(T0, 0.2, 200.0)])
    monkeypatch.setattr(events_render.cv2, "imwrite", lambda *_a, **_k: False)
    assert main(["render", str(path), "--out", str(tmp_path / "fig")]) == 1
    last = capsys.readouterr().err.splitlines()[-1]  # after the progress bar
    assert last == f"atsvo-events: error: could not write {tmp_path / 'fig' / 'fig5_selection_slow.png'}"


@pytest.mark.parametrize("value", ["nan", "inf", "0", "-1"])
def test_render_bin_must_be_a_finite_positive_window(tmp_path, capsys, bag, value):
    with pytest.raises(SystemExit) as exc:
        main(["render", str(bag), "--out", str(tmp_path / "fig"), "--bin", value])
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last == f"atsvo-events render: error: argument --bin: must be a window in seconds from 1e-06 (the " \
                   f"event clock) to 3600, got {value}"
