"""AEDAT 4 files (iniVation DV, the DVXplorer's own format) through the ``aedat`` package.

``pip install 'atsvo_ros[aedat]'``. The first event stream of the file is read; its packets are
yielded as :class:`EventBatch` (time in ns, converted from the file's microseconds).
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from atsvo_ros.core.events import EventBatch
from atsvo_ros.errors import DecodeError


def _decoder(path: str | Path):
    try:
        import aedat
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise DecodeError("reading .aedat4 needs the 'aedat' package: pip install 'atsvo_ros[aedat]'") from exc
    if not Path(path).is_file():
        raise FileNotFoundError(path)
    try:
        return aedat.Decoder(str(path))
    except Exception as exc:  # the Rust extension raises plain exceptions
        raise DecodeError(f"{path}: not a readable AEDAT 4 file ({exc})") from exc


def aedat4_event_stream(path: str | Path) -> tuple[int, int, int]:
    """(stream id, width, height) of the first event stream of an AEDAT 4 file."""
    dec = _decoder(path)
    for sid, info in sorted(dec.id_to_stream().items()):
        if info.get("type") == "events":
            return int(sid), int(info.get("width", 0)), int(info.get("height", 0))
    raise DecodeError(f"{path}: no event stream in this AEDAT 4 file")


def iter_aedat4(path: str | Path) -> Iterator[EventBatch]:
    """Event packets of the first event stream, in file order."""
    sid, width, height = aedat4_event_stream(path)
    for packet in _decoder(path):
        if packet.get("stream_id") != sid or "events" not in packet:
            continue
        ev = packet["events"]
        yield EventBatch(ev["x"], ev["y"], ev["t"].astype(np.int64) * 1000, ev["on"].astype(np.uint8), width, height)
