"""Learning-progress sampling of the sub-tasks of a task set (e.g. the ten envs of MT10).

Why: uniform sampling gives as many episodes to a solved or a hopeless sub-task as to one that is
being learned right now. Following Kanitscheider et al. (2021), *Multi-task curriculum learning in
a complex, visual, hard-exploration domain: Minecraft*, we keep a fast and a slow exponential
moving average (EMA) of episode success for each sub-task. Their absolute difference, the learning
progress (LP), is large where success is changing: rising (being learned) or falling (being
forgotten). It is near zero where success is flat (solved, or still out of reach). Sub-tasks are
drawn in proportion to LP, mixed with a uniform share ε. The ε share works like the
random-sampling share of ALP-GMM (Portelas et al., 2019, *Teacher algorithms for curriculum
learning of Deep RL in continuously parameterized environments*): no sub-task starves, and its
EMAs can still notice when it starts to move.

Choices, and how they differ from the paper:
- α_fast = 0.1 (about the last 10 episodes of that sub-task) and α_slow = 0.01 (about the last 100).
  The slow average must lag the fast one by more than the window noise of binary outcomes.
- Both EMAs start at 0 ("not solved yet"). A sub-task that succeeds from the start therefore looks
  like progress for its first few dozen episodes, as if it had been learned. That is harmless: it is
  sampled a little more until the slow EMA catches up.
- EMAs update once per finished episode of that sub-task, not once per evaluation round of all
  sub-tasks as in the paper. Sub-tasks with many episodes therefore update more often. The ε share
  keeps every sub-task at ≥ ε/n of the episodes.
- The paper's reweighting of success toward low probabilities is optional (`reweight`, its p_θ;
  off by default, which is plain ∝ LP plus ε). Both EMAs pass through
  R(p) = (1 − θ)·p / (p + θ·(1 − 2p)) before they are differenced. R maps [0, 1] onto itself;
  with θ = 0.1 its slope is 9 at p = 0 and 1/9 at p = 1, so the same change in success counts
  about 80 times more near 0 than near 1: episodes go where success is *low and rising*, not to a
  solved task's noise (MT10 from scratch: reach, solved at 0.95, drew most episodes with plain LP).
  On warm-started MT10 it made no measurable difference (RESULTS.md, multi-task).
  θ = 0.5 is the identity. No z-score/sigmoid: proportional sampling is easy to reason about.
- When no sub-task shows progress of at least `MIN_PROGRESS` (one percentage point between the two
  averages), sampling is uniform. Without this floor, LP/ΣLP normalises leftovers: MT10 from scratch
  (benchmarks/RESULTS.md, multi-task) solved reach and drawer-close early, their slow EMAs crept to
  1 (LP ~1e-5) while the eight unsolved tasks had LP exactly 0, so the two solved tasks drew 92 %
  of the episodes at the end of the 2M steps and each unsolved one 1 % (ε/n). As long as one
  sub-task moves by the floor, LP sampling is unchanged.
"""

from __future__ import annotations

import numpy as np

ALPHA_FAST = 0.1
ALPHA_SLOW = 0.01
EPSILON = 0.1
MIN_PROGRESS = 0.01


class LearningProgressSampler:
    """Fast/slow success EMAs per sub-task (by index), and sampling ∝ |fast − slow| with an ε floor."""

    def __init__(
        self,
        num_tasks: int,
        alpha_fast: float = ALPHA_FAST,
        alpha_slow: float = ALPHA_SLOW,
        epsilon: float = EPSILON,
        min_progress: float = MIN_PROGRESS,
        reweight: float | None = None,
    ):
        if num_tasks < 1:
            raise ValueError(f"need at least one sub-task, got {num_tasks}")
        if not 0.0 < alpha_slow < alpha_fast <= 1.0:
            raise ValueError(f"need 0 < alpha_slow < alpha_fast <= 1, got {alpha_slow}, {alpha_fast}")
        if not 0.0 < epsilon <= 1.0:
            raise ValueError(f"need 0 < epsilon <= 1, got {epsilon}")
        if min_progress < 0.0:
            raise ValueError(f"need min_progress >= 0, got {min_progress}")
        if reweight is not None and not 0.0 < reweight <= 0.5:
            raise ValueError(f"need 0 < reweight <= 0.5, got {reweight}")
        self.alpha_fast = alpha_fast
        self.alpha_slow = alpha_slow
        self.epsilon = epsilon
        self.min_progress = min_progress
        self.reweight = reweight
        self._fast = np.zeros(num_tasks)
        self._slow = np.zeros(num_tasks)

    def update(self, task: int, success: bool) -> None:
        outcome = float(success)
        self._fast[task] += self.alpha_fast * (outcome - self._fast[task])
        self._slow[task] += self.alpha_slow * (outcome - self._slow[task])

    def learning_progress(self) -> np.ndarray:
        """|R(fast) − R(slow)|, R the low-success reweighting (identity when `reweight` is None)."""
        return np.abs(self._reweighted(self._fast) - self._reweighted(self._slow))

    def _reweighted(self, p: np.ndarray) -> np.ndarray:
        theta = self.reweight
        if theta is None:
            return p
        return (1.0 - theta) * p / (p + theta * (1.0 - 2.0 * p))

    def probabilities(self) -> np.ndarray:
        """(1 − ε)·LP/ΣLP + ε/n. Uniform while no sub-task's LP reaches `min_progress` (none has
        progressed yet, or every one has settled, solved or not)."""
        progress = self.learning_progress()
        uniform = np.full(progress.size, 1.0 / progress.size)
        if progress.max() < self.min_progress or progress.sum() <= 0.0:
            return uniform
        return (1.0 - self.epsilon) * progress / progress.sum() + self.epsilon * uniform

    def sample(self, rng: np.random.Generator) -> int:
        probabilities = self.probabilities()
        return int(rng.choice(probabilities.size, p=probabilities))

    def state_dict(self) -> dict:
        return {"fast": self._fast.tolist(), "slow": self._slow.tolist()}

    def load_state_dict(self, state: dict) -> None:
        fast = np.asarray(state["fast"], dtype=float)
        slow = np.asarray(state["slow"], dtype=float)
        if fast.shape != self._fast.shape or slow.shape != self._slow.shape:
            raise ValueError(
                f"learning-progress state is for {fast.size} sub-tasks, this sampler has {self._fast.size}"
            )
        self._fast, self._slow = fast, slow
