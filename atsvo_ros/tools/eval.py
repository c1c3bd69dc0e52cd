"""``atsvo-eval GT EST``: ATE / RPE of a TUM trajectory against TUM ground truth, metrics.json and plots.

Alignment ``paper`` (default) is the paper's protocol: SE(3) Umeyama on the first ``--align-s``
seconds of matched poses (at most 20 % of them), then one body-frame rotation that sets the first
orientation to ground truth's; ``se3`` / ``sim3``
align over all matched poses (like ``evo_ape -a`` / ``-as``); ``origin`` puts the first pose onto ground truth's
(``evo_ape --align_origin``: the odometry's drift as a controller sees it); ``none`` compares as is.

Poses are paired with the nearest ground-truth stamp within ``--t-max-diff``; ground truth is then
interpolated at the estimate stamps, as atsvo-replay does, so both print the same numbers for the
same trajectory (``--nearest-gt``: use the nearest ground-truth pose itself, as ``evo`` does by
default). The estimate's stamps must increase line by line (a repeated stamp would be matched twice);
the ground truth's must not go back (a repeated one keeps its first pose, with a warning).
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from atsvo_ros.eval.metrics import ALIGN_METHODS, EvalOptions, evaluate, format_metrics, metrics_json
from atsvo_ros.eval.plots import plot_run
from atsvo_ros.io.trajectory import read_tum
from atsvo_ros.tools._cli import prepare_out_dir, run
from atsvo_ros.tools._help import description


def _main(args: argparse.Namespace) -> int:
    out = prepare_out_dir(args.out) if args.out else None  # a bad --out fails before any work
    opts = EvalOptions(align=args.align, align_s=args.align_s, max_diff_s=args.t_max_diff, delta_deg=args.delta_deg,
                       interpolate_gt=not args.nearest_gt)
    gt, est = read_tum(args.gt, order="nondecreasing"), read_tum(args.est, order="increasing")
    result = evaluate(gt, est, opts)
    doc = result.to_json()
    for note in doc["extra"]["notes"]:
        if note.startswith("warning: "):
            print(f"atsvo-eval: {note}", file=sys.stderr)
        else:
            print(f"note: {note}")
    print(format_metrics(doc))
    if result.partial is not None:
        p = result.partial.metrics
        print(f"before divergence:   ATE {p['ate_rmse_m'] * 100:.2f} cm over {p['n_matched']} poses")
    if out is not None:
        (out / "metrics.json").write_text(metrics_json(doc))
        if not args.no_plots:
            plot_run(out, est, result, title=Path(args.est).stem)
        print(f"wrote {out / 'metrics.json'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (kept separate for the docs and the tests)."""
    parser = argparse.ArgumentParser(prog="atsvo-eval", description=description(__doc__))
    parser.add_argument("gt", help="ground truth, TUM format (t tx ty tz qx qy qz qw)")
    parser.add_argument("est", help="estimate, TUM format")
    parser.add_argument("--align", choices=ALIGN_METHODS, default="paper",
                        help="alignment of the estimate onto ground truth (default: paper; origin: the first pose "
                             "onto ground truth's, the drift)")
    parser.add_argument("--align-s", type=float, default=2.0,
                        help="paper alignment: seconds of matched poses used for the SE(3) step (default 2)")
    parser.add_argument("--t-max-diff", type=float, default=0.01,
                        help="max stamp difference when associating poses, seconds (default 0.01, like evo)")
    assoc = parser.add_mutually_exclusive_group()
    assoc.add_argument("--nearest-gt", action="store_true",
                       help="pair each pose with the nearest ground-truth pose instead of interpolating ground truth "
                            "at its stamp (evo's default; atsvo-replay's --nearest-gt)")
    assoc.add_argument("--interpolate", action="store_true", help=argparse.SUPPRESS)  # the default now; kept working
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
