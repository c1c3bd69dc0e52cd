"""``atsvo-eval GT EST``: ATE / RPE of a TUM trajectory against TUM ground truth, metrics.json and plots.

Alignment ``paper`` (default) is the paper's protocol: SE(3) Umeyama on the first ``--align-s``
seconds of matched poses (at most 20 % of them), then one body-frame rotation that sets the first
orientation to ground truth's; ``se3`` / ``sim3``
align over all matched poses (like ``evo_ape -a`` / ``-as``); ``none`` compares as is.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

from atsvo_ros.eval.metrics import EvalOptions, evaluate, format_metrics
from atsvo_ros.eval.plots import plot_run
from atsvo_ros.io.trajectory import read_tum
from atsvo_ros.tools._cli import run


def _main(args: argparse.Namespace) -> int:
    opts = EvalOptions(align=args.align, align_s=args.align_s, max_diff_s=args.t_max_diff, delta_deg=args.delta_deg,
                       interpolate_gt=args.interpolate)
    gt, est = read_tum(args.gt), read_tum(args.est)
    result = evaluate(gt, est, opts)
    print(format_metrics(result.metrics))
    if result.partial is not None:
        p = result.partial.metrics
        print(f"before divergence:   ATE {p['ate_rmse_m'] * 100:.2f} cm over {p['n_matched']} poses")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text(json.dumps(result.to_json(), indent=2) + "\n")
        if not args.no_plots:
            plot_run(out, est, result, title=Path(args.est).stem)
        print(f"wrote {out / 'metrics.json'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (kept separate for the docs and the tests)."""
    parser = argparse.ArgumentParser(prog="atsvo-eval", description=__doc__.splitlines()[0])
    parser.add_argument("gt", help="ground truth, TUM format (t tx ty tz qx qy qz qw)")
    parser.add_argument("est", help="estimate, TUM format")
    parser.add_argument("--align", choices=("paper", "se3", "sim3", "none"), default="paper",
                        help="alignment of the estimate onto ground truth (default: paper)")
    parser.add_argument("--align-s", type=float, default=2.0,
                        help="paper alignment: seconds of matched poses used for the SE(3) step (default 2)")
    parser.add_argument("--t-max-diff", type=float, default=0.01,
                        help="max stamp difference when associating poses, seconds (default 0.01, like evo)")
    parser.add_argument("--interpolate", action="store_true",
                        help="interpolate ground truth at the estimate stamps (pairs stay the same)")
    parser.add_argument("--delta-deg", type=float, default=1.0,
                        help="ground-truth rotation per segment for the per-degree RPE (default 1)")
    parser.add_argument("--out", help="directory for metrics.json and plots")
    parser.add_argument("--no-plots", action="store_true", help="write metrics.json only")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-eval``."""
    return run(_main, build_parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
