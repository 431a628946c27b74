"""How a diagonal Gaussian policy meets a bounded `Box` action space: `clip` or `squash`.

Both sample a *raw* action `u ~ N(mean, std)` (continuous details #1-#3: Gaussian, state-
independent log-std, independent components) and store `u` in the rollout buffer; they differ in
the map from `u` to the action the env receives, and so in the log-probability PPO's ratio uses.

`clip` is the default (`PolicySpec.action_bounds`) because it is what CleanRL and the 37-details
study validated: the log-prob is that of the unclipped sample (continuous detail #5), the
entropy has a closed form, and the mean's gradient never vanishes. Its bias, probability mass
piled on the bounds, is harmless when the useful actions lie inside the box. `squash` keeps
every sample inside the box and the density exact (tanh with its log-det-Jacobian), at the
price of saturating gradients near the bounds; prefer it when the env punishes actions at the
limits or the box is narrow compared to the initial std.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch.distributions import Normal


def sample_normal(dist: Normal, generator: torch.Generator) -> torch.Tensor:
    """A reparameterised sample `mean + std * eps`, drawn from the agent's own generator so a
    seed fixes the run without touching torch's global RNG."""
    eps = torch.randn(dist.mean.shape, generator=generator, dtype=dist.mean.dtype)
    return dist.mean + dist.stddev * eps


class ClipGaussian:
    """Gaussian in env units, clipped to the box only when sent to the env (CleanRL)."""

    def __init__(self, low: torch.Tensor, high: torch.Tensor) -> None:
        self.low = low
        self.high = high

    def log_prob(self, dist: Normal, raw: torch.Tensor) -> torch.Tensor:
        return dist.log_prob(raw).sum(-1)

    def entropy(self, dist: Normal, generator: torch.Generator) -> torch.Tensor:
        return dist.entropy().sum(-1)

    def to_env(self, raw: torch.Tensor) -> torch.Tensor:
        return torch.clamp(raw, self.low, self.high)

    def from_env(self, action: torch.Tensor) -> torch.Tensor:
        """A raw sample that maps to `action` (itself, for an action inside the box)."""
        return action


class SquashGaussian:
    """`a = center + scale * tanh(u)`: every action inside the box, density corrected.

    `log p(a) = log N(u) - sum_i log|da_i/du_i|` with `da/du = scale * (1 - tanh(u)^2)`. The raw
    `u` is what is stored, so the update never needs `atanh` of a saturated action.
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor) -> None:
        if not (torch.isfinite(low).all() and torch.isfinite(high).all()):
            raise ValueError("action_bounds 'squash' needs a finite action Box (use 'clip' for unbounded actions)")
        self.center = (high + low) / 2.0
        self.scale = (high - low) / 2.0

    def log_abs_det_jacobian(self, raw: torch.Tensor) -> torch.Tensor:
        """Per-component `log|da/du|`; `log(1 - tanh(u)^2)` written as
        `2 * (log 2 - u - softplus(-2u))`, which stays finite for large |u|."""
        return torch.log(self.scale) + 2.0 * (math.log(2.0) - raw - F.softplus(-2.0 * raw))

    def log_prob(self, dist: Normal, raw: torch.Tensor) -> torch.Tensor:
        return (dist.log_prob(raw) - self.log_abs_det_jacobian(raw)).sum(-1)

    def entropy(self, dist: Normal, generator: torch.Generator) -> torch.Tensor:
        """`H(a) = H(u) + E[log|da/du|]`; the expectation has no closed form, so it is estimated
        with one reparameterised sample (as Brax does), which keeps its gradient."""
        return dist.entropy().sum(-1) + self.log_abs_det_jacobian(sample_normal(dist, generator)).sum(-1)

    def to_env(self, raw: torch.Tensor) -> torch.Tensor:
        return self.center + self.scale * torch.tanh(raw)

    def from_env(self, action: torch.Tensor, bound: float = 0.999) -> torch.Tensor:
        """`atanh` of the action in box units; actions on the bounds (common in demonstrations)
        are pulled to `bound` first, where the inverse is finite."""
        return torch.atanh(((action - self.center) / self.scale).clamp(-bound, bound))


GaussianActions = ClipGaussian | SquashGaussian
