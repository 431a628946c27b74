"""Every phase of a curriculum behind one worker env, so that one worker can play any phase.

A curriculum's phases are different task files (Meta-World then the xArm7, or the xArm7's
variants: nominal, big cube, high goals, low table). Replay of an earlier phase while the
curriculum is in a later one needs a worker that can run either, episode by episode, without
rebuilding the vector env. `PhasedEnv` holds one `TaskEnv` per phase, built on first use (a
phase the curriculum never reaches costs nothing), and routes each episode to the phase its
options name.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from taskforge.backends import Split
from taskforge.envs.task_env import TaskEnv
from taskforge.spec import TaskSpec


class PhasedEnv(gym.Env[np.ndarray, np.ndarray]):
    """The phases' `TaskEnv`s as one env. `reset(options={"phase": i, ...})`, or the same dict in
    `next_episode` (a vectorised trainer's way, as for `TaskEnv`), plays phase i; the other options
    (stage, task, goal_index, replay, same_task) go to that phase's env unchanged, and `same_task`
    stays in the phase it repeats. Without `phase` the previous episode's phase plays again.
    `info["phase"]` says which phase an episode ran. Every phase must have the same observation and
    action spaces (`probe_phases` checks a curriculum's), since one policy acts in all of them."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        phases: Sequence[tuple[TaskSpec, str | Path]],
        split: Split = "train",
        privileged: bool = False,
        phase: int = 0,
    ):
        if not phases:
            raise ValueError("a PhasedEnv needs at least one phase")
        self._phases = phases
        self._split: Split = split
        self._privileged = privileged
        self._envs: dict[int, TaskEnv] = {}
        self._seeded: set[int] = set()
        self.phase = self._check(phase)
        env = self._env(phase)
        self.observation_space, self.action_space = env.observation_space, env.action_space
        self.next_episode: dict[str, Any] | None = None

    def _check(self, phase: int) -> int:
        if not 0 <= phase < len(self._phases):
            raise ValueError(f"no phase {phase}; this env has phases 0 to {len(self._phases) - 1}")
        return phase

    def _env(self, phase: int) -> TaskEnv:
        if phase not in self._envs:
            task, file = self._phases[phase]
            self._envs[phase] = TaskEnv(task, file, split=self._split, privileged=self._privileged)
        return self._envs[phase]

    @property
    def env(self) -> TaskEnv:
        """The env of the current phase (what the last reset played)."""
        return self._env(self.phase)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or self.next_episode or {})
        if not options.get("same_task"):
            self.phase = self._check(int(options.pop("phase", self.phase)))
        options.pop("phase", None)
        env = self._env(self.phase)
        if seed is None and self.phase not in self._seeded:
            # a phase first played after the vector env's seeded reset: seed it from this env's own
            # stream, so the same seed gives the same run however late a phase starts
            seed = int(self.np_random.integers(2**31))
        self._seeded.add(self.phase)
        obs, info = env.reset(seed=seed, options=options)
        return obs, {**info, "phase": self.phase}

    def step(self, action: np.ndarray):
        obs, reward, terminated, truncated, info = self._env(self.phase).step(action)
        return obs, reward, terminated, truncated, {**info, "phase": self.phase}

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()
