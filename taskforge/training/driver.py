"""The glue between the curriculum scheduler and a vector env of `TaskEnv` workers.

Workers reset themselves (gymnasium autoreset, inside the step that ends an episode), so the
scheduler's choice for a worker's *next* episode is pushed ahead of time into its `next_episode`
attribute. That reset happens before the trainer learns the episode ended, so a choice drawn at
the end of episode k starts episode k+2: a lag of one episode per worker. What an episode
actually ran (phase, stage, sub-task, replay label) comes back in its own `info`, so the driver never
has to track which pushed choice a worker consumed at which reset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from gymnasium.vector import VectorEnv

from taskforge.curriculum import Assignment, CurriculumEvent, CurriculumScheduler


@dataclass
class EpisodeStats:
    """Episodes finished since the last `drain()`, for logging."""

    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)
    successes: list[bool] = field(default_factory=list)
    """Success of each finished episode; for an RL² trial, of its last episode."""
    first_successes: list[bool] = field(default_factory=list)
    """RL² only: success of each finished trial's first episode (before it could adapt)."""
    stages: list[str] = field(default_factory=list)
    unstable: int = 0
    """Episodes cut short because the simulation blew up (`TaskEnv._unstable_step`)."""
    reward_terms: dict[str, list[float]] = field(default_factory=dict)
    """Each reward term's weighted sum over each finished episode that had it (stages differ)."""


class CurriculumDriver:
    def __init__(self, scheduler: CurriculumScheduler, envs: VectorEnv):
        """`envs`: workers that can play every phase of the curriculum (`PhasedEnv`)."""
        self.scheduler = scheduler
        self.envs = envs
        n = envs.num_envs
        self._return = np.zeros(n)
        self._length = np.zeros(n, dtype=int)
        self.stats = EpisodeStats()
        self.new_events: list[CurriculumEvent] = []
        self._next: list[dict] = [{} for _ in range(n)]
        self.push(range(n))

    def _options(self) -> dict:
        assignment = self.scheduler.assign()
        return {"phase": assignment.phase, "stage": assignment.stage, "task": assignment.task, "replay": assignment.replay}

    def push(self, workers) -> None:
        """Draw the next episode of `workers` (all others keep what they were given)."""
        for i in workers:
            self._next[i] = self._options()
        self.envs.set_attr("next_episode", list(self._next))

    def on_step(self, rewards: np.ndarray, terminated: np.ndarray, truncated: np.ndarray, infos: dict) -> None:
        self._return += rewards
        self._length += 1
        done = np.flatnonzero(terminated | truncated)
        if done.size == 0:
            return
        final = infos["final_info"]
        events: list[CurriculumEvent] = []
        for i in done:
            assignment = Assignment(int(final["phase"][i]), str(final["stage"][i]), str(final["task"][i]), bool(final["replay"][i]))
            success = bool(final["episode_success"][i])
            events += self.scheduler.record(assignment, success, int(self._length[i]))
            self.stats.returns.append(float(self._return[i]))
            self.stats.lengths.append(int(self._length[i]))
            self.stats.successes.append(success)
            if "trial_successes" in final:
                self.stats.first_successes.append(bool(final["trial_successes"][i][0]))
            self.stats.stages.append(assignment.stage)
            self.stats.unstable += bool(final.get("unstable", np.zeros(i + 1, bool))[i])
            for term, value in _at(final, "episode_reward_terms", i).items():
                self.stats.reward_terms.setdefault(term, []).append(float(value))
            self._return[i] = 0.0
            self._length[i] = 0
        self.new_events += events
        # A promotion redraws every worker's next episode so none lingers on the old stage.
        self.push(range(self.envs.num_envs) if events else done.tolist())

    def drain(self) -> tuple[EpisodeStats, list[CurriculumEvent]]:
        stats, events = self.stats, self.new_events
        self.stats, self.new_events = EpisodeStats(), []
        return stats, events


def _at(info: dict, key: str, i: int) -> dict[str, float]:
    """Worker i's entry of a nested dict in a vector env's info: gymnasium stacks each sub-key
    into an array with a `_<sub-key>` mask of the workers that had it."""
    nested = info.get(key)
    if not nested:
        return {}
    return {k: v[i] for k, v in nested.items() if not k.startswith("_") and nested.get(f"_{k}", np.ones(i + 1, bool))[i]}
