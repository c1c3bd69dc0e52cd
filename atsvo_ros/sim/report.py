"""What the sensors gave, per motion phase: why a segment of a sequence is hard.

``atsvo-sim`` prints it after generating a sequence: for stance, flight and landing (see
:meth:`~atsvo_ros.sim.motion.Motion.phase`), the share of colour pixels with depth, the depth error
against the truth at the colour image's time, the colour image's motion blur and the event rate.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from atsvo_ros.sim.motion import PHASES, Motion
from atsvo_ros.sim.sequence import FrameReport


@dataclass(frozen=True)
class PhaseSummary:
    """The sensors over one motion phase (frame figures are medians over the phase's frames)."""

    phase: str
    frames: int
    depth_valid: float  # share of colour pixels with depth
    depth_error: float  # median relative depth error
    colour_blur_px: float  # median largest apparent motion over the colour exposure
    colour_blur_max_px: float
    ir_exposure_ms: float
    events_per_s: float

    def as_dict(self) -> dict:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


def summarise(motion: Motion, frames: Sequence[FrameReport], event_counts: Sequence[tuple[int, int]]
              ) -> list[PhaseSummary]:
    """Per-phase figures from the frames' reports and ``(packet end ns, events)`` of the event stream."""
    out = []
    stamps = np.array([f.stamp_ns for f in frames], np.int64)
    f_phase = motion.phase(stamps) if len(stamps) else np.zeros(0, np.int64)
    ev = np.array(event_counts, np.int64).reshape(-1, 2)
    e_phase = motion.phase(ev[:, 0]) if len(ev) else np.zeros(0, np.int64)
    # time spent in each phase, from a fine grid over the sequence
    grid = np.arange(motion.t0_ns, motion.t_end_ns, 1_000_000, dtype=np.int64)
    g_phase = motion.phase(grid)
    for i, name in enumerate(PHASES):
        sel = [f for f, p in zip(frames, f_phase) if p == i]
        if not sel:
            continue
        seconds = float(np.count_nonzero(g_phase == i)) * 1e-3
        n_events = float(ev[e_phase == i, 1].sum()) if len(ev) else 0.0
        out.append(PhaseSummary(
            name, len(sel), float(np.median([f.depth_valid for f in sel])),
            float(np.nanmedian([f.depth_error for f in sel])) if any(np.isfinite(f.depth_error) for f in sel)
            else float("nan"),
            float(np.median([f.colour_blur_px for f in sel])), float(max(f.colour_blur_px for f in sel)),
            float(np.median([f.ir_exposure_s for f in sel])) * 1e3,
            n_events / seconds if seconds > 0 else 0.0))
    return out


def format_summary(rows: Sequence[PhaseSummary]) -> str:
    """A small table, one line per phase."""
    lines = ["phase    frames  depth valid  depth error  colour blur px (median/max)  IR exposure  events/s"]
    for r in rows:
        lines.append(f"{r.phase:<8} {r.frames:6d}  {100 * r.depth_valid:10.1f}%  {100 * r.depth_error:10.2f}%  "
                     f"{r.colour_blur_px:13.1f} / {r.colour_blur_max_px:<12.1f}  {r.ir_exposure_ms:8.1f} ms  "
                     f"{r.events_per_s / 1e6:6.2f} M")
    return "\n".join(lines)


__all__ = ["PhaseSummary", "format_summary", "summarise"]
