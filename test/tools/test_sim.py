"""``atsvo-sim`` command line: writes a bag directory; user errors give one line and exit code 1."""
from __future__ import annotations

import pytest
import yaml

from atsvo_ros.tools.sim import main

TINY = ["--width", "32", "--event-scale", "0.1", "--texture-size", "16", "--quiet"]


def test_cli_writes_a_sequence(tmp_path, capsys):
    out = tmp_path / "trot"
    code = main(["--scenario", "trot", "--duration", "0.2", "--seed", "3", "--out", str(out), "--format", "ros1",
                 *TINY])
    assert code == 0
    assert (out / "sequence.bag").is_file() and (out / "groundtruth.tum").is_file()
    assert (out / "sequence.yaml").is_file()
    err = capsys.readouterr().err
    assert "RGB-D frames" in err
    # what the sensors gave, per motion phase (the trot strikes the ground twice per stride: landing frames)
    assert "depth: d455" in err and "stance" in err and "landing" in err and "events/s" in err


def test_cli_depth_and_ir_options_reach_the_model(tmp_path):
    out = tmp_path / "b"
    assert main(["--scenario", "bound", "--duration", "0.2", "--out", str(out), "--ir-exposure", "0.004",
                 "--ir-ambient", "0.1", "--depth-phase", "0.005", *TINY]) == 0
    depth = yaml.safe_load((out / "sequence.yaml").read_text())["models"]["depth"]
    assert depth["sensor"] == "d455" and depth["exposure_s"] == 0.004 and depth["ambient_ir"] == 0.1
    assert depth["phase_s_this_seed"] == 0.005
    assert main(["--scenario", "bound", "--duration", "0.2", "--out", str(tmp_path / "s"), "--depth", "sharp",
                 *TINY]) == 0
    assert yaml.safe_load((tmp_path / "s" / "sequence.yaml").read_text())["models"]["depth"]["sensor"] == "sharp"


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


def test_cli_event_readout_options_reach_the_model(tmp_path):
    import yaml

    out = tmp_path / "trot"
    assert main(["--scenario", "trot", "--duration", "0.2", "--out", str(out), "--scan-period-us", "100",
                 "--refractory-us", "150", "--contrast", "0.3", *TINY]) == 0
    em = yaml.safe_load((out / "sequence.yaml").read_text())["models"]["events"]
    assert em["scan_period_s"] == pytest.approx(100e-6) and em["refractory_s"] == pytest.approx(150e-6)
    assert em["contrast_neg"] == 0.3
    assert 0 < em["scan_sweep_s"] < 100e-6  # the column sweep keeps its share of the scan
    assert main(["--scenario", "trot", "--duration", "0.2", "--out", str(tmp_path / "a"), "--scan-period-us", "0",
                 *TINY]) == 0


def test_demo_cache_key_changes_with_the_simulator_model(tmp_path, monkeypatch):
    """A cached demo sequence is keyed on the simulator's model identity: a new model version or a changed
    default of a sensor model (here the event readout) never replays a sequence generated before."""
    import dataclasses

    import atsvo_ros.sim.sequence as seq
    from atsvo_ros.sim.events import EventModel
    from atsvo_ros.tools.demo import sequence_path

    before = sequence_path(tmp_path, "backflip", 3.0, 0)
    assert seq.model_key() in before.name
    monkeypatch.setattr(seq, "MODEL_VERSION", seq.MODEL_VERSION + 1)
    bumped = sequence_path(tmp_path, "backflip", 3.0, 0)
    monkeypatch.undo()
    faster = dataclasses.field(default_factory=lambda: EventModel(scan_period_s=100e-6, scan_sweep_s=90e-6))
    changed = dataclasses.make_dataclass("SequenceSpec", [("event_model", EventModel, faster)],
                                         bases=(seq.SequenceSpec,), frozen=True)
    monkeypatch.setattr(seq, "SequenceSpec", changed)
    assert len({before, bumped, sequence_path(tmp_path, "backflip", 3.0, 0)}) == 3
