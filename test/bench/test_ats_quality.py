"""``atsvo-bench ats-quality``: the figures per half, and the white-out the paper's argument is about."""
from __future__ import annotations

import numpy as np

from atsvo_ros.bench.ats_quality import bench_quality, mixed_canvas, surface_quality
from atsvo_ros.bench.cli import main


def test_quality_figures_on_a_known_surface():
    s = np.zeros((40, 80), np.float32)
    s[:20, :20] = 255.0  # one saturated block in the dense (left) half
    s[25, 45] = 100.0  # one pixel above h in the sparse half
    uv = np.array([[5.0, 5.0], [45.0, 25.0], [46.0, 25.0]])
    q = surface_quality(s, uv, h=60.0)
    assert q["dense"]["saturated"] == 0.25 and q["dense"]["empty"] == 0.75 and q["dense"]["selected"] == 1
    assert q["sparse"]["saturated"] == 0.0 and q["sparse"]["empty"] == 0.75 and q["sparse"]["selected"] == 2
    assert q["dense"]["spread"] == 0.25 and q["sparse"]["spread"] == 0.25


def test_mixed_canvas_is_dense_left_and_sparse_right():
    c = mixed_canvas(256)
    gx = np.abs(np.diff(c, axis=1))
    assert (gx[:, :128] > 0.05).mean() > 3 * (gx[:, 128:] > 0.05).mean()


def test_constant_tau_whites_out_dense_texture_at_flip_speed_and_the_ats_does_not():
    """The paper's argument, measured (2640 px/s = a 560 deg/s flip at f = 270 px): with the default 30 ms a
    constant-tau surface saturates 44 % of the dense half, the ATS 7 % (benchmark, 2 scenes each)."""
    rows = {r["rule"]: r for r in bench_quality(["fire_age", "constant"], {"flip": 2640.0}, 1, 2.0, progress=False)}
    assert rows["constant"]["dense_saturated"] > 0.3
    assert rows["fire_age"]["dense_saturated"] < 0.15
    slow = {r["rule"]: r for r in bench_quality(["fire_age", "constant"], {"trot": 235.0}, 1, 2.0, progress=False)}
    assert slow["constant"]["dense_saturated"] < 0.05 and slow["fire_age"]["dense_saturated"] < 0.05


def test_subcommand_rejects_unknown_rules(capsys):
    assert main(["ats-quality", "--rules", "fire_age,fancy"]) == 1
    assert "unknown rule" in capsys.readouterr().err
