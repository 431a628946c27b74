"""Observation noise, action noise and action latency: the 'unmodelled effects' a policy must
survive on a real robot. Each is reset once per episode from the env's generator."""

from __future__ import annotations

from collections import deque

import numpy as np

from taskforge.randomization.distributions import sample
from taskforge.spec import LatencySpec, NoiseSpec


class AdditiveNoise:
    """`x + per_episode_offset + per_step_draw`; a no-op when neither is configured."""

    def __init__(self, spec: NoiseSpec, size: int):
        self.spec = spec
        self.size = size
        self.enabled = spec.per_step is not None or spec.per_episode is not None
        self._offset = np.zeros(size)

    def reset(self, rng: np.random.Generator) -> None:
        if self.spec.per_episode is not None:
            self._offset = sample(self.spec.per_episode, rng, self.size)

    def __call__(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        if not self.enabled:
            return x
        noisy = x + self._offset
        if self.spec.per_step is not None:
            noisy = noisy + sample(self.spec.per_step, rng, self.size)
        return noisy


class ActionLatency:
    """Applies the action chosen `k` steps ago (`k` drawn per episode); before `k` actions have
    been chosen, the robot holds still (the zero action)."""

    def __init__(self, spec: LatencySpec, size: int):
        self.spec = spec
        self.size = size
        self.steps = 0
        self._queue: deque[np.ndarray] = deque()

    def reset(self, rng: np.random.Generator) -> None:
        self.steps = int(rng.integers(self.spec.min_steps, self.spec.max_steps + 1))
        self._queue = deque(np.zeros(self.size) for _ in range(self.steps))

    def __call__(self, action: np.ndarray) -> np.ndarray:
        if self.steps == 0:
            return action
        self._queue.append(action)
        return self._queue.popleft()
