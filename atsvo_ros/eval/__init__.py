"""Evaluation: ATE / RPE metrics against ground truth (numpy), peer odometry on the same frames, plots."""
from __future__ import annotations

from atsvo_ros.eval.metrics import EvalOptions, EvalResult, evaluate, evaluate_files, format_metrics

__all__ = ["EvalOptions", "EvalResult", "evaluate", "evaluate_files", "format_metrics"]
