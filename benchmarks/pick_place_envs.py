"""The two pick-place-v3 envs the speed benchmarks race: Meta-World's own, and taskforge's.

One home so env_speed.py and ppo_throughput.py time exactly the same envs.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium
import mujoco
import numpy as np

import taskforge
from taskforge.backends.metaworld import ml1_goals

TASK = Path(__file__).resolve().parents[1] / "tasks/metaworld/pick_place.yaml"
ENV_NAME = "pick-place-v3"


class MetaWorldEnv(gymnasium.Env):
    """Meta-World's own pick-place-v3 on a random ML1 train goal per episode (500 steps), as a
    gymnasium env a vector env (taskforge's or SB3's) can hold: `reset` accepts seed/options."""

    def __init__(self, physics_only: bool = False):
        from metaworld.env_dict import ALL_V3_ENVIRONMENTS

        self.env = ALL_V3_ENVIRONMENTS[ENV_NAME]()
        self.physics_only = physics_only
        """Step only `mj_step` x frame_skip (the physics ceiling), no observation or reward."""
        self.observation_space, self.action_space = self.env.observation_space, self.env.action_space
        self._train = ml1_goals(ENV_NAME, 0)[0]
        self._rng = np.random.default_rng(0)

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.env.set_task(self._train[int(self._rng.integers(len(self._train)))])
        return self.env.reset()

    def step(self, action):
        if self.physics_only:
            env = self.env
            env.data.ctrl[:] = (action[-1], -action[-1])
            mujoco.mj_step(env.model, env.data, env.frame_skip)
            return np.zeros(39), 0.0, False, False, {}
        return self.env.step(action)


def taskforge_env(seed: int = 0) -> gymnasium.Env:
    """taskforge's pick-place `place` stage with the task's full randomisation: it skips
    Meta-World's reward (the stage does not read it) and uses the cheaper observation."""
    return taskforge.make(TASK, stage="place", seed=seed)
