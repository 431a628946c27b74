"""Running statistics that bring observations and rewards to unit scale for PPO.

PPO's fixed hyperparameters (clip range, learning rate, initial log-std, value-loss weight) assume
inputs and value targets of order one; the environments of a curriculum promise nothing of the
sort, and their scales drift as stages change. The statistics live in float64 torch tensors so
that `state_dict()` loads under `torch.load(weights_only=True)` and a resumed run normalises
exactly as the saved one did.
"""

from __future__ import annotations

import numpy as np
import torch


class RunningMeanStd:
    """Mean and variance of a stream of batches, merged with the parallel update of Chan et al.

    The same algorithm (and the same tiny starting count, which lets the first batch dominate
    without dividing by zero) as gymnasium's `RunningMeanStd`, so numbers are comparable with
    CleanRL runs that use gymnasium's normalisation wrappers.
    """

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4) -> None:
        self.mean = torch.zeros(shape, dtype=torch.float64)
        self.var = torch.ones(shape, dtype=torch.float64)
        self.count = torch.tensor(epsilon, dtype=torch.float64)

    def update(self, batch: torch.Tensor) -> None:
        """Fold in a batch whose first dimension indexes samples."""
        batch = batch.to(torch.float64)
        batch_mean = batch.mean(0)
        batch_var = batch.var(0, unbiased=False)
        batch_count = batch.shape[0]
        delta = batch_mean - self.mean
        total = self.count + batch_count
        self.mean = self.mean + delta * batch_count / total
        m2 = self.var * self.count + batch_var * batch_count + delta.square() * self.count * batch_count / total
        self.var = m2 / total
        self.count = total

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"mean": self.mean.clone(), "var": self.var.clone(), "count": self.count.clone()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        if state["mean"].shape != self.mean.shape:
            raise ValueError(f"normaliser shape {tuple(state['mean'].shape)} != expected {tuple(self.mean.shape)}")
        self.mean = state["mean"].to(torch.float64).clone()
        self.var = state["var"].to(torch.float64).clone()
        self.count = state["count"].to(torch.float64).clone()


class ObservationNormalizer:
    """`clip((x - mean) / std, -10, 10)` with running statistics (continuous details #6 and #7).

    Clipping keeps a rare outlier (a contact spike, a freshly randomised physics draw) from
    saturating the tanh units. With `enabled=False` it only converts to float32, so callers need
    no branch.
    """

    def __init__(self, size: int, enabled: bool, clip: float = 10.0, epsilon: float = 1e-8) -> None:
        self.rms = RunningMeanStd((size,))
        self.enabled = enabled
        self.clip = clip
        self.epsilon = epsilon

    def __call__(self, obs: np.ndarray, update: bool) -> torch.Tensor:
        """Normalise a batch `[n, size]`; `update=False` freezes the statistics (evaluation,
        and final observations that are only used for bootstrapping)."""
        x = torch.as_tensor(np.asarray(obs), dtype=torch.float64)
        if not self.enabled:
            return x.float()
        if update:
            self.rms.update(x)
        normalised = (x - self.rms.mean) / torch.sqrt(self.rms.var + self.epsilon)
        return normalised.clamp(-self.clip, self.clip).float()


class RewardScaler:
    """Divides rewards by the running std of the discounted return, then clips to ±10
    (continuous details #8 and #9).

    Identical to gymnasium 1.x's vector `NormalizeReward` under SAME_STEP autoreset: the
    per-env return accumulator is discounted (cut on termination), fed to the statistics, and
    zeroed once the episode ends either way, because the next reward already belongs to a new
    episode. Only the scale is normalised, never the mean: shifting rewards would change which
    behaviour is optimal when episodes can terminate.
    """

    def __init__(self, num_envs: int, gamma: float, enabled: bool, clip: float = 10.0, epsilon: float = 1e-8) -> None:
        self.rms = RunningMeanStd(())
        self.returns = torch.zeros(num_envs, dtype=torch.float64)
        self.gamma = gamma
        self.enabled = enabled
        self.clip = clip
        self.epsilon = epsilon

    def __call__(self, rewards: np.ndarray, terminated: np.ndarray, truncated: np.ndarray) -> torch.Tensor:
        r = torch.as_tensor(np.asarray(rewards), dtype=torch.float64)
        if not self.enabled:
            return r.float()
        self.returns = self.returns * self.gamma * (1.0 - torch.as_tensor(terminated, dtype=torch.float64)) + r
        self.rms.update(self.returns)
        self.returns[torch.as_tensor(terminated | truncated)] = 0.0
        return (r / torch.sqrt(self.rms.var + self.epsilon)).clamp(-self.clip, self.clip).float()

    def reset(self) -> None:
        """Forget the returns of episodes in flight (the envs were reset)."""
        self.returns.zero_()
