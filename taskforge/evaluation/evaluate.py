"""Deterministic evaluation of a policy on a stage of a task, goal by goal.

Episodes run on a handful of envs in this process, batched through the policy; episode k uses
goal `k mod number-of-goals` of the split, so 50 episodes on ML1's test split visit every
held-out goal once.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from taskforge.agents import PPOAgent
from taskforge.backends import Split
from taskforge.envs import TaskEnv
from taskforge.evaluation.stats import wilson_interval
from taskforge.spec import TaskSpec


@dataclass
class StageResult:
    task: str
    stage: str
    split: str
    successes: list[bool] = field(default_factory=list)
    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)

    @property
    def episodes(self) -> int:
        return len(self.successes)

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.successes)) if self.successes else 0.0

    def as_dict(self) -> dict:
        low, high = wilson_interval(sum(self.successes), self.episodes)
        return {
            "task": self.task,
            "stage": self.stage,
            "split": self.split,
            "episodes": self.episodes,
            "successes": int(sum(self.successes)),
            "success_rate": self.success_rate,
            "success_ci95": [low, high],
            "mean_return": float(np.mean(self.returns)) if self.returns else 0.0,
            "mean_length": float(np.mean(self.lengths)) if self.lengths else 0.0,
        }


def evaluate(
    agent: PPOAgent,
    task: TaskSpec,
    task_file: str | Path,
    stage: str,
    split: Split,
    episodes: int,
    sub_task: str | None = None,
    seed: int = 0,
    parallel: int = 4,
) -> StageResult:
    """Run `episodes` deterministic episodes of `stage` (one sub-task of a set, or all)."""
    privileged = agent.privileged_dim > 0
    envs = [TaskEnv(task, task_file, stage=stage, split=split, task_name=sub_task, privileged=privileged)
            for _ in range(min(parallel, episodes))]
    num_goals = envs[0].backend.num_goals(split)
    result = StageResult(sub_task or task.name, stage, split)
    queue = list(range(episodes))
    active: list[int | None] = [None] * len(envs)  # episode index each env is playing
    obs = np.zeros((len(envs), envs[0].observation_space.shape[0]), dtype=np.float32)
    ret = np.zeros(len(envs))
    length = np.zeros(len(envs), dtype=int)
    ever = np.zeros(len(envs), dtype=bool)
    starts = np.ones(len(envs), dtype=bool)

    def start(i: int) -> None:
        k = queue.pop(0)
        obs[i], _ = envs[i].reset(seed=seed + k, options={"stage": stage, "goal_index": k % num_goals})
        active[i], ret[i], length[i], ever[i], starts[i] = k, 0.0, 0, False, True

    for i in range(len(envs)):
        start(i)
    state = agent.initial_state(len(envs))
    while any(a is not None for a in active):
        actions, state = agent.act(obs, state, starts, deterministic=True)
        starts[:] = False
        for i, env in enumerate(envs):
            if active[i] is None:
                continue
            obs[i], reward, terminated, truncated, info = env.step(actions[i])
            ret[i] += reward
            length[i] += 1
            ever[i] |= info["success"]
            if terminated or truncated:
                result.successes.append(bool(ever[i]))
                result.returns.append(float(ret[i]))
                result.lengths.append(int(length[i]))
                if queue:
                    start(i)
                else:
                    active[i] = None
    for env in envs:
        env.close()
    return result
