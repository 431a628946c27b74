"""Expert labels on any state: the scripted policy queried wherever the *student* goes.

Recorded demonstrations only cover the states the scripted policy visits itself; a cloned
policy drifts off them and meets states no demo shows (the compounding error of behaviour
cloning). Scripted policies read the true simulator state, so they can be asked for their action
at any state: DAgger (Ross et al., 2011) rolls out the student, labels what it visits with the
expert's action and refits on the aggregate. `ExpertLabels` is the labelling half, as a
gymnasium wrapper, so the student's rollouts can run on the same vector env as PPO's.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from taskforge.demos.policies import ScriptedPolicy, Source, act_in_box, scripted_policy
from taskforge.envs import TaskEnv

EXPERT_ACTION = "expert_action"
"""The info key: the scripted action for the state the returned observation describes."""


class ExpertLabels(gymnasium.Wrapper):
    """A `TaskEnv` whose reset and step infos carry `info["expert_action"]`: what the scripted
    policy of `stage` would do at the state the returned observation describes, clipped to the
    action box. It labels only; the action stepped is always the caller's."""

    def __init__(self, env: TaskEnv, stage: str | None = None, source: Source = "auto"):
        super().__init__(env)
        self.task_env = env
        self.policy: ScriptedPolicy = scripted_policy(env, stage, source)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.policy.reset(self.task_env)
        info[EXPERT_ACTION] = act_in_box(self.policy, self.task_env)
        return obs, info

    def step(self, action: np.ndarray):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info[EXPERT_ACTION] = act_in_box(self.policy, self.task_env)
        return obs, reward, terminated, truncated, info
