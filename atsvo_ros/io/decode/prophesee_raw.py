"""Prophesee RAW files (``% ...`` text header, then EVT 2.0 or EVT 3.0 words).

EVT 2.0: 32-bit words, type in bits 28-31 (0 CD_OFF, 1 CD_ON, 8 EV_TIME_HIGH, 10 EXT_TRIGGER,
14 OTHERS, 15 CONTINUED); a CD word holds 6 low time bits (22-27), x (11-21), y (0-10); time high
carries bits 6-33 of the microsecond clock. EVT 3.0 uses the same 16-bit stream as the evt3
EventPacket encoding (see :mod:`.packet`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.errors import DecodeError
from atsvo_ros.io.decode.packet import Evt3State, decode_evt3

#: sensor size by HAL plugin name when the header has no geometry line
_PLUGIN_SIZES = {"gen3": (640, 480), "gen31": (640, 480), "gen4": (1280, 720), "gen41": (1280, 720),
                 "imx636": (1280, 720), "imx646": (1280, 720), "gen3_fx3": (640, 480)}


@dataclass
class RawHeader:
    """What the text header of a RAW file says."""

    evt: str
    width: int
    height: int
    data_offset: int


def read_raw_header(data: bytes) -> RawHeader:
    """Parse the ``% key value`` lines at the start of a RAW file."""
    pos = 0
    lines = []
    while pos < len(data) and data[pos:pos + 1] == b"%":
        end = data.find(b"\n", pos)
        if end < 0:
            raise DecodeError("truncated RAW header")
        lines.append(data[pos + 1:end].decode(errors="replace").strip())
        pos = end + 1
    evt, width, height = "", 0, 0
    for line in lines:
        key, _, value = line.partition(" ")
        if key == "evt":
            evt = value.strip()
        elif key == "format":  # "EVT3;height=720;width=1280"
            fields = value.split(";")
            evt = {"EVT2": "2.0", "EVT21": "2.1", "EVT3": "3.0"}.get(fields[0].strip().upper(), evt)
            kv = dict(f.split("=", 1) for f in fields[1:] if "=" in f)
            width, height = int(kv.get("width", width)), int(kv.get("height", height))
        elif key == "geometry":
            m = re.match(r"(\d+)x(\d+)", value.strip())
            if m:
                width, height = int(m.group(1)), int(m.group(2))
        elif key == "plugin_name" and not width:
            for name, size in sorted(_PLUGIN_SIZES.items(), key=lambda kv: -len(kv[0])):
                if name in value:
                    width, height = size
                    break
    if evt not in ("2.0", "3.0"):
        raise DecodeError(f"unsupported RAW event format {evt or '(none in header)'!r}; supported: EVT 2.0, EVT 3.0")
    return RawHeader(evt, width, height, pos)


def decode_evt2(words: np.ndarray, width: int = 0, height: int = 0) -> tuple[EventBatch, int]:
    """Decode EVT 2.0 words; returns the CD events (time in ns) and the number of out-of-range ones."""
    typ = words >> 28
    is_th = typ == 8
    high = np.where(is_th, (words & 0x0FFFFFFF).astype(np.int64), -1)
    idx = np.where(is_th, np.arange(len(words)), -1)
    np.maximum.accumulate(idx, out=idx)
    has_high = idx >= 0
    cur_high = np.where(has_high, high[np.maximum(idx, 0)], 0)
    cd = (typ <= 1) & has_high
    w = words[cd]
    t_us = (cur_high[cd] << 6) | ((w >> 22) & 0x3F).astype(np.int64)
    x = ((w >> 11) & 0x7FF).astype(np.uint16)
    y = (w & 0x7FF).astype(np.uint16)
    p = typ[cd].astype(np.uint8)
    n_oob = 0
    if width and height:
        ok = (x < width) & (y < height)
        n_oob = int(len(ok) - np.count_nonzero(ok))
        x, y, t_us, p = x[ok], y[ok], t_us[ok], p[ok]
    return EventBatch(x, y, t_us * 1000, p, width, height), n_oob


def read_prophesee_raw(path: str | Path) -> tuple[EventBatch, RawHeader]:
    """All CD events of a RAW file (time = camera clock in ns)."""
    data = Path(path).read_bytes()
    head = read_raw_header(data)
    body = np.frombuffer(data, np.uint8, offset=head.data_offset)
    if head.evt == "2.0":
        n = len(body) // 4
        batch, _ = decode_evt2(body[: 4 * n].view("<u4"), head.width, head.height)
        return batch, head
    r = decode_evt3(body, head.width, head.height, state=Evt3State())
    return EventBatch(r.x, r.y, r.t, r.p, head.width, head.height), head
