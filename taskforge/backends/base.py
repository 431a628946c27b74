"""What every simulator backend offers the env: reset to a goal, step, and the shared features.

A backend knows nothing about rewards, stages' success or agents (those live in
`taskforge.terms` and `taskforge.agents`); it only moves the simulator and reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import mujoco
import numpy as np
from gymnasium.spaces import Box

from taskforge.spec import SpecIssue, TaskSpec
from taskforge.terms import Features

Split = Literal["train", "test"]


@dataclass(frozen=True)
class GoalOverride:
    """A stage's reshaping of the goal (see `GoalOverrideSpec`)."""

    height: Literal["keep", "object"] | float = "keep"
    distance_scale: float = 1.0
    height_scale: float = 0.0

    @property
    def is_identity(self) -> bool:
        return self.height == "keep" and self.distance_scale == 1.0


def draw_starts_apart(
    low: np.ndarray, high: np.ndarray, goals: np.ndarray, min_distance: float, rng: np.random.Generator
) -> np.ndarray | None:
    """Object starts uniform over [low, high] (one row per goal, as many columns as `low`),
    each start redrawn until at least `min_distance` from its goal horizontally (x, y). None
    when 1000 redraws leave some start too close (the regions cannot satisfy the distance).
    One sampler for every backend's object placement, so all keep the same rule."""
    starts = rng.uniform(low, high, size=(len(goals), len(low)))
    for _ in range(1000):
        bad = np.linalg.norm(starts[:, :2] - goals[:, :2], axis=1) < min_distance
        if not bad.any():
            return starts
        starts[bad] = rng.uniform(low, high, size=(int(bad.sum()), len(low)))
    return None


def mujoco_only_issues(task: TaskSpec, file: str | Path, what: str) -> list[SpecIssue]:
    """What a backend without MuJoCo or an object (`what`, e.g. 'a Gymnasium env') cannot
    honour: physics terms, a random object start and fresh training goals."""
    issues = []
    if task.randomization.physics:
        msg = f"physics randomisation needs a MuJoCo backend (metaworld, xarm7); remove it for {what}"
        issues.append(SpecIssue(str(file), "randomization.physics", msg))
    if task.randomization.object_start != "goal_set":
        msg = f"{what} has no object to place; expected 'goal_set' (the default)"
        issues.append(SpecIssue(str(file), "randomization.object_start", msg))
    if task.goals.train.draw != "set":
        msg = f"{what} has no goal distribution to draw from; expected 'set' (the default)"
        issues.append(SpecIssue(str(file), "goals.train.draw", msg))
    return issues


class Backend(Protocol):
    provides: frozenset[str]
    """Feature names this backend fills (checked against what a task's terms read)."""
    task_names: list[str]
    """Sub-tasks this backend can run (one for a single env, ten for MT10)."""
    action_space: Box
    obs_size: int
    goal_slice: slice
    """Where the goal sits in the observation; zeroed by the env when the goal is hidden."""
    dt: float
    """Seconds of simulated time per control step."""
    native: bool
    """Whether `features()` must carry the suite's own reward and success (`native_*`). The env
    sets it from what its stages read; a backend for which they are costly (Meta-World) skips
    them while it is off, one for which they are free may ignore it."""

    def model(self, task_name: str) -> mujoco.MjModel | None:
        """The compiled MuJoCo model of a sub-task, for physics randomisation (changed in
        place); None for simulators that are not MuJoCo."""

    @property
    def data(self) -> mujoco.MjData | None:
        """The current episode's MuJoCo state, for rendering (None: not a MuJoCo simulator)."""

    def object_geoms(self, task_name: str) -> list[str]:
        """Names of the main object's geoms (the default target of `object_size`)."""

    def num_goals(self, split: Split) -> int:
        ...

    def reset(
        self, task_name: str, split: Split, goal_index: int, goal: GoalOverride,
        task_rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        """Reset to a goal of a split; returns the observation with the true goal in `goal_slice`.

        `task_rng` None: goal entry `goal_index` of the split, the object where it puts it. A
        generator: what the task draws per task instance comes from it — on the train split
        with `goals.train.draw: fresh`, the goal and the object's start together (from the
        distribution the split's set is drawn from; `goal_index` is then unused), otherwise,
        with `randomization.object_start: random`, the object's start over the backend's object
        region, independently of the goal. The env hands a generator seeded the same way to
        repeat a task. Backends that cannot draw refuse those options in `check_task`.
        """

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        """Apply one control step; returns the observation and whether the simulated episode
        ended on its own (a crash or landing; Meta-World never ends)."""

    def features(self) -> Features:
        """The shared features after the last reset/step (`action` and `stage_success` excluded)."""

    def close(self) -> None:
        ...
