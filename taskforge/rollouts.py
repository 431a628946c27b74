"""Rollouts of a policy on a stage of a task, goal by goal, in trials: the measurement that
training's periodic evaluation and `taskforge eval` both make (so it lives below both; neither
imports the other). Deterministic (the Gaussian's mean) by default, or sampled, since an RL²
policy explores by sampling (Duan et al. meta-test their stochastic policy).

A trial is K episodes on one goal from a fresh recurrent state (`RL2Trial`): K is the RL² agent's
`trial_episodes`, or 1 for a memoryless PPO policy unless asked otherwise (K > 1 for PPO is the
meta-test baseline: its adaptation curve is flat). Trials run on a handful of envs in this
process, batched through the policy; trial k uses goal `k mod number-of-goals` of the split, so
50 trials on ML1's test split visit every held-out goal once.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium
import numpy as np

from taskforge.agents import Agent, RL2Trial
from taskforge.backends import Split
from taskforge.envs import TaskEnv
from taskforge.spec import TaskSpec


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval (Wilson, 1927) for a binomial proportion.

    Why Wilson and not p ± z·sqrt(p(1-p)/n): with 20 episodes and 0 or 20 successes the normal
    interval collapses to a point; Wilson stays honest at the extremes.
    """
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # clamped to contain p: at p = 0 or 1 rounding would otherwise leave it a hair outside
    return (min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half)))


def _rate(successes: np.ndarray) -> dict:
    """Success rate of a flat array of episode outcomes, with its 95 % Wilson interval."""
    low, high = wilson_interval(int(successes.sum()), successes.size)
    return {"success_rate": float(successes.mean()) if successes.size else 0.0, "success_ci95": [low, high]}


@dataclass
class StageResult:
    """Outcomes of `trials` trials of `trial_episodes` episodes: arrays `[trial, episode]`, in the
    order the trials ended, with each trial's goal index and reset seed (`goals`, `seeds`; empty
    where a caller built the result without them) and where its goal and object stood at its
    first reset (`start_positions`: `goal_pos`, `object_pos`, those of them the backend has)."""

    task: str
    stage: str
    split: str
    trial_episodes: int
    successes: list[list[bool]] = field(default_factory=list)
    returns: list[list[float]] = field(default_factory=list)
    lengths: list[list[int]] = field(default_factory=list)
    goals: list[int] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    start_positions: list[dict[str, list[float]]] = field(default_factory=list)

    @property
    def trials(self) -> int:
        return len(self.successes)

    @property
    def success_rate(self) -> float:
        """Over every episode of every trial."""
        return float(np.mean(self.successes)) if self.successes else 0.0

    @property
    def missed_goals(self) -> list[int]:
        """The goals (indices into the split) of the trials in which no episode succeeded."""
        return sorted({goal for goal, successes in zip(self.goals, self.successes) if not any(successes)})

    @property
    def mean_return(self) -> float:
        return float(np.mean(self.returns)) if self.returns else 0.0

    def as_dict(self) -> dict:
        successes = np.asarray(self.successes, dtype=bool).reshape(-1, self.trial_episodes)
        returns = np.asarray(self.returns, dtype=float).reshape(-1, self.trial_episodes)
        lengths = np.asarray(self.lengths, dtype=float).reshape(-1, self.trial_episodes)
        # the adaptation curve: episode k of every trial. Its length too: where episodes end at
        # success (`terminate_on_success`), an agent that returns to a goal it found shows it as
        # shorter later episodes before (or without) a rise in success.
        per_episode = [
            {"episode": k + 1, **_rate(successes[:, k]), "mean_return": float(returns[:, k].mean()) if self.trials else 0.0,
             "mean_length": float(lengths[:, k].mean()) if self.trials else 0.0}
            for k in range(self.trial_episodes)
        ]
        row = {
            "task": self.task,
            "stage": self.stage,
            "split": self.split,
            "trials": self.trials,
            "trial_episodes": self.trial_episodes,
            "episodes": int(successes.size),
            "successes": int(successes.sum()),
            **_rate(successes.ravel()),
            "mean_return": self.mean_return,
            "mean_length": float(lengths.mean()) if lengths.size else 0.0,
            "per_episode": per_episode,
        }
        if self.trial_episodes > 1:
            row["after_first_episode"] = _after_first_episode(successes)
        if self.goals:
            row |= self._by_goal()
        return row

    def _by_goal(self) -> dict:
        """`missed_goals` and every trial's goal, reset seed, start positions and episode outcomes
        (`per_trial`, by seed).

        Why: a success rate says how often, not where. Whether two agents (a planner and the
        prior it starts from, say) fail on the same goals, or whether misses share a place on the
        table, can only be read from the goals themselves; with the seed, any one trial can be
        replayed (`taskforge eval --seed`, trial n resets with seed + n). The positions say where
        without a second simulator: whether the misses of a pick-place run are the high goals, say."""
        positions = self.start_positions or [{}] * self.trials
        trials = sorted(zip(self.seeds, self.goals, positions, self.successes, self.returns, self.lengths), key=lambda t: t[0])
        return {
            "missed_goals": self.missed_goals,
            "per_trial": [{"seed": seed, "goal": goal, **start, "successes": successes, "returns": returns, "lengths": lengths}
                          for seed, goal, start, successes, returns, lengths in trials],
        }


def _after_first_episode(successes: np.ndarray) -> dict[str, dict]:
    """Success in episodes 2..K of the trials whose first episode succeeded (`hit`) and of those
    whose first episode failed (`miss`).

    Why: on a sparse task the mean adaptation curve mixes two behaviours. A deterministic
    memoryless policy repeats its first episode, so it scores exactly 1 after a hit and 0 after
    a miss; an agent that learnt from the trial keeps going back after a hit and searches
    elsewhere after a miss, and only the second number tells it apart from the first."""
    first = successes[:, 0]
    return {
        outcome: {"trials": int(mask.sum()), **_rate(successes[mask, 1:].ravel())}
        for outcome, mask in (("hit", first), ("miss", ~first))
    }


def summarize(results: list[StageResult]) -> dict:
    """One result as its `as_dict()`; several (one per task) as their pooled success over every
    episode (the mean over tasks when each ran as many) with the rows under `tasks`."""
    if len(results) == 1:
        return results[0].as_dict()
    rows = [r.as_dict() for r in results]
    successes = np.concatenate([np.ravel(np.asarray(r.successes, dtype=bool)) for r in results])
    return {
        "task": "all",
        "stage": ", ".join(dict.fromkeys(r.stage for r in results)),
        "split": results[0].split,
        "episodes": int(successes.size),
        "successes": int(successes.sum()),
        **_rate(successes),
        "mean_return": float(np.mean([r.mean_return for r in results])),
        "tasks": rows,
    }


def evaluate(
    agent: Agent,
    task: TaskSpec,
    task_file: str | Path,
    stage: str,
    split: Split,
    trials: int,
    trial_episodes: int | None = None,
    sub_task: str | None = None,
    seed: int = 0,
    parallel: int = 4,
    deterministic: bool = True,
    stop_on_success: bool = False,
) -> StageResult:
    """Run `trials` trials of `stage` (one sub-task of a set, or all), each of `trial_episodes`
    episodes (default: the agent's K, 1 for PPO) on one goal. Sampled actions (`deterministic`
    False) draw from the agent's generator reseeded with `seed`, and its state is restored
    afterwards, so an evaluation during training leaves the training's random stream alone.
    `stop_on_success` ends each episode at its first success (same success rate, fewer steps)."""
    return evaluate_rows(agent, task, task_file, [(stage, sub_task)], split, trials, trial_episodes, seed, parallel,
                         deterministic, stop_on_success)[0]


def evaluate_rows(
    agent: Agent,
    task: TaskSpec,
    task_file: str | Path,
    rows: Sequence[tuple[str, str | None]],
    split: Split,
    trials: int,
    trial_episodes: int | None = None,
    seed: int = 0,
    parallel: int = 4,
    deterministic: bool = True,
    stop_on_success: bool = False,
) -> list[StageResult]:
    """`evaluate` for each (stage, sub-task) of one task in turn, on one set of envs.

    Why one set: a task-set env builds the simulator of every sub-task at construction (its
    physics randomiser needs each model; ~50 MB for a Meta-World env), so four fresh envs per
    sub-task built 400 of them per MT10 evaluation; reused, 40. Every trial
    resets with its own seed, stage, sub-task and goal, so a row's trials do not depend on the rows
    before it."""
    if not rows:
        raise ValueError("nothing to evaluate: no (stage, sub-task) rows")
    k = trial_episodes or agent.spec.trial_episodes
    envs = [trial_env(agent, TaskEnv(task, task_file, stage=rows[0][0], split=split, privileged=agent.privileged_dim > 0,
                                     end_on_success=stop_on_success), k)
            for _ in range(min(parallel, trials))]
    try:
        return [_trials(agent, envs, task.name, stage, sub_task, split, trials, k, seed, deterministic)
                for stage, sub_task in rows]
    finally:
        for env in envs:
            env.close()


def trial_env(agent: Agent, env: gymnasium.Env, trial_episodes: int) -> RL2Trial:
    """`env` (a `TaskEnv`, or a wrapper of one) played in trials of `trial_episodes` episodes as
    the meta-test plays them for `agent`: with RL²'s inputs (previous action, scaled reward,
    episode start) for an RL² agent, the observation unchanged for a memoryless one."""
    scale = agent.spec.rl2.reward_input_scale if agent.spec.rl2 else 1.0
    return RL2Trial(env, trial_episodes, augment=agent.spec.algo == "rl2", reward_scale=scale)


def _trials(
    agent: Agent, envs: list[RL2Trial], task_name: str, stage: str, sub_task: str | None, split: Split,
    trials: int, k: int, seed: int, deterministic: bool,
) -> StageResult:
    """One row: trial n on goal `n mod number-of-goals`, seeded `seed + n`, batched over `envs`."""
    num_goals = envs[0].unwrapped.backend.num_goals(split)
    result = StageResult(sub_task or task_name, stage, split, k)
    queue = list(range(trials))
    playing = [0] * len(envs)  # the trial each env plays
    active = [True] * len(envs)
    obs = np.zeros((len(envs), envs[0].observation_space.shape[0]), dtype=np.float32)
    starts = np.ones(len(envs), dtype=bool)
    positions: list[dict[str, list[float]]] = [{}] * len(envs)  # where the goal and object of each env's trial began

    def start(i: int) -> None:
        n = playing[i] = queue.pop(0)
        options = {"stage": stage, "task": sub_task, "goal_index": n % num_goals}
        obs[i], _ = envs[i].reset(seed=seed + n, options=options)
        starts[i] = True  # a fresh recurrent state for every trial
        features = envs[i].unwrapped.features()
        positions[i] = {name: np.asarray(features[name], dtype=float).round(4).tolist()
                        for name in ("goal_pos", "object_pos") if name in features}

    for i in range(len(envs)):
        start(i)
    state = agent.initial_state(len(envs))
    training_rng = agent.generator.get_state()
    agent.generator.manual_seed(seed)
    while any(active):
        actions, state = agent.act(obs, state, starts, deterministic=deterministic)
        starts[:] = False
        for i, env in enumerate(envs):
            if not active[i]:
                continue
            obs[i], _, trial_over, _, info = env.step(actions[i])
            if trial_over:
                result.successes.append(info["trial_successes"].tolist())
                result.returns.append(info["trial_returns"].tolist())
                result.lengths.append(info["trial_lengths"].tolist())
                result.goals.append(playing[i] % num_goals)
                result.seeds.append(seed + playing[i])
                result.start_positions.append(positions[i])
                if queue:
                    start(i)
                else:
                    active[i] = False
    agent.generator.set_state(training_rng)
    return result
