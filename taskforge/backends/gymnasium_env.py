"""Any registered Gymnasium env with a Box action space, behind taskforge's feature names.

Only the `native_*` features exist here (there is no gripper or object), so its tasks use the
`native` reward and conditions on `native_return` / `native_reward`. It lets the same PPO and
curriculum machinery be sanity-checked on a classic benchmark (LunarLanderContinuous).

'Goals' are reset seeds: goal `i` of the train split resets with seed `i`, of the test split with
seed `TEST_SEED_OFFSET + i`, so held-out evaluation uses initial states never trained on.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.spaces import Box

from taskforge.backends.base import GoalOverride, Split, mujoco_only_issues
from taskforge.spec import SpecIssue, TaskSpec, expected_one_of
from taskforge.spec.backends import GymnasiumBackendSpec
from taskforge.spec.task import GoalsSpec
from taskforge.terms import Features

PROVIDES = frozenset({"native_reward", "native_success", "native_return"})
TEST_SEED_OFFSET = 1_000_000


class GymnasiumBackend:
    provides = PROVIDES
    native = True  # its native features are the wrapped env's own reward and flags: always computed
    goal_slice = slice(0, 0)  # no goal in the observation

    def __init__(self, spec: GymnasiumBackendSpec, goals: GoalsSpec):
        # Unwrap gymnasium's TimeLimit: the task's stages own episode length.
        self._env = gym.make(spec.env, max_episode_steps=None, **spec.kwargs).unwrapped
        self.task_names = [spec.env]
        self.action_space = self._env.action_space
        self.obs_size = int(np.prod(self._env.observation_space.shape))
        self.dt = float(self._env.metadata.get("render_fps", 50)) ** -1
        self._goals = goals
        self._reward = self._return = self._success = 0.0

    def model(self, task_name: str) -> None:
        return None

    data = None  # not a MuJoCo simulator: nothing to render off-screen

    def object_geoms(self, task_name: str) -> list[str]:
        return []

    def num_goals(self, split: Split) -> int:
        return getattr(self._goals, split).count

    def reset(
        self, task_name: str, split: Split, goal_index: int, goal: GoalOverride,
        task_rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        seed = goal_index + (TEST_SEED_OFFSET if split == "test" else 0)
        obs, _ = self._env.reset(seed=seed)
        self._reward = self._return = self._success = 0.0
        return np.asarray(obs, dtype=np.float64).ravel()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        low, high = self.action_space.low, self.action_space.high
        # The agent acts in [-1, 1]; rescale to the env's own bounds.
        scaled = low + (np.asarray(action) + 1.0) * 0.5 * (high - low)
        obs, reward, terminated, _, info = self._env.step(scaled.astype(self.action_space.dtype))
        self._reward = float(reward)
        self._return += self._reward
        self._success = float(info.get("is_success", 0.0))
        return np.asarray(obs, dtype=np.float64).ravel(), bool(terminated)

    def features(self) -> Features:
        return {"native_reward": self._reward, "native_success": self._success, "native_return": self._return}

    def close(self) -> None:
        self._env.close()


def check_task(task: TaskSpec, file: str | Path) -> list[SpecIssue]:
    spec = task.backend
    if spec.env not in gym.registry:
        return [SpecIssue(str(file), "backend.env", f"unknown Gymnasium env '{spec.env}'; {expected_one_of(spec.env, gym.registry)}")]
    issues = []
    try:
        probe = gym.make(spec.env, **spec.kwargs)
    except Exception as exc:  # a missing optional dependency or a bad kwarg: the user's to fix
        return [SpecIssue(str(file), "backend.kwargs", f"gymnasium.make('{spec.env}') failed: {exc}")]
    if not isinstance(probe.action_space, Box):
        issues.append(SpecIssue(str(file), "backend.env", f"needs a continuous (Box) action space; {spec.env} has {probe.action_space}"))
    probe.close()
    return issues + mujoco_only_issues(task, file, "a Gymnasium env")


def create(task: TaskSpec, file: str | Path) -> GymnasiumBackend:
    """The backend of a task that passed `check_task` (see `taskforge.backends.make_backend`)."""
    return GymnasiumBackend(task.backend, task.goals)
