"""Evaluation: ATE / RPE metrics against ground truth (numpy) and matplotlib plots."""
