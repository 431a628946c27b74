"""DAgger (Ross, Gordon and Bagnell, 2011): roll out the student, label every state it visits
with the scripted expert's action, aggregate with everything labelled so far, refit.

Round 0 is the recorded demonstrations (the expert's own states, β = 1 in the paper's mixture);
every later round runs the *student* (β = 0: the paper's best-performing schedule, `I(i = 0)`),
sampling from the Gaussian it will start PPO with, so the labels cover the states PPO's first
rollouts visit, noise included. The rollouts run on the same vector env as PPO's (one worker per
core), each env wrapped in `ExpertLabels`, so the expert is queried inside the workers.

For a task set (MT10) the rounds need not split evenly: with `allocation="failures"` each round
after the first draws its sub-tasks in proportion to how often the *previous* round's student
failed them (`failure_weights`). Why: the expert's time is the budget, and a label on a task the
student already solves teaches little. Measured on MT10 (benchmarks/RESULTS.md, "What the warm
start's size buys"): peg-insert-side needed about 3 x its even share of data, while six tasks were
solved after the demos alone.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from gymnasium.vector import VectorEnv

from taskforge.agents import PPOAgent
from taskforge.demos.labels import EXPERT_ACTION

Allocation = Literal["uniform", "failures"]

UNIFORM_SHARE = 0.2
"""Under `failures`, this share of each round is still spread evenly over the sub-tasks: the
failure rates come from a handful of episodes per sub-task (30k steps of 500-step MT10 episodes
is 6 per task), and a task that looked solved must still be seen, as ALP-GMM's random share and
our learning-progress sampler's ε do."""


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


def failure_weights(names: list[str], batch: DaggerRound, uniform_share: float = UNIFORM_SHARE) -> dict[str, float]:
    """Sampling weights of a task set's sub-tasks for the next round: (1 − u)·f/Σf + u/n, f the
    sub-task's failure rate in `batch`. A sub-task with no finished episode counts as failed (the
    student never got to show it); with no failure anywhere the split is even."""
    rates = batch.success_by_task()
    failures = np.array([1.0 - rates.get(name, 0.0) for name in names])
    if failures.sum() == 0.0:
        return dict.fromkeys(names, 1.0 / len(names))
    weights = (1.0 - uniform_share) * failures / failures.sum() + uniform_share / len(names)
    return dict(zip(names, weights.tolist()))


def student_rollout(
    agent: PPOAgent, envs: VectorEnv, steps: int, seed: int, task_weights: dict[str, float] | None = None
) -> DaggerRound:
    """Run the student (sampled actions, frozen normaliser; a recurrent one with its state carried
    through each episode) for at least `steps` env steps in all envs together; return every
    observation it acted on, with the expert's label for it.

    `task_weights`: draw each episode's sub-task in proportion to its weight (each worker over its
    own task's sub-task names), pushed into the worker's `next_episode` as the curriculum driver
    does; None leaves the choice to the env (uniform).

    Order: step by step (all envs at step 0, then step 1, ...) for an MLP, which reads each step
    alone; env by env for a recurrent policy, so each env's episodes lie contiguous and are
    cloned as sequences (`agents/sequences.py`)."""
    choose = _task_chooser(envs, task_weights, seed) if task_weights else None
    if choose is not None:
        choose(range(envs.num_envs))
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
            if choose is not None:  # the reset already happened: this choice starts the episode after next
                choose(np.flatnonzero(starts))
    by_env = (lambda x: np.swapaxes(np.stack(x), 0, 1).reshape(-1, *x[0].shape[1:])) if agent.policy.recurrent \
        else np.concatenate
    return DaggerRound(by_env(observations), by_env(labels), by_env(start_flags), successes, tasks)


def _task_chooser(envs: VectorEnv, weights: dict[str, float], seed: int) -> Callable[[object], None]:
    """A function that draws the next sub-task of the given workers and pushes it to them."""
    names: list[list[str]] = list(envs.get_attr("task_names"))
    p = [np.array([weights.get(n, 0.0) for n in ns]) for ns in names]
    p = [w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w)) for w in p]
    rng = np.random.default_rng(seed)
    pushed: list[dict] = [{} for _ in names]

    def choose(workers) -> None:
        for i in workers:
            pushed[i] = {"task": names[i][int(rng.choice(len(names[i]), p=p[i]))]}
        envs.set_attr("next_episode", list(pushed))

    return choose


def dagger(
    agent: PPOAgent,
    envs: VectorEnv,
    demos: Labelled,
    rounds: int,
    steps_per_round: int,
    refit: Callable[[Labelled], dict[str, float]],
    seed: int,
    on_round: Callable[[int, DaggerRound, dict[str, float]], None] | None = None,
    allocation: Allocation = "uniform",
) -> Labelled:
    """`rounds` DAgger rounds after the demos (round 0, assumed already fitted): each rolls out
    the current student, aggregates its labelled states with all earlier data and calls
    `refit(aggregate)`. Returns the aggregate, for PPO's BC term. `allocation="failures"`:
    round k + 1 draws sub-tasks by round k's failures (`failure_weights`); the first is even."""
    aggregate, weights = demos, None
    names = sorted({n for ns in envs.get_attr("task_names") for n in ns}) if allocation == "failures" else []
    for k in range(1, rounds + 1):
        batch = student_rollout(agent, envs, steps_per_round, seed=seed + 1000 * k, task_weights=weights)
        if len(names) > 1:
            weights = failure_weights(names, batch)
        aggregate = aggregate.extend(Labelled(batch.observations, batch.expert_actions, batch.episode_starts))
        metrics = refit(aggregate)
        if on_round is not None:
            on_round(k, batch, metrics)
    return aggregate
