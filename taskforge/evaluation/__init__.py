"""`taskforge eval` reports and learning-curve plots. The rollouts they measure with live in
`taskforge.rollouts` (training evaluates with them too); re-exported here."""

from taskforge.rollouts import StageResult, evaluate, wilson_interval

__all__ = ["StageResult", "evaluate", "wilson_interval"]
