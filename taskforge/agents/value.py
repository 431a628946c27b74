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
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from taskforge.agents.dynamics import ensemble_mlp, run_mlp


class TerminalValue(nn.Module):
    """V(s) on standardised observations (statistics refitted with the model's, before each fit)."""

    def __init__(self, obs_size: int, hidden_sizes: list[int], discount: float, tau: float, generator: torch.Generator):
        super().__init__()
        self.discount, self.tau, self.scale = discount, tau, 1.0 / (1.0 - discount)
        self.net = ensemble_mlp(1, [obs_size, *hidden_sizes], 1, generator)
        self.target = copy.deepcopy(self.net).requires_grad_(False)
        self.register_buffer("obs_mean", torch.zeros(obs_size))
        self.register_buffer("obs_std", torch.ones(obs_size))

    def forward(self, obs: torch.Tensor, target: bool = False) -> torch.Tensor:
        """V of observations `[..., obs]` -> `[...]`, from the target network if `target`."""
        x = ((obs - self.obs_mean) / self.obs_std).reshape(1, -1, obs.shape[-1])
        return run_mlp(self.target if target else self.net, x).reshape(obs.shape[:-1]) * self.scale

    def fit(self, obs: torch.Tensor, rewards: torch.Tensor, next_obs: torch.Tensor, mean: torch.Tensor, std: torch.Tensor,
            optimizer: torch.optim.Optimizer, updates: int, batch: int, generator: torch.Generator) -> dict[str, float]:
        """`updates` TD(0) steps on random batches of the transitions; the mean loss (in squared
        value units / scale²) and the mean value, as metrics."""
        self.obs_mean.copy_(mean)
        self.obs_std.copy_(std)
        total = 0.0
        for _ in range(updates):
            idx = torch.randint(len(rewards), (batch,), generator=generator).to(obs.device)
            with torch.no_grad():
                target = rewards[idx] + self.discount * self(next_obs[idx], target=True)
            loss = (((self(obs[idx]) - target) / self.scale) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += loss.item()
            with torch.no_grad():  # Polyak: V' <- (1 - tau) V' + tau V
                for slow, fast in zip(self.target.parameters(), self.net.parameters()):
                    slow.lerp_(fast, self.tau)
        with torch.no_grad():
            value = self(obs[torch.randint(len(rewards), (min(2048, len(rewards)),), generator=generator).to(obs.device)]).mean().item()
        return {"value_loss": total / updates, "value_mean": value}
