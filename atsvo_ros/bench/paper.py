"""The paper's published figures that the benchmarks print beside ours (Zhu et al., Tables I-III)."""
from __future__ import annotations

#: The paper's real-robot figures (Table III, ours): R_rpe deg/d, t_rpe cm/d, t_ate cm.
PAPER_ROBOT = {"backflip": [("backflip1", 1.45, 1.99, 8.51), ("backflip2", 1.18, 1.75, 5.31)],
               "running": [("running1", 0.75, 0.55, 4.65), ("running2", 0.71, 0.56, 4.74)],
               "bound": [("bounding", 0.66, 0.42, 2.26)], "pronk": [("pronking", 0.84, 0.92, 6.90)]}
#: The paper's MVSEC figures (Tables I and II, ours): R_rpe deg/d, t_rpe cm/d, t_ate cm, R_rpe deg/f, t_rpe cm/f.
PAPER_MVSEC = {"indoor_flying1": (0.36, 1.20, 6.89, 0.15, 0.57), "indoor_flying2": (0.49, 1.56, 8.92, 0.20, 0.70),
               "indoor_flying3": (0.36, 1.25, 5.26, 0.15, 0.60), "indoor_flying4": (0.63, 1.75, 9.16, 0.26, 0.81)}


__all__ = ["PAPER_MVSEC", "PAPER_ROBOT"]
