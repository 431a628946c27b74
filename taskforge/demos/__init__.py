"""Scripted demonstrations: policies per backend and stage, recording through a `TaskEnv`, and
the `.npz` files `taskforge demos` writes and a curriculum's `warm_start` reads.

Imports spec, backends and envs only (never agents or training)."""

from taskforge.demos.dataset import Demos, concatenate, generate, load, record, save
from taskforge.demos.policies import (
    BEHAVIOURS,
    MetaWorldPolicy,
    PlannerConfig,
    ScriptedPolicy,
    WaypointPlanner,
    infer_behaviour,
    register_backend,
    scripted_policy,
)

__all__ = [
    "BEHAVIOURS",
    "Demos",
    "concatenate",
    "MetaWorldPolicy",
    "PlannerConfig",
    "ScriptedPolicy",
    "WaypointPlanner",
    "generate",
    "infer_behaviour",
    "load",
    "record",
    "register_backend",
    "save",
    "scripted_policy",
]
