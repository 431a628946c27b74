"""DAgger (Ross, Gordon and Bagnell, 2011): roll out the student, label every state it visits
with the scripted expert's action, aggregate with everything labelled so far, refit.

Round 0 is the recorded demonstrations (the expert's own states, β = 1 in the paper's mixture);
every later round runs the *student* (β = 0: the paper's best-performing schedule, `I(i = 0)`),
sampling from the Gaussian it will start PPO with, so the labels cover the states PPO's first
rollouts visit, noise included. The rollouts run on the same vector env as PPO's (one worker per
core), each env wrapped in `ExpertLabels`, so the expert is queried inside the workers.

Every sub-task of a task set gets the same share of each round. Tried and dropped: drawing the
sub-tasks of round k + 1 in proportion to round k's student failures. On MT10 it gave the weak
peg-insert-side three times its share, yet the student right after pretraining was no better
(0.82 / 0.91 / 0.83 held-out on seeds 0-2 vs 0.86 / 0.82 / 0.95 evenly; benchmarks/RESULTS.md,
"What the warm start's size buys").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from gymnasium.vector import VectorEnv

from taskforge.agents import PPOAgent
from taskforge.demos.labels import EXPERT_ACTION


@dataclass(frozen=True)
class Labelled:
    """States with the expert's action for each, and where their episodes begin (what a
    recurrent student is cloned on; an MLP ignores it)."""

    observations: np.ndarray
    actions: np.ndarray
    episode_starts: np.ndarray

    def __len__(self) -> int:
        return len(self.observations)

    def extend(self, more: Labelled) -> Labelled:
        return Labelled(*(np.concatenate([a, b]) for a, b in zip(self.fields(), more.fields())))

    def fields(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.observations, self.actions, self.episode_starts

    def after(self, n: int) -> Labelled:
        """Everything past the first `n` entries (DAgger's part of an aggregate with the demos)."""
        return Labelled(*(x[n:] for x in self.fields()))


@dataclass
class DaggerRound:
    """What one round collected: labelled states and the student's episodes that finished."""

    observations: np.ndarray
    expert_actions: np.ndarray
    episode_starts: np.ndarray
    """Where each env's episodes begin, in the order of `observations` (see `student_rollout`)."""
    episode_successes: list[bool] = field(default_factory=list)
    episode_tasks: list[str] = field(default_factory=list)
    """The sub-task of each entry of `episode_successes`."""

    @property
    def success_rate(self) -> float | None:
        return float(np.mean(self.episode_successes)) if self.episode_successes else None

    def success_by_task(self) -> dict[str, float]:
        """Student success per sub-task over this round's finished episodes."""
        tasks, successes = np.array(self.episode_tasks), np.array(self.episode_successes, dtype=float)
        return {name: float(successes[tasks == name].mean()) for name in dict.fromkeys(self.episode_tasks)}


def student_rollout(agent: PPOAgent, envs: VectorEnv, steps: int, seed: int) -> DaggerRound:
    """Run the student (sampled actions, frozen normaliser; a recurrent one with its state carried
    through each episode) for at least `steps` env steps in all envs together; return every
    observation it acted on, with the expert's label for it.

    Order: step by step (all envs at step 0, then step 1, ...) for an MLP, which reads each step
    alone; env by env for a recurrent policy, so each env's episodes lie contiguous and are
    cloned as sequences (`agents/sequences.py`)."""
    obs, infos = envs.reset(seed=seed)
    state, starts = agent.initial_state(envs.num_envs), np.ones(envs.num_envs, dtype=bool)
    observations, labels, start_flags, successes, tasks = [], [], [], [], []
    for _ in range(-(-steps // envs.num_envs)):  # ceil: every env steps the same number of times
        observations.append(obs)
        labels.append(np.stack(infos[EXPERT_ACTION]))
        start_flags.append(starts)
        actions, state = agent.act(obs, state, starts, deterministic=False)
        obs, _, terminated, truncated, infos = envs.step(actions)
        starts = terminated | truncated
        if starts.any():  # SAME_STEP autoreset: the finished episodes' last info is in final_info
            successes += [bool(s) for s in infos["final_info"]["episode_success"][starts]]
            tasks += [str(t) for t in infos["final_info"]["task"][starts]]
    by_env = (lambda x: np.swapaxes(np.stack(x), 0, 1).reshape(-1, *x[0].shape[1:])) if agent.policy.recurrent \
        else np.concatenate
    return DaggerRound(by_env(observations), by_env(labels), by_env(start_flags), successes, tasks)


def dagger(
    agent: PPOAgent,
    envs: VectorEnv,
    demos: Labelled,
    rounds: int,
    steps_per_round: int,
    refit: Callable[[Labelled], dict[str, float]],
    seed: int,
    on_round: Callable[[int, DaggerRound, dict[str, float]], None] | None = None,
) -> Labelled:
    """`rounds` DAgger rounds after the demos (round 0, assumed already fitted): each rolls out
    the current student, aggregates its labelled states with all earlier data and calls
    `refit(aggregate)`. Returns the aggregate, for PPO's BC term."""
    aggregate = demos
    for k in range(1, rounds + 1):
        batch = student_rollout(agent, envs, steps_per_round, seed=seed + 1000 * k)
        aggregate = aggregate.extend(Labelled(batch.observations, batch.expert_actions, batch.episode_starts))
        metrics = refit(aggregate)
        if on_round is not None:
            on_round(k, batch, metrics)
    return aggregate
