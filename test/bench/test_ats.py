"""``atsvo-bench ats-basin``: the basin rule, the surfaces by rule name, and one small synthetic measurement."""
from __future__ import annotations

import numpy as np
import pytest

from atsvo_ros.bench.ats import RULES, basin, bench_synthetic, make_surface
from atsvo_ros.bench.cli import build_parser, main
from atsvo_ros.config import AtsConfig, TrackerConfig
from atsvo_ros.core.events.time_surface import AdaptiveTimeSurface, ConstantTimeSurface, SpeedInvariantTimeSurface


def test_basin_is_the_last_offset_of_the_leading_run_of_successes():
    offsets = [1, 2, 3, 4, 6]
    assert basin(offsets, [1.0, 0.9, 0.8, 0.5, 1.0]) == 3  # a later success does not count
    assert basin(offsets, [0.7, 1.0, 1.0, 1.0, 1.0]) == 0.0
    assert basin(offsets, [1.0] * 5) == 6


def test_rules_map_to_the_surfaces_and_tau_modes():
    kinds = {r: make_surface(r, 20, 10, AtsConfig()) for r in RULES}
    assert isinstance(kinds["constant"], ConstantTimeSurface) and isinstance(kinds["sits"], SpeedInvariantTimeSurface)
    for mode in ("fire_age", "mean_age", "eq2_printed"):
        assert isinstance(kinds[mode], AdaptiveTimeSurface) and kinds[mode].cfg.tau_mode == mode


def test_subcommand_is_registered_and_rejects_unknown_rules(capsys):
    args = build_parser().parse_args(["ats-basin", "--parts", "real", "--rules", "fire_age"])
    assert args.rules == "fire_age"
    assert main(["ats-basin", "--parts", "real", "--rules", "fire_age,fancy"]) == 1
    assert "unknown rule" in capsys.readouterr().err


@pytest.mark.parametrize("rule", ["fire_age", "mean_age"])
def test_synthetic_pair_converges_from_a_small_offset(rule):
    """A sparse scene at 1000 px/s: on one pyramid level the ATS term pulls a guess 2 px off back to the truth
    in every direction (the table's basins start at 3 px or more)."""
    rows = bench_synthetic([rule], [1], ["sparse"], [1000.0], 1, [1.0, 2.0], TrackerConfig(), progress=False)
    (row,) = rows
    assert row["pairs"] == 1
    for d in ("all", "lag", "lead"):
        assert np.all(np.array(row[f"success_{d}"]) == 1.0), row
