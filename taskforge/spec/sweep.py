"""Schema of a sweep file (`sweeps/*.yaml`): a base curriculum, a grid of variants of it, seeds,
and the test conditions every trained policy is evaluated under: one command for an ablation
table in the form of Learning Dexterity's (OpenAI et al. 2018, "different training environments
compared": training environment x test condition, mean and spread over seeds).

Variants and conditions are *overrides*, merged as a file's `base:` is (docs/authoring.md):
a mapping merges key by key, anything else (a number, a list, null) replaces the base's value.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, field_validator

from taskforge.spec.common import StrictModel

Override = dict[str, Any]


def _unique_names(items: list[Any], what: str) -> list[Any]:
    names = [item.name for item in items]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"each {what} needs its own name; repeated: {', '.join(repeated)}")
    return items


class VariantSpec(StrictModel):
    """One training environment of the grid: the base curriculum with these overrides."""

    name: str = Field(min_length=1, max_length=80)
    """The table's row label; also names the variant's folder (lower-cased, spaces as dashes)."""
    curriculum: Override = {}
    """Merged over the curriculum file (e.g. `total_steps`, `promotion`)."""
    agent: Override = {}
    """Merged over the curriculum's agent preset (e.g. `policy: {type: lstm}`)."""
    task: Override = {}
    """Merged over every phase's task (e.g. `randomization: {observation_noise: null}`)."""


class TestConditionSpec(StrictModel):
    """One test condition: the trained policy's last task with these overrides (e.g. nominal
    physics, or a wider 'reality' draw the training never saw)."""

    __test__ = False  # not a pytest class, whatever its name says

    name: str = Field(min_length=1, max_length=80)
    task: Override = {}


class SweepEvaluationSpec(StrictModel):
    """How each trained policy is tested: `episodes` episodes (episode k on goal k of `split`)
    of `stage` (default the last phase's last stage) under each condition."""

    conditions: list[TestConditionSpec] = Field(min_length=1)
    episodes: int = Field(default=50, ge=1, le=100_000)
    split: Literal["train", "test"] = "test"
    stage: str | None = None
    seed: int = 0
    """Seed of the test episodes: the same for every trial, so each policy meets the same draws."""

    @field_validator("conditions")
    @classmethod
    def _named_apart(cls, conditions: list[TestConditionSpec]) -> list[TestConditionSpec]:
        return _unique_names(conditions, "condition")


class SweepSpec(StrictModel):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-.]+$")
    """Names the sweep's folder (`runs/sweeps/<name>/` by default)."""
    description: str = ""
    curriculum: str
    """The base curriculum file, relative to this file."""
    seeds: list[int] = Field(min_length=1)
    total_steps: int | None = Field(default=None, ge=1)
    """Every trial's budget; default the curriculum's (after a variant's overrides)."""
    variants: list[VariantSpec] = Field(min_length=1)
    evaluation: SweepEvaluationSpec
    cpus_per_trial: int | None = Field(default=None, ge=1, le=1024)
    """Ray CPUs each trial holds; default every core of the machine the sweep starts on, so one
    trial runs per machine (a training's env workers use its cores)."""

    @field_validator("variants")
    @classmethod
    def _named_apart(cls, variants: list[VariantSpec]) -> list[VariantSpec]:
        return _unique_names(variants, "variant")

    @field_validator("seeds")
    @classmethod
    def _distinct(cls, seeds: list[int]) -> list[int]:
        if len(set(seeds)) != len(seeds):
            raise ValueError(f"each seed once (got {seeds})")
        return seeds
