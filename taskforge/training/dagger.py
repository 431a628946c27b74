"""DAgger (Ross, Gordon and Bagnell, 2011): roll out the student, label every state it visits
with the scripted expert's action, aggregate with everything labelled so far, refit.

Round 0 is the recorded demonstrations (the expert's own states, β = 1 in the paper's mixture);
every later round runs the *student* (β = 0: the paper's best-performing schedule, `I(i = 0)`),
sampling from the Gaussian it will start PPO with, so the labels cover the states PPO's first
rollouts visit, noise included. The rollouts run on the same vector env as PPO's (one worker per
core), each env wrapped in `ExpertLabels`, so the expert is queried inside the workers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from gymnasium.vector import VectorEnv

from taskforge.agents import PPOAgent
from taskforge.demos.labels import EXPERT_ACTION


@dataclass
class DaggerRound:
    """What one round collected: labelled states and the student's episodes that finished."""

    observations: np.ndarray
    expert_actions: np.ndarray
    episode_successes: list[bool] = field(default_factory=list)

    @property
    def success_rate(self) -> float | None:
        return float(np.mean(self.episode_successes)) if self.episode_successes else None


def student_rollout(agent: PPOAgent, envs: VectorEnv, steps: int, seed: int) -> DaggerRound:
    """Run the student (sampled actions, frozen normaliser) for at least `steps` env steps in
    all envs together; return every observation it acted on, with the expert's label for it."""
    obs, infos = envs.reset(seed=seed)
    observations, labels, successes = [], [], []
    for _ in range(-(-steps // envs.num_envs)):  # ceil: every env steps the same number of times
        observations.append(obs)
        labels.append(np.stack(infos[EXPERT_ACTION]))
        actions, _ = agent.act(obs, deterministic=False)
        obs, _, terminated, truncated, infos = envs.step(actions)
        ended = terminated | truncated
        if ended.any():  # SAME_STEP autoreset: the finished episodes' last info is in final_info
            successes += [bool(s) for s in infos["final_info"]["episode_success"][ended]]
    return DaggerRound(np.concatenate(observations), np.concatenate(labels), successes)


def dagger(
    agent: PPOAgent,
    envs: VectorEnv,
    demo_observations: np.ndarray,
    demo_actions: np.ndarray,
    rounds: int,
    steps_per_round: int,
    refit: Callable[[np.ndarray, np.ndarray], dict[str, float]],
    seed: int,
    on_round: Callable[[int, DaggerRound, dict[str, float]], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """`rounds` DAgger rounds after the demos (round 0, assumed already fitted): each rolls out
    the current student, aggregates its labelled states with all earlier data and calls
    `refit(observations, actions)` on the aggregate. Returns the aggregate, for PPO's BC term."""
    observations, actions = demo_observations, demo_actions
    for k in range(1, rounds + 1):
        batch = student_rollout(agent, envs, steps_per_round, seed=seed + 1000 * k)
        observations = np.concatenate([observations, batch.observations])
        actions = np.concatenate([actions, batch.expert_actions])
        metrics = refit(observations, actions)
        if on_round is not None:
            on_round(k, batch, metrics)
    return observations, actions
