"""``atsvo-bench``'s command line: every benchmark registered as a subcommand."""
from __future__ import annotations

import pytest

from atsvo_ros.bench.cli import SUBCOMMANDS, build_parser
from atsvo_ros.bench.events import bench_decode, main_events


def test_bench_front_end_and_decode_part_run():
    """Smoke test of ``atsvo-bench events`` (no timing asserted: benchmarks are not tests)."""
    assert "events" in SUBCOMMANDS
    args = build_parser().parse_args(["events", "--events", "1000", "--repeats", "1"])
    assert args.events == 1000 and args._target is main_events
    rows = bench_decode(3000, 1000, 1)
    assert {r["encoding"] for r in rows} >= {"libcaer_cmp", "libcaer", "mono", "evt3"}
    assert all(r["ours_eps"] > 0 and r["rosbags_eps"] > 0 for r in rows)


def test_an_unusable_out_is_refused_before_the_benchmark_runs(tmp_path, capsys, monkeypatch):
    from atsvo_ros.bench import real as real_mod
    from atsvo_ros.bench.cli import main

    monkeypatch.setattr(real_mod, "bench_folder", lambda *a, **k: pytest.fail("the benchmark ran before --out"))
    existing = tmp_path / "results.json"
    existing.touch()
    assert main(["real", str(tmp_path), "--no-paper", "--out", str(existing), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == f"atsvo-bench: error: --out {existing} is a file, not a folder", err


def test_the_tracking_benchmark_takes_the_sensor_settings():
    """--exposure / --contrast / --noise-rate / --ir-ambient reach the simulated sequence (and its cache key)."""
    from atsvo_ros.bench.tracking import _cache_file, sensor_settings
    from atsvo_ros.sim.sequence import SequenceSpec, with_sensors

    args = build_parser().parse_args(["tracking", "--exposure", "0.015", "--contrast", "0.3", "--noise-rate", "1",
                                      "--ir-ambient", "0.1"])
    given = sensor_settings(args)
    assert given == {"exposure_s": 0.015, "contrast": 0.3, "noise_rate_hz": 1.0, "ambient_ir": 0.1}
    assert sensor_settings(build_parser().parse_args(["tracking"])) == {}
    spec = SequenceSpec(scenario="backflip", duration_s=3.0, seed=1)
    assert _cache_file(with_sensors(spec, **given)) != _cache_file(spec)
