"""A point robot in the plane, with goals on an arc around its start: the meta-RL testbed.

Why it exists: RL² on Meta-World needs tens of millions of steps before it adapts (or not), so a
broken implementation and a too-small budget look the same. On this testbed (Finn et al. 2017's
2-D navigation; the sparse semicircle of Rakelly et al. 2019, PEARL, and Zintgraf et al. 2020,
VariBAD) an experiment takes minutes, not hours: with the goal hidden and a reward only near the
goal, the first episode of a trial must search the arc, and the later ones can go straight to
where the reward was found. A memoryless policy cannot do better than one fixed sweep in every
episode. A step is a few numpy operations (no physics engine).

The point starts at the origin; an action `a` in [-1, 1]^2 moves it by `max_step * a`, clamped
to the square [-bound, bound]^2. Goal `i` of a split is at angle `theta_i` on the arc of radius
`goal_radius`; train and test angles are independent uniform draws over `goal_arc` (seeded by
`goals.seed`), as Meta-World's ML1 draws its train and test goals from one distribution.
Observation: `(x, y, goal_x, goal_y)`; the env zeroes the goal when it is hidden. Positions are
reported as 3-vectors with z = 0, so the shared distance features and reward terms apply as is.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from gymnasium.spaces import Box

from taskforge.backends.base import GoalOverride, Split, mujoco_only_issues
from taskforge.spec import SpecIssue, TaskSpec
from taskforge.spec.backends import PointMassBackendSpec
from taskforge.spec.task import GoalsSpec
from taskforge.terms import Features

PROVIDES = frozenset({"tcp_pos", "goal_pos", "tcp_to_goal_distance"})
_SPLIT_STREAM = {"train": 0, "test": 1}
"""Each split's goals come from their own random stream of `goals.seed`."""


def goal_angles(spec: PointMassBackendSpec, goals: GoalsSpec, split: Split) -> np.ndarray:
    """The angles (radians) of a split's goals, in goal-index order."""
    rng = np.random.default_rng([goals.seed, _SPLIT_STREAM[split]])
    low, high = np.radians(spec.goal_arc)
    return rng.uniform(low, high, size=getattr(goals, split).count)


class PointMassBackend:
    provides = PROVIDES
    native = False  # no suite of its own: stages read the shared features
    task_names = ["point-mass"]
    obs_size = 4
    goal_slice = slice(2, 4)
    dt = 0.1
    data = None  # not a MuJoCo simulator: nothing to render off-screen

    def __init__(self, spec: PointMassBackendSpec, goals: GoalsSpec) -> None:
        self._spec = spec
        self.action_space = Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._goals = {split: self._on_arc(goal_angles(spec, goals, split)) for split in ("train", "test")}
        self._pos = np.zeros(2)
        self._goal = np.zeros(2)

    def _on_arc(self, angles: np.ndarray) -> np.ndarray:
        return self._spec.goal_radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def model(self, task_name: str) -> None:
        return None

    def object_geoms(self, task_name: str) -> list[str]:
        return []

    def num_goals(self, split: Split) -> int:
        return len(self._goals[split])

    def reset(
        self, task_name: str, split: Split, goal_index: int, goal: GoalOverride,
        task_rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        # `distance_scale` pulls the goal towards the start (an easier first stage); the start
        # is the origin, so that is a scaling. `check_task` refuses a height override.
        self._goal = self._goals[split][goal_index] * goal.distance_scale
        self._pos = np.zeros(2)
        return self._observation()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        bound = self._spec.bound
        self._pos = np.clip(self._pos + self._spec.max_step * np.asarray(action, dtype=np.float64), -bound, bound)
        return self._observation(), False

    def _observation(self) -> np.ndarray:
        return np.concatenate([self._pos, self._goal])

    def features(self) -> Features:
        return {
            "tcp_pos": np.array([self._pos[0], self._pos[1], 0.0]),
            "goal_pos": np.array([self._goal[0], self._goal[1], 0.0]),
            "tcp_to_goal_distance": float(math.dist(self._pos, self._goal)),
        }

    def close(self) -> None:
        pass


def check_task(task: TaskSpec, file: str | Path) -> list[SpecIssue]:
    issues = mujoco_only_issues(task, file, "a point mass")
    for k, stage in enumerate(task.stages):
        if stage.goal.height != "keep":
            msg = f"a point mass moves in the plane; expected 'keep' (got {stage.goal.height!r}); use distance_scale to bring goals nearer"
            issues.append(SpecIssue(str(file), f"stages[{k}].goal.height", msg))
    return issues


def create(task: TaskSpec, file: str | Path) -> PointMassBackend:
    """The backend of a task that passed `check_task` (see `taskforge.backends.make_backend`)."""
    return PointMassBackend(task.backend, task.goals)
