"""Shared CLI plumbing: turn AtsvoError (and user errors) into one line on stderr and exit code 1."""
from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from atsvo_ros.errors import AtsvoError, OutputError
from atsvo_ros.io.paths import ensure_writable_folder


def run(main: Callable[[argparse.Namespace], int | None], parser: argparse.ArgumentParser,
        argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, call ``main(args)``; map known errors to a one-line message and exit code 1."""
    args = parser.parse_args(argv)
    prog = parser.prog
    try:
        code = main(args)
    except AtsvoError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    except FileNotFoundError as exc:
        print(f"{prog}: error: file not found: {exc.filename or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `atsvo-eval ... | head`: the reader left; not an error of ours
        _silence_stdout()
        return 0
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
    return int(code or 0)


def _silence_stdout() -> None:
    """Point stdout at /dev/null so Python's exit flush does not raise again on the closed pipe."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def prepare_out_dir(path: str | Path, what: str = "--out") -> Path:
    """Create the output folder ``path`` now and prove it writable, before any long work starts.

    Raises:
        OutputError: one line naming the problem: a file where the folder (or a parent) should be,
            no permission, a read-only file system.
    """
    out = Path(path)
    ensure_writable_folder(out, out, what, OutputError)
    return out


def add_config_args(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    """``--config`` (a YAML file or a bundled preset name) and repeatable ``--set key=value``."""
    parser.add_argument("--config", default=default,
                        help="ROS-parameter YAML or preset name (mini_cheetah, mvsec, synthetic)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override one parameter, e.g. --set ats.tau_u_s=0.05 (YAML value syntax)")


