"""Figures of ``atsvo-events render``: the paper's Fig. 4 (constant-tau TS vs ATS at slow and fast
motion) and Fig. 5 (event pixel selection on the ATS) for any event recording.

The recording is read twice, streaming: once for the event rate per window (to find the slowest and
the fastest moment), once to collect the events that shape the surfaces at those two moments.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.core.events.selection import EventSelection, select_event_pixels_detailed
from atsvo_ros.core.events.time_surface import AdaptiveTimeSurface, ConstantTimeSurface
from atsvo_ros.errors import DecodeError, OutputError
from atsvo_ros.io.event_files import open_events
from atsvo_ros.tools._cli import prepare_out_dir

GREEN, RED, YELLOW, WHITE = (0, 220, 0), (0, 0, 255), (0, 200, 255), (255, 255, 255)


@dataclass
class Moment:
    """One query time picked by event rate."""

    name: str
    t_ns: int
    rate_eps: float


def event_rate_bins(path: str | Path, bin_ns: int, topic: str | None = None,
                    progress: bool = False) -> tuple[int, np.ndarray, tuple[int, int]]:
    """(t0_ns, events per bin, (width, height)) over the whole recording, streaming."""


    src = open_events(path, topic)
    counts = np.zeros(0, np.int64)
    t0 = None
    for b in tqdm(src, total=src.n_messages or None, unit="msg", disable=not progress, file=sys.stderr,
                  desc="event rate"):
        if len(b) == 0:
            continue
        if t0 is None:
            t0 = int(b.t[0])
        idx = (b.t - t0) // bin_ns
        idx = idx[idx >= 0]
        c = np.bincount(idx)
        if len(c) > len(counts):
            counts = np.concatenate([counts, np.zeros(len(c) - len(counts), np.int64)])
        counts[: len(c)] += c
    if t0 is None:
        raise DecodeError(f"{path}: no events")
    return t0, counts, (src.width, src.height)


def pick_moments(t0_ns: int, counts: np.ndarray, bin_ns: int, min_share: float = 0.05) -> list[Moment]:
    """The fastest window and the slowest one that still has ``min_share`` of the peak rate."""
    usable = counts[:-1] if len(counts) > 1 else counts  # the last bin is usually cut short
    fast = int(np.argmax(usable))
    ok = np.flatnonzero(usable >= max(1, min_share * usable[fast]))
    slow = int(ok[np.argmin(usable[ok])])
    rate = 1e9 / bin_ns
    return [Moment("slow", t0_ns + (slow + 1) * bin_ns, usable[slow] * rate),
            Moment("fast", t0_ns + (fast + 1) * bin_ns, usable[fast] * rate)]


def collect_windows(path: str | Path, windows: list[tuple[int, int]], topic: str | None = None) -> list[EventBatch]:
    """Events of each ``[t_start, t_end]`` window, in one streaming pass."""

    src = open_events(path, topic)
    parts: list[list[EventBatch]] = [[] for _ in windows]
    for b in src:
        if len(b) == 0:
            continue
        for k, (a, z) in enumerate(windows):
            if b.t[-1] >= a and b.t[0] <= z:
                parts[k].append(b.select((b.t >= a) & (b.t <= z)))
    return [EventBatch.concatenate(p) if p else EventBatch.empty(src.width, src.height) for p in parts]


def _grey(img: np.ndarray, scale: int) -> np.ndarray:
    g = np.clip(img + 0.5, 0, 255).astype(np.uint8)
    g = cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    return cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)


def _label(img: np.ndarray, text: str) -> np.ndarray:
    out = img.copy()
    cv2.rectangle(out, (0, 0), (min(out.shape[1], 9 * len(text) + 8), 20), (0, 0, 0), -1)
    cv2.putText(out, text, (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, WHITE, 1, cv2.LINE_AA)
    return out


def _draw_selection(base: np.ndarray, sel: EventSelection, scale: int) -> np.ndarray:
    out = base.copy()
    c = (sel.candidates * scale + scale // 2).astype(int)
    for (x, y), ok in zip(c.tolist(), sel.passed.tolist()):
        if not ok:
            cv2.drawMarker(out, (x, y), RED, cv2.MARKER_TILTED_CROSS, 3 * scale, 1)
    for x, y in (sel.selected * scale + scale // 2).astype(int).tolist():
        cv2.circle(out, (x, y), max(2, scale + 1), GREEN, -1)
    return out


def _panels(moment: Moment, events: EventBatch, width: int, height: int, cfg: AtsvoConfig,
            scale: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, EventSelection]:
    ts = ConstantTimeSurface(width, height, cfg.ats)
    ats = AdaptiveTimeSurface(width, height, cfg.ats)
    ts.update(events)
    ats.update(events)
    ts_img = ts.render(moment.t_ns)
    ats_img = ats.render(moment.t_ns)
    sel = select_event_pixels_detailed(ats_img, events, moment.t_ns, ats.window_ns(), cfg.event_selection)
    return _grey(ts_img, scale), _grey(ats_img, scale), _grey(sel.mask.astype(np.float32) * 255, scale), sel


def render_figures(path: str | Path, out_dir: str | Path, cfg: AtsvoConfig, topic: str | None = None,
                   bin_s: float | None = None, progress: bool = False) -> list[Path]:
    """Write ``fig4_ts_vs_ats.png`` and ``fig5_selection_{slow,fast}.png``; returns the paths.

    Raises:
        OutputError: ``out_dir`` is a file, lies under one or cannot be written (checked before the recording is
            read), or a figure could not be written.
    """
    out = prepare_out_dir(out_dir)
    bin_ns = int(round((bin_s or cfg.ats.tau_u_s) * 1e9))
    t0, counts, (width, height) = event_rate_bins(path, bin_ns, topic, progress)
    if not (width and height):
        raise DecodeError(f"{path}: the sensor size is unknown, cannot draw time surfaces")
    moments = pick_moments(t0, counts, bin_ns)
    # events older than this leave less than half a grey level in either surface
    history_ns = int(math.log(510.0) * max(cfg.ats.tau_u_s, cfg.ats.constant_tau_s) * 1e9)
    windows = [(m.t_ns - history_ns, m.t_ns) for m in moments]
    batches = collect_windows(path, windows, topic)
    scale = max(1, int(round(640 / width)))
    rows, written = [], []
    for m, ev in zip(moments, batches):
        ts_p, ats_p, mask_p, sel = _panels(m, ev, width, height, cfg, scale)
        tag = f"{m.name}: {m.rate_eps / 1e6:.2f} Mev/s"
        rows.append(np.hstack([_label(ts_p, f"TS tau={cfg.ats.constant_tau_s * 1e3:g} ms ({tag})"),
                               _label(ats_p, f"ATS ({tag})")]))
        cand = ats_p.copy()
        for x, y in (sel.candidates * scale + scale // 2).astype(int).tolist():
            cv2.circle(cand, (x, y), 1, YELLOW, -1)
        fig5 = np.vstack([
            np.hstack([_label(cand, f"(a) events of the last {cfg.event_selection.window_fraction:g} window"),
                       _label(mask_p, "(b) median-blur mask")]),
            np.hstack([_label(_draw_selection(ats_p, sel, scale), "(c) rejected x / selected o"),
                       _label(_draw_selection(ats_p * 0, sel, scale), f"(d) {len(sel.selected)} selected")]),
        ])
        p5 = out / f"fig5_selection_{m.name}.png"
        _write_png(p5, fig5)
        written.append(p5)
    p4 = out / "fig4_ts_vs_ats.png"
    _write_png(p4, np.vstack(rows))
    return [p4, *written]


def _write_png(path: Path, img: np.ndarray) -> None:
    """``cv2.imwrite``, which reports a failure only by returning False, as an error."""
    if not cv2.imwrite(str(path), img):
        raise OutputError(f"could not write {path}")
