"""AEDAT 4 files (iniVation DV, the DVXplorer's own format) through the ``aedat`` package.

``pip install 'atsvo_ros[aedat]'``. The first event stream of the file is read; its packets are
yielded as :class:`EventBatch` (time in ns, converted from the file's microseconds).
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.read_report import ReadReport, describe


def _decoder(path: str | Path):
    try:
        import aedat
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise DecodeError("reading .aedat4 needs the 'aedat' package: pip install 'atsvo_ros[aedat]'") from exc
    if not Path(path).is_file():
        raise FileNotFoundError(path)
    try:
        return aedat.Decoder(str(path))
    except (RuntimeError, OSError, ValueError) as exc:  # the Rust extension's errors on bad data
        raise DecodeError(f"{path}: not a readable AEDAT 4 file ({describe(exc)})") from None


def aedat4_event_stream(path: str | Path) -> tuple[int, int, int]:
    """(stream id, width, height) of the first event stream of an AEDAT 4 file."""
    dec = _decoder(path)
    for sid, info in sorted(dec.id_to_stream().items()):
        if info.get("type") == "events":
            return int(sid), int(info.get("width", 0)), int(info.get("height", 0))
    raise DecodeError(f"{path}: no event stream in this AEDAT 4 file")


def iter_aedat4(path: str | Path, report: ReadReport | None = None) -> Iterator[EventBatch]:
    """Event packets of the first event stream, in file order.

    A packet the ``aedat`` decoder cannot read (bad LZ4 block, corrupt flatbuffer) is skipped and
    counted in ``report`` (as undecodable on the ``events`` topic); a file that ends early stops
    the iteration, noted in ``report.stopped``. Without ``report`` both raise :class:`DecodeError`.
    """
    sid, width, height = aedat4_event_stream(path)
    it = iter(_decoder(path))
    n_packets = failures = 0
    counts = report.topic("events") if report is not None else None
    while True:
        try:
            packet = next(it)
        except StopIteration:
            break
        except (RuntimeError, OSError, ValueError) as exc:  # the Rust extension's errors on bad data
            where = f"packet {n_packets + failures + 1}: {describe(exc)}"
            truncated = "fill whole buffer" in str(exc)
            if report is None:
                raise DecodeError(f"{path}: {where}", "truncated" if truncated else "malformed") from None
            report.add_error(where)
            failures += 1
            counts.undecodable += 1
            if truncated or failures - n_packets > 3:
                report.stopped = "the file ends early (truncated)" if truncated else "repeated read errors"
                break
            continue
        n_packets += 1
        if counts is not None:
            counts.read += 1
        if packet.get("stream_id") != sid or "events" not in packet:
            continue
        ev = packet["events"]
        yield EventBatch(ev["x"], ev["y"], ev["t"].astype(np.int64) * 1000, ev["on"].astype(np.uint8), width, height)
    if report is not None:
        report.finished = True
