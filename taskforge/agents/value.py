"""The terminal value of `algo: mpc` (`mpc.terminal_value`): V(s), added to each planned
trajectory's predicted return at its last state, so a plan is scored on more than `horizon` steps.

Why: a planner that sees 10 steps (4 cm of hand travel on Meta-World) of a shaped reward cannot
tell that stepping back from the puck to get behind it pays later; on push it hovered at the
puck (held-out success 0.02 at 200k, benchmarks/RESULTS.md). LOOP (Sikchi et al. 2021) and
TD-MPC (Hansen et al. 2022) close that gap with a value at the horizon's end. Design choices:

* **V of the data, by TD(0)**: `V(s) <- r + discount * V'(s')` on the buffer's transitions,
  the behaviour being the planner's own past (POLO, Lowrey et al. 2019, fits its value to the
  planner's data the same way). No policy network and no Q: the planner is the policy. Even the
  value of a policy that hovers ranks states by the reward they will keep earning, which is
  what a 10-step plan lacks.
* **A target network** (`V'`, Polyak-averaged at `value_tau` per step, DQN/SAC's device) keeps
  the bootstrap target from chasing its own update.
* **Time limits are bootstrapped** (a truncated episode's last state still has a future); like
  the model, V ignores termination (module doc of mpc.py).
* **Outputs in units of 1 / (1 - discount)**: a value is ~that many rewards, so the network's own
  output stays near the reward's scale and trains at the model's step size.
* **Targets within the rewards' range** (`value_bound`, off by default): each TD target clipped
  to `[min r, max r] / (1 - discount)` of the rows fitted (`target_range`, shared with
  policy_value.py's Q).
* **Heads and a lower bound** (`value_ensemble`, `value_pessimism`): `heads` Vs, each fitted on
  its own bootstrap draw against its own target head (Osband et al. 2016's bootstrapped DQN), so
  where the data says little about a state they disagree; a plan's last state is scored by the
  heads' mean minus `pessimism` x their std. Why: the planner searches for the states V scores
  highest, so it finds the ones one V overrates. On push, a V refitted at 100k on data that
  succeeded three times in four held the hand above the puck (held-out 0.72 -> 0.16); refitted
  offline on the same data, one V planned 0.20 of 30 held-out goals, single heads 0.30 and 0.47,
  the 5 heads' mean 0.60 and their lower bound (LOOP's and MOPO's pessimism) 0.53
  (benchmarks/RESULTS.md): the average of draws is what helped there. One head: the V above.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable

import torch
from torch import nn

from taskforge.agents.dynamics import ensemble_mlp, run_mlp


def polyak(slow: Iterable[torch.Tensor], fast: Iterable[torch.Tensor], tau: float) -> None:
    """A target network's step toward its network: slow <- (1 - tau) slow + tau fast (DQN's and
    SAC's device, so a bootstrap target does not chase its own update)."""
    with torch.no_grad():
        for s, f in zip(slow, fast):
            s.lerp_(f, tau)


def target_range(rewards: torch.Tensor, scale: float, bound: bool) -> tuple[float, float]:
    """What a value of these rewards can be, `[min r, max r] * scale` (scale = 1 / (1 - discount)),
    as the TD targets' clamp with `bound` (`mpc.value_bound`); without, (-inf, inf): no clamp.
    Read once per fit (the rows do not change within it). Why: a bootstrap that has begun to
    overestimate feeds its own growth; push seed 0's first Q fit ran to ~12x its rows' worth,
    and the bound is the one thing the data says for certain about any value of it."""
    if not bound:
        return -math.inf, math.inf
    return rewards.min().item() * scale, rewards.max().item() * scale


class TerminalValue(nn.Module):
    """V(s) on standardised observations (statistics refitted with the model's, before each fit),
    as `heads` networks scored together by their mean minus `pessimism` x their std."""

    def __init__(self, obs_size: int, hidden_sizes: list[int], discount: float, tau: float, generator: torch.Generator,
                 heads: int = 1, pessimism: float = 0.0, bound: bool = False):
        super().__init__()
        self.discount, self.tau, self.scale = discount, tau, 1.0 / (1.0 - discount)
        self.heads, self.pessimism, self.bound = heads, pessimism, bound
        self.net = ensemble_mlp(heads, [obs_size, *hidden_sizes], 1, generator)
        self.target = copy.deepcopy(self.net).requires_grad_(False)
        self.register_buffer("obs_mean", torch.zeros(obs_size))
        self.register_buffer("obs_std", torch.ones(obs_size))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """The planner's score of observations `[..., obs]` -> `[...]`: the heads' mean minus `pessimism` x their std (one head: its V)."""
        values = self.each(obs)
        if self.heads == 1:
            return values[0]
        return values.mean(dim=0) - self.pessimism * values.std(dim=0)

    def each(self, obs: torch.Tensor, target: bool = False) -> torch.Tensor:
        """Every head's V of the same observations `[..., obs]` -> `[heads, ...]` (from the
        target heads if `target`)."""
        rows = obs.reshape(1, -1, obs.shape[-1]).expand(self.heads, -1, -1)
        return self._own(rows, target).reshape(self.heads, *obs.shape[:-1])

    def _own(self, obs: torch.Tensor, target: bool = False) -> torch.Tensor:
        """Head h's V of its own rows `obs[h]` (`[heads, batch, obs]` -> `[heads, batch]`)."""
        x = (obs - self.obs_mean) / self.obs_std
        return run_mlp(self.target if target else self.net, x).squeeze(-1) * self.scale

    def fit(self, obs: torch.Tensor, rewards: torch.Tensor, next_obs: torch.Tensor, mean: torch.Tensor, std: torch.Tensor,
            optimizer: torch.optim.Optimizer, updates: int, batch: int, generator: torch.Generator) -> dict[str, float]:
        """`updates` TD(0) steps on random batches of the transitions, each head on its own draw
        against its own target head; the mean loss (in squared value units / scale²), the mean
        value and (with heads) the heads' mean spread, as metrics."""
        self.obs_mean.copy_(mean)
        self.obs_std.copy_(std)
        total, (low, high) = 0.0, target_range(rewards, self.scale, self.bound)
        for _ in range(updates):
            idx = torch.randint(len(rewards), (self.heads, batch), generator=generator).to(obs.device)
            with torch.no_grad():
                target = (rewards[idx] + self.discount * self._own(next_obs[idx], target=True)).clamp(low, high)
            loss = (((self._own(obs[idx]) - target) / self.scale) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item()
            polyak(self.target.parameters(), self.net.parameters(), self.tau)
        with torch.no_grad():
            values = self.each(obs[torch.randint(len(rewards), (min(2048, len(rewards)),), generator=generator).to(obs.device)])
        metrics = {"value_loss": total / updates, "value_mean": values.mean().item()}
        if self.heads > 1:  # where the heads disagree, the planner's score drops by pessimism x this
            metrics["value_head_std"] = values.std(dim=0).mean().item()
        return metrics
