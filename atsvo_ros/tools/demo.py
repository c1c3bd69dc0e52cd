"""``atsvo-demo``: generate a synthetic legged-robot sequence (cached), replay it in every mode, score it.

On a fresh machine with no data: the simulator writes the default backflip sequence once into
the cache (``$ATSVO_CACHE`` or ``~/.cache/atsvo_ros``), then the odometry replays it in each mode
the pipeline has (RGB-D, and fused once the core fuses events), and a table of ATE, RPE, divergence
and real-time factor is printed; trajectories, metrics and plots go to ``--out`` (one folder per mode).
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from atsvo_ros.config import load_config
from atsvo_ros.errors import ConfigError, SimulationError
from atsvo_ros.eval.metrics import ASSOCIATION_TEXT, describe_alignment
from atsvo_ros.eval.plots import plot_comparison
from atsvo_ros.sim.sequence import SequenceSpec, model_key
from atsvo_ros.tools._cli import prepare_out_dir, run
from atsvo_ros.tools._help import description
from atsvo_ros.tools.replay import replay
from atsvo_ros.tools.sim import main as sim_main

DEFAULT_SCENARIO = "backflip"
DEFAULT_DURATION_S = 3.0
CACHE_VERSION = 1  # bump when the simulator's output for a given spec changes


def cache_dir(override: str | None = None) -> Path:
    """``--cache``, else ``$ATSVO_CACHE``, else ``~/.cache/atsvo_ros``."""
    if override:
        return Path(override).expanduser()
    env = os.environ.get("ATSVO_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "atsvo_ros"


def cache_source(override: str | None = None) -> str:
    """Where :func:`cache_dir` took the folder from, as error messages name it: ``--cache``, ``ATSVO_CACHE``
    or ``cache directory`` (the default)."""
    if override:
        return "--cache"
    return "ATSVO_CACHE" if os.environ.get("ATSVO_CACHE") else "cache directory"


def sequence_path(cache: Path, scenario: str, duration_s: float, seed: int, sim_args: Sequence[str] = ()) -> Path:
    """Where the bag of one (scenario, duration, seed, extra simulator options) lives in the cache; the key
    includes the simulator's model identity, so a changed sensor model never replays an old sequence."""

    extra = "".join(f"_{a.lstrip('-')}" for a in sim_args)
    return cache / f"sim_v{CACHE_VERSION}_{model_key()}_{scenario}_{duration_s:g}s_seed{seed}{extra}"


class SimulatorExitError(SimulationError):
    """``atsvo-sim`` exited with an error that it has already printed on stderr (its own one line).

    ``atsvo-demo`` exits with ``code`` without printing a second line about the same failure; a library
    caller gets the exception as any :class:`SimulationError`.
    """

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code

    def __reduce__(self):  # keep ``code`` through pickling (multiprocessing)
        return (type(self), (str(self), self.code))


def check_sequence(scenario: str, duration_s: float, seed: int, width: int | None = None, height: int | None = None,
                   event_scale: float | None = None) -> None:
    """Check the sequence's options as ``atsvo-sim`` will, before anything is created or generated.

    Why: a bad ``--seed`` or ``--duration`` is then one line of ``atsvo-demo`` naming the value, not the
    simulator's error followed by the demo's report of the simulator's failure.

    Raises:
        SimulationError: an unknown scenario or a value out of the simulator's range (the message names it).
    """
    SequenceSpec(scenario=scenario, duration_s=duration_s, seed=seed, width=width, height=height,
                 event_scale=1.0 if event_scale is None else event_scale)


def simulate(out: Path, scenario: str, duration_s: float, seed: int, sim_args: Sequence[str] = (),
             quiet: bool = False) -> None:
    """Write one synthetic sequence as an mcap bag with the simulator's CLI (``atsvo-sim``).

    Raises:
        SimulatorExitError: ``atsvo-sim`` returned a non-zero exit code (it printed why on stderr).
    """
    code = sim_main(["--scenario", scenario, "--duration", f"{duration_s:g}", "--seed", str(seed),
                     "--out", str(out), "--format", "mcap", *sim_args, *(["--quiet"] if quiet else [])])
    if code:
        raise SimulatorExitError(f"atsvo-sim failed (exit code {code}) for scenario {scenario}, {duration_s:g} s", code)


def ensure_sequence(cache: Path, scenario: str, duration_s: float, seed: int, regenerate: bool = False,
                    sim_args: Sequence[str] = (), quiet: bool = False, what: str = "cache directory") -> Path:
    """The cached bag, generated on first use (into a temporary folder, then moved: never half-written).

    Raises:
        OutputError: the sequence must be generated and ``cache`` is a file or not writable (the message names
            the folder as ``what``, e.g. ``ATSVO_CACHE``).
    """
    final = sequence_path(cache, scenario, duration_s, seed, sim_args)
    if final.exists() and not regenerate:
        return final
    prepare_out_dir(cache, what=what)
    tmp = Path(tempfile.mkdtemp(prefix=".generating_", dir=cache))
    try:
        print(f"generating the synthetic {scenario} sequence ({duration_s:g} s, seed {seed}) into {final} ...")
        simulate(tmp / "seq", scenario, duration_s, seed, sim_args, quiet)
        if final.exists():
            shutil.rmtree(final)
        (tmp / "seq").rename(final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final


#: The modes the demo compares, side by side.
MODES = ("rgbd", "fused")


def _fmt(v: Any, scale: float = 1.0, digits: int = 3) -> str:
    return "n/a" if v is None else f"{v * scale:.{digits}f}"


def format_table(rows: list[dict[str, Any]]) -> str:
    """The summary table (one row per mode), in atsvo-replay's vocabulary.

    ``rows[i]["metrics"]`` is a metrics.json document (:meth:`EvalResult.to_json`). The columns are the
    ATE RMSE and the RPE per frame as RMSE (``extra``), as atsvo-replay and atsvo-eval print them;
    the lines under the table name the alignment behind the ATE and the association behind the RPE.
    """
    head = (f"{'mode':6s} {'ATE RMSE [cm]':>13s} {'RPE RMSE [deg/f]':>16s} {'RPE RMSE [cm/f]':>15s} "
            f"{'diverged':>9s} {'lost':>5s} {'reinit':>6s} {'RTF':>6s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        m = r.get("metrics") or {}
        x = m.get("extra") or {}
        div = "n/a" if not m else ("yes" if m.get("diverged") else "no")
        st = r.get("statuses")
        lost, reinit = ("n/a", "n/a") if st is None else (str(st.count("lost")), str(st.count("reinitialised")))
        rot, trans = _fmt(x.get("rpe_rot_deg_per_frame_rmse")), _fmt(x.get("rpe_trans_cm_per_frame_rmse"))
        lines.append(f"{r['mode']:6s} {_fmt(m.get('ate_rmse_m'), 100, 2):>13s} {rot:>16s} {trans:>15s} "
                     f"{div:>9s} {lost:>5s} {reinit:>6s} {r['rtf']:6.2f}")
    lines += _vocabulary(rows)
    lines.append("(ATE and RPE over every frame's pose, whatever its status; lost and reinit count the frames "
                 "with that status)")
    return "\n".join(lines)


def _vocabulary(rows: list[dict[str, Any]]) -> list[str]:
    """What the table's ATE and RPE are: the alignment (per mode where they differ) and the association."""
    extras = {r["mode"]: (r.get("metrics") or {}).get("extra") for r in rows}
    extras = {mode: x for mode, x in extras.items() if x}
    if not extras:
        return []
    aligned = {mode: describe_alignment(x.get("alignment")) for mode, x in extras.items()}
    if len(set(aligned.values())) == 1:
        ate = f"ATE RMSE (aligned: {next(iter(aligned.values()))})"
    else:
        ate = "ATE RMSE (aligned: " + "; ".join(f"{mode}: {text}" for mode, text in aligned.items()) + ")"
    associations = dict.fromkeys(ASSOCIATION_TEXT.get(x.get("association"), "association not recorded")
                                 for x in extras.values())
    return [ate, f"RPE per frame, RMSE, {', '.join(associations)}"]


def demo(out: Path, scenario: str = DEFAULT_SCENARIO, duration_s: float = DEFAULT_DURATION_S, seed: int = 0,
         cache: str | None = None, regenerate: bool = False, progress: bool | None = None,
         sim_args: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Generate (or reuse) the sequence, replay it in every mode, return one summary row per mode.

    ``sim_args`` are extra ``atsvo-sim`` options (e.g. ``["--width", "160"]``); they are part of
    the cache key. ``out`` and the cache are checked before the generation starts.
    """
    check_sequence(scenario, duration_s, seed)
    prepare_out_dir(out)
    bag = ensure_sequence(cache_dir(cache), scenario, duration_s, seed, regenerate, sim_args,
                          quiet=progress is False, what=cache_source(cache))
    rows = []
    evaluations = {}
    for mode in MODES:
        res = replay(bag, out / mode, load_config("synthetic"), mode=mode, progress=progress)
        rows.append({"mode": res.mode, "metrics": res.metrics, "rtf": res.real_time_factor, "statuses": res.statuses,
                     "out": str(out / mode), "notes": res.notes})
        if res.evaluation is not None:
            evaluations[res.mode] = res.evaluation
    if evaluations:
        plot_comparison(out / "comparison.png", evaluations,
                        title=f"{scenario}, {duration_s:g} s, seed {seed}: every mode against ground truth")
    return rows


def _main(args: argparse.Namespace) -> int:
    out = Path(args.out)
    sim_args: list[str] = []
    for flag in ("width", "height", "event_scale"):
        if getattr(args, flag) is not None:
            sim_args += [f"--{flag.replace('_', '-')}", f"{getattr(args, flag):g}"]
    check_sequence(args.scenario, args.duration, args.seed, args.width, args.height, args.event_scale)
    if args.max_ate_cm is not None and not args.max_ate_cm > 0:  # NaN too: no run could pass it
        raise ConfigError(f"--max-ate-cm must be a positive number of centimetres, got {args.max_ate_cm:g}")
    try:
        rows = demo(out, args.scenario, args.duration, args.seed, args.cache, args.regenerate,
                    progress=False if args.no_progress else None, sim_args=sim_args)
    except SimulatorExitError as exc:  # atsvo-sim printed its one line already: exit as it did, no second line
        return exc.code
    print(f"\n{args.scenario}, {args.duration:g} s, seed {args.seed} (synthetic, ground truth known)")
    print(format_table(rows))
    for note in sorted({n for r in rows for n in r["notes"] if n.startswith("RGB-D only")}):
        print(f"note: {note}")
    for r in rows:
        for note in r["notes"]:
            if note.startswith("warning: "):
                print(f"atsvo-demo: {r['mode']}: {note}", file=sys.stderr)
    print(f"\ntrajectories, metrics.json and plots in {out}/<mode>/; all modes side by side in "
          f"{out / 'comparison.png'}")
    if args.max_ate_cm is not None:
        return check_accuracy(rows, args.max_ate_cm)
    return 0


def check_accuracy(rows: list[dict[str, Any]], max_ate_cm: float) -> int:
    """Exit code 1 (with one line per failing mode) when a mode has no metrics or an ATE above the limit."""
    failed = 0
    for r in rows:
        ate = (r.get("metrics") or {}).get("ate_rmse_m")
        if ate is None or not ate * 100.0 <= max_ate_cm:
            got = "no metrics" if ate is None else f"ATE {ate * 100.0:.2f} cm"
            print(f"atsvo-demo: check failed: mode {r['mode']}: {got} (limit {max_ate_cm:g} cm)", file=sys.stderr)
            failed = 1
    return failed


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``atsvo-demo``."""
    parser = argparse.ArgumentParser(prog="atsvo-demo", description=description(__doc__))
    parser.add_argument("--scenario", default=DEFAULT_SCENARIO,
                        help=f"synthetic motion (default {DEFAULT_SCENARIO}; see atsvo-sim --help)")
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION_S,
                        help=f"sequence length in seconds (default {DEFAULT_DURATION_S:g})")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the scene and motion (default 0)")
    parser.add_argument("--out", default="atsvo_demo", help="output directory (default ./atsvo_demo)")
    parser.add_argument("--cache", help="cache directory (default $ATSVO_CACHE or ~/.cache/atsvo_ros)")
    parser.add_argument("--regenerate", action="store_true", help="regenerate the cached sequence")
    parser.add_argument("--width", type=int, help="colour image width (default 640; smaller is faster)")
    parser.add_argument("--height", type=int, help="colour image height (default 480)")
    parser.add_argument("--event-scale", type=float, help="event sensor scale (default 1; smaller is faster)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument("--max-ate-cm", type=float, metavar="CM",
                        help="exit with code 1 if any mode's ATE RMSE exceeds this (a smoke test of the install)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``atsvo-demo``."""
    return run(_main, build_parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
