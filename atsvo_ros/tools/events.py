"""``atsvo-events``: look inside event recordings.

* ``atsvo-events stats PATH [--topic T] [--json]`` -- resolution, encoding, event counts, time span,
  rate and checksums (``sum_t`` is the int64 ns timestamps summed modulo 2**64, like the reference
  decoders' checksum processors; ``sum_p`` counts ON events). Times are as the encoding carries them:
  evt3 and Prophesee RAW report the camera clock, the others ROS time. Like ``ros2 bag info``, for
  events; reads ROS 1/2 bags (EventPacket in every encoding, dvs/dv_ros2 EventArray), .mcap/.db3,
  .aedat4, Prophesee .raw and MVSEC .hdf5. A file that cannot be opened gives one error line and exit
  code 1; records that cannot be read mid-stream are skipped: the figures of what could be read are
  printed, followed by one error line naming the file, topic and what was skipped, and exit code 1.
* ``atsvo-events render PATH --out DIR`` -- the paper's Fig. 4 and 5 for a recording: constant-tau
  time surface next to the ATS at the slowest and the fastest moment (by event rate), and the event
  pixel selection on the ATS (candidates rejected by the mask or by Eq. 3 in red, selected in green).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from atsvo_ros.config import load_config, parse_overrides
from atsvo_ros.io.event_files import open_events
from atsvo_ros.tools._cli import add_config_args, run
from atsvo_ros.tools._help import description
from atsvo_ros.tools.events_render import render_figures

STATS_KEYS = ("width", "height", "encoding", "n_events", "n_on", "n_off", "t_first_ns", "t_last_ns", "duration",
              "rate", "sum_t", "sum_x", "sum_y", "sum_p")


def event_stats(path: str | Path, topic: str | None = None, progress: bool = False) -> tuple[dict, object]:
    """Counts, time span and checksums of every event in a recording (streamed, constant memory).

    Returns ``(stats, source)``; ``stats`` has exactly :data:`STATS_KEYS`.
    """


    src = open_events(path, topic, drop_backwards=False)
    n = n_on = 0
    sum_t = 0
    sum_x = sum_y = 0
    t_first = t_last = None
    with tqdm(total=src.n_messages or None, unit="msg", disable=not progress, file=sys.stderr) as bar:
        for b in src:
            bar.update(max(0, src.stats.n_messages - bar.n) if src.kind in ("bag1", "bag2") else 1)
            if len(b) == 0:
                continue
            n += len(b)
            n_on += int(np.count_nonzero(b.p))
            sum_t = (sum_t + int(b.t.view(np.uint64).sum(dtype=np.uint64))) % (1 << 64)
            sum_x += int(b.x.sum(dtype=np.int64))
            sum_y += int(b.y.sum(dtype=np.int64))
            lo, hi = int(b.t.min()), int(b.t.max())
            t_first = lo if t_first is None else min(t_first, lo)
            t_last = hi if t_last is None else max(t_last, hi)
    duration = (t_last - t_first) * 1e-9 if n else 0.0
    stats = {
        "width": int(src.width), "height": int(src.height), "encoding": src.encoding,
        "n_events": n, "n_on": n_on, "n_off": n - n_on,
        "t_first_ns": t_first if n else 0, "t_last_ns": t_last if n else 0,
        "duration": duration, "rate": n / duration if duration > 0 else 0.0,
        "sum_t": sum_t, "sum_x": sum_x, "sum_y": sum_y, "sum_p": n_on,
    }
    return stats, src


def _print_stats(path: str, stats: dict, src) -> None:
    where = f"{src.topic} ({src.msgtype})" if src.topic else src.kind
    s = src.stats
    print(f"path:        {path}")
    print(f"stream:      {where}, {s.n_messages} messages")
    print(f"resolution:  {stats['width']}x{stats['height']}")
    print(f"encoding:    {stats['encoding']}")
    print(f"events:      {stats['n_events']:,} ({stats['n_on']:,} ON, {stats['n_off']:,} OFF)")
    print(f"time:        {stats['t_first_ns']} .. {stats['t_last_ns']} ns ({stats['duration']:.6f} s)")
    print(f"rate:        {stats['rate'] / 1e6:.3f} M events/s")
    print(f"checksums:   sum_t {stats['sum_t']}  sum_x {stats['sum_x']}  sum_y {stats['sum_y']}  "
          f"sum_p {stats['sum_p']}")
    dropped = {k: v for k, v in (("out of range", s.dropped_out_of_range), ("broken messages", s.dropped_messages),
                                 ("unknown words", s.n_unknown_words), ("trigger events", s.n_trigger)) if v}
    if dropped:
        print("not counted: " + ", ".join(f"{v:,} {k}" for k, v in dropped.items()))


def _stats(args: argparse.Namespace) -> int:
    stats, src = event_stats(args.path, args.topic, progress=not args.json)
    if args.json:
        print(json.dumps(stats, indent=2))
    else:
        _print_stats(args.path, stats, src)
    if src.report is not None and not src.report.clean:
        topic = f" topic {src.topic}:" if src.topic else ""
        print(f"atsvo-events: error:{topic} incomplete read, the figures above cover what could be read; "
              f"{src.report.summary()}", file=sys.stderr)
        return 1
    return 0


def _render(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, overrides=parse_overrides(args.set))
    written = render_figures(args.path, args.out, cfg, topic=args.topic, bin_s=args.bin, progress=True)
    for p in written:
        print(f"wrote {p}")
    return 0


def _bin_seconds(text: str) -> float:
    """``--bin``: a window in seconds, finite, at least 1 us (the event clock) and at most an hour."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not (math.isfinite(v) and 1e-6 <= v <= 3600.0):
        raise argparse.ArgumentTypeError(f"must be a window in seconds from 1e-06 (the event clock) to 3600, "
                                         f"got {text}")
    return v


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``atsvo-events`` (sub-commands ``stats`` and ``render``)."""
    p = argparse.ArgumentParser(prog="atsvo-events", description=description(__doc__))
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("stats", help="counts, time span, rate and checksums of an event recording")
    s.add_argument("path", help="bag (ROS 1/2), .mcap, .db3, .aedat4, .raw or MVSEC .hdf5")
    s.add_argument("--topic", default=None, help="event topic in a bag (default: the only one)")
    s.add_argument("--json", action="store_true", help=f"print JSON with exactly the keys {', '.join(STATS_KEYS)}")
    s.set_defaults(func=_stats)
    r = sub.add_parser("render", help="Fig. 4/5: constant-tau TS vs ATS at slow and fast motion, selected pixels")
    r.add_argument("path", help="bag (ROS 1/2), .mcap, .db3, .aedat4, .raw or MVSEC .hdf5")
    r.add_argument("--out", required=True, help="output directory for the PNGs")
    r.add_argument("--topic", default=None, help="event topic in a bag (default: the only one)")
    r.add_argument("--bin", type=_bin_seconds, default=None,
                   help="window (s, 1e-06 to 3600) over which the event rate is measured to find the slow/fast "
                        "moments (default: the ATS tau_u)")
    add_config_args(r, default=None)
    r.set_defaults(func=_render)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    return run(lambda a: a.func(a), build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
