"""Held-out evaluation, Wilson intervals, reports and learning-curve plots."""

from taskforge.evaluation.evaluate import StageResult, evaluate
from taskforge.evaluation.stats import wilson_interval

__all__ = ["StageResult", "evaluate", "wilson_interval"]
