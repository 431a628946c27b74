"""Schema models of task, agent and curriculum files, and loading them with one-line errors.

This package imports nothing else of taskforge: everything else depends on it.
"""

from taskforge.spec.agent import AgentSpec, PolicySpec, PPOSpec
from taskforge.spec.common import Distribution, StrictModel
from taskforge.spec.curriculum import SEED_PLACEHOLDER, CurriculumSpec, PhaseSpec, init_for_seed
from taskforge.spec.errors import SpecError, SpecIssue, did_you_mean, expected_one_of, format_path
from taskforge.spec.loader import (
    load_agent_spec,
    load_curriculum_spec,
    load_sweep_spec,
    load_task_spec,
    read_curriculum_yaml,
    read_task_yaml,
    read_yaml,
    read_yaml_with_base,
    resolve_relative,
    validate,
)
from taskforge.spec.sweep import SweepSpec
from taskforge.spec.task import (
    ConditionSpec,
    LatencySpec,
    NoiseSpec,
    PhysicsTermSpec,
    RandomizationSpec,
    RewardTermSpec,
    StageSpec,
    TaskSpec,
)

__all__ = [
    "SEED_PLACEHOLDER",
    "AgentSpec",
    "ConditionSpec",
    "CurriculumSpec",
    "Distribution",
    "LatencySpec",
    "NoiseSpec",
    "PPOSpec",
    "PhaseSpec",
    "PhysicsTermSpec",
    "PolicySpec",
    "RandomizationSpec",
    "RewardTermSpec",
    "SpecError",
    "SpecIssue",
    "StageSpec",
    "StrictModel",
    "SweepSpec",
    "TaskSpec",
    "did_you_mean",
    "expected_one_of",
    "format_path",
    "init_for_seed",
    "load_agent_spec",
    "load_curriculum_spec",
    "load_sweep_spec",
    "load_task_spec",
    "read_curriculum_yaml",
    "read_task_yaml",
    "read_yaml",
    "read_yaml_with_base",
    "resolve_relative",
    "validate",
]
