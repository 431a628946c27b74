"""Reward terms, success conditions and feature names: small pure functions over a features
dict, each registered by name (Isaac Lab's manager-based terms, without the managers)."""

from taskforge.terms.features import (
    ENV_FEATURES,
    FEATURES,
    GOAL_FEATURES,
    NATIVE_FEATURES,
    PROGRESS_FEATURES,
    SCALAR_FEATURES,
    FeatureInfo,
    Features,
    env_features,
)
from taskforge.terms.kernels import KERNELS
from taskforge.terms.rewards import REWARD_TERMS, RewardTerm, reward_term
from taskforge.terms.stage import CompiledStage, stage_issues, task_issues

__all__ = [
    "ENV_FEATURES",
    "FEATURES",
    "GOAL_FEATURES",
    "KERNELS",
    "NATIVE_FEATURES",
    "PROGRESS_FEATURES",
    "REWARD_TERMS",
    "SCALAR_FEATURES",
    "CompiledStage",
    "FeatureInfo",
    "Features",
    "RewardTerm",
    "env_features",
    "reward_term",
    "stage_issues",
    "task_issues",
]
