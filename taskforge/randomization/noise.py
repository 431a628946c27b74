"""Observation noise, action noise and action latency: the 'unmodelled effects' a policy must
survive on a real robot. Each is reset once per episode from the env's generator."""

from __future__ import annotations

from collections import deque

import numpy as np

from taskforge.randomization.distributions import sample
from taskforge.spec import Distribution, LatencySpec, NoiseSpec


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


class ActionBacklash:
    """The classic backlash (play) operator per action dimension: the output stays put while the
    input moves within ±width/2 of it, and is dragged along, half a width behind, beyond that.
    Policies that chatter around a set point get no motion, as with worn gears or a cable drive.
    The width is drawn once per episode; the output starts at the zero action."""

    def __init__(self, width: Distribution | None, size: int):
        self.width_dist = width
        self.half = np.zeros(size)
        self._out = np.zeros(size)

    def reset(self, rng: np.random.Generator) -> None:
        if self.width_dist is not None:
            self.half = np.maximum(sample(self.width_dist, rng, self.half.size), 0.0) / 2
        self._out = np.zeros_like(self.half)

    def __call__(self, action: np.ndarray) -> np.ndarray:
        if self.width_dist is None:
            return action
        self._out = np.clip(self._out, action - self.half, action + self.half)
        return self._out.copy()
