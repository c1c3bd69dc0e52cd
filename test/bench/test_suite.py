"""atsvo-bench's report: results.json -> results.md -> the README block (nothing measured here)."""
from __future__ import annotations

from pathlib import Path

import pytest

from atsvo_ros.bench.report import README_BEGIN, README_END, markdown
from atsvo_ros.bench.suite import QUICK, update_readme
from atsvo_ros.errors import ConfigError


def _acc(scenario: str, seed: int, mode: str, ate_cm: float, lost: int = 0) -> dict:
    return {"scenario": scenario, "seed": seed, "mode": mode, "ate_rmse_cm": ate_cm, "rpe_deg_per_deg": 0.5,
            "rpe_cm_per_deg": 0.8, "diverged": ate_cm > 10, "statuses": {"ok": 89, "lost": lost},
            "modes": {"fused": 40, "rgbd": 50}, "frames": 90, "lost": lost, "reinitialised": 0,
            "phases": {"stance": {"ate_rmse_cm": ate_cm / 2, "rpe_deg_per_frame": 0.1, "rpe_cm_per_frame": 0.2},
                       "flight": {"ate_rmse_cm": ate_cm * 2, "rpe_deg_per_frame": 1.5, "rpe_cm_per_frame": 2.0}}}


def _results() -> dict:
    import dataclasses

    settings = dataclasses.asdict(QUICK)
    return {
        "plan": "quick", "settings": settings, "generation_s": 12.0, "measure_s": 240.0, "total_s": 252.0,
        "machine": {"date": "2026-11-22", "cpus": 2, "platform": "Linux", "python": "3.12",
                    "versions": {"numpy": "2.1", "numba": "0.60"}, "load_avg_1min_at_start": 0.3},
        "speed": {"time_surfaces": [{"input": "real 320x240", "ats_update_eps": 700e6, "sits_update_eps": 30e6,
                                     "ats_render_ms": 0.22, "dv_timesurface_accept_eps": 430e6,
                                     "dv_sits_accept_eps": 80e6, "dv_timesurface_generateFrame_ms": 0.18}],
                  "decode_real": [], "decode": []},
        "accuracy": [_acc("backflip", 0, "fused", 2.77), _acc("backflip", 0, "rgbd", 65.0, lost=3),
                     _acc("bound", 0, "fused", 1.1), _acc("bound", 0, "rgbd", 1.4)],
        "timing": [{"mode": "fused", "scenario": "backflip", "seed": 0, "frames": 90, "ms_median": 21.0,
                    "ms_p95": 40.0, "ms_max": 80.0, "fused_ms_median": 25.0}],
        "replay": [{"sequence": "backflip_3s", "mode": "fused", "frames": 90, "rtf": 0.8, "peak_rss_mb": 410.0,
                    "track_ms_median": 21.0, "metrics": {"ate_rmse_m": 0.0277}}],
        "real": {"skipped": "open3d not installed"},
    }


def test_markdown_has_every_section_with_the_measured_values() -> None:
    md = markdown(_results())
    assert "## Speed of the event front end" in md
    assert "700 M ev/s" in md and "dv-processing TimeSurface.accept 430 M ev/s" in md
    # the speed-invariant surface is below its peer: the table must say so, not hide it
    sits_row = next(line for line in md.splitlines() if line.startswith("| speed-invariant TS update"))
    assert sits_row.rstrip(" |").endswith("no")
    assert "| backflip seed 0 |" in md and "2.77" in md and "65.00 (div.)" in md
    # the status summary counts the lost frames of the RGB-D run
    rgbd_row = next(line for line in md.splitlines() if line.startswith("| rgbd | 65.00"))
    assert "| 3 |" in rgbd_row
    assert "## Real RGB-D data" in md and "Skipped: open3d not installed" in md
    assert "backflip_3s" in md and "2.77" in md


def test_readme_block_is_replaced_and_the_rest_kept(tmp_path: Path) -> None:
    readme = tmp_path / "README.md"
    readme.write_text(f"# pkg\n\nintro\n\n## Results\n\n{README_BEGIN}\nold table\n{README_END}\n\n## After\n")
    md = tmp_path / "results.md"
    md.write_text(markdown(_results()))
    fig = tmp_path / "backflip.png"
    fig.write_bytes(b"\x89PNG\r\n\x1a\n")
    full = update_readme(readme, _results(), md, fig)
    text = readme.read_text()
    assert "old table" not in text and text.startswith("# pkg\n\nintro") and text.endswith("## After\n")
    # the README gets the headline per gait; docs/results.md everything, the accuracy per motion phase too
    assert "| backflip | 65.00 (65.00) |" in text and "### Accuracy per motion phase" not in text
    assert "| backflip | rgbd | 65.00 | 65.00 | 32.50 / 0.100 / 0.20 | 130.00 / 1.500 / 2.00 | - | 3 |" in \
        full.read_text()
    assert "### Speed of the event front end" not in text and "(docs/results.md)" in text
    assert full == tmp_path / "docs" / "results.md" and "## Speed of the event front end" in full.read_text()
    assert "(docs/results_backflip.png)" in text and (tmp_path / "docs" / "results_backflip.png").is_file()
    # idempotent: a second fill gives the same files
    update_readme(readme, _results(), md, fig)
    assert readme.read_text() == text


def test_readme_without_markers_is_a_clear_error(tmp_path: Path) -> None:
    readme = tmp_path / "README.md"
    readme.write_text("# pkg\n")
    md = tmp_path / "results.md"
    md.write_text(markdown(_results()))
    with pytest.raises(ConfigError, match="no .* block"):
        update_readme(readme, _results(), md, None)


def test_runs_in_successive_pools_all_complete() -> None:
    """More tasks than one pool's share: every result comes back (max_tasks_per_child hung here: CPython gh-115634)."""
    from atsvo_ros.bench.suite import _in_pools

    assert sorted(_in_pools(divmod, [(k, 3) for k in range(7)], jobs=1, per_worker=2)) == \
        sorted(divmod(k, 3) for k in range(7))
