"""``atsvo-sim`` command line: writes a bag directory; user errors give one line and exit code 1."""
from __future__ import annotations

from atsvo_ros.tools.sim import main

TINY = ["--width", "32", "--event-scale", "0.1", "--texture-size", "16", "--quiet"]


def test_cli_writes_a_sequence(tmp_path, capsys):
    out = tmp_path / "trot"
    code = main(["--scenario", "trot", "--duration", "0.2", "--seed", "3", "--out", str(out), "--format", "ros1",
                 *TINY])
    assert code == 0
    assert (out / "sequence.bag").is_file() and (out / "groundtruth.tum").is_file()
    assert (out / "sequence.yaml").is_file()
    assert "RGB-D frames" in capsys.readouterr().err


def test_cli_reports_user_errors_in_one_line(tmp_path, capsys):
    code = main(["--scenario", "backflip", "--duration", "1", "--out", str(tmp_path / "b"), *TINY])
    err = capsys.readouterr().err.strip()
    assert code == 1 and err.count("\n") == 0 and "backflip needs at least" in err
    code = main(["--scenario", "trot", "--duration", "0.1", "--exposure", "0.5", "--out", str(tmp_path / "c"),
                 *TINY])
    assert code == 1 and "exposure" in capsys.readouterr().err


def test_cli_failure_late_in_generation_leaves_no_partial_output(tmp_path, capsys, monkeypatch):
    import atsvo_ros.sim.writer as writer
    from atsvo_ros.errors import SimulationError

    def boom(*_a, **_k):
        raise SimulationError("disk full (injected)")

    out = tmp_path / "trot"
    args = ["--scenario", "trot", "--duration", "0.2", "--seed", "3", "--out", str(out), *TINY]
    with monkeypatch.context() as m:
        m.setattr(writer, "write_tum", boom)  # after the whole bag is written
        assert main(args) == 1
    assert "disk full" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert main(args) == 0 and (out / "metadata.yaml").is_file()
